//! `deog map`, the cartographer, as a real process against a real server:
//! the map it builds equals the frames applied one after another, and a
//! restart resumes after the last frame the server applied, never applying
//! one twice.

use deog_grid::{
    ClampLimits, FrameIntegrator, Pose2, Resolution, SensorRing, SonarModel, TileMap, TileSize,
};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, wander_frames};
use std::process::Command;

fn map_run(server: &ServerProcess, extra: &[&str]) -> String {
    let output = Command::new(deog_binary())
        .args([
            "map",
            "--robot",
            "r",
            "--map",
            "m",
            "--idle-exit",
            "1",
            "--batch-frames",
            "1",
        ])
        .args(extra)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog map");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_map_is_the_frames_applied_in_order_and_a_restart_resumes_exactly() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    let frames = wander_frames("r", 21, 160);
    let (first, last) = (frames[0].sequence, frames[159].sequence);
    client
        .publish_frames(frames.clone())
        .await
        .expect("publish");

    // Half, then the rest after a "restart", then once more: nothing left.
    // The thesis's sonar method, whose deltas depend on the frame alone.
    let thesis = ["--sonar-method", "thesis"];
    let middle = (first + 79).to_string();
    let out = map_run(&server, &["--to", &middle, thesis[0], thesis[1]]);
    assert!(out.contains(": 80 frames integrated"), "{out}");
    let out = map_run(&server, &thesis);
    assert!(out.contains(": 80 frames integrated"), "{out}");
    let out = map_run(&server, &thesis);
    assert!(out.contains(": 0 frames integrated"), "{out}");
    let cursor = client.update_cursor("m", "carto/r").await.expect("cursor");
    assert_eq!(cursor, last);
    let info = client.map_info("m").await.expect("info");
    assert_eq!(info.version, 160, "one batch per frame, each applied once");

    // The reference: the same frames integrated here and applied one by one.
    let size = TileSize::new(info.tile_size).expect("size");
    let resolution = Resolution::new(info.resolution_m).expect("resolution");
    let limits =
        ClampLimits::from_probabilities(info.clamp_min_probability, info.clamp_max_probability)
            .expect("limits");
    let mut reference = TileMap::new(resolution, size, limits);
    // `deog map`'s own sonar model, which it ran with.
    let model = SonarModel::new(deog_mapping::mapping_sonar_model()).expect("model");
    let mut integrator = FrameIntegrator::new(model, SensorRing::scout(), resolution, size);
    let mut deltas = Vec::new();
    for frame in &frames {
        let p = frame.true_pose.expect("pose");
        deltas.clear();
        integrator
            .integrate(&Pose2::new(p.x, p.y, p.theta), &frame.ranges, &mut deltas)
            .expect("integrate");
        for delta in &deltas {
            reference.apply(delta).expect("apply");
        }
    }
    let tiles = client
        .tiles(deog_tests::whole_map("m"))
        .await
        .expect("tiles");
    let expected: Vec<_> = reference.tiles().collect();
    assert_eq!(tiles.len(), expected.len());
    let mut compared = 0;
    for tile in &tiles {
        let key = tile.key.expect("key");
        let key = deog_grid::TileKey::new(key.x, key.y);
        let want = expected
            .iter()
            .find(|(k, _)| **k == key)
            .map(|(_, t)| t.raw_cells())
            .expect("tile in the reference");
        let got: Vec<i16> = tile
            .cells
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(got.as_slice(), want, "tile {key:?}");
        compared += got.len();
    }
    assert!(compared > 10_000, "{compared}");
    drop(server);
}

