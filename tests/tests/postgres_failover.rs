//! Failover: two map servers share a PostgreSQL primary that has a
//! synchronous streaming standby, and both are given both addresses. Writers
//! stream batches through the robot client to both servers while the
//! primary is killed with SIGKILL and the standby promoted. The servers
//! recover by themselves, the writes land again, and at the end every batch
//! the writers were told is acknowledged is stored exactly once.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_pg_cluster::{ClusterOptions, LocalCluster, Replication};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, RetryPolicy, UpdateSenderConfig};
use deog_tests::{ServerProcess, health_status, wait_for_health};
use tonic_health::pb::health_check_response::ServingStatus;

/// Writers, spread over the two servers: writer `w` talks to server `w % 2`.
const WRITERS: usize = 4;
const SIDE: u32 = 8;
const MAP: &str = "failover";
/// How long the servers may take to write again after the primary dies.
const FAILOVER_LIMIT: Duration = Duration::from_secs(30);

fn client_config(addr: std::net::SocketAddr) -> ClientConfig {
    ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(50),
            max: Duration::from_millis(250),
            max_attempts: Some(400),
        },
        ..ClientConfig::new(addr.to_string())
    }
}

fn client_id(w: usize) -> String {
    format!("failover/{w}")
}

/// What a writer did: tiles pushed (tile (i, w) for i below it, each +1
/// in every cell, each in exactly one batch) and the acknowledgements.
#[derive(Debug)]
struct Written {
    pushed: u32,
    last_acked: u64,
    duplicates: u64,
    reconnects: u64,
}

/// Writer `w` pushes +1 to every cell of tile (i, w) for i = 0, 1, ...
/// until `stop`, then flushes. After each push it publishes the highest
/// acknowledged sequence in `acked`.
async fn write(
    client: MapClient,
    w: usize,
    acked: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) -> Written {
    let size = TileSize::new(SIDE).expect("size");
    let mut sender = client
        .updates(
            MAP,
            &client_id(w),
            UpdateSenderConfig {
                max_batch_tiles: 4,
                window: 8,
            },
        )
        .await
        .expect("sender");
    let mut pushed = 0u32;
    while !stop.load(Ordering::Relaxed) {
        let key = TileKey::new(pushed as i32, w as i32);
        let delta = TileDelta::from_raw(key, size, vec![1; size.area()]).expect("delta");
        sender.push(delta).await.expect("push");
        pushed += 1;
        acked.store(sender.acks().last_acked, Ordering::Relaxed);
        tokio::time::sleep(Duration::from_millis(3)).await;
    }
    let state = tokio::time::timeout(Duration::from_secs(60), sender.flush())
        .await
        .expect("the last batches acknowledged within 60 s")
        .expect("flush");
    assert!(state.failure.is_none(), "writer {w}: {state:?}");
    assert_eq!(state.last_acked, sender.next_sequence() - 1);
    Written {
        pushed,
        last_acked: state.last_acked,
        duplicates: state.duplicates,
        reconnects: state.reconnects,
    }
}

/// Waits (bounded) until `done` holds, polling; the time it took, or
/// `None` if it never held within `limit`.
async fn time_until(limit: Duration, done: impl Fn() -> bool) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if done() {
            return Some(start.elapsed());
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    None
}

