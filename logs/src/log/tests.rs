use std::f64::consts::PI;

use approx::assert_abs_diff_eq;
use deog_grid::{Pose2, normalize_angle};

use super::*;

fn assert_pose(a: Pose2, b: Pose2) {
    assert_abs_diff_eq!(a.x, b.x, epsilon = 1e-6);
    assert_abs_diff_eq!(a.y, b.y, epsilon = 1e-6);
    assert_abs_diff_eq!(normalize_angle(a.theta - b.theta), 0.0, epsilon = 1e-6);
}

fn parse(text: &str) -> CarmenLog {
    CarmenLog::parse_str(text, "t.log").unwrap()
}

fn error(text: &str) -> String {
    CarmenLog::parse_str(text, "t.log").unwrap_err().to_string()
}

/// A corrected log: each scan's anchor equals its pose, the raw odometry
/// drifts from the correction. The second anchor has a leftover timestamp,
/// as 69 of the Intel log's do.
const CORRECTED: &str = "\
# message formats defined: PARAM SYNC ODOM FLASER RLASER TRUEPOS
PARAM robot_frontlaser_offset 0.0 nohost 0
ODOM 0 0 0 0 0 0 0.1 pippo 0.1
ODOM 0.2 0 0 0 0 0 0.2 pippo 0.2
FLASER 3 1 2 3 10 10 0 10 10 0 0.3 pippo 0.3
ODOM 10 10 0 0 0 0 0 pippo 0
NEFF 15
ODOM 10.4 10 0 0 0 0 0.4 pippo 0.4
ODOM 10.9 10 0 0 0 0 0.5 pippo 0.5
FLASER 3 1 2 3 11 10 0 11 10 0 0.45 pippo 0.45
ODOM 11 10 0 0 0 0 1.13 pippo 1.13
ODOM 11 10 0.5 0 0 0 0.6 pippo 0.6
FLASER 3 1 2 40 11 10 0.4 11 10 0.4 0.6 pippo 0.6
ODOM 11 10 0.4 0 0 0 0 pippo 0
";

#[test]
fn a_corrected_log_chains_raw_motion_only() {
    let log = parse(CORRECTED);
    assert_eq!(log.reference_source(), ReferenceSource::Corrected);
    assert_eq!(log.anchors(), 3);
    let s = log.scans();
    assert_eq!(s.len(), 3);
    assert_eq!(s.iter().map(|s| s.line).collect::<Vec<_>>(), [5, 10, 13]);
    // File order: the second scan's time (0.45) is before the ODOM line
    // above it (0.5).
    assert_eq!(s[1].time_s, 0.45);
    // The chain starts at the first reference pose.
    assert_pose(s[0].odometry, Pose2::new(10.0, 10.0, 0.0));
    // 0.9 m ahead by the wheels (anchor 10,10 to 10.9,10), not the 1 m of
    // the correction.
    assert_pose(
        relative(&s[0].odometry, &s[1].odometry),
        Pose2::new(0.9, 0.0, 0.0),
    );
    assert_pose(
        relative(&s[1].odometry, &s[2].odometry),
        Pose2::new(0.0, 0.0, 0.5),
    );
    assert_pose(s[1].reference.unwrap(), Pose2::new(11.0, 10.0, 0.0));
    assert_pose(s[2].reference.unwrap(), Pose2::new(11.0, 10.0, 0.4));
    let g = log.geometry(LaserSource::Front).unwrap();
    assert_eq!((g.beam_count, g.max_range), (3, 40.0));
    assert_eq!(log.sources(), [LaserSource::Front]);
    assert!(log.geometry(LaserSource::Rear).is_none());
}

#[test]
fn a_raw_log_chains_every_odom_line() {
    // The same lines with one anchor moved: the log is not corrected, so
    // every ODOM line is motion and there is no reference.
    let raw = CORRECTED.replace(
        "ODOM 11 10 0 0 0 0 1.13 pippo 1.13",
        "ODOM 11.5 10 0 0 0 0 1.13 pippo 1.13",
    );
    let log = parse(&raw);
    assert_eq!(log.reference_source(), ReferenceSource::Absent);
    assert_eq!(log.anchors(), 0);
    let s = log.scans();
    assert!(s.iter().all(|s| s.reference.is_none()));
    // It starts at the last ODOM before the first scan.
    assert_pose(s[0].odometry, Pose2::new(0.2, 0.0, 0.0));
    // The jump to (10, 10) and the turn are now motion.
    let step = relative(&s[0].odometry, &s[1].odometry);
    let want = relative(&Pose2::new(0.2, 0.0, 0.0), &Pose2::new(10.9, 10.0, 0.0));
    assert_pose(step, want);
}

#[test]
fn without_odom_lines_the_scans_own_odometry_is_used() {
    let log = parse(
        "FLASER 2 1 2 5 5 0 1 1 0 1 h 1\n\
         FLASER 2 1 2 6 5 0 1.5 1 0.1 2 h 2\n",
    );
    assert_eq!(log.reference_source(), ReferenceSource::Absent);
    let s = log.scans();
    assert_pose(s[0].odometry, Pose2::new(1.0, 1.0, 0.0));
    assert_pose(s[1].odometry, Pose2::new(1.5, 1.0, 0.1));
}

