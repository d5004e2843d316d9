//! `deog status` through the real binary: against a map server being
//! written to (a map's tiles, a robot's frames, a localizer's estimates),
//! and against no server at all.

use std::process::Command;
use std::time::{Duration, Instant};

use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{
    ServerProcess, deog_binary, failure, free_loopback_addr, run_deog, wander_frames,
};

const MAP: &str = "hall";
const ROBOT: &str = "scout-1";
/// Cells per tile side of the map the test makes.
const SIDE: usize = 8;

/// Batch `sequence` adds 1 to every cell of tile (sequence, 0).
fn batch(sequence: u64) -> pb::UpdateBatch {
    let cells: Vec<u8> = std::iter::repeat_n(1i16.to_le_bytes(), SIDE * SIDE)
        .flatten()
        .collect();
    pb::UpdateBatch {
        map: MAP.into(),
        client_id: "carto/scout-1".into(),
        sequence,
        tiles: vec![pb::TileDelta {
            key: Some(pb::TileKey {
                x: sequence as i32,
                y: 0,
            }),
            encoding: pb::CellEncoding::DenseI16Le as i32,
            cells,
        }],
    }
}

/// An estimate of frame `frame` 3 m east and 4 m north of where it truly
/// was: 5 m off.
fn estimate(frame: &pb::SonarFrame) -> pb::PoseEstimate {
    let truth = frame.true_pose.expect("simulated frames carry the truth");
    pb::PoseEstimate {
        robot: ROBOT.into(),
        map: MAP.into(),
        frame_sequence: frame.sequence,
        time_s: frame.time_s,
        pose: Some(pb::Pose2 {
            x: truth.x + 3.0,
            y: truth.y + 4.0,
            theta: truth.theta,
        }),
        covariance: vec![0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.001],
        particle_count: 500,
        converged: true,
        lost_score: 0.25,
        particle_sample: Vec::new(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn status_shows_the_maps_robots_and_localizers_being_written() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(data.path(), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("connect");
    client
        .ensure_map(pb::CreateMapRequest {
            name: MAP.into(),
            tile_size: SIDE as u32,
            ..Default::default()
        })
        .await
        .expect("map");
    let frames = wander_frames(ROBOT, 7, 400);
    let (first, live) = frames.split_at(20);
    client.publish_frames(first.to_vec()).await.expect("frames");
    // The writer's first batch lands before status's first sample, so its
    // rate has a start to count from.
    let mut raw = client.raw();
    let mut acks = raw
        .apply_updates(tokio_stream::iter([batch(1)]))
        .await
        .expect("updates")
        .into_inner();
    assert!(acks.message().await.expect("ack").is_some());

    // Status samples twice, 1 s apart, while frames, estimates (lagging two
    // frames behind) and tile batches keep arriving.
    let status = std::thread::spawn({
        let address = server.addr.to_string();
        move || run_deog(&["status", "--server", &address, "--json"], &[])
    });
    // Batches landed, and live frames sent.
    let mut sent = 1;
    let mut frames_sent = 0;
    for (i, frame) in live.iter().enumerate() {
        if status.is_finished() {
            break;
        }
        client
            .publish_frames(vec![frame.clone()])
            .await
            .expect("frame");
        client
            .publish_pose(estimate(&live[i.saturating_sub(2)]))
            .await
            .expect("estimate");
        let mut acks = raw
            .apply_updates(tokio_stream::iter([batch(i as u64 + 2)]))
            .await
            .expect("updates")
            .into_inner();
        assert!(acks.message().await.expect("ack").is_some());
        sent = i + 2;
        frames_sent = i + 1;
        // Status lists the robots, then reads their estimates: a frame and
        // its estimates every 0.1 s keep a busy machine's gap between the
        // two reads from showing a newer estimate beside an older frame
        // (at 20 ms, a lag of one frame was seen).
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let output = status.join().expect("status thread");
    let stdout = deog_tests::succeeded(&output);
    assert!(
        frames_sent < live.len(),
        "status outlasted the frames: {stdout}"
    );
    let json: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON object");

    assert_eq!(json["server"]["address"], server.addr.to_string());
    assert_eq!(json["server"]["health"], "SERVING");

    let maps = json["maps"].as_array().expect("maps");
    assert_eq!(maps.len(), 1, "{json}");
    assert_eq!(maps[0]["name"], MAP);
    let version = maps[0]["version"].as_u64().expect("version");
    assert!(version >= 5 && version <= sent as u64, "{json}");
    // Each batch writes a tile of its own, every cell of it.
    let tiles = maps[0]["tiles"].as_u64().expect("tiles");
    assert!(tiles >= 5 && tiles <= version, "{json}");
    let cells = maps[0]["cells"].as_u64().expect("cells");
    assert!(cells > 0 && cells % (SIDE * SIDE) as u64 == 0, "{json}");
    assert!(maps[0]["bounds"]["max_x"].as_f64().expect("bounds") > 0.0);
    assert!(
        maps[0]["writes_per_s"].as_f64().expect("rate") > 1.0,
        "{json}"
    );
    let writers = maps[0]["writers"].as_array().expect("writers");
    assert_eq!(writers.len(), 1, "{json}");
    assert_eq!(writers[0]["client_id"], "carto/scout-1");
    // Read just after the map's version, while batches keep landing.
    let last_sequence = writers[0]["last_sequence"].as_u64().expect("sequence");
    assert!(
        last_sequence >= version && last_sequence <= sent as u64,
        "{json}"
    );
    assert!(
        writers[0]["batches_per_s"].as_f64().expect("rate") > 1.0,
        "{json}"
    );

    let robots = json["robots"].as_array().expect("robots");
    assert_eq!(robots.len(), 1, "{json}");
    assert_eq!(robots[0]["name"], ROBOT);
    let frames_stored = robots[0]["frames"].as_u64().expect("frames");
    assert!(
        frames_stored > 20 && frames_stored <= 20 + frames_sent as u64,
        "{json}"
    );
    assert!(
        robots[0]["frames_per_s"].as_f64().expect("rate") > 1.0,
        "{json}"
    );
    let age = robots[0]["last_frame_age_s"].as_f64().expect("frame age");
    assert!((0.0..1.0).contains(&age), "{json}");

    let localizers = json["localizers"].as_array().expect("localizers");
    assert_eq!(localizers.len(), 1, "{json}");
    let row = &localizers[0];
    assert_eq!(row["robot"], ROBOT);
    assert_eq!(row["map"], MAP);
    assert_eq!(row["converged"], true);
    assert_eq!(row["lost_score"].as_f64(), Some(0.25));
    // Two frames behind; status reads the robots' frames and then the
    // estimates, so a frame and an estimate landing between the two reads
    // show one frame less (seen on a busy two-core machine), and a frame
    // in with its estimate not yet one more.
    let lag = row["lag_frames"].as_u64().expect("lag");
    assert!((1..=3).contains(&lag), "{json}");
    assert!(row["lag_s"].as_f64().expect("lag") > 0.0, "{json}");
    let error = row["error_m"].as_f64().expect("error");
    assert!((error - 5.0).abs() < 1e-6, "{json}");
    let age = row["last_estimate_age_s"].as_f64().expect("estimate age");
    assert!((0.0..1.0).contains(&age), "{json}");

    // And as a table: a person's view names the same things.
    let table = deog_tests::succeeded(&tokio::task::block_in_place(|| {
        run_deog(
            &[
                "status",
                "--server",
                &server.addr.to_string(),
                "--interval-s",
                "0.2",
            ],
            &[],
        )
    }));
    for word in [
        "SERVING",
        MAP,
        ROBOT,
        "carto/scout-1",
        "writes/s",
        "frames/s",
        "lag (frames)",
    ] {
        assert!(table.contains(word), "{word} in {table}");
    }
}

#[test]
fn status_without_a_server_fails_quickly_on_one_line() {
    let address = free_loopback_addr().to_string();
    let started = Instant::now();
    let output = run_deog(
        &["status", "--server", &address, "--connect-timeout", "2"],
        &[],
    );
    let stderr = failure(&output);
    assert!(started.elapsed() < Duration::from_secs(4), "{stderr}");
    // Besides the warning while it tries, one error line.
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(
        errors[0].contains(&format!("cannot reach the map server at {address}")),
        "{stderr}"
    );
}

#[test]
fn status_refuses_a_bad_interval() {
    let output = Command::new(deog_binary())
        .args(["status", "--interval-s", "0"])
        .env("RUST_LOG", "warn")
        .output()
        .expect("deog runs");
    let stderr = failure(&output);
    assert!(stderr.contains("--interval-s"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}

/// A child process killed when dropped, so that a failing test leaves no
/// `deog status --watch` running.
struct KillOnDrop(std::process::Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Reads the lines a child prints, one at a time, each within `timeout`.
fn lines_of(stdout: std::process::ChildStdout) -> std::sync::mpsc::Receiver<String> {
    use std::io::BufRead as _;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn status_watch_outlives_a_server_restart_and_times_frames_after_it() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(data.path(), &[]).await;
    let addr = server.addr;
    // Frames stored before status starts: it follows the robot from its
    // first sample but times no arrival.
    let frames = wander_frames(ROBOT, 3, 200);
    let (before, after) = frames.split_at(5);
    MapClient::connect(ClientConfig::new(addr.to_string()))
        .await
        .expect("connect")
        .publish_frames(before.to_vec())
        .await
        .expect("frames");
    let watch = Command::new(deog_binary())
        .args(["status", "--watch", "--json", "--interval-s", "0.3"])
        .args(["--server", &addr.to_string()])
        .env("RUST_LOG", "warn")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("deog status starts");
    let mut watch = KillOnDrop(watch);
    let lines = lines_of(watch.0.stdout.take().expect("stdout"));
    let next = || {
        lines
            .recv_timeout(Duration::from_secs(20))
            .expect("a line within 20 s")
    };
    let first: serde_json::Value = serde_json::from_str(&next()).expect("JSON");
    assert_eq!(first["server"]["health"], "SERVING");
    assert_eq!(first["robots"][0]["name"], ROBOT);
    assert!(first["robots"][0]["last_frame_age_s"].is_null(), "{first}");

    server.kill();
    let down = (0..50)
        .map(|_| next())
        .find(|line| line.starts_with("error: "))
        .expect("an error line while the server is down");
    assert!(!down.contains('\n'), "{down}");

    let server = ServerProcess::start_on(addr, data.path(), &[]).await;
    let client = MapClient::connect(ClientConfig::new(addr.to_string()))
        .await
        .expect("connect");
    // Frames keep arriving until status has seen one arrive: it followed
    // the robot's frames anew on the restarted server.
    let mut seen = None;
    for frame in after {
        client
            .publish_frames(vec![frame.clone()])
            .await
            .expect("frame");
        while let Ok(line) = lines.try_recv() {
            if let Ok(json) = serde_json::from_str::<serde_json::Value>(&line)
                && json["robots"][0]["last_frame_age_s"].is_f64()
            {
                seen = Some(json);
            }
        }
        if seen.is_some() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let json = seen.expect("status timed a frame after the restart");
    assert_eq!(json["server"]["health"], "SERVING");
    assert_eq!(json["robots"][0]["name"], ROBOT);

    let stopped = Command::new("kill")
        .args(["-INT", &watch.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(stopped.success());
    let status = watch.0.wait().expect("deog status ends");
    assert!(status.success(), "ctrl-c ends --watch cleanly: {status:?}");
    drop(server);
}
