//! Three cartographers, one per robot, build one map at the same time, each
//! its own `deog map` process. docs/ARCHITECTURE.md promises that the map
//! equals the batches applied one at a time in the server's commit order
//! (the order of the map versions in their acknowledgements); with log-odds
//! clamping that order matters, so the same frames fed one robot after
//! another give a map that equals *its* replay, observes the same cells, and
//! may differ only where clamping met a different order.

use deog_grid::{
    ClampLimits, FrameIntegrator, Pose2, Resolution, SensorRing, SonarModel, SonarModelParams,
    TileDelta, TileKey, TileMap, TileSize,
};
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, wander_frames};
use std::collections::HashMap;
use std::path::Path;
use std::process::{Child, Command, Stdio};

const ROBOTS: [&str; 3] = ["r1", "r2", "r3"];
const FRAMES: usize = 80;
/// The sonar model's Max_occupied the cartographers run with.
const MAX_OCCUPIED: f64 = 0.6;

fn start_cartographer(server: &ServerProcess, robot: &str, map: &str, log: &Path) -> Child {
    Command::new(deog_binary())
        .args(["map", "--robot", robot, "--map", map, "--idle-exit", "1"])
        .args(["--max-occupied", &MAX_OCCUPIED.to_string()])
        // The thesis's method: a frame's deltas then depend on the frame
        // alone, not on what the other cartographers wrote before it.
        .args(["--sonar-method", "thesis"])
        .args(["--batch-frames", "1", "--ack-log"])
        .arg(log)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .spawn()
        .expect("start deog map")
}

fn wait(child: Child) {
    let output = child.wait_with_output().expect("deog map runs");
    assert!(output.status.success(), "deog map failed");
}

/// (map version, robot, batch sequence) of every applied batch.
fn read_log(path: &Path, robot: &str) -> Vec<(u64, String, u64)> {
    std::fs::read_to_string(path)
        .expect("ack log")
        .lines()
        .map(|line| {
            let parts: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(parts.len(), 3, "{line}");
            assert_eq!(parts[2], "true", "every batch applied once: {line}");
            (
                parts[1].parse().expect("version"),
                robot.to_string(),
                parts[0].parse().expect("sequence"),
            )
        })
        .collect()
}

/// The map's cells as the server holds them.
async fn server_cells(client: &MapClient, map: &str) -> HashMap<TileKey, Vec<i16>> {
    let (_, tiles) = client.download(map).await.expect("download");
    tiles
        .tiles()
        .map(|(k, t)| (*k, t.raw_cells().to_vec()))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_cartographers_equal_their_commit_order_replay() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    let mut frames = HashMap::new();
    for (i, robot) in ROBOTS.iter().enumerate() {
        let robot_frames = wander_frames(robot, 40 + i as u64, FRAMES);
        client
            .publish_frames(robot_frames.clone())
            .await
            .expect("publish");
        frames.insert(robot.to_string(), robot_frames);
    }

    // Together: three processes at once.
    let logs = |map: &str, robot: &str| dir.path().join(format!("{map}-{robot}.log"));
    let children: Vec<Child> = ROBOTS
        .iter()
        .map(|r| start_cartographer(&server, r, "together", &logs("together", r)))
        .collect();
    children.into_iter().for_each(wait);
    // One after another.
    for robot in ROBOTS {
        wait(start_cartographer(
            &server,
            robot,
            "apart",
            &logs("apart", robot),
        ));
    }

    // Each frame's deltas, computed here as the cartographer does.
    let info = client.map_info("together").await.expect("info");
    let size = TileSize::new(info.tile_size).expect("size");
    let resolution = Resolution::new(info.resolution_m).expect("resolution");
    let limits =
        ClampLimits::from_probabilities(info.clamp_min_probability, info.clamp_max_probability)
            .expect("limits");
    let model = SonarModel::new(SonarModelParams {
        max_occupied: MAX_OCCUPIED,
        ..deog_mapping::mapping_sonar_model()
    })
    .expect("model");
    let mut integrator = FrameIntegrator::new(model, SensorRing::scout(), resolution, size);
    let mut deltas: HashMap<(String, u64), Vec<TileDelta>> = HashMap::new();
    for (robot, robot_frames) in &frames {
        for frame in robot_frames {
            let p = frame.true_pose.expect("pose");
            let mut out = Vec::new();
            integrator
                .integrate(&Pose2::new(p.x, p.y, p.theta), &frame.ranges, &mut out)
                .expect("integrate");
            deltas.insert((robot.clone(), frame.sequence), out);
        }
    }
    let replay = |map: &str| {
        let mut order: Vec<(u64, String, u64)> = ROBOTS
            .iter()
            .flat_map(|r| read_log(&logs(map, r), r))
            .collect();
        order.sort();
        assert_eq!(order.len(), ROBOTS.len() * FRAMES, "one batch per frame");
        let versions: Vec<u64> = order.iter().map(|o| o.0).collect();
        assert_eq!(versions, (1..=order.len() as u64).collect::<Vec<_>>());
        let mut reference = TileMap::new(resolution, size, limits);
        for (_, robot, sequence) in &order {
            for delta in &deltas[&(robot.clone(), *sequence)] {
                reference.apply(delta).expect("apply");
            }
        }
        let cells: HashMap<TileKey, Vec<i16>> = reference
            .tiles()
            .map(|(k, t)| (*k, t.raw_cells().to_vec()))
            .collect();
        (order, cells)
    };

    let (together_order, together_expected) = replay("together");
    let (_, apart_expected) = replay("apart");
    let together = server_cells(&client, "together").await;
    let apart = server_cells(&client, "apart").await;
    assert_eq!(
        together, together_expected,
        "together = its commit-order replay"
    );
    assert_eq!(apart, apart_expected, "apart = its commit-order replay");

    // The three really ran at the same time: their batches interleave.
    let switches = together_order
        .windows(2)
        .filter(|w| w[0].1 != w[1].1)
        .count();
    assert!(switches > 10, "only {switches} switches between robots");

    // Same cells observed either way; values differ only through clamping.
    assert_eq!(
        together.keys().collect::<std::collections::BTreeSet<_>>(),
        apart.keys().collect::<std::collections::BTreeSet<_>>()
    );
    let (mut cells, mut differ) = (0usize, 0usize);
    for (key, a) in &together {
        let b = &apart[key];
        for (x, y) in a.iter().zip(b) {
            assert_eq!(
                *x == i16::MIN,
                *y == i16::MIN,
                "observed in one map and not the other"
            );
            cells += usize::from(*x != i16::MIN);
            differ += usize::from(x != y);
        }
    }
    assert!(cells > 5_000, "{cells}");
    eprintln!("{differ} of {cells} observed cells differ between the two orders");
    drop(server);
}
