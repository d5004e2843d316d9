//! The two real logs of `data/carmen`: what the reader makes of them, and
//! the raw odometry checked against the files' own lines.

use std::io::Read;
use std::path::PathBuf;
use std::sync::LazyLock;

use deog_grid::{Pose2, normalize_angle};
use deog_logs::{CarmenLog, LaserSource, ReferenceSource, relative};
use flate2::read::MultiGzDecoder;

fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/carmen")
        .join(format!("{name}-corrected.log.gz"))
}

static INTEL: LazyLock<CarmenLog> = LazyLock::new(|| CarmenLog::load(path("intel")).unwrap());
static ACES: LazyLock<CarmenLog> = LazyLock::new(|| CarmenLog::load(path("aces")).unwrap());

/// What each log should be.
struct Expected {
    name: &'static str,
    scans: usize,
    first_line: usize,
    no_return: f64,
    /// Readings at the no-return value.
    no_returns: usize,
    /// Seconds from the first scan to the last.
    span_s: f64,
    /// Scans whose timestamp is before the previous scan's.
    steps_back: usize,
    /// Re-anchoring ODOM lines whose timestamp is not 0.
    anchors_not_at_zero: usize,
}

const LOGS: [Expected; 2] = [
    Expected {
        name: "intel",
        scans: 910,
        first_line: 175,
        no_return: 81.83,
        no_returns: 4172,
        span_s: 2650.86,
        steps_back: 4,
        anchors_not_at_zero: 69,
    },
    Expected {
        name: "aces",
        scans: 440,
        first_line: 144,
        no_return: 50.0,
        no_returns: 620,
        span_s: 1318.06,
        steps_back: 0,
        anchors_not_at_zero: 0,
    },
];

fn log(name: &str) -> &'static CarmenLog {
    match name {
        "intel" => &INTEL,
        _ => &ACES,
    }
}

#[test]
fn the_logs_hold_their_front_scans_and_corrected_poses() {
    for want in LOGS {
        let log = log(want.name);
        let scans = log.scans();
        assert_eq!(scans.len(), want.scans, "{}", want.name);
        assert_eq!(log.sources(), [LaserSource::Front]);
        assert!(scans.iter().all(|s| s.ranges.len() == 180));
        assert_eq!(scans[0].line, want.first_line);
        assert!(scans.windows(2).all(|w| w[0].line < w[1].line));
        assert_eq!(log.reference_source(), ReferenceSource::Corrected);
        // One re-anchoring ODOM after every scan.
        assert_eq!(log.anchors(), want.scans);
        assert!(scans.iter().all(|s| s.reference.is_some()));
        assert_eq!(Some(scans[0].odometry), scans[0].reference);

        let g = log.geometry(LaserSource::Front).unwrap();
        assert_eq!(g.beam_count, 180);
        assert_eq!(g.max_range, want.no_return);
        assert_eq!(g.mount, Pose2::default());
        let at_max = scans
            .iter()
            .flat_map(|s| &s.ranges)
            .filter(|&&r| r >= want.no_return)
            .count();
        assert_eq!(at_max, want.no_returns, "{}", want.name);

        let rig = log.rig(LaserSource::Front, want.name).unwrap();
        assert_eq!((rig.readings(), rig.max_range()), (180, want.no_return));
        log.check_rig(LaserSource::Front, &rig).unwrap();
    }
}

#[test]
fn timestamps_step_back_in_places_but_order_is_the_files() {
    for want in LOGS {
        let scans = log(want.name).scans();
        let steps_back = scans
            .windows(2)
            .filter(|w| w[1].time_s < w[0].time_s)
            .count();
        assert_eq!(steps_back, want.steps_back, "{}", want.name);
        let span = scans.last().unwrap().time_s - scans[0].time_s;
        assert!((span - want.span_s).abs() < 0.01, "{}: {span}", want.name);
    }
}

fn odom_pose(fields: &[&str]) -> Pose2 {
    let f = |i: usize| fields[i].parse::<f64>().unwrap();
    Pose2::new(f(1), f(2), f(3))
}

