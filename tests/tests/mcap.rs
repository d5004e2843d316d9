//! MCAP both ways through the real binary and a real map server: a ROS 2
//! recording written by the official Python packages (`mcap`,
//! `mcap-ros2-support`) imports, maps and localizes; `deog record`'s
//! output reads in those packages with the ROS 2 schemas and the values
//! recorded; recording a robot and importing the recording into another
//! gives the same frames. Needs python3 with those packages (`.ci/run`
//! installs them).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use deog_grid::{Pose2, TileMap};
use deog_proto::v1 as pb;
use deog_rig::BeamShape;
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, failure, require_python, run_deog, succeeded, wander_frames};
use serde_json::Value;

fn deog(args: &[&str], server: &ServerProcess) -> Output {
    run_deog(args, &[("DEOG_SERVER", server.addr.to_string())])
}

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(name)
}

/// Runs a script of `tests/scripts` with python3; fails the test with
/// what to install when python3 or the MCAP packages are missing.
fn python(name: &str, args: &[&str]) -> String {
    require_python(
        "mcap, mcap_ros2.reader, mcap_ros2.writer",
        "mcap mcap-ros2-support",
    );
    let out = Command::new("python3")
        .arg(script(name))
        .args(args)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{name} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("UTF-8")
}

/// The room `write_ros2_bag.py` drives in: its walls and the box.
const WALLS: [((f64, f64), (f64, f64)); 8] = [
    ((0.0, 0.0), (8.0, 0.0)),
    ((8.0, 0.0), (8.0, 6.0)),
    ((8.0, 6.0), (0.0, 6.0)),
    ((0.0, 6.0), (0.0, 0.0)),
    ((5.5, 3.5), (6.5, 3.5)),
    ((6.5, 3.5), (6.5, 4.5)),
    ((6.5, 4.5), (5.5, 4.5)),
    ((5.5, 4.5), (5.5, 3.5)),
];

/// The robot's true pose `t` seconds into the bag (the script's circle).
fn room_pose(t: f64) -> Pose2 {
    let phi = 0.5 * t / 1.5;
    Pose2::new(
        3.5 + 1.5 * phi.cos(),
        3.0 + 1.5 * phi.sin(),
        phi + std::f64::consts::FRAC_PI_2,
    )
}

/// The bag's first stamp, seconds.
const BAG_START_S: f64 = 1_700_000_001.0;

fn distance_to_walls(x: f64, y: f64) -> f64 {
    WALLS
        .iter()
        .map(|&((ax, ay), (bx, by))| {
            let (ex, ey) = (bx - ax, by - ay);
            let t = (((x - ax) * ex + (y - ay) * ey) / (ex * ex + ey * ey)).clamp(0.0, 1.0);
            (x - ax - t * ex).hypot(y - ay - t * ey)
        })
        .fold(f64::INFINITY, f64::min)
}

fn occupied(map: &TileMap, x: f64, y: f64) -> Option<bool> {
    let cell = map.resolution().cell_of(x, y).expect("cell");
    map.get(cell).map(|b| b.probability() > 0.5)
}

/// Writes the room bag into `dir` with `compression`, returning its path.
fn room_bag(dir: &Path, compression: &str) -> String {
    let bag = dir.join(format!("room-{compression}.mcap"));
    let bag = bag.to_str().expect("UTF-8 path").to_owned();
    let out = python(
        "write_ros2_bag.py",
        &[&bag, "--scans", "200", "--compression", compression],
    );
    assert!(out.contains("200 scans"), "{out}");
    bag
}

async fn client(server: &ServerProcess) -> MapClient {
    MapClient::connect(ClientConfig::new(server.url()))
        .await
        .expect("client")
}

