//! `deog explore` as a real process: a map server, the simulator with
//! map1, a cartographer and one explorer. The explorer ends by itself,
//! saying the map is explored, without a bump, and the map then covers the
//! room's reachable free space.

use std::process::Command;
use std::time::Duration;

use deog_tests::{RunningDeog, ServerProcess, deog_binary, json_field};

fn field(json: &str, name: &str) -> f64 {
    json_field(json, name)
        .parse()
        .unwrap_or_else(|_| panic!("{name} is a number in {json}"))
}

#[test]
fn one_explorer_maps_a_room_and_stops_by_itself() {
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
