//! `deog import --carmen` through the real binary and a real map server: a
//! real log's scans become frames with their rig, raw odometry and
//! reference poses; a wrong rig or a malformed log is refused naming the
//! line, with nothing stored.

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, failure, run_deog, succeeded};
use std::process::Output;

fn deog(args: &[&str], server: &ServerProcess) -> Output {
    run_deog(args, &[("DEOG_SERVER", server.addr.to_string())])
}

fn log(name: &str) -> String {
    format!("{}/../data/carmen/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[tokio::test]
async fn a_real_log_imports_with_its_own_laser_and_poses() {
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    let aces = log("aces-corrected.log.gz");
    let out = succeeded(&deog(
        &["import", "--carmen", &aces, "--robot", "aces"],
        &server,
    ));
    assert!(out.contains("440 FLASER scans read, 440 stored"), "{out}");
    // Again: nothing twice.
    let out = succeeded(&deog(
        &["import", "--carmen", &aces, "--robot", "aces"],
        &server,
    ));
    assert!(out.contains("0 stored, 440 already there"), "{out}");

    let client = MapClient::connect(ClientConfig::new(server.url()))
        .await
        .unwrap();
    let frames = client.read_frames("aces", 1, 0).await.unwrap();
    assert_eq!(frames.len(), 440);
    let rig = client.rig(&frames[0].rig).await.unwrap();
    assert_eq!(rig.readings(), 180);
    assert_eq!(rig.max_range(), 50.0);
    assert!(rig.all_laser());
    for frame in &frames {
        assert_eq!(frame.ranges.len(), 180);
        assert!(frame.true_pose.is_none());
        assert!(frame.reference_pose.is_some());
    }
    // Raw odometry drifts from the corrected poses, but slowly.
    let (first, last) = (&frames[0], &frames[439]);
    let odo = first.odometry.unwrap();
    let reference = first.reference_pose.unwrap();
    assert!((odo.x - reference.x).abs() < 1e-9 && (odo.y - reference.y).abs() < 1e-9);
    let odo = last.odometry.unwrap();
    let reference = last.reference_pose.unwrap();
    let apart = (odo.x - reference.x).hypot(odo.y - reference.y);
    assert!(apart > 0.1 && apart < 30.0, "{apart} m");
}

#[tokio::test]
async fn a_wrong_rig_or_a_malformed_log_is_refused_and_nothing_is_stored() {
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    let intel = log("intel-corrected.log.gz");
    let out = deog(
        &[
            "import",
            "--carmen",
            &intel,
            "--robot",
            "r",
            "--rig",
            "pioneer3dx",
        ],
        &server,
    );
    let err = failure(&out);
    assert!(
        err.contains(":175: rig pioneer3dx reads 16 ranges per frame, the frame has 180"),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.log");
    std::fs::write(
        &bad,
        "# a log\nODOM 0 0 0 0 0 0 0.1 h 0.1\nFLASER 3 1 2 3 0 0 0 0 0 0 0.2 h 0.2\nFLASER 3 1 2 0 0 0 0 0 0 0.3 h 0.3\n",
    )
    .unwrap();
    let err = failure(&deog(
        &["import", "--carmen", bad.to_str().unwrap(), "--robot", "r"],
        &server,
    ));
    assert!(err.contains("bad.log:4"), "{err}");
    let err = failure(&deog(
        &["import", "--carmen", "/nonexistent/x.log", "--robot", "r"],
        &server,
    ));
    assert!(err.contains("/nonexistent/x.log"), "{err}");

    let client = MapClient::connect(ClientConfig::new(server.url()))
        .await
        .unwrap();
    assert!(client.robots().await.unwrap().is_empty());
}

/// The share of a frame's echoes (placed at `pose`) that end within one
/// cell of a cell the map holds occupied.
fn echoes_on_walls(
    map: &deog_grid::TileMap,
    rig: &deog_rig::Rig,
    pose: deog_grid::Pose2,
    ranges: &[f64],
) -> f64 {
    let res = map.resolution();
    let (mut echoes, mut on_walls) = (0, 0);
    for (beam, &r) in rig.beams().iter().zip(ranges) {
        let Some(deog_rig::Reading::Echo(r)) = beam.classify(r) else {
            continue;
        };
        if r > 20.0 {
            continue;
        }
        let sensor = pose.compose(&beam.mount);
        let (x, y) = (
            sensor.x + r * sensor.theta.cos(),
            sensor.y + r * sensor.theta.sin(),
        );
        let cell = res.cell_of(x, y).unwrap();
        echoes += 1;
        let near_wall = (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                map.get(deog_grid::CellIndex::new(cell.x + dx, cell.y + dy))
                    .is_some_and(|b| b.probability() > 0.5)
            })
        });
        on_walls += usize::from(near_wall);
    }
    on_walls as f64 / echoes as f64
}

#[tokio::test]
async fn a_map_built_from_a_logs_reference_poses_puts_its_echoes_on_walls() {
    let data = tempfile::tempdir().unwrap();
    let server = ServerProcess::start(data.path(), &[]).await;
    let aces = log("aces-corrected.log.gz");
    succeeded(&deog(
        &["import", "--carmen", &aces, "--robot", "aces"],
        &server,
    ));
    for (pose, map) in [("reference", "by-reference"), ("odometry", "by-odometry")] {
        let out = succeeded(&deog(
            &[
                "map", "--robot", "aces", "--map", map, "--pose", pose, "--to", "150",
            ],
            &server,
        ));
        assert!(out.contains("150 frames integrated"), "{out}");
    }
    let client = MapClient::connect(ClientConfig::new(server.url()))
        .await
        .unwrap();
    let frames = client.read_frames("aces", 1, 150).await.unwrap();
    let rig = client.rig(&frames[0].rig).await.unwrap();
    let (_, by_reference) = client.download("by-reference").await.unwrap();
    let (_, by_odometry) = client.download("by-odometry").await.unwrap();
    let pose = |p: deog_proto::v1::Pose2| deog_grid::Pose2::new(p.x, p.y, p.theta);
    let mean = |map: &deog_grid::TileMap,
                pick: &dyn Fn(&deog_proto::v1::SonarFrame) -> deog_grid::Pose2| {
        frames
            .iter()
            .map(|f| echoes_on_walls(map, &rig, pick(f), &f.ranges))
            .sum::<f64>()
            / frames.len() as f64
    };
    let reference = mean(&by_reference, &|f| pose(f.reference_pose.unwrap()));
    let odometry = mean(&by_odometry, &|f| pose(f.odometry.unwrap()));
    // Where the log says the robot was, each scan meets the walls the
    // whole log built; odometry drifts, and its map smears.
    assert!(reference > 0.9, "reference: {reference:.3}");
    assert!(
        odometry < reference,
        "odometry {odometry:.3}, reference {reference:.3}"
    );
}