/// Maps robot `r`'s frames into `map` with `deog map` and `extra` flags,
/// to the end of its frames.
fn map_robot_r(server: &ServerProcess, map: &str, extra: &[&str]) {
    let output = Command::new(deog_binary())
        .args(["map", "--robot", "r", "--idle-exit", "1", "--map", map])
        .args(extra)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog map");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The Scout at the origin facing +x, its front sonar reading `front`
/// (a wall stands 1.8 m ahead of it), the others no echo.
fn facing_wall(robot: &str, sequence: u64, front: f64) -> pb::SonarFrame {
    front_reading(robot, sequence, (0.0, 0.0, 0.0), front)
}

/// The Scout at `(x, y, theta)`, its front sonar reading `front`, the
/// others no echo.
fn front_reading(
    robot: &str,
    sequence: u64,
    (x, y, theta): (f64, f64, f64),
    front: f64,
) -> pb::SonarFrame {
    let pose = pb::Pose2 { x, y, theta };
    let mut ranges = vec![10.668; 16];
    ranges[0] = front;
    pb::SonarFrame {
        robot: robot.into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pose),
        true_pose: Some(pose),
        ranges,
        ..Default::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keeping_walls_a_reading_that_missed_the_wall_does_not_erase_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    // Fifteen echoes off the wall, then twenty readings that glanced off
    // it and heard something 4 m away.
    let frames: Vec<_> = (1..=15)
        .map(|k| facing_wall("r", k, 1.8))
        .chain((16..=35).map(|k| facing_wall("r", k, 4.0)))
        .collect();
    client.publish_frames(frames).await.expect("publish");
    let wall_belief = |map: &str| {
        let client = client.clone();
        let map = map.to_owned();
        async move {
            let (_, tiles) = client.download(&map).await.expect("download");
            let cell = tiles.resolution().cell_of(2.0, 0.0).expect("cell");
            let behind = tiles.resolution().cell_of(3.0, 0.0).expect("cell");
            (
                tiles.get(cell).map(|b| b.probability()),
                tiles.get(behind).map(|b| b.probability()),
            )
        }
    };
    let map_to = |map: &str, extra: &[&str]| map_robot_r(&server, map, extra);
    map_to("kept", &["--sonar-method", "keep-walls"]);
    map_to("thesis", &[]);
    let (wall, behind) = wall_belief("kept").await;
    assert!(wall.is_some_and(|p| p > 0.7), "kept: {wall:?}");
    assert_eq!(behind, None, "nothing mapped behind a kept wall");
    let (wall, behind) = wall_belief("thesis").await;
    assert!(wall.is_some_and(|p| p < 0.5), "thesis: {wall:?}");
    assert!(behind.is_some(), "the thesis's model maps through the wall");
    drop(server);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn directional_a_reading_that_swept_along_the_wall_does_not_erase_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    // Fifteen echoes off the wall from straight in front of it, then
    // twenty readings from beside it, looking along it, that heard
    // something 4 m away: a specular sonar's sweep past a wall.
    let along = (2.0, -1.5, std::f64::consts::FRAC_PI_2);
    let frames: Vec<_> = (1..=15)
        .map(|k| facing_wall("r", k, 1.8))
        .chain((16..=35).map(|k| front_reading("r", k, along, 4.0)))
        .collect();
    client.publish_frames(frames).await.expect("publish");
    let map_to = |map: &str, extra: &[&str]| map_robot_r(&server, map, extra);
    map_to("directional", &["--sonar-method", "directional"]);
    map_to("thesis", &[]);
    let wall = |map: &str| {
        let client = client.clone();
        let map = map.to_owned();
        async move {
            let (_, tiles) = client.download(&map).await.expect("download");
            let cell = tiles.resolution().cell_of(2.0, 0.0).expect("cell");
            tiles.get(cell).map(|b| b.probability())
        }
    };
    let kept = wall("directional").await;
    assert!(kept.is_some_and(|p| p > 0.7), "directional: {kept:?}");
    let erased = wall("thesis").await;
    assert!(erased.is_some_and(|p| p < 0.5), "thesis: {erased:?}");
    drop(client);
    drop(server);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn directional_space_walled_off_from_the_path_is_mapped_as_a_wall() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    // Twenty readings from the origin that heard something 3 m ahead
    // (freeing the cone out to 2 m), then a hundred echoes off a face 1 m
    // ahead of the front sonar (1.2 m from the robot's centre) from along
    // a line across it: the space between 1.2 and 2.2 m was
    // freed through a face that walls it off from every pose the robot
    // took.
    let frames: Vec<_> = (1..=20)
        .map(|k| facing_wall("r", k, 3.0))
        .chain((21..=120).map(|k| {
            let y = -0.6 + 0.05 * ((k - 21) % 25) as f64;
            front_reading("r", k, (0.0, y, 0.0), 1.0)
        }))
        .collect();
    client.publish_frames(frames).await.expect("publish");
    let specular = [
        "--sonar-method",
        "directional",
        "--no-echo-free-range",
        "0",
        "--max-free-range",
        "2",
    ];
    let map_to = |map: &str, period: &str, shadow: &str| {
        map_robot_r(
            &server,
            map,
            &[
                specular.as_slice(),
                &["--enclosure-period", period, "--shadow-depth", shadow],
            ]
            .concat(),
        )
    };
    map_to("judged", "10", "0");
    map_to("open", "0", "0");
    // The face, once heard, takes back what was freed through it.
    map_to("shadowed", "0", "1");
    let belief = |map: &str, x: f64| {
        let client = client.clone();
        let map = map.to_owned();
        async move {
            let (_, tiles) = client.download(&map).await.expect("download");
            let cell = tiles.resolution().cell_of(x, 0.0).expect("cell");
            tiles.get(cell).map(|b| b.probability())
        }
    };
    let open = belief("open", 1.7).await;
    assert!(open.is_some_and(|p| p < 0.196), "open: {open:?}");
    let judged = belief("judged", 1.7).await;
    assert!(judged.is_some_and(|p| p > 0.65), "judged: {judged:?}");
    let shadowed = belief("shadowed", 1.7).await;
    assert!(shadowed.is_some_and(|p| p > 0.65), "shadowed: {shadowed:?}");
    // The face and the space before it are what the readings made them.
    for map in ["judged", "open", "shadowed"] {
        let face = belief(map, 1.2).await;
        assert!(face.is_some_and(|p| p > 0.65), "{map}, the face: {face:?}");
        let before = belief(map, 0.6).await;
        assert!(
            before.is_some_and(|p| p < 0.196),
            "{map}, before it: {before:?}"
        );
    }
    drop(client);
    drop(server);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ring_fired_in_turn_is_mapped_where_its_sonar_fired() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    // Turning on the spot at 2 rad/s, 0.2 rad a frame; in frame 5
    // (heading 1.0) the front sonar, which fired first of the ring
    // 0.09375 s before the frame, at heading 0.8125, heard a wall 2 m off.
    let frames: Vec<_> = (1..=8)
        .map(|k| {
            let front = if k == 5 { 2.0 } else { 10.668 };
            front_reading("r", k, (0.0, 0.0, 0.2 * k as f64), front)
        })
        .collect();
    client.publish_frames(frames).await.expect("publish");
    let quiet = ["--no-echo-free-range", "0"];
    map_robot_r(
        &server,
        "fired",
        &[&quiet[..], &["--firing-period", "0.1"]].concat(),
    );
    map_robot_r(&server, "together", &quiet);
    let belief = |map: &str, heading: f64| {
        let client = client.clone();
        let map = map.to_owned();
        async move {
            let (_, tiles) = client.download(&map).await.expect("download");
            // The sonar sits 0.2 m out on the ring: its echo 2.2 m from the centre.
            let (x, y) = (2.2 * heading.cos(), 2.2 * heading.sin());
            let cell = tiles.resolution().cell_of(x, y).expect("cell");
            tiles.get(cell).map_or(0.5, |b| b.probability())
        }
    };
    let (fired_at, frame_at) = (0.8125, 1.0);
    let fired = (
        belief("fired", fired_at).await,
        belief("fired", frame_at).await,
    );
    let together = (
        belief("together", fired_at).await,
        belief("together", frame_at).await,
    );
    assert!(fired.0 > fired.1, "placed where it fired: {fired:?}");
    assert!(together.1 > together.0, "placed at the frame: {together:?}");
    drop(client);
    drop(server);
}
