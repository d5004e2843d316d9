//! The real `deog server` process: acknowledged writes survive SIGKILL, and
//! SIGTERM and ctrl-c shut down cleanly.

use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use deog_tests::ServerProcess;
use std::collections::HashMap;
use tonic::transport::Channel;

const SIDE: usize = 16;

async fn client(server: &ServerProcess) -> MapServiceClient<Channel> {
    MapServiceClient::connect(server.url())
        .await
        .expect("connect")
}

/// The map every batch here writes to.
async fn create_durable_map(map: &mut MapServiceClient<Channel>) {
    map.create_map(pb::CreateMapRequest {
        name: "durable".into(),
        tile_size: SIDE as u32,
        ..Default::default()
    })
    .await
    .expect("create map");
}

/// Batch `i` writes tile (i, 0) with every cell `i % 1000 + 1`, so each
/// acknowledged batch is recognisable afterwards.
fn numbered_batch(i: u64) -> pb::UpdateBatch {
    let value = (i % 1000 + 1) as i16;
    pb::UpdateBatch {
        map: "durable".into(),
        client_id: "writer".into(),
        sequence: i + 1,
        tiles: vec![pb::TileDelta {
            key: Some(pb::TileKey { x: i as i32, y: 0 }),
            encoding: pb::CellEncoding::DenseI16Le as i32,
            cells: std::iter::repeat_n(value.to_le_bytes(), SIDE * SIDE)
                .flatten()
                .collect(),
        }],
    }
}

async fn stored_tiles(client: &mut MapServiceClient<Channel>) -> HashMap<i32, Vec<u8>> {
    let mut stream = client
        .get_tiles(deog_tests::whole_map("durable"))
        .await
        .expect("get tiles")
        .into_inner();
    let mut out = HashMap::new();
    while let Some(tile) = stream.message().await.expect("tile") {
        out.insert(tile.key.expect("key").x, tile.cells);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acknowledged_updates_and_frames_survive_sigkill() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    let server = ServerProcess::start(&data, &[]).await;
    let mut map = client(&server).await;
    create_durable_map(&mut map).await;
    map.publish_frames(pb::PublishFramesRequest {
        frames: (1..=20)
            .map(|s| pb::SonarFrame {
                robot: "scout-1".into(),
                sequence: s,
                time_s: s as f64,
                odometry: Some(pb::Pose2 {
                    x: 0.0,
                    y: 0.0,
                    theta: 0.0,
                }),
                true_pose: None,
                ranges: vec![1.0; 16],
                rig: String::new(),
                reference_pose: None,
            })
            .collect(),
    })
    .await
    .expect("frames stored");

    // Far more batches than will be acknowledged before the kill.
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    let feeder = tokio::spawn(async move {
        for i in 0..5000 {
            if tx.send(numbered_batch(i)).await.is_err() {
                break;
            }
        }
    });
    let mut acks = map
        .apply_updates(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .expect("open stream")
        .into_inner();
    let mut acked = Vec::new();
    while acked.len() < 300 {
        let ack = acks.message().await.expect("ack").expect("stream open");
        assert!(ack.applied);
        acked.push(ack.sequence);
    }
    // Right after the 300th acknowledgement, with batches still in flight.
    server.kill();
    feeder.abort();
    // Acks that were already on the wire count too.
    while let Ok(Some(ack)) = acks.message().await {
        acked.push(ack.sequence);
    }

    let server = ServerProcess::start(&data, &[]).await;
    let mut map = client(&server).await;
    let tiles = stored_tiles(&mut map).await;
    for sequence in &acked {
        let i = sequence - 1;
        let cells = tiles
            .get(&(i as i32))
            .unwrap_or_else(|| panic!("acknowledged batch {sequence} lost"));
        assert_eq!(cells, &numbered_batch(i).tiles[0].cells, "batch {sequence}");
    }
    // Whatever else survived is whole: batches are atomic.
    for (x, cells) in &tiles {
        assert_eq!(cells, &numbered_batch(*x as u64).tiles[0].cells);
    }
    let info = map
        .get_map_info(pb::MapRef {
            name: "durable".into(),
        })
        .await
        .expect("info")
        .into_inner();
    assert_eq!(info.tile_count, tiles.len() as u64);
    assert_eq!(
        info.version,
        tiles.len() as u64,
        "one version per applied batch"
    );
    let cursor = map
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "durable".into(),
            client_id: "writer".into(),
        })
        .await
        .expect("cursor")
        .into_inner();
    assert_eq!(cursor.last_sequence, tiles.len() as u64);
    let robots = map
        .list_robots(pb::ListRobotsRequest {})
        .await
        .expect("robots")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 1);
    assert_eq!(robots[0].frame_count, 20);
    assert!(server.terminate(), "SIGTERM ends the server cleanly");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ctrl_c_stops_the_server_cleanly_and_keeps_what_it_acknowledged() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    let server = ServerProcess::start(&data, &[]).await;
    let mut map = client(&server).await;
    create_durable_map(&mut map).await;
    let batches: Vec<pb::UpdateBatch> = (0..10).map(numbered_batch).collect();
    let mut acks = map
        .apply_updates(tokio_stream::iter(batches))
        .await
        .expect("open stream")
        .into_inner();
    for _ in 0..10 {
        let ack = acks.message().await.expect("ack").expect("stream open");
        assert!(ack.applied);
    }
    drop(acks);
    drop(map);
    assert!(server.interrupt(), "SIGINT ends the server cleanly");

    let server = ServerProcess::start(&data, &[]).await;
    let tiles = stored_tiles(&mut client(&server).await).await;
    assert_eq!(tiles.len(), 10);
    for (x, cells) in &tiles {
        assert_eq!(cells, &numbered_batch(*x as u64).tiles[0].cells);
    }
    assert!(server.terminate());
}