#[tokio::test]
async fn a_ros2_bag_imports_and_maps_the_room_it_was_recorded_in() {
    let dir = tempfile::tempdir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    // rosbag2 compresses chunks with zstd or lz4: lz4 here, zstd below.
    let bag = room_bag(dir.path(), "lz4");
    let import = [
        "import",
        "--mcap",
        &bag,
        "--robot",
        "room",
        "--reference-topic",
        "/ground_truth",
    ];
    let out = succeeded(&deog(&import, &server));
    assert!(
        out.contains("200 messages on /scan and odometry from /odom read, 200 frames, 200 stored, 0 already there"),
        "{out}"
    );
    assert!(
        out.contains("mounts from /tf_static on base_footprint"),
        "{out}"
    );
    // Again: nothing twice.
    let out = succeeded(&deog(&import, &server));
    assert!(out.contains("0 stored, 200 already there"), "{out}");

    let client = client(&server).await;
    let frames = client.read_frames("room", 0, 0).await.unwrap();
    assert_eq!(frames.len(), 200);
    assert!(
        frames
            .iter()
            .enumerate()
            .all(|(i, f)| f.sequence == i as u64 + 1)
    );
    let rig = client.rig(&frames[0].rig).await.unwrap();
    assert!(rig.all_laser());
    assert_eq!(rig.readings(), 360);
    assert!((rig.sensors()[0].mount.x - 0.2).abs() < 1e-9);
    for frame in [&frames[0], &frames[77], &frames[199]] {
        let t = frame.time_s - BAG_START_S;
        let truth = room_pose(t);
        // Odometry came at other stamps: interpolated, off the circle by
        // the chord's sagitta at most (under a millimetre).
        let odometry = frame.odometry.unwrap();
        assert!(
            (odometry.x - truth.x).hypot(odometry.y - truth.y) < 1e-3,
            "frame {}: {odometry:?} vs {truth:?}",
            frame.sequence
        );
        let reference = frame.reference_pose.unwrap();
        // Exact but for the stamp's nanoseconds at 0.5 m/s.
        assert!((reference.x - truth.x).hypot(reference.y - truth.y) < 1e-6);
        assert!(frame.true_pose.is_none());
    }

    let out = succeeded(&deog(
        &[
            "map", "--robot", "room", "--map", "room", "--pose", "odometry", "--to", "200",
        ],
        &server,
    ));
    assert!(out.contains("200 frames integrated"), "{out}");
    let (_, map) = client.download("room").await.unwrap();

    // Every wall the laser saw is in the map where the room has it.
    let mut wall_points = Vec::new();
    for i in 1..80 {
        let x = f64::from(i) * 0.1;
        wall_points.extend([(x, 0.0), (x, 6.0)]);
    }
    for i in 1..60 {
        let y = f64::from(i) * 0.1;
        wall_points.extend([(0.0, y), (8.0, y)]);
    }
    for i in 1..10 {
        let d = f64::from(i) * 0.1;
        // The box's faces towards the robot.
        wall_points.extend([(5.5, 3.5 + d), (5.5 + d, 3.5)]);
    }
    let walls_found = wall_points
        .iter()
        .filter(|&&(x, y)| {
            [
                (-0.05, 0.0),
                (0.05, 0.0),
                (0.0, -0.05),
                (0.0, 0.05),
                (0.0, 0.0),
            ]
            .iter()
            .any(|(dx, dy)| occupied(&map, x + dx, y + dy) == Some(true))
        })
        .count();
    assert!(
        walls_found as f64 > 0.95 * wall_points.len() as f64,
        "{walls_found} of {} wall points are occupied",
        wall_points.len()
    );
    // The floor is free, away from the walls and outside the box.
    let (mut floor, mut free) = (0, 0);
    for i in 0..32 {
        for j in 0..24 {
            let (x, y) = (0.125 + 0.25 * f64::from(i), 0.125 + 0.25 * f64::from(j));
            let in_box = (5.5..=6.5).contains(&x) && (3.5..=4.5).contains(&y);
            let behind_box = x > 5.5 && y > 3.5;
            if in_box || behind_box || distance_to_walls(x, y) < 0.2 {
                continue;
            }
            floor += 1;
            free += usize::from(occupied(&map, x, y) == Some(false));
        }
    }
    assert!(
        free as f64 > 0.97 * f64::from(floor),
        "{free} of {floor} floor points are free"
    );
    // And nothing is occupied away from a wall.
    let (mut occupied_cells, mut stray) = (0, 0);
    let size = map.tile_size();
    for (key, tile) in map.tiles() {
        for (index, &raw) in tile.raw_cells().iter().enumerate() {
            let cell = size
                .join(*key, deog_grid::CellOffset::from_index(index, size))
                .unwrap();
            let belief = deog_grid::LogOdds::from_raw(raw);
            if belief.is_some_and(|b| b.probability() > 0.5) {
                let (x, y) = map.resolution().cell_center(cell);
                occupied_cells += 1;
                stray += usize::from(distance_to_walls(x, y) > 0.1);
            }
        }
    }
    assert!(occupied_cells > 400, "{occupied_cells} occupied cells");
    assert!(
        (stray as f64) < 0.02 * f64::from(occupied_cells),
        "{stray} of {occupied_cells} occupied cells lie off the walls"
    );
}

