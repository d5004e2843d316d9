//! The map server on a disk that fills and empties (a small tmpfs, mounted
//! for the test; where mounting is not allowed the test says so and
//! passes): while the store cannot write, health says NOT_SERVING and
//! writes fail with UNAVAILABLE naming the full device; reads show only
//! what is durable (or are refused the same way); once the disk has room the server recovers by
//! itself, and every acknowledged batch is there exactly once.

use std::collections::HashMap;
use std::time::Duration;

use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use deog_tests::{ServerProcess, SmallDisk, wait_for_health};
use tonic::transport::Channel;
use tonic_health::pb::health_check_response::ServingStatus;

const SIDE: usize = 64;
const TILES_PER_BATCH: i32 = 4;

/// Batch `sequence` adds `sequence % 100 + 1` to every cell of tiles
/// (0..4, sequence): each batch's tiles are its own, so a tile holding
/// twice its value was applied twice.
fn batch(sequence: u64) -> pb::UpdateBatch {
    let value = (sequence % 100 + 1) as i16;
    let cells: Vec<u8> = std::iter::repeat_n(value.to_le_bytes(), SIDE * SIDE)
        .flatten()
        .collect();
    pb::UpdateBatch {
        map: "m".into(),
        client_id: "filler".into(),
        sequence,
        tiles: (0..TILES_PER_BATCH)
            .map(|x| pb::TileDelta {
                key: Some(pb::TileKey {
                    x,
                    y: sequence as i32,
                }),
                encoding: pb::CellEncoding::DenseI16Le as i32,
                cells: cells.clone(),
            })
            .collect(),
    }
}

/// Sends one batch on its own stream: its acknowledgement (whether it was
/// applied) or the status that refused it. Bounded: 20 s.
async fn send(
    client: &mut MapServiceClient<Channel>,
    sequence: u64,
) -> Result<bool, tonic::Status> {
    let answer = async {
        let mut stream = client
            .apply_updates(tokio_stream::iter([batch(sequence)]))
            .await?
            .into_inner();
        match stream.message().await? {
            Some(ack) => {
                assert_eq!(ack.sequence, sequence);
                Ok(ack.applied)
            }
            None => panic!("batch {sequence}: the stream ended with no acknowledgement"),
        }
    };
    tokio::time::timeout(Duration::from_secs(20), answer)
        .await
        .unwrap_or_else(|_| panic!("batch {sequence}: no answer within 20 s"))
}

/// Every stored tile's first cell by row (the batch's sequence) and column.
async fn stored(
    client: &mut MapServiceClient<Channel>,
) -> Result<HashMap<(i32, i32), i16>, tonic::Status> {
    let read = async {
        let mut stream = client
            .get_tiles(deog_tests::whole_map("m"))
            .await?
            .into_inner();
        let mut out = HashMap::new();
        while let Some(tile) = stream.message().await? {
            let key = tile.key.expect("key");
            let first = i16::from_le_bytes([tile.cells[0], tile.cells[1]]);
            out.insert((key.x, key.y), first);
        }
        Ok(out)
    };
    tokio::time::timeout(Duration::from_secs(20), read)
        .await
        .expect("tiles within 20 s")
}

/// A map server on a 24 MiB tmpfs with map "m", and a client of it; `None`
/// (saying so) where the test may not mount.
async fn server_on_a_small_disk() -> Option<(SmallDisk, ServerProcess, MapServiceClient<Channel>)> {
    let Some(disk) = SmallDisk::mount("24m") else {
        eprintln!("skipped: this machine does not let the test mount a tmpfs");
        return None;
    };
    let server = ServerProcess::start(&disk.path().join("data"), &[]).await;
    let mut client = MapServiceClient::connect(server.url())
        .await
        .expect("connect");
    client
        .create_map(pb::CreateMapRequest {
            name: "m".into(),
            tile_size: SIDE as u32,
            // Wide enough that no sum here is clamped.
            clamp_min_probability: 1e-9,
            clamp_max_probability: 1.0 - 1e-9,
            ..Default::default()
        })
        .await
        .expect("create map");
    Some((disk, server, client))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_is_reported_refused_and_healed_with_nothing_acknowledged_lost() {
    let Some((disk, server, mut client)) = server_on_a_small_disk().await else {
        return;
    };
    let mut acknowledged = Vec::new();
    for sequence in 1..=10u64 {
        assert!(
            send(&mut client, sequence)
                .await
                .expect("a batch before the disk fills")
        );
        acknowledged.push(sequence);
    }

    assert!(disk.fill() > 0, "the filler took no space");
    let mut refused = None;
    for sequence in 11..=400u64 {
        match send(&mut client, sequence).await {
            Ok(applied) => {
                assert!(applied);
                acknowledged.push(sequence);
            }
            Err(status) => {
                refused = Some((sequence, status));
                break;
            }
        }
    }
    let (first_refused, status) = refused.expect("a full disk refused a write");
    assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
    assert!(
        status.message().contains("cannot write") && status.message().contains("space"),
        "{}",
        status.message()
    );
    wait_for_health(
        &server.url(),
        "deog.v1.MapService",
        ServingStatus::NotServing,
    )
    .await;
    // While it cannot write, a write is refused at once.
    let status = send(&mut client, first_refused)
        .await
        .expect_err("a write while the store is failing");
    assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
    // A read shows what was acknowledged, or is refused while the store
    // is being opened again; it never shows the refused batch's tiles
    // unless they landed after all (then a resend is not applied again).
    match stored(&mut client).await {
        Ok(tiles) => {
            for &sequence in &acknowledged {
                assert_eq!(
                    tiles.get(&(0, sequence as i32)),
                    Some(&((sequence % 100 + 1) as i16)),
                    "acknowledged batch {sequence} while the disk is full"
                );
            }
        }
        Err(status) => {
            assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
            assert!(status.message().contains("space"), "{}", status.message());
        }
    }

    disk.empty();
    wait_for_health(&server.url(), "deog.v1.MapService", ServingStatus::Serving).await;
    // The refused batch again, and more: a refused batch may have reached
    // the disk all the same, and is then acknowledged as already applied.
    for sequence in first_refused..first_refused + 10 {
        send(&mut client, sequence)
            .await
            .expect("a write once the disk has room");
        acknowledged.push(sequence);
    }
    let tiles = stored(&mut client).await.expect("tiles after recovery");
    for &sequence in &acknowledged {
        for x in 0..TILES_PER_BATCH {
            assert_eq!(
                tiles.get(&(x, sequence as i32)),
                Some(&((sequence % 100 + 1) as i16)),
                "tile ({x}, {sequence}): acknowledged batch {sequence} must be there exactly once"
            );
        }
    }
    let last = *acknowledged.last().expect("batches") as i32;
    assert!(
        tiles.keys().all(|&(_, row)| row <= last),
        "a tile of a batch never sent"
    );
    assert!(server.terminate(), "the shutdown after recovery failed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_last_flush_fails_the_shutdown() {
    let Some((disk, server, mut client)) = server_on_a_small_disk().await else {
        return;
    };
    disk.fill();
    let mut failed = false;
    for sequence in 1..=400u64 {
        if send(&mut client, sequence).await.is_err() {
            failed = true;
            break;
        }
    }
    assert!(failed, "a full disk refused a write");
    assert!(
        !server.terminate(),
        "the shutdown on a full disk exited with success"
    );
}