fn snapshot(acked: &[Arc<AtomicU64>]) -> Vec<u64> {
    acked.iter().map(|a| a.load(Ordering::Relaxed)).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acknowledged_batches_survive_a_failover_to_a_synchronous_standby_exactly_once() {
    let test_started = Instant::now();
    // A SIGKILL leaves the page cache, so fsync buys nothing here; commits
    // still wait for the standby (synchronous_commit stays on).
    let mut primary = LocalCluster::start_with(&ClusterOptions {
        fsync: false,
        ..ClusterOptions::default()
    })
    .expect("primary");
    let standby = primary
        .start_standby(Replication::Synchronous)
        .expect("standby");
    primary.create_database(MAP).expect("database");
    let url = format!(
        "postgres://deog@127.0.0.1:{},127.0.0.1:{}/{MAP}?target_session_attrs=read-write",
        primary.port(),
        standby.port()
    );

    eprintln!(
        "primary and synchronous standby up after {:?}",
        test_started.elapsed()
    );

    let scratch = tempfile::tempdir().expect("temp dir");
    let mut servers = Vec::new();
    // One after the other: the first creates the schema.
    for name in ["a", "b"] {
        servers.push(ServerProcess::start(&scratch.path().join(name), &["--store", &url]).await);
    }
    eprintln!("servers up after {:?}", test_started.elapsed());
    let mut clients = Vec::new();
    for server in &servers {
        clients.push(
            MapClient::connect(client_config(server.addr))
                .await
                .expect("connect"),
        );
    }
    // Limits this wide are never reached: each tile is its pushes' count.
    clients[0]
        .ensure_map(pb::CreateMapRequest {
            name: MAP.into(),
            tile_size: SIDE,
            clamp_min_probability: 1e-9,
            clamp_max_probability: 1.0 - 1e-9,
            ..Default::default()
        })
        .await
        .expect("map");

    eprintln!("map made after {:?}", test_started.elapsed());
    let stop = Arc::new(AtomicBool::new(false));
    let acked: Vec<Arc<AtomicU64>> = (0..WRITERS).map(|_| Arc::default()).collect();
    let mut writers: Vec<_> = (0..WRITERS)
        .map(|w| {
            let client = clients[w % servers.len()].clone();
            tokio::spawn(write(client, w, acked[w].clone(), stop.clone()))
        })
        .collect();

    // Mid-write: every writer has had batches acknowledged.
    time_until(Duration::from_secs(30), || {
        snapshot(&acked).iter().all(|&a| a >= 10)
    })
    .await
    .expect("every writer's first batches acknowledged within 30 s");

    eprintln!(
        "writing; killing the primary {:?} into the test",
        test_started.elapsed()
    );
    let killed_at = Instant::now();
    primary.kill().expect("kill the primary");
    // The servers notice while only the read-only standby is left, as
    // before any real failover: a server whose commit failed says it is
    // not serving. Waited for, but not required: a server whose writer
    // was idle at the kill stays serving, since its next batches fail
    // earlier, reading the map, and never reach its writer.
    let mut noticed = false;
    for _ in 0..100 {
        for server in &servers {
            noticed |= health_status(&server.url(), "deog.v1.MapService").await
                == Some(ServingStatus::NotServing);
        }
        if noticed {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let noticed_after = killed_at.elapsed();
    // What was acknowledged by now was committed before the kill.
    let before_failover = snapshot(&acked);
    let promoting_at = Instant::now();
    standby.promote().expect("promote the standby");
    let promoted_after = killed_at.elapsed();
    let advanced = |all: bool| {
        let now = snapshot(&acked);
        let mut moved = now.iter().zip(&before_failover).map(|(n, b)| n > b);
        if all {
            moved.all(|m| m)
        } else {
            moved.any(|m| m)
        }
    };
    let first_landed = time_until(FAILOVER_LIMIT, || advanced(false))
        .await
        .map(|_| (promoting_at.elapsed(), killed_at.elapsed()))
        .unwrap_or_else(|| panic!("no write landed within {FAILOVER_LIMIT:?} of the promotion"));
    let all_landed = time_until(FAILOVER_LIMIT, || {
        advanced(true) || writers.iter().any(|w| w.is_finished())
    })
    .await
    .map(|_| promoting_at.elapsed())
    .unwrap_or_else(|| {
        panic!(
            "not every writer wrote again within {FAILOVER_LIMIT:?}: {:?} then {:?}",
            before_failover,
            snapshot(&acked)
        )
    });
    // A writer that ended early failed (its sender gave up): say why.
    if let Some(at) = writers.iter().position(|w| w.is_finished()) {
        let ended = writers.remove(at).await;
        panic!("writer {at} ended during the failover: {ended:?}");
    }
    for server in &servers {
        wait_for_health(&server.url(), "deog.v1.MapService", ServingStatus::Serving).await;
    }
    eprintln!(
        "failover: a server not serving: {noticed} ({noticed_after:?} after the kill), standby \
         promoted after {promoted_after:?}; the first write landed {:?} after the \
         promotion ({:?} after the kill), every writer's {all_landed:?} after the promotion",
        first_landed.0, first_landed.1
    );

    // Writes go on on the new primary.
    let after_failover = snapshot(&acked);
    time_until(Duration::from_secs(30), || {
        snapshot(&acked)
            .iter()
            .zip(&after_failover)
            .all(|(n, b)| *n >= b + 10)
    })
    .await
    .expect("every writer goes on writing after the failover");
    stop.store(true, Ordering::Relaxed);
    let mut written = Vec::new();
    for writer in writers {
        written.push(writer.await.expect("writer task"));
    }
    for (w, done) in written.iter().enumerate() {
        assert!(
            done.reconnects >= 1,
            "writer {w} never reconnected: {done:?}"
        );
    }
    eprintln!(
        "writers: {written:?}; {} batches committed but not acknowledged before the \
         failover were resent and acknowledged as duplicates",
        written.iter().map(|w| w.duplicates).sum::<u64>()
    );

    // Every server reads the same map: each pushed tile exactly once.
    let mut seen = Vec::new();
    for client in &clients {
        seen.push(check_exactly_once(client, &written).await);
    }
    assert_eq!(seen[0], seen[1], "the two servers read different maps");
    for (w, done) in written.iter().enumerate() {
        for client in &clients {
            assert_eq!(
                client
                    .update_cursor(MAP, &client_id(w))
                    .await
                    .expect("cursor"),
                done.last_acked,
                "writer {w}'s cursor"
            );
        }
    }
    assert_eq!(
        standby
            .psql(MAP, "SELECT pg_is_in_recovery()")
            .expect("psql"),
        "f"
    );
    for server in servers {
        assert!(server.terminate(), "a server's shutdown failed");
    }
    eprintln!("the whole test took {:?}", test_started.elapsed());
}

/// Reads every tile of the map through `client` and checks that each
/// tile a writer pushed holds 1 in every cell (applied once: neither lost
/// nor applied again), and that there is no other tile. Returns the tiles'
/// versions, by key, to compare servers.
async fn check_exactly_once(client: &MapClient, written: &[Written]) -> Vec<(i32, i32, u64)> {
    let tiles = client
        .tiles(deog_tests::whole_map(MAP))
        .await
        .expect("tiles");
    let expected: u32 = written.iter().map(|w| w.pushed).sum();
    assert!(expected > 200, "the writers pushed only {written:?}");
    let mut seen = Vec::new();
    for tile in &tiles {
        let key = tile.key.expect("key");
        let (x, w) = (key.x, key.y);
        assert!(
            (0..WRITERS as i32).contains(&w) && x >= 0 && (x as u32) < written[w as usize].pushed,
            "tile ({x}, {w}) was never pushed"
        );
        let cells = deog_tests::tile_cells(tile);
        assert!(
            cells.len() == (SIDE * SIDE) as usize && cells.iter().all(|&c| c == 1),
            "tile ({x}, {w}) was applied {} times",
            cells.first().copied().unwrap_or(0)
        );
        seen.push((x, w, tile.version));
    }
    assert_eq!(
        tiles.len() as u32,
        expected,
        "acknowledged tiles missing: {written:?}"
    );
    seen.sort_unstable();
    seen
}