/// The summary `read_ros2_bag.py` prints of `file`.
fn read_back(file: &Path) -> Value {
    let text = python("read_ros2_bag.py", &[file.to_str().expect("UTF-8 path")]);
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

fn number(value: &Value) -> f64 {
    value
        .as_f64()
        .unwrap_or_else(|| panic!("a number: {value}"))
}

#[tokio::test]
async fn a_recording_reads_in_the_ros2_packages_with_its_schemas_and_values() {
    let dir = tempfile::tempdir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    let bag = room_bag(dir.path(), "zstd");
    succeeded(&deog(
        &[
            "import",
            "--mcap",
            &bag,
            "--robot",
            "room",
            "--reference-topic",
            "/ground_truth",
        ],
        &server,
    ));
    succeeded(&deog(
        &[
            "map",
            "--robot",
            "room",
            "--map",
            "room",
            "--pose",
            "reference",
            "--to",
            "200",
        ],
        &server,
    ));
    let out = succeeded(&deog(
        &[
            "localize",
            "--robot",
            "room",
            "--map",
            "room",
            "--from",
            "1",
            "--to",
            "200",
            "--initial-pose",
            "reference",
        ],
        &server,
    ));
    assert!(out.contains("200 frames"), "{out}");
    let client = client(&server).await;
    let frames = client.read_frames("room", 0, 0).await.unwrap();
    let estimates = client.read_poses("room", 0, 0).await.unwrap();
    assert!(!estimates.is_empty());

    let recording = dir.path().join("room-recorded.mcap");
    let out = succeeded(&deog(
        &[
            "record",
            "--robot",
            "room",
            "--mcap",
            recording.to_str().unwrap(),
            "--map",
            "room",
        ],
        &server,
    ));
    assert!(out.contains("200 frames"), "{out}");
    let summary = read_back(&recording);
    assert_eq!(summary["profile"], "ros2");
    let topics = &summary["topics"];
    let expected = [
        ("/scan", "sensor_msgs/msg/LaserScan", 200),
        ("/odom", "nav_msgs/msg/Odometry", 200),
        ("/tf", "tf2_msgs/msg/TFMessage", 200),
        ("/tf_static", "tf2_msgs/msg/TFMessage", 1),
        ("/reference_pose", "geometry_msgs/msg/PoseStamped", 200),
        (
            "/estimate",
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            estimates.len(),
        ),
        ("/map", "nav_msgs/msg/OccupancyGrid", 1),
    ];
    assert_eq!(
        topics.as_object().unwrap().len(),
        expected.len(),
        "{topics:#}"
    );
    for (topic, schema, count) in expected {
        let t = &topics[topic];
        assert_eq!(t["schema"], schema, "{topic}");
        assert_eq!(t["schema_encoding"], "ros2msg", "{topic}");
        assert_eq!(t["message_encoding"], "cdr", "{topic}");
        assert_eq!(t["count"], count, "{topic}");
    }
    let scan = &topics["/scan"]["first"];
    assert_eq!(scan["frame_id"], "laser");
    assert_eq!(scan["ranges"].as_array().unwrap().len(), 360);
    assert!((number(&scan["angle_min"]) + std::f64::consts::PI).abs() < 1e-6);
    assert_eq!(number(&scan["range_max"]), 12.0);
    for (i, value) in scan["ranges"].as_array().unwrap().iter().enumerate() {
        assert!(
            (number(value) - frames[0].ranges[i]).abs() < 1e-5,
            "beam {i}"
        );
    }
    let odometry = &topics["/odom"]["last"];
    let last = frames[199].odometry.unwrap();
    assert_eq!(odometry["frame_id"], "odom");
    assert_eq!(odometry["child_frame_id"], "base_link");
    assert!((number(&odometry["x"]) - last.x).abs() < 1e-9);
    assert!((number(&odometry["yaw"]) - last.theta).abs() < 1e-9);
    assert!((number(&odometry["stamp"]) - frames[199].time_s).abs() < 1e-6);
    let mounts = topics["/tf_static"]["first"]["transforms"]
        .as_array()
        .unwrap();
    assert_eq!(mounts.len(), 1);
    assert_eq!(mounts[0]["parent"], "base_link");
    assert_eq!(mounts[0]["child"], "laser");
    assert!((number(&mounts[0]["x"]) - 0.2).abs() < 1e-9);
    let tf = topics["/tf"]["first"]["transforms"].as_array().unwrap();
    let pairs: Vec<(&str, &str)> = tf
        .iter()
        .map(|t| (t["parent"].as_str().unwrap(), t["child"].as_str().unwrap()))
        .collect();
    assert_eq!(pairs, vec![("map", "odom"), ("odom", "base_link")]);
    let estimate = &topics["/estimate"]["last"];
    let last_estimate = estimates.last().unwrap();
    let pose = last_estimate.pose.unwrap();
    assert_eq!(estimate["frame_id"], "map");
    assert!((number(&estimate["x"]) - pose.x).abs() < 1e-9);
    assert!((number(&estimate["covariance"][0]) - last_estimate.covariance[0]).abs() < 1e-12);
    assert!((number(&estimate["covariance"][35]) - last_estimate.covariance[8]).abs() < 1e-12);
    // The localizer stayed on the room's circle.
    let truth = room_pose(last_estimate.time_s - BAG_START_S);
    assert!((pose.x - truth.x).hypot(pose.y - truth.y) < 0.3, "{pose:?}");
    let grid = &topics["/map"]["first"];
    assert_eq!(grid["frame_id"], "map");
    assert!((number(&grid["resolution"]) - 0.05).abs() < 1e-6);
    let (width, height) = (number(&grid["width"]), number(&grid["height"]));
    // The room's 8 x 6 m, and a cell or two of wall around.
    assert!((160.0..=166.0).contains(&width), "{width}");
    assert!((120.0..=126.0).contains(&height), "{height}");
    assert_eq!(number(&grid["cells"]), width * height);
    assert_eq!(number(&grid["out_of_range"]), 0.0);
    assert!(number(&grid["occupied"]) > 400.0);
    assert!(number(&grid["free"]) > 0.8 * width * height);
    assert!(number(&grid["origin_x"]) < 0.0 && number(&grid["origin_x"]) > -0.2);

    // A sonar robot: one Range per sonar, each in its own frame.
    let scout = wander_frames("scout", 5, 30);
    client.publish_frames(scout.clone()).await.unwrap();
    let recording = dir.path().join("scout.mcap");
    succeeded(&deog(
        &[
            "record",
            "--robot",
            "scout",
            "--mcap",
            recording.to_str().unwrap(),
        ],
        &server,
    ));
    let summary = read_back(&recording);
    let topics = &summary["topics"];
    let sonar = &topics["/sonar"];
    assert_eq!(sonar["schema"], "sensor_msgs/msg/Range");
    assert_eq!(sonar["count"], 30 * 16);
    let frame_ids: Vec<String> = (0..16).map(|i| format!("sonar_{i}")).collect();
    assert_eq!(sonar["frame_ids"], serde_json::json!(frame_ids));
    assert_eq!(sonar["first"]["radiation_type"], 0);
    assert!((number(&sonar["first"]["range"]) - scout[0].ranges[0]).abs() < 1e-5);
    assert!(number(&sonar["first"]["field_of_view"]) > 0.1);
    assert_eq!(topics["/true_pose"]["count"], 30);
    assert_eq!(
        topics["/tf_static"]["first"]["transforms"]
            .as_array()
            .unwrap()
            .len(),
        16
    );
    assert!(topics.get("/scan").is_none());
}

/// Frames equal up to the float32 a LaserScan or Range holds its ranges in.
fn assert_same_frames(a: &[pb::SonarFrame], b: &[pb::SonarFrame], reference_of_a: bool) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.sequence, y.sequence);
        assert!(
            (x.time_s - y.time_s).abs() < 1e-6,
            "{} vs {}",
            x.time_s,
            y.time_s
        );
        let (ox, oy) = (x.odometry.unwrap(), y.odometry.unwrap());
        assert!((ox.x - oy.x).abs() < 1e-9 && (ox.y - oy.y).abs() < 1e-9);
        assert!(deog_grid::normalize_angle(ox.theta - oy.theta).abs() < 1e-9);
        let reference = if reference_of_a {
            x.reference_pose
        } else {
            x.true_pose
        };
        let (rx, ry) = (reference.unwrap(), y.reference_pose.unwrap());
        assert!((rx.x - ry.x).abs() < 1e-9 && (rx.y - ry.y).abs() < 1e-9);
        assert_eq!(x.ranges.len(), y.ranges.len());
        for (r, s) in x.ranges.iter().zip(&y.ranges) {
            assert!((r - s).abs() <= 1e-6 * r.abs().max(1.0), "{r} vs {s}");
        }
    }
}

