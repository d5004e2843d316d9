//! `deog map --pose estimate` stops on SIGTERM and ctrl-c while a frame
//! waits for a localizer that never publishes: the wait ends on the
//! signal, not on `--estimate-wait`.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, wander_frames};

/// A cartographer mapping from estimates that will not come within the
/// test: each frame would wait a minute.
fn waiting_cartographer(server: &ServerProcess) -> Child {
    Command::new(deog_binary())
        .args([
            "map",
            "--robot",
            "r",
            "--map",
            "m",
            "--pose",
            "estimate",
            "--estimate-wait",
            "60",
        ])
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start deog map")
}

/// Sends `signal` and waits, at most `within`, for the process to end;
/// what it printed, or `None` if it did not end.
fn stop_within(mut child: Child, signal: &str, within: Duration) -> Option<String> {
    let sent = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(sent.success(), "kill {signal}");
    let began = Instant::now();
    while began.elapsed() < within {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "deog map exits 0 on {signal}: {status}");
            let output = child.wait_with_output().expect("output");
            return Some(String::from_utf8_lossy(&output.stdout).into_owned());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cartographer_waiting_for_estimates_stops_on_sigterm_and_ctrl_c() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    client
        .publish_frames(wander_frames("r", 5, 20))
        .await
        .expect("publish");
    for signal in ["-TERM", "-INT"] {
        let mut child = waiting_cartographer(&server);
        // Long enough to connect, read the first frame and wait on it.
        std::thread::sleep(Duration::from_secs(3));
        assert!(
            child.try_wait().expect("wait").is_none(),
            "deog map waits for the estimates"
        );
        // It ends in well under a second; the bound leaves room for a
        // loaded machine, far below the minute the frame would wait.
        let printed = stop_within(child, signal, Duration::from_secs(5))
            .unwrap_or_else(|| panic!("deog map still running 5 s after kill {signal}"));
        // The frame it waited on was neither mapped nor skipped: the next
        // run takes it up.
        assert!(printed.contains("r -> m: 0 frames integrated"), "{printed}");
        assert!(
            printed.contains(", 0 the localizer passed over"),
            "{printed}"
        );
    }
}
