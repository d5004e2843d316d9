//! Every long-running `deog` command ends, exit 0, soon after SIGTERM or
//! ctrl-c (SIGINT), whatever it is waiting on: a server that is not there,
//! frames that do not come, estimates that do not come, or its own work
//! (a localizer building the map's range tables).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, free_loopback_addr, succeeded, wander_frames};

/// How long a process may take to end after the signal: the 2 s every
/// process is held to, and a second for a loaded test machine.
const WITHIN: Duration = Duration::from_secs(3);

/// `deog <args>` with `DEOG_SERVER` and `DEOG_SIM` at `server` and `sim`,
/// its log (info) in `log`.
fn spawn(args: &[&str], server: &str, sim: &str, log: &Path) -> Child {
    let mut command = Command::new(deog_binary());
    command
        .args(args)
        .env("DEOG_SERVER", server)
        .env("DEOG_SIM", sim)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(log).expect("log file"));
    command.spawn().expect("start deog")
}

/// Waits, at most `within`, for `needle` in the log.
fn wait_for_log(log: &Path, needle: &str, within: Duration) -> bool {
    let began = Instant::now();
    while began.elapsed() < within {
        if std::fs::read_to_string(log).is_ok_and(|text| text.contains(needle)) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    false
}

/// Sends `signal` and waits, at most [`WITHIN`], for the process to end
/// with exit 0; what it printed. Panics naming `what` otherwise.
fn stops_on(mut child: Child, signal: &str, what: &str) -> String {
    assert!(
        child.try_wait().expect("wait").is_none(),
        "{what}: still running before the signal"
    );
    let sent = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(sent.success(), "kill {signal}");
    let began = Instant::now();
    while began.elapsed() < WITHIN {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "{what}: exit 0 on {signal}, got {status}");
            let output = child.wait_with_output().expect("output");
            return String::from_utf8_lossy(&output.stdout).into_owned();
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("{what}: still running {WITHIN:?} after kill {signal}");
}

/// Each command in `cases` (its arguments and the log line that says it is
/// in the state to test), started twice: stopped with SIGTERM, then ctrl-c.
fn each_stops(cases: &[(&str, Vec<&str>, &str)], server: &str, sim: &str, dir: &Path) {
    for (what, args, waiting) in cases {
        for signal in ["-TERM", "-INT"] {
            let log: PathBuf = dir.join(format!("{}{signal}.log", what.replace(' ', "_")));
            let child = spawn(args, server, sim, &log);
            assert!(
                wait_for_log(&log, waiting, Duration::from_secs(30)),
                "{what}: never logged {waiting:?}: {}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
            // Into the wait, past the line that announced it.
            std::thread::sleep(Duration::from_millis(300));
            stops_on(child, signal, &format!("{what} ({waiting})"));
        }
    }
}

#[test]
fn commands_waiting_for_a_server_that_is_not_there_stop_on_either_signal() {
    let dir = tempfile::tempdir().expect("temp dir");
    let nobody = free_loopback_addr().to_string();
    let cases = [
        ("map", vec!["map", "--robot", "r", "--map", "m"], "retrying"),
        (
            "localize",
            vec!["localize", "--robot", "r", "--map", "m"],
            "retrying",
        ),
        (
            "frames follow",
            vec!["frames", "--robot", "r", "--follow"],
            "retrying",
        ),
        (
            "wander",
            vec!["wander", "--robot", "r", "--spawn"],
            "retrying",
        ),
        (
            "explore",
            vec!["explore", "--robot", "r", "--spawn", "--map", "m"],
            "retrying",
        ),
        ("status watch", vec!["status", "--watch"], "retrying"),
    ];
    each_stops(&cases, &nobody, &nobody, dir.path());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn commands_waiting_for_frames_or_their_own_work_stop_on_either_signal() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let addr = server.addr.to_string();
    let map = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mapfile/tests/data/lse_arena.yaml");
    succeeded(&deog_tests::run_deog(
        &["import", "--map", "arena", map.to_str().expect("path")],
        &[("DEOG_SERVER", addr.clone())],
    ));
    let client = MapClient::connect(ClientConfig::new(addr.clone()))
        .await
        .expect("client");
    client
        .publish_frames(wander_frames("moving", 5, 20))
        .await
        .expect("publish");
    let cases = [
        (
            "map",
            vec!["map", "--robot", "idle", "--map", "m"],
            "waiting for frames",
        ),
        (
            "localize",
            vec!["localize", "--robot", "idle", "--map", "arena"],
            "waiting for frames",
        ),
        (
            "frames follow",
            vec!["frames", "--robot", "idle", "--follow"],
            "waiting for frames",
        ),
        (
            "localize building tables",
            vec![
                "localize", "--robot", "moving", "--map", "arena", "--from", "1",
            ],
            "localizing with the frames' rig",
        ),
    ];
    each_stops(&cases, &addr, &free_loopback_addr().to_string(), dir.path());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cartographer_stopped_while_waiting_for_an_estimate_leaves_the_frame_for_the_next_run() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let addr = server.addr.to_string();
    let client = MapClient::connect(ClientConfig::new(addr.clone()))
        .await
        .expect("client");
    client
        .publish_frames(wander_frames("r", 5, 20))
        .await
        .expect("publish");
    let args = [
        "map",
        "--robot",
        "r",
        "--map",
        "m",
        "--pose",
        "estimate",
        "--estimate-wait",
        "60",
    ];
    for signal in ["-TERM", "-INT"] {
        let log = dir.path().join(format!("map{signal}.log"));
        let child = spawn(&args, &addr, &free_loopback_addr().to_string(), &log);
        assert!(
            wait_for_log(
                &log,
                "waiting for the localizer's estimate",
                Duration::from_secs(30)
            ),
            "{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        let printed = stops_on(child, signal, "deog map waiting for an estimate");
        // The frame it waited on was neither mapped nor skipped.
        assert!(printed.contains("r -> m: 0 frames integrated"), "{printed}");
        assert!(
            printed.contains(", 0 the localizer passed over"),
            "{printed}"
        );
    }
}
