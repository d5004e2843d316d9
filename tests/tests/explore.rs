//! `deog explore` as a real process: a map server, the simulator with
//! map1, a cartographer and one explorer. The explorer ends by itself,
//! saying the map is explored, without a bump, and the map then covers the
//! room's reachable free space. And `deog demo --explore --no-localize`:
//! two explorers sharing the map end by themselves, its report.json saying
//! so (driven_s, bumps, the coverage curve); three do the same between the
//! pillars of the TurtleBot3 world's map_server map.

use std::process::Command;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use deog_tests::{RunningDeog, ServerProcess, deog_binary, json_field};

fn field(json: &str, name: &str) -> f64 {
    json_field(json, name)
        .parse()
        .unwrap_or_else(|_| panic!("{name} is a number in {json}"))
}

/// Held by each test while its explorers drive: they steer in real time
/// at 4x or 8x, and two runs at once on a small machine starve each other's
/// steering of the CPU (a late stop is a bump no faster machine makes).
/// Under `cargo test`; cargo-nextest runs each test in a process of its
/// own, and `.config/nextest.toml` runs these alone.
static DRIVING: Mutex<()> = Mutex::new(());

fn driving_alone() -> MutexGuard<'static, ()> {
    // A test that failed holding it poisons it; the next still runs alone.
    DRIVING
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Runs `deog demo --explore --no-localize` at `speed` times real time in
/// a temp folder and returns its report.json, parsed and as text.
fn explore_demo(
    world: &str,
    robots: &str,
    duration: &str,
    speed: &str,
) -> (serde_json::Value, String) {
    let _alone = driving_alone();
    let out = tempfile::tempdir().expect("temp dir");
    let output = Command::new(deog_binary())
        .args([
            "demo",
            "--explore",
            "--no-localize",
            "--no-view",
            "--world",
            world,
            "--robots",
            robots,
            "--duration",
            duration,
            "--speed",
            speed,
            "--out",
        ])
        .arg(out.path())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog demo");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    println!("{stdout}");
    let text = std::fs::read_to_string(out.path().join("report.json")).expect("report.json");
    let report = serde_json::from_str(&text).expect("JSON");
    (report, text)
}

#[test]
fn one_explorer_maps_a_room_and_stops_by_itself() {
    let _alone = driving_alone();
    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    let dir = tempfile::tempdir().expect("temp dir");
    let server = runtime.block_on(ServerProcess::start(&dir.path().join("data"), &[]));
    let sim = runtime.block_on(ServerProcess::start_sim("map1", &["--speed", "8"]));
    let (server_url, sim_url) = (server.url(), sim.url());
    let cartographer = RunningDeog::spawn(&[
        "map",
        "--robot",
        "e1",
        "--map",
        "ex",
        "--server",
        &server_url,
    ]);
    // Bounded: the explorer gives up after 1,200 simulated seconds (150 s
    // at this speed) whatever is left.
    let output = Command::new(deog_binary())
        .args([
            "explore",
            "--robot",
            "e1",
            "--map",
            "ex",
            "--spawn",
            "--duration",
            "1200",
            "--sim",
            &sim_url,
            "--server",
            &server_url,
        ])
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog explore");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("no reachable frontier left: explored"),
        "{stdout}"
    );
    assert!(stdout.contains(", 0 bumps"), "{stdout}");

    // The cartographer's last frames, then the map judged against the world.
    std::thread::sleep(Duration::from_secs(3));
    drop(cartographer);
    let json_path = dir.path().join("map.json");
    let eval = Command::new(deog_binary())
        .args(["eval", "map", "--map", "ex", "--world", "map1", "--json"])
        .arg(&json_path)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog eval");
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let json = std::fs::read_to_string(&json_path).expect("the evaluation's JSON");
    let coverage = field(&json, "coverage");
    let correct = field(&json, "fraction_correct");
    println!("{stdout}coverage {coverage:.3}, {correct:.3} of observed cells right");
    assert!(coverage >= 0.9, "{json}");
    assert!(correct >= 0.9, "{json}");
}

#[test]
fn a_demo_of_two_explorers_ends_by_itself_with_the_room_covered() {
    let (report, text) = explore_demo("map1", "2", "900", "8");
    assert_eq!(report["explore"], true, "{text}");
    assert_eq!(report["localize"], false, "{text}");
    assert_eq!(
        report["robots"],
        serde_json::json!([]),
        "no localizer: {text}"
    );
    let driven = report["driven_s"].as_f64().expect("driven_s");
    assert!(
        driven < 900.0 - 2.0,
        "the explorers ran out of time: {text}"
    );
    let bumps = report["bumps"].as_object().expect("bumps per robot");
    assert_eq!(bumps.len(), 2, "{text}");
    assert!(bumps.values().all(|b| b == 0), "{text}");
    assert!(report["coverage_95_s"].as_f64().is_some(), "{text}");
    let last = report["coverage"]
        .as_array()
        .and_then(|c| c.last())
        .and_then(|s| s["fraction"].as_f64())
        .expect("a coverage sample");
    assert!(last >= 0.95, "{text}");
    assert!(
        report["map"]["fraction_correct"].as_f64().expect("a map") >= 0.9,
        "{text}"
    );
}

/// The TurtleBot3 world's map_server map: a hexagon with nine pillars
/// 0.75 to 0.85 m apart, made for a robot half a Scout's size. Merged
/// cells close every gap between the pillars, and a sonar's cones narrow
/// them further on the map; the explorers must still get through, stop
/// nowhere near a pillar, and end by themselves.
#[test]
fn three_explorers_get_between_the_pillars_of_a_world_never_tuned_on() {
    let world = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../mapfile/tests/data/turtlebot3_world/map.yaml"
    );
    // At 4x, not 8x: three robots steering between pillars 0.75 m apart
    // at 8x sometimes stopped late enough on two cores to touch one.
    let (report, text) = explore_demo(world, "3", "600", "4");
    let driven = report["driven_s"].as_f64().expect("driven_s");
    assert!(
        driven < 600.0 - 2.0,
        "the explorers ran out of time: {text}"
    );
    let bumps = report["bumps"].as_object().expect("bumps per robot");
    assert_eq!(bumps.len(), 3, "{text}");
    assert!(bumps.values().all(|b| b == 0), "{text}");
    // Stopped among the pillars, the first explorers saw half the arena.
    let best = report["coverage"]
        .as_array()
        .expect("coverage samples")
        .iter()
        .filter_map(|s| s["fraction"].as_f64())
        .fold(0.0, f64::max);
    assert!(best >= 0.95, "{text}");
}
