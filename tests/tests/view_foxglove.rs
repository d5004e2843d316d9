//! `deog view --foxglove` against a Foxglove WebSocket protocol client
//! made by others: `@foxglove/ws-protocol`'s `FoxgloveClient` over `ws`,
//! in the Node script `tests/foxglove/client.mjs` (its packages pinned in
//! `tests/foxglove/package-lock.json`; `npm ci --prefix tests/foxglove`
//! installs them). A map server, a simulator of the office whose robot
//! carries four sonars and a laser, a wanderer, its cartographer and the
//! view run as processes; the script subscribes to every advertised
//! channel, decodes the messages with the protobuf schemas the
//! advertisements carry, and its report is checked against what the map
//! server and the world hold.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, SimClient};
use deog_tests::{RunningDeog, ServerProcess, failure, free_loopback_addr, run_deog, succeeded};
use serde_json::Value;

/// Four sonars round the body and a 91-beam laser over the front half.
const RIG: &str = r#"
name = "foxglove-test"
body_radius_m = 0.2

[defaults]
min_range_m = 0.1
max_range_m = 6.0

[[sensor]]
kind = "sonar"
half_angle_deg = 12.5
x_m = 0.15
heading_deg = 0.0

[[sensor]]
kind = "sonar"
half_angle_deg = 12.5
y_m = 0.15
heading_deg = 90.0

[[sensor]]
kind = "sonar"
half_angle_deg = 12.5
x_m = -0.15
heading_deg = 180.0

[[sensor]]
kind = "sonar"
half_angle_deg = 12.5
y_m = -0.15
heading_deg = -90.0

[[sensor]]
kind = "laser"
first_angle_deg = -90.0
angle_step_deg = 2.0
beam_count = 91
max_range_m = 20.0
"#;

const LASER_BEAMS: usize = 91;
const SONARS: u64 = 4;

/// The script's folder, with its packages installed; panics saying how
/// to install them when they are missing.
fn client_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("foxglove");
    assert!(
        dir.join("node_modules/@foxglove/ws-protocol").is_dir()
            && dir.join("node_modules/protobufjs").is_dir()
            && dir.join("node_modules/ws").is_dir(),
        "the Foxglove client's packages are missing: run `npm ci --prefix tests/foxglove` \
         (Node.js 20 and npm)"
    );
    dir
}

/// Panics with what to install unless `node` runs.
fn require_node() {
    let output = Command::new("node")
        .arg("--version")
        .output()
        .unwrap_or_else(|e| panic!("running `node` (Node.js 20 is needed): {e}"));
    assert!(output.status.success(), "`node --version` failed");
}

/// Runs the client script against `url` and parses its report.
fn run_client(url: &str, want: &[&str]) -> Value {
    let dir = client_dir();
    let output = Command::new("node")
        .arg(dir.join("client.mjs"))
        .args(["--url", url, "--seconds", "5", "--timeout", "60"])
        .args(["--want", &want.join(",")])
        .current_dir(&dir)
        .output()
        .unwrap_or_else(|e| panic!("running `node` (Node.js 20 is needed): {e}"));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the Foxglove client failed ({}): {}\n{stdout}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("the client's report is not JSON ({e}): {stdout}"))
}

/// Whether the view's `/api/robots` gives `robot` a true pose. A plain
/// HTTP/1.0 request: the server closes the connection after answering.
fn view_follows_true_pose(view_addr: std::net::SocketAddr, robot: &str) -> bool {
    use std::io::{Read, Write};
    let Ok(mut stream) = std::net::TcpStream::connect(view_addr) else {
        return false;
    };
    let timeout = Some(Duration::from_secs(5));
    if stream.set_read_timeout(timeout).is_err() || stream.set_write_timeout(timeout).is_err() {
        return false;
    }
    let request = format!("GET /api/robots HTTP/1.0\r\nHost: {view_addr}\r\n\r\n");
    let mut response = String::new();
    if stream.write_all(request.as_bytes()).is_err()
        || stream.read_to_string(&mut response).is_err()
    {
        return false;
    }
    let Some((_, body)) = response.split_once("\r\n\r\n") else {
        return false;
    };
    serde_json::from_str::<Value>(body).is_ok_and(|robots| {
        robots["robots"].as_array().is_some_and(|list| {
            list.iter()
                .any(|r| r["name"] == robot && r["true_pose"].is_array())
        })
    })
}

