//! Chaos: writers stream batches through the robot client while the map
//! server is killed with SIGKILL and restarted several times, and its disk
//! (a small tmpfs) fills and empties under it. At the end every batch the
//! writers were told is acknowledged is stored exactly once.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, RetryPolicy, UpdateSenderConfig};
use deog_tests::{ServerProcess, SmallDisk, free_loopback_addr, wait_for_health};
use tonic_health::pb::health_check_response::ServingStatus;

const WRITERS: i32 = 2;
const SIDE: u32 = 8;

fn client_config(addr: std::net::SocketAddr) -> ClientConfig {
    ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(50),
            max: Duration::from_millis(500),
            max_attempts: Some(400),
        },
        ..ClientConfig::new(addr.to_string())
    }
}

/// Writer `w` pushes +1 to every cell of tile (i, w) for i = 0, 1, ...
/// until `stop`, then flushes; returns how many tiles it pushed.
async fn write(client: MapClient, w: i32, stop: Arc<AtomicBool>) -> u32 {
    let size = TileSize::new(SIDE).expect("size");
    let mut sender = client
        .updates(
            "chaos",
            &format!("chaos/{w}"),
            UpdateSenderConfig {
                max_batch_tiles: 4,
                window: 8,
            },
        )
        .await
        .expect("sender");
    let mut pushed = 0u32;
    while !stop.load(Ordering::Relaxed) {
        let delta = TileDelta::from_raw(TileKey::new(pushed as i32, w), size, vec![1; size.area()])
            .expect("delta");
        sender.push(delta).await.expect("push");
        pushed += 1;
        tokio::time::sleep(Duration::from_millis(3)).await;
    }
    let state = tokio::time::timeout(Duration::from_secs(120), sender.flush())
        .await
        .expect("the last batches acknowledged within 120 s")
        .expect("flush");
    assert!(state.failure.is_none(), "writer {w}: {state:?}");
    assert!(
        state.reconnects >= 1,
        "writer {w} never reconnected: {state:?}"
    );
    pushed
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acknowledged_batches_survive_kills_and_a_full_disk_exactly_once() {
    let disk = SmallDisk::mount("64m");
    let scratch = tempfile::tempdir().expect("temp dir");
    let data = match &disk {
        Some(disk) => disk.path().join("data"),
        None => {
            eprintln!("this machine does not let the test mount a tmpfs: kills only");
            scratch.path().join("data")
        }
    };
    let addr = free_loopback_addr();
    let mut server = ServerProcess::start_on(addr, &data, &[]).await;
    let client = MapClient::connect(client_config(addr))
        .await
        .expect("connect");
    // Limits this wide are never reached: each tile is its pushes' count.
    client
        .ensure_map(pb::CreateMapRequest {
            name: "chaos".into(),
            tile_size: SIDE,
            clamp_min_probability: 1e-9,
            clamp_max_probability: 1.0 - 1e-9,
            ..Default::default()
        })
        .await
        .expect("map");
    let stop = Arc::new(AtomicBool::new(false));
    let writers: Vec<_> = (0..WRITERS)
        .map(|w| {
            let client = client.clone();
            tokio::spawn(write(client, w, stop.clone()))
        })
        .collect();

    for _ in 0..3 {
        tokio::time::sleep(Duration::from_millis(1500)).await;
        server.kill();
        tokio::time::sleep(Duration::from_millis(300)).await;
        server = ServerProcess::start_on(addr, &data, &[]).await;
    }
    if let Some(disk) = &disk {
        tokio::time::sleep(Duration::from_millis(1000)).await;
        disk.fill();
        wait_for_health(
            &server.url(),
            "deog.v1.MapService",
            ServingStatus::NotServing,
        )
        .await;
        tokio::time::sleep(Duration::from_millis(1500)).await;
        disk.empty();
        wait_for_health(&server.url(), "deog.v1.MapService", ServingStatus::Serving).await;
    }
    tokio::time::sleep(Duration::from_millis(1000)).await;
    server.kill();
    server = ServerProcess::start_on(addr, &data, &[]).await;
    tokio::time::sleep(Duration::from_millis(1000)).await;
    stop.store(true, Ordering::Relaxed);
    let mut pushed = Vec::new();
    for writer in writers {
        pushed.push(writer.await.expect("writer task"));
    }

    let tiles = client
        .tiles(deog_tests::whole_map("chaos"))
        .await
        .expect("tiles");
    let stored = tiles.len();
    let expected: u32 = pushed.iter().sum();
    assert!(expected > 500, "the writers pushed only {pushed:?}");
    for tile in tiles {
        let key = tile.key.expect("key");
        let (x, w) = (key.x, key.y);
        assert!(
            (0..WRITERS).contains(&w) && x >= 0 && (x as u32) < pushed[w as usize],
            "tile ({x}, {w}) was never pushed"
        );
        let cells = deog_tests::tile_cells(&tile);
        assert!(
            cells.len() == (SIDE * SIDE) as usize && cells.iter().all(|&c| c == 1),
            "tile ({x}, {w}) was applied {} times",
            cells.first().copied().unwrap_or(0)
        );
    }
    assert_eq!(
        stored as u32, expected,
        "acknowledged tiles missing: {pushed:?} pushed"
    );
    assert!(server.terminate(), "the last shutdown failed");
}