#[test]
fn true_poses_are_the_reference_when_present() {
    let log = parse(
        "FLASER 2 1 2 0 0 0 0 0 0 1 h 1\n\
         ODOM 0 0 0 0 0 0 1 h 1\n\
         TRUEPOS 3 4 0.5 0 0 0 1.5 sim 1.5\n\
         ODOM 1 0 0 0 0 0 2 h 2\n\
         FLASER 2 1 2 1 0 0 1 0 0 2 h 2\n\
         TRUEPOS 4 4 0.5 1 0 0 2.5 sim 2.5\n\
         FLASER 2 1 2 1 0 0 1 0 0 3 h 3\n",
    );
    assert_eq!(log.reference_source(), ReferenceSource::TruePos);
    let s = log.scans();
    assert_eq!(s[0].reference, None);
    assert_eq!(s[1].reference, Some(Pose2::new(3.0, 4.0, 0.5)));
    assert_eq!(s[2].reference, Some(Pose2::new(4.0, 4.0, 0.5)));
    // No reference at the first scan: the chain starts at its odometry.
    assert_pose(s[0].odometry, Pose2::new(0.0, 0.0, 0.0));
    assert_pose(s[1].odometry, Pose2::new(1.0, 0.0, 0.0));
}

#[test]
fn a_rear_laser_faces_back_with_its_offset() {
    let log = parse(
        "PARAM robot_frontlaser_offset 0.1 nohost 0\n\
         PARAM robot_rearlaser_offset 0.2 nohost 0\n\
         FLASER 181 {f} 0 0 0 0 0 0 1 h 1\n\
         RLASER 4 1 2 3 7.5 0 0 3.14 0 0 0 1 h 1\n"
            .replace("{f}", &vec!["1"; 181].join(" "))
            .as_str(),
    );
    assert_eq!(log.sources(), [LaserSource::Front, LaserSource::Rear]);
    let front = log.geometry(LaserSource::Front).unwrap();
    assert_eq!(front.mount, Pose2::new(0.1, 0.0, 0.0));
    assert_abs_diff_eq!(front.beam_angle(180), PI / 2.0, epsilon = 1e-12);
    assert_eq!(front.max_range, 1.0);
    let rear = log.geometry(LaserSource::Rear).unwrap();
    assert_eq!(rear.mount, Pose2::new(-0.2, 0.0, PI));
    assert_eq!((rear.beam_count, rear.max_range), (4, 7.5));
    assert_abs_diff_eq!(rear.angle_step, PI / 4.0);
    assert_eq!(log.scans_from(LaserSource::Rear).count(), 1);
    assert_eq!(log.scans()[1].source, LaserSource::Rear);
}

#[test]
fn a_robot_laser_carries_its_geometry_and_mount() {
    // The laser sits 0.3 m ahead of the robot, which heads 0.5 rad.
    let line = |x: f64| {
        format!(
            "ROBOTLASER1 0 -1.5 3 0.75 8.5 0.01 0 5 1 2 3 4 5 0 \
             {lx} {ly} 0.5 {x} 2 0.5 0 0 1 0.3 1e6 {x} host {x}\n",
            lx = x + 0.3 * 0.5f64.cos(),
            ly = 2.0 + 0.3 * 0.5f64.sin(),
        )
    };
    let log = parse(&(line(1.0) + &line(2.0)));
    let g = log.geometry(LaserSource::RobotLaser).unwrap();
    assert_eq!(
        (g.first_angle, g.angle_step, g.beam_count, g.max_range),
        (-1.5, 0.75, 5, 8.5)
    );
    assert_pose(g.mount, Pose2::new(0.3, 0.0, 0.0));
    let s = log.scans();
    assert_eq!(s[0].source, LaserSource::RobotLaser);
    // Its odometry is the robot pose of its lines (there is no ODOM).
    assert_pose(s[1].odometry, Pose2::new(2.0, 2.0, 0.5));
}

#[test]
fn errors_name_the_origin_and_the_line() {
    assert_eq!(
        error("# ok\nODOM 1 2 3 0 0 0 1 h 1\nFLASER 3 1 2 0 0 0 0 0 0 1 h 1\n"),
        "t.log:3: FLASER with 3 readings needs 14 fields, found 13 \
         (the reading count does not match the line)"
    );
    assert!(error("ODOM 1 2 x 0 0 0 1 h 1").starts_with("t.log:1: ODOM field 3 (theta)"));
    let bad_param =
        error("PARAM robot_rearlaser_offset far nohost 0\nFLASER 1 1 0 0 0 0 0 0 1 h 1");
    assert_eq!(
        bad_param,
        "t.log:1: PARAM robot_rearlaser_offset: \"far\" is not a finite number"
    );
    let counts = error("FLASER 1 1 0 0 0 0 0 0 1 h 1\n\nFLASER 2 1 1 0 0 0 0 0 0 1 h 1\n");
    assert_eq!(
        counts,
        "t.log:3: FLASER with 2 readings, but the FLASER on line 1 has 1"
    );
    let rl = "ROBOTLASER1 0 -1.5 3 0.75 8.5 0.01 0 1 1 0 0 0 0 0 0 0 0 0 1 0.3 1e6 1 h 1\n";
    let err = error(&format!("{rl}{}", rl.replace("8.5", "9")));
    assert!(err.starts_with("t.log:2: ROBOTLASER1 start_angle"), "{err}");
}

#[test]
fn a_log_without_scans_is_refused() {
    for text in ["", "# only a comment\n", "ODOM 1 2 3 0 0 0 1 h 1\nNEFF 3\n"] {
        assert_eq!(
            error(text),
            "t.log: no laser scans (no FLASER, RLASER or ROBOTLASER1 line)"
        );
    }
}

#[test]
fn text_that_is_not_utf8_names_its_line() {
    let bytes: &[u8] = b"# fine\n\xff\xfe\n";
    let err = CarmenLog::parse(bytes, "bin").unwrap_err();
    assert_eq!(err.to_string(), "bin:2: not UTF-8 text");
}
