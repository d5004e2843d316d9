//! `UpdateSender` against a real map server on 127.0.0.1: a batch the server
//! cannot read, or a sequence no batch may carry, is an error the sender
//! reports, never a clean end.

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientError, UpdateSenderConfig};
use deog_server::{Limits, ServerConfig};
use std::time::Duration;

use crate::common::Server;

const MAP: &str = "errors";
/// Cells per tile side: 64 x 64 cells are 8 KiB a tile when dense.
const SIDE: u32 = 64;

/// The common server with the test map created.
async fn server_with_map(config: ServerConfig) -> Server {
    Server::with_map(config, MAP, SIDE).await
}

/// A delta of `value` in every cell of tile (x, 0).
fn full_delta(x: i32, value: i16) -> TileDelta {
    let size = TileSize::new(SIDE).expect("size");
    TileDelta::from_raw(TileKey::new(x, 0), size, vec![value; size.area()]).expect("delta")
}

async fn stored_keys(server: &Server) -> Vec<(i32, i32)> {
    server
        .client
        .tiles(pb::TileQuery {
            map: MAP.into(),
            selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
                min_x: -10_000,
                min_y: -10_000,
                max_x: 10_000,
                max_y: 10_000,
            })),
            newer_than_version: 0,
        })
        .await
        .expect("tiles")
        .iter()
        .filter_map(|t| t.key.map(|k| (k.x, k.y)))
        .collect()
}

#[tokio::test]
async fn a_batch_over_the_transport_limit_fails_the_sender_naming_the_problem() {
    let limits = Limits {
        max_message_bytes: 64 << 10,
        ..Default::default()
    };
    let transport_limit = limits.transport_message_bytes();
    let server = server_with_map(ServerConfig {
        limits,
        ..Default::default()
    })
    .await;
    let mut sender = server
        .client
        .updates(
            MAP,
            "carto",
            UpdateSenderConfig {
                max_batch_tiles: 4096,
                window: 8,
            },
        )
        .await
        .expect("sender");

    sender.push(full_delta(0, 5)).await.expect("push");
    sender.send_batch().await.expect("first batch");
    // Dense tiles of 8 KiB each, past the transport's limit together.
    let tiles = transport_limit / (2 * (SIDE * SIDE) as usize) + 2;
    for x in 1..=tiles as i32 {
        sender.push(full_delta(x, 5)).await.expect("push");
    }
    sender.send_batch().await.expect("oversize batch queued");
    sender.push(full_delta(-1, 5)).await.expect("push");
    let flushed = tokio::time::timeout(Duration::from_secs(20), sender.flush())
        .await
        .expect("the sender must fail, not retry without end");

    let error = flushed.expect_err("an unreadable batch must fail the sender");
    let ClientError::Updates(message) = &error else {
        panic!("expected an update failure, got {error:?}");
    };
    assert!(
        message.contains("batch 2") && message.contains("too large"),
        "the failure should name the batch and the reason: {message:?}"
    );
    let acks = sender.acks();
    assert_eq!((acks.last_acked, acks.applied), (1, 1), "{acks:?}");
    assert_eq!(stored_keys(&server).await, [(0, 0)]);
}

#[tokio::test]
async fn the_sender_never_numbers_a_batch_u64_max() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server
        .client
        .updates(MAP, "carto", UpdateSenderConfig::default())
        .await
        .expect("sender");
    sender.push(full_delta(0, 5)).await.expect("push");
    let error = sender
        .send_batch_as(u64::MAX)
        .await
        .expect_err("u64::MAX is no batch sequence");
    assert!(matches!(error, ClientError::Config(_)), "{error:?}");
    sender
        .send_batch_as(u64::MAX - 1)
        .await
        .expect("the highest sequence");
    let acks = sender.flush().await.expect("flushed");
    assert_eq!((acks.last_acked, acks.applied), (u64::MAX - 1, 1));
    sender.push(full_delta(1, 5)).await.expect("push");
    let error = sender
        .send_batch()
        .await
        .expect_err("no batch can follow u64::MAX - 1");
    assert!(matches!(error, ClientError::Config(_)), "{error:?}");
    assert_eq!(stored_keys(&server).await, [(0, 0)]);
}
