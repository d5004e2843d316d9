//! The robot client against the real server process: it waits for a server
//! that is not up yet, and its batches survive a server crash exactly once.

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, RetryPolicy, UpdateSenderConfig};
use deog_tests::{ServerProcess, free_loopback_addr};
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_are_resent_after_a_crash_and_applied_exactly_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    let addr = free_loopback_addr();
    let config = ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(50),
            max: Duration::from_millis(500),
            max_attempts: Some(200),
        },
        ..ClientConfig::new(addr.to_string())
    };
    // The client starts first and waits for the server.
    let connecting = tokio::spawn(MapClient::connect(config));
    let server = ServerProcess::start_on(addr, &data, &[]).await;
    let client = connecting
        .await
        .expect("task")
        .expect("connected after retries");

    // Limits this wide are never reached: the map is the exact count of pushes.
    client
        .ensure_map(pb::CreateMapRequest {
            name: "crash".into(),
            tile_size: 8,
            clamp_min_probability: 1e-9,
            clamp_max_probability: 1.0 - 1e-9,
            ..Default::default()
        })
        .await
        .expect("map");
    let size = TileSize::new(8).expect("size");
    let mut sender = client
        .updates(
            "crash",
            "carto/scout-1",
            UpdateSenderConfig {
                max_batch_tiles: 2,
                window: 8,
            },
        )
        .await
        .expect("sender");
    let push = move |i: u32| {
        TileDelta::from_raw(TileKey::new((i % 10) as i32, 0), size, vec![1; 64]).expect("delta")
    };

    for i in 0..500 {
        sender.push(push(i)).await.expect("push");
    }
    // Kill the server with batches unacknowledged; the client keeps pushing
    // (blocking once its window is full) while the server restarts on the
    // same port.
    server.kill();
    let pushing = tokio::spawn(async move {
        for i in 500..1000 {
            sender.push(push(i)).await.expect("push");
        }
        let state = sender.flush().await.expect("flush after restart");
        (sender, state)
    });
    tokio::time::sleep(Duration::from_millis(300)).await;
    let server = ServerProcess::start_on(addr, &data, &[]).await;
    let (sender, state) = pushing.await.expect("pushing task");
    assert!(state.reconnects >= 1, "{state:?}");
    assert!(state.failure.is_none());

    let tiles = client
        .tiles(pb::TileQuery {
            map: "crash".into(),
            selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
                min_x: 0,
                min_y: 0,
                max_x: 79,
                max_y: 7,
            })),
            newer_than_version: 0,
        })
        .await
        .expect("tiles");
    assert_eq!(tiles.len(), 10);
    for tile in tiles {
        let cells: Vec<i16> = tile
            .cells
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        // 1000 pushes over 10 tiles: each cell got +1 exactly 100 times.
        assert!(
            cells.iter().all(|&c| c == 100),
            "tile {:?}: {:?}",
            tile.key,
            &cells[..4]
        );
    }
    // A restarted client continues after the server's cursor.
    drop(sender);
    let again = client
        .updates("crash", "carto/scout-1", UpdateSenderConfig::default())
        .await
        .expect("sender");
    assert_eq!(again.next_sequence(), 501);
    drop(server);
}

#[tokio::test]
async fn connecting_to_nothing_gives_up_with_a_clear_error() {
    let config = ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(10),
            max: Duration::from_millis(20),
            max_attempts: Some(3),
        },
        ..ClientConfig::new(free_loopback_addr().to_string())
    };
    let error = MapClient::connect(config)
        .await
        .expect_err("nothing listens");
    let text = error.to_string();
    assert!(
        text.contains("3 attempts") && text.contains("start one with `deog server"),
        "{text}"
    );
}