fn assert_same_geometry(a: &deog_rig::Rig, b: &deog_rig::Rig) {
    assert_eq!(a.readings(), b.readings());
    for (x, y) in a.beams().iter().zip(b.beams()) {
        assert!((x.mount.x - y.mount.x).abs() < 1e-9);
        assert!((x.mount.y - y.mount.y).abs() < 1e-9);
        assert!(deog_grid::normalize_angle(x.mount.theta - y.mount.theta).abs() < 1e-6);
        assert!((x.max_range - y.max_range).abs() < 1e-5);
        match (x.shape, y.shape) {
            (BeamShape::Ray, BeamShape::Ray) => {}
            (BeamShape::Cone { half_angle: a }, BeamShape::Cone { half_angle: b }) => {
                // A Range's field of view is a float32.
                assert!((a - b).abs() < 1e-6, "{a} vs {b}");
            }
            (a, b) => panic!("{a:?} vs {b:?}"),
        }
    }
}

#[tokio::test]
async fn recording_a_robot_and_importing_it_into_another_gives_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    let client = client(&server).await;

    // A laser robot, from a ROS 2 bag.
    let bag = room_bag(dir.path(), "none");
    succeeded(&deog(
        &[
            "import",
            "--mcap",
            &bag,
            "--robot",
            "room",
            "--reference-topic",
            "/ground_truth",
        ],
        &server,
    ));
    let recording = dir.path().join("room.mcap");
    let recording = recording.to_str().unwrap();
    succeeded(&deog(
        &["record", "--robot", "room", "--mcap", recording],
        &server,
    ));
    let import = [
        "import",
        "--mcap",
        recording,
        "--robot",
        "room-again",
        "--reference-topic",
        "/reference_pose",
    ];
    let out = succeeded(&deog(&import, &server));
    assert!(
        out.contains("200 frames, 200 stored, 0 already there"),
        "{out}"
    );
    let out = succeeded(&deog(&import, &server));
    assert!(out.contains("0 stored, 200 already there"), "{out}");
    let original = client.read_frames("room", 0, 0).await.unwrap();
    let again = client.read_frames("room-again", 0, 0).await.unwrap();
    assert_same_frames(&original, &again, true);
    let (rig, rig_again) = (
        client.rig(&original[0].rig).await.unwrap(),
        client.rig(&again[0].rig).await.unwrap(),
    );
    assert_same_geometry(&rig, &rig_again);

    // A sonar robot, from the simulator, with its true pose as the
    // reference of the copy.
    let scout = wander_frames("scout", 11, 40);
    // The simulator's first frame need not be sequence 1: the copy
    // starts where the original does.
    let first = scout[0].sequence.to_string();
    client.publish_frames(scout).await.unwrap();
    let recording = dir.path().join("scout.mcap");
    let recording = recording.to_str().unwrap();
    succeeded(&deog(
        &["record", "--robot", "scout", "--mcap", recording],
        &server,
    ));
    let out = succeeded(&deog(
        &[
            "import",
            "--mcap",
            recording,
            "--robot",
            "scout-again",
            "--reference-topic",
            "/true_pose",
            "--first-sequence",
            &first,
        ],
        &server,
    ));
    assert!(out.contains("640 messages on /sonar"), "{out}");
    let original = client.read_frames("scout", 0, 0).await.unwrap();
    let again = client.read_frames("scout-again", 0, 0).await.unwrap();
    assert_same_frames(&original, &again, false);
    assert_same_geometry(
        &client.rig(&original[0].rig).await.unwrap(),
        &client.rig(&again[0].rig).await.unwrap(),
    );
}

