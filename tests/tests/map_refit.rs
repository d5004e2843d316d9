//! `deog refit` through the real binary and a real map server: a
//! specular sonar's map, built by `deog map` as `deog demo` builds it, is
//! refitted to its frames; the files it writes, imported as a map, judge
//! better against the world than the map it started from. Bad requests
//! are refused with a line that says why.

use std::path::Path;
use std::process::{Command, Output};

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, deog_binary, json_field, wander_frames_with};

fn deog(server: &ServerProcess, args: &[&str]) -> Output {
    Command::new(deog_binary())
        .args(args)
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog")
}

fn ok(output: &Output) -> String {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn refused(output: &Output) -> String {
    assert!(!output.status.success(), "expected a refusal");
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// `deog eval map`'s figures for `map` against map2: cells right, and
/// the recall of the walls it observed.
fn judge(server: &ServerProcess, map: &str, json: &Path) -> (f64, f64) {
    let json_arg = json.to_str().expect("utf-8 path");
    ok(&deog(
        server,
        &[
            "eval", "map", "--map", map, "--world", "map2", "--json", json_arg,
        ],
    ));
    let text = std::fs::read_to_string(json).expect("report written");
    let number = |name: &str| -> f64 {
        json_field(&text, name)
            .parse()
            .unwrap_or_else(|_| panic!("{name} in {text}"))
    };
    (
        number("fraction_correct"),
        number("observed_occupied_recall"),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_specular_sonars_map_refitted_to_its_frames_judges_better() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    // Five simulated minutes of `deog sim --sonar realistic`.
    let frames = wander_frames_with("r", 5, 3000, deog_simulator::SonarParams::realistic());
    client.publish_frames(frames).await.expect("publish");

    // The map as `deog demo` maps a specular sonar.
    let out = ok(&deog(
        &server,
        &[
            "map",
            "--robot",
            "r",
            "--map",
            "m",
            "--idle-exit",
            "1",
            "--firing-period",
            "0.1",
            "--sonar-method",
            "directional",
            "--no-echo-free-range",
            "0",
            "--max-free-range",
            "2",
        ],
    ));
    assert!(out.contains("3000 frames integrated"), "{out}");
    let (mapped_right, mapped_recall) = judge(&server, "m", &dir.path().join("m.json"));

    let files = dir.path().join("refit");
    let files_arg = files.to_str().expect("utf-8 path");
    let out = ok(&deog(
        &server,
        &[
            "refit",
            "--map",
            "m",
            "--robots",
            "r",
            "--firing-period",
            "0.1",
            "--out",
            files_arg,
        ],
    ));
    assert!(out.contains("map m refitted to 48000 readings"), "{out}");
    for ext in ["pgm", "yaml", "png"] {
        assert!(files.join(format!("m-refit.{ext}")).is_file(), "{ext}");
    }
    let yaml = files.join("m-refit.yaml");
    ok(&deog(
        &server,
        &[
            "import",
            "--map",
            "refit",
            yaml.to_str().expect("utf-8 path"),
        ],
    ));
    let (refit_right, refit_recall) = judge(&server, "refit", &dir.path().join("refit.json"));
    assert!(
        refit_right >= 0.98 && refit_right > mapped_right,
        "cells right: refitted {refit_right}, mapped {mapped_right}"
    );
    assert!(
        refit_recall >= 0.9 && refit_recall + 0.02 >= mapped_recall,
        "walls observed held: refitted {refit_recall}, mapped {mapped_recall}"
    );
    // The map it started from is as it was.
    let (again, _) = judge(&server, "m", &dir.path().join("m2.json"));
    assert_eq!(again, mapped_right);

    // What cannot be refitted says why.
    let refusals: [(&[&str], &str); 4] = [
        (
            &["--map", "nosuch", "--robots", "r"],
            "no map named \"nosuch\"",
        ),
        (
            &["--map", "m", "--robots", "ghost"],
            "no frame of robot \"ghost\"",
        ),
        (
            &[
                "--map",
                "m",
                "--robots",
                "r",
                "--critical-incidence-deg",
                "120",
            ],
            "--critical-incidence-deg",
        ),
        (
            &["--map", "m", "--robots", "r", "--iterations", "0"],
            "--iterations takes 1 to 50",
        ),
    ];
    for (args, says) in refusals {
        let mut command = vec!["refit"];
        command.extend_from_slice(args);
        command.extend_from_slice(&["--out", files_arg]);
        let line = refused(&deog(&server, &command));
        assert!(line.contains(says), "{args:?}: {line}");
    }
}
