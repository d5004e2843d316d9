//! `deog copy` between two data directories, and from sled to PostgreSQL
//! and back, through the real binary and real servers: what a server held
//! (tiles, cursors, frames, estimates) is what a server on the copy serves;
//! a second copy writes nothing; a store in use and a missing one are
//! refused with a clear line.

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use deog_tests::{ServerProcess, failure, run_deog, succeeded, wander_frames, whole_map};

/// What a server serves: every tile of map "m" (key, version, cells), each
/// robot's frame count, robot r's estimates, and client "c"'s cursor.
async fn contents(
    server: &ServerProcess,
) -> (
    Vec<(i32, i32, u64, Vec<u8>)>,
    Vec<(String, u64)>,
    usize,
    u64,
) {
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("connect");
    let mut tiles: Vec<_> = client
        .tiles(whole_map("m"))
        .await
        .expect("tiles")
        .into_iter()
        .map(|t| {
            let key = t.key.expect("key");
            (key.x, key.y, t.version, t.cells)
        })
        .collect();
    tiles.sort();
    let mut robots: Vec<_> = client
        .robots()
        .await
        .expect("robots")
        .into_iter()
        .map(|r| (r.robot, r.frame_count))
        .collect();
    robots.sort();
    let poses = client.read_poses("r", 0, 0).await.expect("poses").len();
    let cursor = client
        .raw()
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "m".into(),
            client_id: "c".into(),
        })
        .await
        .expect("cursor")
        .into_inner()
        .last_sequence;
    (tiles, robots, poses, cursor)
}

/// Writes map "m" (300 tile deltas from client "c"), 400 frames each of
/// robots r and s, and 30 estimates of r through `server`.
async fn fill(server: &ServerProcess) {
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("connect");
    client
        .ensure_map(pb::CreateMapRequest {
            name: "m".into(),
            tile_size: 16,
            ..Default::default()
        })
        .await
        .expect("map");
    let size = TileSize::new(16).expect("size");
    let mut sender = client
        .updates("m", "c", UpdateSenderConfig::default())
        .await
        .expect("sender");
    for i in 0..300 {
        let cells = (0..256).map(|c| ((i * 7 + c) % 50) as i16 - 25).collect();
        let delta = TileDelta::from_raw(TileKey::new(i % 40, i / 40), size, cells).expect("delta");
        sender.push(delta).await.expect("push");
        if i % 10 == 9 {
            sender.send_batch().await.expect("batch");
        }
    }
    sender.close().await.expect("acknowledged");
    for robot in ["r", "s"] {
        client
            .publish_frames(wander_frames(robot, 2, 400))
            .await
            .expect("frames");
    }
    for sequence in 1..=30 {
        client
            .publish_pose(pb::PoseEstimate {
                robot: "r".into(),
                map: "m".into(),
                frame_sequence: sequence,
                pose: Some(pb::Pose2 {
                    x: 1.0,
                    y: 2.0,
                    theta: 0.5,
                }),
                ..Default::default()
            })
            .await
            .expect("pose");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_copy_serves_what_the_original_served_and_a_second_copy_writes_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (original, copy) = (dir.path().join("original"), dir.path().join("copy"));
    let server = ServerProcess::start(&original, &[]).await;
    fill(&server).await;
    let held = contents(&server).await;
    assert!(
        held.0.len() > 100 && held.1.len() == 2 && held.2 == 30 && held.3 > 0,
        "{:?}",
        (held.0.len(), &held.1, held.2, held.3)
    );

    // A store in use is refused, naming why.
    let (from, to) = (
        original.to_string_lossy().into_owned(),
        copy.to_string_lossy().into_owned(),
    );
    let refused = tokio::task::block_in_place(|| {
        failure(&run_deog(&["copy", "--from", &from, "--to", &to], &[]))
    });
    assert!(refused.contains("in use"), "{refused}");
    assert!(server.terminate());

    let first = tokio::task::block_in_place(|| {
        succeeded(&run_deog(&["copy", "--from", &from, "--to", &to], &[]))
    });
    assert!(first.contains("the same in both stores"), "{first}");
    assert!(first.contains("800 frames written"), "{first}");
    let again = tokio::task::block_in_place(|| {
        succeeded(&run_deog(&["copy", "--from", &from, "--to", &to], &[]))
    });
    assert!(
        again.contains("(0 tiles written)") && again.contains(" 0 frames written"),
        "{again}"
    );

    let served = ServerProcess::start(&copy, &[]).await;
    assert_eq!(contents(&served).await, held);
}

#[test]
fn a_missing_store_or_the_same_one_twice_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().to_string_lossy().into_owned();
    let missing = failure(&run_deog(
        &["copy", "--from", "/nonexistent/deog-data", "--to", &path],
        &[],
    ));
    assert!(missing.contains("no such data directory"), "{missing}");
    let not_a_store = failure(&run_deog(
        &["copy", "--from", &path, "--to", &format!("{path}/copy")],
        &[],
    ));
    assert!(not_a_store.contains("holds no store"), "{not_a_store}");
    assert!(
        std::fs::read_dir(dir.path()).expect("dir").next().is_none(),
        "the folder that was no store was written to"
    );
    std::fs::create_dir(dir.path().join("store")).expect("mkdir");
    std::fs::write(dir.path().join("store/db"), b"").expect("db file");
    let store = dir.path().join("store").to_string_lossy().into_owned();
    let same = failure(&run_deog(&["copy", "--from", &store, "--to", &store], &[]));
    assert!(same.contains("the same store"), "{same}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sled_store_moves_to_postgresql_and_back_whole() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (original, back) = (dir.path().join("original"), dir.path().join("back"));
    let server = ServerProcess::start(&original, &[]).await;
    fill(&server).await;
    let held = contents(&server).await;
    assert!(server.terminate());
    let cluster = tokio::task::block_in_place(deog_pg_cluster::LocalCluster::start)
        .expect("start PostgreSQL");
    let url = tokio::task::block_in_place(|| cluster.create_database("maps")).expect("database");
    let original = original.to_string_lossy().into_owned();

    let moved = tokio::task::block_in_place(|| {
        succeeded(&run_deog(&["copy", "--from", &original, "--to", &url], &[]))
    });
    assert!(moved.contains("the same in both stores"), "{moved}");
    assert!(moved.contains("800 frames written"), "{moved}");
    let again = tokio::task::block_in_place(|| {
        succeeded(&run_deog(&["copy", "--from", &original, "--to", &url], &[]))
    });
    assert!(
        again.contains("(0 tiles written)") && again.contains(" 0 frames written"),
        "{again}"
    );
    let on_postgres = ServerProcess::start(&dir.path().join("unused"), &["--store", &url]).await;
    assert_eq!(contents(&on_postgres).await, held);

    // Out again while a server keeps serving the database.
    let back_path = back.to_string_lossy().into_owned();
    let returned = tokio::task::block_in_place(|| {
        succeeded(&run_deog(
            &["copy", "--from", &url, "--to", &back_path],
            &[],
        ))
    });
    assert!(returned.contains("the same in both stores"), "{returned}");
    let served = ServerProcess::start(&back, &[]).await;
    assert_eq!(contents(&served).await, held);
}
