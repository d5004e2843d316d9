//! `deog frames` writing into a pipe whose reader has gone (as `deog
//! frames | head` leaves it): the listing ends quietly, never with a panic.

use std::process::{Command, Stdio};

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, wander_frames};

/// Runs `deog frames` with `args` against `server`, its standard output a
/// pipe whose reading end is closed before it writes anything.
fn frames_into_a_closed_pipe(server: &ServerProcess, args: &[&str]) -> std::process::Output {
    let mut child = Command::new(deog_binary())
        .arg("frames")
        .args(args)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("deog starts");
    drop(child.stdout.take());
    child.wait_with_output().expect("deog ends")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_listing_into_a_closed_pipe_ends_without_a_panic() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(data.path(), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("connect");
    for robot in ["scout-1", "scout-2"] {
        let (stored, _) = client
            .publish_frames(wander_frames(robot, 1, 50))
            .await
            .expect("frames");
        assert_eq!(stored, 50);
    }
    for args in [&["--robot", "scout-1"][..], &[][..]] {
        let output = tokio::task::block_in_place(|| frames_into_a_closed_pipe(&server, args));
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            output.status.success() && !stderr.contains("panicked"),
            "deog frames {args:?} into a closed pipe: {:?}\n{stderr}",
            output.status
        );
    }
}
