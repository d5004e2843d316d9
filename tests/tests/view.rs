//! `deog view` in a real headless Chromium: a map server, a simulator, a
//! wandering robot and its cartographer run as processes; the page, served
//! by the view process, is opened through ChromeDriver. The map's pixels
//! appear on the canvas, the robot's marker moves as it drives, a tile
//! written through the server shows on the page soon after its
//! acknowledgement, and a published estimate is shown and judged.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_harness::browser::Browser;
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use deog_tests::{RunningDeog, ServerProcess, free_loopback_addr};
use serde_json::{Value, json};

/// Polls `script` in the page until `done` accepts its value; panics with
/// the last value after `limit`.
fn wait_for(
    browser: &Browser,
    what: &str,
    script: &str,
    limit: Duration,
    done: impl Fn(&Value) -> bool,
) -> Value {
    let deadline = Instant::now() + limit;
    loop {
        let value = browser
            .eval(script, json!([]))
            .expect("run a script in the page");
        if done(&value) {
            return value;
        }
        assert!(
            Instant::now() < deadline,
            "{what}: not within {limit:?}; last: {value}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Counts the canvas's pixels by kind: occupied cells are near black,
/// free cells near white.
const PIXEL_COUNTS: &str = "
    const c = document.getElementById('map');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let dark = 0, light = 0;
    for (let i = 0; i < d.length; i += 4) {
        const [r, g, b] = [d[i], d[i + 1], d[i + 2]];
        if (r < 70 && g < 70 && b < 80) dark++;
        else if (r > 215 && g > 215 && b > 215) light++;
    }
    return { dark, light, width: c.width, height: c.height };
";

/// Whether a pixel near (x, y) has the colour `hex`.
const COLOUR_NEAR: &str = "
    const [x, y, hex] = arguments;
    const want = [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));
    const c = document.getElementById('map');
    const d = c.getContext('2d').getImageData(Math.round(x) - 4, Math.round(y) - 4, 9, 9).data;
    for (let i = 0; i < d.length; i += 4) {
        if (Math.abs(d[i] - want[0]) + Math.abs(d[i + 1] - want[1]) + Math.abs(d[i + 2] - want[2]) < 30) return true;
    }
    return false;
";

fn now_ms() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("a clock after 1970")
        .as_secs_f64()
        * 1000.0
}

#[test]
fn the_page_shows_the_map_growing_and_the_robot_driving() {
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let dir = tempfile::tempdir().expect("temp dir");
    let server = runtime.block_on(ServerProcess::start(&dir.path().join("data"), &[]));
    let sim = runtime.block_on(ServerProcess::start_sim("office", &["--speed", "2"]));
    let server_url = server.url();
    let sim_url = sim.url();
    let _wander = RunningDeog::spawn(&[
        "wander",
        "--robot",
        "r1",
        "--spawn",
        "--seed",
        "3",
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
    let view_addr = free_loopback_addr();
    let mut view = RunningDeog::spawn(&[
        "view",
        "--listen",
        &view_addr.to_string(),
        "--map",
        "shared",
        "--server",
        &server_url,
        "--sim",
        &sim_url,
    ]);
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(view_addr).is_err() {
        assert!(view.is_running(), "deog view exited");
        assert!(
            Instant::now() < deadline,
            "deog view did not listen on {view_addr}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }

    let browser = Browser::start(1100, 700).expect("a headless Chromium");
    browser
        .goto(&format!("http://{view_addr}/"))
        .expect("open the page");

    // The map's tiles arrive and its cells are drawn.
    wait_for(
        &browser,
        "tiles and a robot on the page",
        "const s = window.deogView.stats(); const r = window.deogView.robots();
         return { tiles: s.tiles, map: window.deogView.mapName(), marker: r.length ? r[0].marker : null };",
        Duration::from_secs(90),
        |v| v["tiles"].as_u64().unwrap_or(0) >= 4 && v["map"] == "shared" && !v["marker"].is_null(),
    );
    let pixels = wait_for(
        &browser,
        "map pixels",
        PIXEL_COUNTS,
        Duration::from_secs(60),
        |v| v["dark"].as_u64().unwrap_or(0) >= 100 && v["light"].as_u64().unwrap_or(0) >= 2_000,
    );
    println!("canvas pixels: {pixels}");

    // The robot's marker moves as it drives, and is drawn in its colour.
    let robot = |browser: &Browser| {
        browser
            .eval("return window.deogView.robots()[0];", json!([]))
            .expect("robots")
    };
    let at = |v: &Value| {
        (
            v["marker"][0].as_f64().unwrap_or(0.0),
            v["marker"][1].as_f64().unwrap_or(0.0),
        )
    };
    // The page draws on its next animation frame: a pose that came just
    // before the read may not be on the canvas yet, so a few reads, each
    // of a pose and the pixels there, are allowed.
    let mut first = robot(&browser);
    let colour = first["color"].as_str().expect("a colour").to_string();
    let mut drawn = false;
    for _ in 0..20 {
        let (x, y) = at(&first);
        drawn = browser
            .eval(COLOUR_NEAR, json!([x, y, colour]))
            .expect("colour")
            == Value::Bool(true);
        if drawn {
            break;
        }
        std::thread::sleep(Duration::from_millis(250));
        first = robot(&browser);
    }
    let (x0, y0) = at(&first);
    assert!(
        drawn,
        "the robot's marker is not drawn in its colour at {x0:.0}, {y0:.0}"
    );
    let deadline = Instant::now() + Duration::from_secs(60);
    let moved = loop {
        let now = robot(&browser);
        let (x, y) = at(&now);
        if (x - x0).hypot(y - y0) > 5.0 {
            break now;
        }
        assert!(
            Instant::now() < deadline,
            "the marker stayed at {x0:.0}, {y0:.0}"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    let (x1, y1) = at(&moved);
    println!("marker moved from ({x0:.0}, {y0:.0}) to ({x1:.0}, {y1:.0})");

    // A tile written through the server appears on the page: the time from
    // its acknowledgement to the page drawing it.
    let latency_ms = runtime.block_on(async {
        let client = MapClient::connect(ClientConfig::new(server_url.clone()))
            .await
            .expect("client");
        let size =
            TileSize::new(client.map_info("shared").await.expect("map").tile_size).expect("size");
        let mut sender = client
            .updates("shared", "view-test", UpdateSenderConfig::default())
            .await
            .expect("updates");
        let key = TileKey::new(-3, -3);
        sender
            .push(TileDelta::from_raw(key, size, vec![1500; size.area()]).expect("delta"))
            .await
            .expect("push");
        sender.flush().await.expect("flush");
        let acked = now_ms();
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let seen = browser
                .eval("return window.deogView.tileSeenAt(-3, -3);", json!([]))
                .expect("tileSeenAt");
            if let Some(seen) = seen.as_f64() {
                break seen - acked;
            }
            assert!(
                Instant::now() < deadline,
                "tile (-3, -3) never reached the page"
            );
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    });
    println!("tile on the page {latency_ms:.0} ms after its acknowledgement");
    assert!(latency_ms < 2_000.0, "{latency_ms} ms");

    // An estimate published for the robot's newest frame is shown, judged
    // against that frame's true pose.
    runtime.block_on(async {
        let client = MapClient::connect(ClientConfig::new(server_url.clone()))
            .await
            .expect("client");
        let robots = client.robots().await.expect("robots");
        let last = robots
            .iter()
            .find(|r| r.robot == "r1")
            .expect("r1")
            .last_sequence;
        let frame = client
            .read_frames("r1", last, last)
            .await
            .expect("frame")
            .remove(0);
        let truth = frame.true_pose.expect("a simulated frame has its truth");
        client
            .publish_pose(pb::PoseEstimate {
                robot: "r1".into(),
                map: "shared".into(),
                frame_sequence: last,
                time_s: frame.time_s,
                pose: Some(pb::Pose2 {
                    x: truth.x + 0.03,
                    y: truth.y + 0.04,
                    theta: truth.theta,
                }),
                covariance: vec![0.01, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.001],
                particle_count: 700,
                converged: true,
                lost_score: 0.1,
                // Three particles about the truth.
                particle_sample: [-0.1f32, 0.0, 0.1]
                    .iter()
                    .flat_map(|d| [truth.x as f32 + d, truth.y as f32 - d, truth.theta as f32])
                    .collect(),
            })
            .await
            .expect("publish an estimate");
    });
    let shown = wait_for(
        &browser,
        "the estimate on the page",
        "return window.deogView.robots()[0];",
        Duration::from_secs(10),
        |v| v["estimate"]["particles"] == 700 && v["particlesShown"] == 3,
    );
    assert_eq!(shown["estimate"]["converged"], true);
    let error_m = shown["error"]["m"]
        .as_f64()
        .expect("the estimate is judged");
    assert!((error_m - 0.05).abs() < 1e-3, "{shown}");
    let state = browser
        .eval(
            "return document.querySelector('#robots tbody tr td:nth-child(2)').textContent;",
            json!([]),
        )
        .expect("the robot list");
    assert_eq!(state, "converged");

    let stats = browser
        .eval("return window.deogView.stats();", json!([]))
        .expect("stats");
    println!("page: {stats}");
    if let Some(path) = std::env::var_os("DEOG_VIEW_SCREENSHOT") {
        std::fs::write(&path, browser.screenshot().expect("screenshot"))
            .expect("write the screenshot");
    }
    assert!(view.is_running(), "deog view ran throughout");
}
