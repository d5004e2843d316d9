//! The mistakes a person makes first, through the real `deog` binary: a
//! server that is not running, a map or robot that does not exist, a file
//! that is not there, a bad flag. Each ends within its bound with one
//! readable error line: no repeated text, no debug formatting, the gRPC
//! code in words.

use std::time::{Duration, Instant};

use deog_tests::{ServerProcess, failure, free_loopback_addr, run_deog};

/// The `error: ...` line of a failed run's stderr, checked to be the only
/// one and free of what a person should not have to read.
fn error_line(args: &[&str]) -> String {
    let output = run_deog(args, &[]);
    let stderr = failure(&output);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "deog {args:?}: {stderr}");
    let line = errors[0].to_string();
    for debug in ["Status {", "code: '", "Os {", "Error {", "\\n"] {
        assert!(!line.contains(debug), "deog {args:?}: debug text in {line}");
    }
    // No sentence said twice ("x: y: x: y").
    let parts: Vec<&str> = line.split(": ").collect();
    for (i, part) in parts.iter().enumerate() {
        assert!(
            part.len() < 12 || !parts[i + 1..].contains(part),
            "deog {args:?}: {part:?} repeated in {line}"
        );
    }
    line
}

#[test]
fn a_server_that_is_not_running_is_named_with_a_hint_within_the_timeout() {
    // Built before the clock starts.
    deog_tests::deog_binary();
    let addr = free_loopback_addr().to_string();
    let out = tempfile::tempdir().expect("temp dir");
    let data = out.path().join("frames.txt");
    std::fs::write(&data, "0 0 0 1 1 1 1 1 1 1 1 1 1 1 1 1 1 1 1\n").expect("data file");
    let out_dir = out.path().to_string_lossy().into_owned();
    let data = data.to_string_lossy().into_owned();
    let one_shots: [Vec<&str>; 4] = [
        vec!["export", "--map", "lab", "--out", &out_dir],
        vec!["frames"],
        vec!["import", "--robot", "r", &data],
        vec!["eval", "map", "--map", "lab", "--world", "map2"],
    ];
    for args in one_shots {
        let mut args = args.clone();
        args.extend(["--server", &addr, "--connect-timeout", "1"]);
        let started = Instant::now();
        let line = error_line(&args);
        let took = started.elapsed();
        assert!(took < Duration::from_secs(4), "deog {args:?} took {took:?}");
        assert!(
            line.contains(&format!("cannot reach the map server at {addr}"))
                && line.contains("start one with `deog server --listen"),
            "deog {args:?}: {line}"
        );
    }
    // What it connects to, at once, and that it cannot, before giving up.
    let output = run_deog(
        &["frames", "--server", &addr, "--connect-timeout", "2"],
        &[("RUST_LOG", "info".to_string())],
    );
    let stderr = failure(&output);
    let said = |text: &str| stderr.lines().position(|l| l.contains(text));
    let connecting = said(&format!("connecting to the map server at {addr}"));
    let retrying = said("; retrying");
    let gave_up = said("error: cannot reach");
    assert!(
        connecting.is_some() && connecting < retrying && retrying < gave_up,
        "{stderr}"
    );
    let line = error_line(&[
        "teleport",
        "--robot",
        "r",
        "--pose",
        "1,1,0",
        "--sim",
        &addr,
        "--connect-timeout",
        "1",
    ]);
    assert!(
        line.contains(&format!("cannot reach the simulator at {addr}"))
            && line.contains("`deog sim --listen"),
        "{line}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_maps_robots_and_files_are_one_line_each() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let addr = server.addr.to_string();
    let run = |args: &[&str]| {
        let mut args = args.to_vec();
        args.extend(["--server", addr.as_str()]);
        tokio::task::block_in_place(|| error_line(&args))
    };
    let line = run(&["localize", "--robot", "r", "--map", "nosuch"]);
    assert!(
        line.contains("map \"nosuch\" does not exist (not found)"),
        "{line}"
    );
    let line = run(&["eval", "map", "--map", "nosuch", "--world", "map2"]);
    assert!(
        line.contains("map \"nosuch\" does not exist (not found)"),
        "{line}"
    );
    let out = dir.path().to_string_lossy().into_owned();
    let line = run(&["export", "--map", "nosuch", "--out", &out]);
    assert!(line.contains("no map named \"nosuch\""), "{line}");
    let line = run(&["frames", "--robot", "nobody"]);
    assert!(
        line.contains("robot nobody has published no frames"),
        "{line}"
    );
    let line = run(&["import", "--robot", "r", "/nonexistent/frames.txt"]);
    assert!(
        line.contains("/nonexistent/frames.txt") && line.contains("No such file"),
        "{line}"
    );
}

#[test]
fn bad_files_and_flags_are_named() {
    let line = error_line(&["sim", "--world", "/nonexistent/world.toml"]);
    assert!(line.contains("/nonexistent/world.toml"), "{line}");
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().to_string_lossy().into_owned();
    let line = error_line(&["server", "--data", &data, "--max-connections", "0"]);
    assert!(
        line.contains("--max-connections must be at least 1"),
        "{line}"
    );
    let line = error_line(&[
        "export",
        "--map",
        "lab",
        "--out",
        &data,
        "--connect-timeout",
        "0",
    ]);
    assert!(line.contains("--connect-timeout"), "{line}");
    // Checked before the map server is asked for anything.
    let line = error_line(&[
        "map",
        "--robot",
        "r",
        "--map",
        "lab",
        "--shadow-depth",
        "11",
    ]);
    assert!(
        line.contains("--shadow-depth") && line.contains("got 11"),
        "{line}"
    );
    // clap's own: the flag named, the usage after it.
    let output = run_deog(&["map", "--robot"], &[]);
    let stderr = failure(&output);
    assert!(
        stderr
            .lines()
            .next()
            .is_some_and(|l| l.starts_with("error:") && l.contains("--robot")),
        "{stderr}"
    );
}