#[tokio::test]
async fn bad_recordings_are_refused_with_a_clear_error_and_nothing_stored() {
    let dir = tempfile::tempdir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;

    let not_mcap = dir.path().join("notes.mcap");
    std::fs::write(&not_mcap, "these are notes, not a recording\n").unwrap();
    let not_mcap = not_mcap.to_str().unwrap();
    let err = failure(&deog(
        &["import", "--mcap", not_mcap, "--robot", "r"],
        &server,
    ));
    assert!(err.contains("notes.mcap") && err.contains("MCAP"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");

    // Cut short: the container's end is missing.
    let bag = room_bag(dir.path(), "zstd");
    let bytes = std::fs::read(&bag).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let err = failure(&deog(
        &["import", "--mcap", cut.to_str().unwrap(), "--robot", "r"],
        &server,
    ));
    assert!(err.contains("cut.mcap"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    let err = failure(&deog(
        &[
            "import",
            "--mcap",
            &bag,
            "--robot",
            "r",
            "--odom-topic",
            "/scan",
        ],
        &server,
    ));
    assert!(
        err.contains("/scan holds sensor_msgs/msg/LaserScan messages, not nav_msgs/msg/Odometry"),
        "{err}"
    );
    let err = failure(&deog(
        &["import", "--mcap", &bag, "--robot", "r", "--rig", "scout"],
        &server,
    ));
    assert!(err.contains("has 360 ranges; rig scout reads 16"), "{err}");
    let err = failure(&deog(
        &["import", "--mcap", "/nonexistent/x.mcap", "--robot", "r"],
        &server,
    ));
    assert!(err.contains("/nonexistent/x.mcap"), "{err}");

    let err = failure(&deog(
        &[
            "record",
            "--robot",
            "nobody",
            "--mcap",
            dir.path().join("x.mcap").to_str().unwrap(),
        ],
        &server,
    ));
    assert!(err.contains("no frame of robot \"nobody\""), "{err}");
    assert!(!dir.path().join("x.mcap").exists());

    let client = client(&server).await;
    assert!(client.robots().await.unwrap().is_empty());
}