fn f64_at(value: &Value, pointer: &str) -> f64 {
    value
        .pointer(pointer)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("{pointer} is not a number in {value}"))
}

fn u64_at(value: &Value, pointer: &str) -> u64 {
    value
        .pointer(pointer)
        .and_then(Value::as_u64)
        .unwrap_or_else(|| panic!("{pointer} is not a count in {value}"))
}

#[test]
fn foxglove_shows_the_map_poses_scans_and_cones_of_a_running_system() {
    // Said before any process starts.
    require_node();
    client_dir();
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let dir = tempfile::tempdir().expect("temp dir");
    let rig_path = dir.path().join("foxglove-test.toml");
    std::fs::write(&rig_path, RIG).expect("write the rig");
    let rig_arg = rig_path.to_str().expect("a UTF-8 path");
    let server = runtime.block_on(ServerProcess::start(&dir.path().join("data"), &[]));
    let sim = runtime.block_on(ServerProcess::start_sim(
        "office",
        &["--speed", "2", "--rig", rig_arg],
    ));
    let server_url = server.url();
    let sim_url = sim.url();
    let _wander = RunningDeog::spawn(&[
        "wander",
        "--robot",
        "r1",
        "--spawn",
        "--seed",
        "5",
        "--duration",
        "900",
        "--sim",
        &sim_url,
        "--server",
        &server_url,
    ]);
    let _cartographer = RunningDeog::spawn(&[
        "map",
        "--robot",
        "r1",
        "--map",
        "shared",
        "--server",
        &server_url,
    ]);
    let foxglove_addr = free_loopback_addr();
    let view_addr = free_loopback_addr();
    let mut view = RunningDeog::spawn(&[
        "view",
        "--listen",
        &view_addr.to_string(),
        "--foxglove",
        &foxglove_addr.to_string(),
        "--map",
        "shared",
        "--server",
        &server_url,
        "--sim",
        &sim_url,
    ]);
    // The page's address is taken first, then Foxglove's; the client
    // retries its connection for a while, so no probe of the Foxglove
    // port (a bare TCP connection is a failed handshake there) is needed.
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(view_addr).is_err() {
        assert!(view.is_running(), "deog view exited");
        assert!(
            Instant::now() < deadline,
            "deog view did not listen on {view_addr}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }

    // The map has walls and the robot frames before the client looks; an
    // estimate is published with a pose and covariance to find again.
    let (info, published) = runtime.block_on(async {
        let client = MapClient::connect(ClientConfig::new(server_url.clone()))
            .await
            .expect("client");
        let deadline = Instant::now() + Duration::from_secs(90);
        let info = loop {
            match client.map_info("shared").await {
                Ok(info) if info.tile_count >= 4 => break info,
                _ => {}
            }
            assert!(Instant::now() < deadline, "the map never grew");
            tokio::time::sleep(Duration::from_millis(200)).await;
        };
        let last = client
            .robots()
            .await
            .expect("robots")
            .into_iter()
            .find(|r| r.robot == "r1")
            .expect("r1 has frames")
            .last_sequence;
        let published = pb::Pose2 {
            x: 3.25,
            y: 2.5,
            theta: 0.75,
        };
        client
            .publish_pose(pb::PoseEstimate {
                robot: "r1".into(),
                map: "shared".into(),
                frame_sequence: last,
                time_s: 0.0,
                pose: Some(published),
                covariance: vec![0.04, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.002],
                particle_count: 700,
                converged: true,
                lost_score: 0.1,
                particle_sample: vec![3.0, 2.5, 0.5, 3.5, 2.5, 1.0],
            })
            .await
            .expect("publish an estimate");
        (info, published)
    });
    // The view must follow r1's true pose before the kidnap, or it has
    // nothing to see r1 jump from: it finds the simulator's robots once a
    // second, and a busy machine can grow four tiles sooner than that.
    let deadline = Instant::now() + Duration::from_secs(60);
    while !view_follows_true_pose(view_addr, "r1") {
        assert!(view.is_running(), "deog view exited");
        assert!(
            Instant::now() < deadline,
            "deog view never followed r1's true pose"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    // A kidnap: r1 put down at least 6 m from where it is, somewhere clear.
    // The view calls a jump a kidnap when no drive could make it (0.5 m
    // plus 2 m/s of the simulated time between the frames it saw): on a
    // busy machine it sees frames a second or two apart, and 2 m would
    // then pass for driving.
    let world = deog_world::load_world_spec("office").expect("the office world");
    let at = runtime
        .block_on(async {
            SimClient::connect(ClientConfig::new(sim_url.clone()))
                .await
                .expect("simulator client")
                .state("r1")
                .await
        })
        .expect("r1's state")
        .true_pose
        .expect("r1's pose");
    let (low, high) = world.bounds();
    let clear = |x: f64, y: f64| {
        (0..16).all(|i| {
            let a = f64::from(i) * std::f64::consts::PI / 8.0;
            [0.0, 0.3, 0.6]
                .iter()
                .all(|r| world.is_free(deog_world::Point2::new(x + r * a.cos(), y + r * a.sin())))
        })
    };
    let put = (0..400)
        .map(|i| {
            let (fx, fy) = (f64::from(i % 20) / 20.0, f64::from(i / 20) / 20.0);
            (low.x + fx * (high.x - low.x), low.y + fy * (high.y - low.y))
        })
        .find(|&(x, y)| (x - at.x).hypot(y - at.y) >= 6.0 && clear(x, y))
        .expect("a clear spot in the office");
    succeeded(&run_deog(
        &[
            "teleport",
            "--robot",
            "r1",
            "--pose",
            &format!("{},{},0", put.0, put.1),
            "--sim",
            &sim_url,
        ],
        &[],
    ));

    let want = [
        "/map",
        "/tf",
        "/r1/true_pose",
        "/r1/estimate",
        "/r1/estimate_covariance",
        "/r1/scan",
        "/r1/sonar",
        "/r1/true_path",
        "/r1/particles",
        "/r1/kidnaps",
    ];
    let report = run_client(&format!("ws://{foxglove_addr}"), &want);
    println!("{report}");
    assert_eq!(report["errors"], Value::Array(vec![]), "{report}");
    assert_eq!(report["missing"], Value::Array(vec![]), "{report}");

    // Every topic is advertised with its Foxglove schema, as protobuf.
    let channels = report["channels"].as_array().expect("channels");
    for (topic, schema) in [
        ("/map", "foxglove.Grid"),
        ("/tf", "foxglove.FrameTransforms"),
        ("/r1/true_pose", "foxglove.PoseInFrame"),
        ("/r1/estimate", "foxglove.PoseInFrame"),
        ("/r1/estimate_covariance", "foxglove.SceneUpdate"),
        ("/r1/scan", "foxglove.LaserScan"),
        ("/r1/sonar", "foxglove.SceneUpdate"),
        ("/r1/true_path", "foxglove.PosesInFrame"),
        ("/r1/particles", "foxglove.PosesInFrame"),
        ("/r1/kidnaps", "foxglove.SceneUpdate"),
    ] {
        let channel = channels
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap_or_else(|| panic!("{topic} is not advertised: {channels:?}"));
        assert_eq!(channel["schemaName"], schema, "{channel}");
        assert_eq!(channel["encoding"], "protobuf", "{channel}");
        assert!(u64_at(&report, &format!("/bytes/{}", topic.replace('/', "~1"))) > 0);
    }
    let count = |topic: &str| u64_at(&report, &format!("/counts/{}", topic.replace('/', "~1")));
    let seconds = f64_at(&report, "/seconds");
    // Poses follow the robot as it drives; the map is throttled to 2 Hz
    // (plus a resend per round of subscriptions).
    assert!(count("/r1/true_pose") as f64 >= 2.0 * seconds, "{report}");
    assert!(count("/tf") as f64 >= 2.0 * seconds, "{report}");
    assert!(
        (1.0..=2.0 * seconds + 4.0).contains(&(count("/map") as f64)),
        "{report}"
    );
    // The grid is sent again as the cartographer changes tiles, well
    // after the subscription's first, and never twice within its period
    // (a subscription to /map is answered at once, once).
    let map_times: Vec<f64> = report["times"]["/map"]
        .as_array()
        .expect("the grids' times")
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    assert!(
        map_times.iter().any(|&t| t > map_times[0] + 1.0),
        "no grid after the first second: {map_times:?}"
    );
    // Arrival times carry the transport's jitter (a grid is a megabyte or
    // two): one that came late brings the next nearer. So the rate is
    // judged over the whole run, and no two may come as one resend would.
    let spacing = (map_times[map_times.len() - 1] - map_times[0]) / (map_times.len() - 1) as f64;
    assert!(
        spacing >= 0.45 && map_times.windows(2).all(|w| w[1] - w[0] >= 0.2),
        "grids closer than the 2 Hz throttle: {map_times:?}"
    );

    // The grid: the map's resolution, aligned to its tiles, covering at
    // least what the server held before the client looked, walls and
    // free space in it.
    let latest = &report["latest"];
    let grid = &latest["/map"];
    let resolution = info.resolution_m;
    assert_eq!(grid["frameId"], "map");
    assert!(
        (f64_at(grid, "/cellSize/x") - resolution).abs() < 1e-12,
        "{grid}"
    );
    assert!(
        (f64_at(grid, "/cellSize/y") - resolution).abs() < 1e-12,
        "{grid}"
    );
    let tile_m = resolution * f64::from(info.tile_size);
    let (origin_x, origin_y) = (f64_at(grid, "/origin/x"), f64_at(grid, "/origin/y"));
    for origin in [origin_x, origin_y] {
        let tiles = origin / tile_m;
        assert!((tiles - tiles.round()).abs() < 1e-6, "{grid}");
    }
    let columns = u64_at(grid, "/columnCount");
    let rows = u64_at(grid, "/rows");
    assert_eq!(u64_at(grid, "/cellStride"), 5);
    assert_eq!(u64_at(grid, "/rowStride"), columns * 5);
    assert_eq!(u64_at(grid, "/dataLength"), columns * rows * 5);
    let names: Vec<&str> = grid["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .filter_map(|f| f["name"].as_str())
        .collect();
    assert_eq!(names, ["red", "green", "blue", "alpha", "occupancy"]);
    let bounds = info.bounds_cells.expect("a map with tiles has bounds");
    assert!(
        origin_x <= f64::from(bounds.min_x) * resolution + 1e-9,
        "{grid}"
    );
    assert!(
        origin_y <= f64::from(bounds.min_y) * resolution + 1e-9,
        "{grid}"
    );
    assert!(
        origin_x + columns as f64 * resolution >= f64::from(bounds.max_x) * resolution - 1e-9,
        "{grid}"
    );
    assert!(
        origin_y + rows as f64 * resolution >= f64::from(bounds.max_y) * resolution - 1e-9,
        "{grid}"
    );
    assert!(u64_at(grid, "/occupied") >= 20, "walls: {grid}");
    assert!(u64_at(grid, "/free") >= 200, "free space: {grid}");
    assert!(
        u64_at(grid, "/occupied") + u64_at(grid, "/free") + u64_at(grid, "/unknown")
            <= columns * rows
    );

    // The true pose, the robot's body frame and its laser are in the
    // office.
    let world = deog_world::load_world_spec("office").expect("the office world");
    let (low, high) = world.bounds();
    let inside = |what: &str, x: f64, y: f64| {
        assert!(
            (low.x..=high.x).contains(&x) && (low.y..=high.y).contains(&y),
            "{what} at ({x}, {y}) is outside the office ({low:?} .. {high:?})"
        );
    };
    let truth = &latest["/r1/true_pose"];
    assert_eq!(truth["frameId"], "map");
    inside("the true pose", f64_at(truth, "/x"), f64_at(truth, "/y"));
    let transforms = latest["/tf"]["transforms"].as_array().expect("transforms");
    let body = transforms
        .iter()
        .find(|t| t["child"] == "r1/base_link")
        .unwrap_or_else(|| panic!("no r1/base_link in {transforms:?}"));
    assert_eq!(body["parent"], "map");
    inside("r1/base_link", f64_at(body, "/x"), f64_at(body, "/y"));

    // The published estimate comes back as it was sent.
    let estimate = &latest["/r1/estimate"];
    assert!(
        (f64_at(estimate, "/x") - published.x).abs() < 1e-9,
        "{estimate}"
    );
    assert!(
        (f64_at(estimate, "/y") - published.y).abs() < 1e-9,
        "{estimate}"
    );
    assert!(
        (f64_at(estimate, "/yaw") - published.theta).abs() < 1e-9,
        "{estimate}"
    );
    let ellipse = &latest["/r1/estimate_covariance"]["entities"][0];
    assert_eq!(ellipse["metadata"]["particles"], "700", "{ellipse}");
    assert_eq!(ellipse["metadata"]["converged"], "true", "{ellipse}");
    // 2σ each side: sqrt(0.04) and sqrt(0.01) metres of deviation.
    assert!(
        (f64_at(ellipse, "/spheres/0/size/x") - 0.8).abs() < 1e-9,
        "{ellipse}"
    );
    assert!(
        (f64_at(ellipse, "/spheres/0/size/y") - 0.4).abs() < 1e-9,
        "{ellipse}"
    );
    assert!((f64_at(ellipse, "/spheres/0/x") - published.x).abs() < 1e-9);

    // The laser: one scan of the rig's beams, 2 degrees apart, from inside
    // the office, with echoes off its walls.
    let scan = &latest["/r1/scan"];
    assert_eq!(scan["frameId"], "map");
    assert_eq!(u64_at(scan, "/ranges") as usize, LASER_BEAMS, "{scan}");
    let span = f64_at(scan, "/endAngle") - f64_at(scan, "/startAngle");
    assert!((span - 180f64.to_radians()).abs() < 1e-6, "{scan}");
    assert!(u64_at(scan, "/finite") >= 10, "{scan}");
    inside(
        "the laser",
        f64_at(scan, "/origin/x"),
        f64_at(scan, "/origin/y"),
    );

    // The sonars: four cones of six triangles each.
    let cones = &latest["/r1/sonar"]["entities"][0];
    assert_eq!(cones["id"], "r1/sonar");
    assert_eq!(u64_at(cones, "/triangles"), SONARS * 6, "{cones}");
    assert!(u64_at(&latest["/r1/true_path"], "/poses") >= 2);
    // The particles sent with the estimate, and the kidnap: a line from
    // where r1 was to where it was put.
    assert_eq!(u64_at(&latest["/r1/particles"], "/poses"), 2);
    // (The first pose seen after the jump: the robot may have driven a
    // step since it was put down.)
    let kidnaps = latest["/r1/kidnaps"]["entities"]
        .as_array()
        .expect("the kidnaps");
    let kidnap = kidnaps.last().expect("a kidnap");
    assert_eq!(
        kidnap["id"],
        format!("r1/kidnap/{}", kidnaps.len() - 1),
        "{kidnap}"
    );
    let arrived = (
        f64_at(kidnap, "/spheres/0/x"),
        f64_at(kidnap, "/spheres/0/y"),
    );
    assert!(
        (arrived.0 - put.0).hypot(arrived.1 - put.1) < 0.1,
        "put at {put:?}: {kidnap}"
    );
    assert!(view.is_running(), "deog view ran throughout");
}

#[test]
fn a_foxglove_address_in_use_is_a_clear_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let taken_addr = taken.local_addr().expect("address").to_string();
    let output = run_deog(
        &[
            "view",
            "--listen",
            &free_loopback_addr().to_string(),
            "--foxglove",
            &taken_addr,
            "--server",
            &format!("http://{}", free_loopback_addr()),
        ],
        &[],
    );
    let stderr = failure(&output);
    assert!(
        stderr.contains(&format!("serving Foxglove on {taken_addr}")),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");

    let output = run_deog(&["view", "--foxglove", "not-an-address"], &[]);
    let stderr = failure(&output);
    assert!(stderr.contains("--foxglove"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