/// Straight from the file: for each scan, the ODOM right after it (its
/// anchor) and the last ODOM before it; and how many anchors have a
/// timestamp other than 0.
fn anchors_and_last_odometry(name: &str) -> (Vec<(Pose2, Option<Pose2>)>, usize) {
    let mut text = String::new();
    MultiGzDecoder::new(std::fs::File::open(path(name)).unwrap())
        .read_to_string(&mut text)
        .unwrap();
    let lines: Vec<Vec<&str>> = text
        .lines()
        .map(|l| l.split_whitespace().collect())
        .collect();
    let mut out = Vec::new();
    let mut not_at_zero = 0;
    let mut last = None;
    for (i, fields) in lines.iter().enumerate() {
        match fields.first() {
            Some(&"ODOM") => last = Some(odom_pose(fields)),
            Some(&"FLASER") => {
                let anchor = &lines[i + 1];
                assert_eq!(anchor[0], "ODOM", "{name}:{}", i + 2);
                let n: usize = fields[1].parse().unwrap();
                let pose = |at: usize| -> Vec<f64> {
                    fields[at..at + 3]
                        .iter()
                        .map(|v| v.parse().unwrap())
                        .collect()
                };
                // The anchor equals the scan's pose, x y theta and odom_*.
                let a = odom_pose(anchor);
                assert_eq!(pose(n + 2), [a.x, a.y, a.theta], "{name}:{}", i + 2);
                assert_eq!(pose(n + 5), [a.x, a.y, a.theta]);
                if anchor[7].parse::<f64>().unwrap() != 0.0 {
                    not_at_zero += 1;
                }
                out.push((a, last));
            }
            _ => {}
        }
    }
    (out, not_at_zero)
}

fn difference(a: &Pose2, b: &Pose2) -> (f64, f64) {
    (
        (a.x - b.x).hypot(a.y - b.y),
        normalize_angle(a.theta - b.theta).abs(),
    )
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn raw_increments_are_the_files_odometry_and_near_the_corrected_ones() {
    for want in LOGS {
        let log = log(want.name);
        let scans = log.scans();
        let (file, not_at_zero) = anchors_and_last_odometry(want.name);
        assert_eq!(not_at_zero, want.anchors_not_at_zero, "{}", want.name);
        assert_eq!(file.len(), scans.len());
        let (mut trans, mut rot) = (Vec::new(), Vec::new());
        for k in 0..scans.len() - 1 {
            let raw = relative(&scans[k].odometry, &scans[k + 1].odometry);
            // inverse(anchor after scan k) ⊕ last ODOM before scan k + 1.
            let last = file[k + 1].1.unwrap();
            let from_file = relative(&file[k].0, &last);
            let (dt, dr) = difference(&raw, &from_file);
            assert!(
                dt < 1e-9 && dr < 1e-9,
                "{} scan {k}: {raw:?} vs {from_file:?}",
                want.name
            );

            let corrected = relative(
                &scans[k].reference.unwrap(),
                &scans[k + 1].reference.unwrap(),
            );
            let (dt, dr) = difference(&raw, &corrected);
            trans.push(dt);
            rot.push(dr.to_degrees());
        }
        let stats = [0.5, 0.9, 1.0].map(|q| (quantile(trans.clone(), q), quantile(rot.clone(), q)));
        eprintln!(
            "{}: raw minus corrected increment, metres / degrees: median {:.3} / {:.2}, \
             90% {:.3} / {:.2}, max {:.3} / {:.2}",
            want.name, stats[0].0, stats[0].1, stats[1].0, stats[1].1, stats[2].0, stats[2].1
        );
        // Raw odometry drifts by centimetres and a few degrees per scan...
        assert!(stats[0].0 < 0.1 && stats[0].1 < 5.0, "{}", want.name);
        assert!(stats[1].0 < 0.2 && stats[1].1 < 10.0, "{}", want.name);
        // ...never by the metres a missed anchor would add.
        assert!(stats[2].0 < 0.5 && stats[2].1 < 20.0, "{}", want.name);
    }
}
