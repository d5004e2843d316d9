//! Several map servers on one PostgreSQL database, each a real server on
//! real TCP: batches to the same tiles through different servers all land,
//! a resend through another server is not applied twice, and watchers on
//! one server (tiles, poses, frames) hear what was written through another.

#[path = "suite/common/mod.rs"]
mod common;

use common::{TestServer, all_tiles, batch, create_map, dense_delta, send_batches};
use deog_proto::v1 as pb;
use deog_server::{PostgresConfig, ServerConfig};
use std::collections::HashMap;
use std::time::{Duration, Instant};
use tonic_health::pb::health_check_response::ServingStatus;

/// Two servers over one fresh database.
async fn two_servers() -> (TestServer, TestServer, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("shared");
    let first = TestServer::start_postgres_at(path.clone(), ServerConfig::default()).await;
    let second = TestServer::start_postgres_at(path, ServerConfig::default()).await;
    (first, second, dir)
}

/// Watches every tile of map "m" within 1,000 cells of the origin.
async fn watch_map(
    client: &mut deog_proto::v1::map_service_client::MapServiceClient<tonic::transport::Channel>,
    include_cells: bool,
) -> tonic::Streaming<pb::TileEvent> {
    client
        .watch_tiles(pb::WatchTilesRequest {
            map: "m".into(),
            region: Some(pb::CellBox {
                min_x: -1000,
                min_y: -1000,
                max_x: 1000,
                max_y: 1000,
            }),
            include_cells,
        })
        .await
        .expect("watch")
        .into_inner()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_batches_to_the_same_tiles_through_two_servers_all_land() {
    let (first, second, _dir) = two_servers().await;
    let mut admin = first.client().await;
    create_map(&mut admin, "m", 8).await;
    // Four clients, two per server, each adding 1 to every cell of the same
    // four tiles in 40 batches: every cell must end at 160.
    let mut writers = Vec::new();
    for client in 0..4 {
        let server = if client % 2 == 0 { &first } else { &second };
        let mut connection = server.client().await;
        writers.push(tokio::spawn(async move {
            let id = format!("writer-{client}");
            for sequence in 1..=40u64 {
                let tiles = (0..4)
                    .map(|i| dense_delta(i % 2, i / 2, &[1; 64]))
                    .collect();
                let (acks, error) =
                    send_batches(&mut connection, vec![batch("m", &id, sequence, tiles)]).await;
                assert!(error.is_none(), "{id} batch {sequence}: {error:?}");
                assert!(acks[0].applied, "{id} batch {sequence} not applied");
            }
        }));
    }
    for writer in writers {
        writer.await.expect("writer");
    }
    for server in [&first, &second] {
        let mut client = server.client().await;
        let tiles = all_tiles(&mut client, "m").await;
        assert_eq!(tiles.len(), 4);
        for (key, _, cells) in &tiles {
            assert!(
                cells.iter().all(|&c| c == 160),
                "tile {key:?}: a lost update ({:?})",
                &cells[..4]
            );
        }
        let info = client
            .get_map_info(pb::MapRef { name: "m".into() })
            .await
            .expect("map")
            .into_inner();
        assert_eq!(info.version, 160, "one version per applied batch");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_resent_through_another_server_is_not_applied_twice() {
    let (first, second, _dir) = two_servers().await;
    let mut through_first = first.client().await;
    create_map(&mut through_first, "m", 8).await;
    let sent = batch("m", "robot-7", 1, vec![dense_delta(0, 0, &[3; 64])]);
    let (acks, error) = send_batches(&mut through_first, vec![sent.clone()]).await;
    assert!(error.is_none() && acks[0].applied);
    // The first server dies; the client sends the same batch to the second.
    drop(through_first);
    first.stop().await;
    let mut through_second = second.client().await;
    let (acks, error) = send_batches(&mut through_second, vec![sent]).await;
    assert!(error.is_none(), "{error:?}");
    assert!(!acks[0].applied, "a resend must not be applied again");
    let next = batch("m", "robot-7", 2, vec![dense_delta(0, 0, &[1; 64])]);
    let (acks, _) = send_batches(&mut through_second, vec![next]).await;
    assert!(acks[0].applied);
    let tiles = all_tiles(&mut through_second, "m").await;
    assert!(tiles[0].2.iter().all(|&c| c == 4), "{:?}", &tiles[0].2[..4]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchers_on_one_server_hear_writes_made_through_another() {
    let (first, second, _dir) = two_servers().await;
    let mut writer = first.client().await;
    create_map(&mut writer, "m", 8).await;
    let mut watcher = second.client().await;
    let mut tiles = watch_map(&mut watcher, true).await;
    let mut poses = watcher
        .watch_poses(pb::WatchPosesRequest::default())
        .await
        .expect("watch poses")
        .into_inner();
    let mut frames = watcher
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence: 0,
        })
        .await
        .expect("subscribe frames")
        .into_inner();
    // The watch is set up once the second server has heard anything.
    tokio::time::sleep(Duration::from_millis(300)).await;

    let mut latencies = HashMap::new();
    for sequence in 1..=5u64 {
        let sent_at = Instant::now();
        let (acks, _) = send_batches(
            &mut writer,
            vec![batch(
                "m",
                "c",
                sequence,
                vec![dense_delta(sequence as i32, 0, &[2; 64])],
            )],
        )
        .await;
        assert!(acks[0].applied);
        let event = tokio::time::timeout(Duration::from_secs(5), async {
            loop {
                let event = tiles.message().await.expect("stream").expect("event");
                if let Some(pb::tile_event::Event::Changed(tile)) = event.event {
                    return tile;
                }
            }
        })
        .await
        .expect("the second server heard the change");
        latencies.insert(sequence, sent_at.elapsed());
        assert_eq!(
            event.key,
            Some(pb::TileKey {
                x: sequence as i32,
                y: 0
            })
        );
        assert_eq!(event.version, sequence);
    }
    eprintln!("tile change through one server, heard on the other: {latencies:?}");

    writer
        .publish_pose(pb::PoseEstimate {
            robot: "r".into(),
            map: "m".into(),
            frame_sequence: 9,
            pose: Some(pb::Pose2 {
                x: 1.0,
                y: 2.0,
                theta: 0.5,
            }),
            ..Default::default()
        })
        .await
        .expect("pose");
    let pose = tokio::time::timeout(Duration::from_secs(5), poses.message())
        .await
        .expect("the second server heard the estimate")
        .expect("stream")
        .expect("pose");
    assert_eq!((pose.robot.as_str(), pose.frame_sequence), ("r", 9));

    writer
        .publish_frames(pb::PublishFramesRequest {
            frames: (1..=3).map(frame).collect(),
        })
        .await
        .expect("frames");
    for expected in 1..=3 {
        let frame = tokio::time::timeout(Duration::from_secs(5), frames.message())
            .await
            .expect("the second server heard the frame")
            .expect("stream")
            .expect("frame");
        assert_eq!(frame.sequence, expected);
    }
}

/// Frame `sequence` of robot "r", on the Scout's rig.
fn frame(sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: "r".into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pb::Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        }),
        ranges: vec![2.0; 16],
        ..Default::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_notifications_watchers_hear_other_servers_by_polling() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("shared");
    let polling = |url| PostgresConfig {
        poll_changes: true,
        ..PostgresConfig::new(url)
    };
    let first =
        TestServer::start_postgres_with(path.clone(), ServerConfig::default(), polling).await;
    let second = TestServer::start_postgres_with(path, ServerConfig::default(), polling).await;
    let mut writer = first.client().await;
    create_map(&mut writer, "m", 8).await;
    let mut watcher = second.client().await;
    let mut tiles = watch_map(&mut watcher, false).await;
    // Two polls: the first only learns where the map stands.
    tokio::time::sleep(Duration::from_millis(2200)).await;
    let (acks, _) = send_batches(
        &mut writer,
        vec![batch("m", "c", 1, vec![dense_delta(0, 0, &[2; 64])])],
    )
    .await;
    assert!(acks[0].applied);
    let event = tokio::time::timeout(Duration::from_secs(5), tiles.message())
        .await
        .expect("the second server saw the map move")
        .expect("stream")
        .expect("event");
    match event.event {
        Some(pb::tile_event::Event::Resync(resync)) => assert_eq!(resync.map_version, 1),
        other => panic!("expected a resync, got {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn reads_past_the_connection_limit_wait_their_turn_and_writes_go_on() {
    let dir = tempfile::tempdir().expect("temp dir");
    let few = |url| PostgresConfig {
        max_connections: 2,
        ..PostgresConfig::new(url)
    };
    let server =
        TestServer::start_postgres_with(dir.path().join("few"), ServerConfig::default(), few).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    let tiles = (0..40).map(|i| dense_delta(i, 0, &[1; 64])).collect();
    let (acks, _) = send_batches(&mut client, vec![batch("m", "c", 1, tiles)]).await;
    assert!(acks[0].applied);
    let mut readers = Vec::new();
    for reader in 0..8u64 {
        let mut client = server.client().await;
        readers.push(tokio::spawn(async move {
            let tiles = all_tiles(&mut client, "m").await;
            let (acks, error) = send_batches(
                &mut client,
                vec![batch(
                    "m",
                    &format!("r{reader}"),
                    1,
                    vec![dense_delta(0, 1, &[1; 64])],
                )],
            )
            .await;
            assert!(error.is_none(), "{error:?}");
            // The 40 written first, and the one the readers add to.
            (tiles.len() >= 40, acks[0].applied)
        }));
    }
    for reader in readers {
        assert_eq!(reader.await.expect("reader"), (true, true));
    }
    let tiles = all_tiles(&mut client, "m").await;
    let row = tiles
        .iter()
        .find(|(key, _, _)| key.y == 1)
        .expect("tile (0, 1)");
    assert!(row.2.iter().all(|&c| c == 8), "{:?}", &row.2[..4]);
}

/// Polls the server's health until it is `status`, for at most 10 s.
async fn wait_for_status(server: &TestServer, status: ServingStatus) -> bool {
    for _ in 0..100 {
        if server.serving_status().await == Some(status as i32) {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    false
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_with_nothing_to_write_reports_the_database_gone_and_back() {
    let mut cluster = tokio::task::block_in_place(deog_pg_cluster::LocalCluster::start)
        .expect("start PostgreSQL");
    let url = tokio::task::block_in_place(|| cluster.create_database("maps")).expect("database");
    let server = TestServer::start_on_database(&url, ServerConfig::default()).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    let (acks, _) = send_batches(
        &mut client,
        vec![batch("m", "c", 1, vec![dense_delta(0, 0, &[1; 64])])],
    )
    .await;
    assert!(acks[0].applied);

    tokio::task::block_in_place(|| cluster.kill()).expect("kill PostgreSQL");
    let (acks, error) = send_batches(
        &mut client,
        vec![batch("m", "c", 2, vec![dense_delta(0, 0, &[1; 64])])],
    )
    .await;
    assert!(acks.is_empty());
    let error = error.expect("a batch with the database gone is refused");
    assert_eq!(error.code(), tonic::Code::Unavailable, "{error:?}");
    assert!(
        wait_for_status(&server, ServingStatus::NotServing).await,
        "health still says serving with the database gone"
    );

    tokio::task::block_in_place(|| cluster.restart()).expect("restart PostgreSQL");
    assert!(
        wait_for_status(&server, ServingStatus::Serving).await,
        "health never came back"
    );
    let (acks, error) = send_batches(
        &mut client,
        vec![batch("m", "c", 2, vec![dense_delta(0, 0, &[1; 64])])],
    )
    .await;
    assert!(error.is_none() && acks[0].applied, "{error:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn long_reads_come_whole_and_in_order_across_pages() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server =
        TestServer::start_postgres_at(dir.path().join("pages"), ServerConfig::default()).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    // 40 x 30 tiles: several pages of 256 whichever way they are cut.
    let batches = (0..30)
        .map(|y| {
            let tiles = (-20..20).map(|x| dense_delta(x, y, &[1; 64])).collect();
            batch("m", "c", y as u64 + 1, tiles)
        })
        .collect();
    let (acks, error) = send_batches(&mut client, batches).await;
    assert!(error.is_none() && acks.len() == 30, "{error:?}");
    let whole = all_tiles(&mut client, "m").await;
    let keys: Vec<(i32, i32)> = whole.iter().map(|(k, _, _)| (k.x, k.y)).collect();
    let mut expected: Vec<(i32, i32)> = (-20..20)
        .flat_map(|x| (0..30).map(move |y| (x, y)))
        .collect();
    expected.sort_unstable();
    assert_eq!(keys, expected, "every tile once, in key order");

    // A box of tiles x -15..=14, y 3..=27 (cells of 8-cell tiles).
    let mut stream = client
        .get_tiles(pb::TileQuery {
            map: "m".into(),
            selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
                min_x: -15 * 8,
                min_y: 3 * 8,
                max_x: 14 * 8 + 7,
                max_y: 27 * 8 + 7,
            })),
            newer_than_version: 0,
        })
        .await
        .expect("get tiles")
        .into_inner();
    let mut boxed = Vec::new();
    while let Some(tile) = stream.message().await.expect("tile") {
        let key = tile.key.expect("key");
        boxed.push((key.x, key.y));
    }
    let expected: Vec<(i32, i32)> = (-15..15)
        .flat_map(|x| (3..28).map(move |y| (x, y)))
        .collect();
    assert_eq!(boxed, expected);

    client
        .publish_frames(pb::PublishFramesRequest {
            frames: (1..=700).map(frame).collect(),
        })
        .await
        .expect("frames");
    let mut read = client
        .read_frames(pb::ReadFramesRequest {
            robot: "r".into(),
            from_sequence: 100,
            to_sequence: 650,
            limit: 0,
        })
        .await
        .expect("read frames")
        .into_inner();
    let mut sequences = Vec::new();
    while let Some(frame) = read.message().await.expect("frame") {
        sequences.push(frame.sequence);
    }
    assert_eq!(sequences, (100..=650).collect::<Vec<u64>>());
}
