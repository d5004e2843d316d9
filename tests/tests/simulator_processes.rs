//! The simulator, wanderers and the map server as separate processes: the
//! wanderers drive their robots without a bump and every frame arrives in
//! the map server; a data file written by a wanderer imports once.

use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, SimClient};
use deog_tests::{ServerProcess, deog_binary, run_deog, succeeded};
use std::process::{Command, Output};

fn deog(args: &[&str], server: &ServerProcess, sim: &ServerProcess) -> Output {
    run_deog(
        args,
        &[
            ("DEOG_SERVER", server.addr.to_string()),
            ("DEOG_SIM", sim.addr.to_string()),
        ],
    )
}

fn stdout(output: &Output) -> String {
    succeeded(output)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wanderers_publish_every_frame_to_the_map_server() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let sim = ServerProcess::start_sim("map2", &["--speed", "10", "--seed", "5"]).await;
    let data_file = dir.path().join("scout-a.dat");
    let data_file = data_file.to_str().expect("utf-8 path");

    // Three wanderers at once, each its own process, 20 simulated seconds.
    let runs: Vec<_> = ["scout-a", "scout-b", "scout-c"]
        .iter()
        .enumerate()
        .map(|(i, robot)| {
            let seed = (i + 1).to_string();
            let mut args = vec![
                "wander",
                "--robot",
                robot,
                "--spawn",
                "--duration",
                "20",
                "--seed",
            ];
            args.push(&seed);
            if i == 0 {
                args.extend(["--data-file", data_file]);
            }
            let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
            let (server_addr, sim_addr) = (server.addr, sim.addr);
            std::thread::spawn(move || {
                Command::new(deog_binary())
                    .args(&args)
                    .env("DEOG_SERVER", server_addr.to_string())
                    .env("DEOG_SIM", sim_addr.to_string())
                    .env("RUST_LOG", "warn")
                    .output()
                    .expect("run wander")
            })
        })
        .collect();
    let mut frames_published = Vec::new();
    for run in runs {
        let out = stdout(&run.join().expect("wander thread"));
        // "scout-a: 201 frames over 20.0 simulated s, 8.1 m driven, 0 bumps, 201 frames published"
        assert!(out.contains(" 0 bumps"), "{out}");
        let frames: u64 = out
            .split_whitespace()
            .nth(1)
            .and_then(|n| n.parse().ok())
            .expect("frame count");
        assert!(frames >= 195, "{out}");
        assert!(
            out.trim_end()
                .ends_with(&format!("{frames} frames published")),
            "{out}"
        );
        frames_published.push(frames);
    }

    let map = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("map client");
    let robots = map
        .raw()
        .list_robots(pb::ListRobotsRequest {})
        .await
        .expect("robots")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 3, "{robots:?}");
    for (robot, published) in robots.iter().zip(&frames_published) {
        assert_eq!(robot.frame_count, *published, "{robot:?}");
        // Consecutive sequences: no frame missing in the middle.
        assert_eq!(
            robot.last_sequence - robot.first_sequence + 1,
            robot.frame_count,
            "{robot:?}"
        );
        let frames = map
            .read_frames(&robot.robot, 0, 0)
            .await
            .expect("read frames");
        assert!(
            frames
                .iter()
                .all(|f| f.ranges.len() == 16 && f.true_pose.is_some())
        );
        assert!(frames.windows(2).all(|w| w[1].time_s > w[0].time_s));
    }

    // The simulator has the robots where the frames say.
    let sim_client = SimClient::connect(ClientConfig::new(sim.addr.to_string()))
        .await
        .expect("sim client");
    let states = sim_client.robots().await.expect("robots");
    assert_eq!(states.len(), 3);
    for state in &states {
        let last = map
            .read_frames(&state.name, 0, 0)
            .await
            .expect("frames")
            .pop()
            .expect("a frame");
        let (a, b) = (
            last.true_pose.expect("pose"),
            state.true_pose.expect("pose"),
        );
        // The robot may roll on a little after its last frame while it
        // brakes.
        assert!((a.x - b.x).hypot(a.y - b.y) < 0.75, "{a:?} vs {b:?}");
    }

    // The data file: one line per frame, and it imports exactly once.
    let lines = std::fs::read_to_string(data_file).expect("data file");
    assert_eq!(lines.lines().count() as u64, frames_published[0]);
    let out = stdout(&deog(
        &["import", "--robot", "replay", data_file],
        &server,
        &sim,
    ));
    assert!(
        out.contains(&format!("{} stored, 0 already there", frames_published[0])),
        "{out}"
    );
    let out = stdout(&deog(
        &["import", "--robot", "replay", data_file],
        &server,
        &sim,
    ));
    assert!(out.contains(" 0 stored,"), "{out}");
    let out = stdout(&deog(&["frames"], &server, &sim));
    assert!(
        out.contains(&format!("replay: {} frames", frames_published[0])),
        "{out}"
    );

    // Bad input gets a clear error, not a panic.
    let out = deog(&["wander", "--robot", "no such robot"], &server, &sim);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--robot") && !err.contains("panicked"),
        "{err}"
    );
    let out = deog(&["sim", "--world", "atlantis"], &server, &sim);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("map1, map2, office"),
        "{err}"
    );

    assert!(sim.terminate(), "the simulator exits cleanly on SIGTERM");
    assert!(
        server.terminate(),
        "the map server exits cleanly on SIGTERM"
    );
}
