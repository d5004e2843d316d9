//! Raw wheel odometry chained through a log, and the re-anchoring ODOM
//! lines of corrected logs that must not count as motion.
//!
//! A corrected CARMEN log (the output of a SLAM run, such as the Intel and
//! ACES logs) writes, right after each laser line, an `ODOM` line equal to
//! the corrected robot pose of that scan; the `ODOM` lines that follow,
//! up to the next scan, continue from that anchor by the raw wheel
//! odometry. Read naively, every anchor would add the correction as a jump.
//! So the chain takes the relative motion between consecutive `ODOM`
//! lines, `inverse(previous) ⊕ current`, and an anchor contributes none:
//! it only becomes the base the next motion starts from. The motion
//! between two scans is then `inverse(anchor after the first) ⊕ last ODOM
//! before the second`, the raw odometry alone.

use deog_grid::{Pose2, normalize_angle};

use crate::record::Record;

/// How close, metres and radians, an `ODOM` line must be to a scan's
/// stated robot pose to be its anchor (the two are printed from one value,
/// so they agree to the last printed digit).
pub const ANCHOR_TOLERANCE: f64 = 1e-6;

/// The inverse of a pose: `p ⊕ inverse(p)` is the identity.
pub fn inverse(p: &Pose2) -> Pose2 {
    let (sin, cos) = p.theta.sin_cos();
    Pose2::new(
        -cos * p.x - sin * p.y,
        sin * p.x - cos * p.y,
        normalize_angle(-p.theta),
    )
}

/// The motion from `from` to `to`, in `from`'s frame:
/// `inverse(from) ⊕ to`, so that `from ⊕ relative(from, to) = to`.
pub fn relative(from: &Pose2, to: &Pose2) -> Pose2 {
    inverse(from).compose(to)
}

fn near(a: &Pose2, b: &Pose2) -> bool {
    (a.x - b.x).abs() <= ANCHOR_TOLERANCE
        && (a.y - b.y).abs() <= ANCHOR_TOLERANCE
        && normalize_angle(a.theta - b.theta).abs() <= ANCHOR_TOLERANCE
}

/// Which records are re-anchoring `ODOM` lines; all `false` unless the log
/// is corrected.
///
/// A scan's anchor is the next `ODOM` or laser line after it, if that is an
/// `ODOM` equal to the robot pose the scan states. The log counts as
/// corrected when every scan followed by an `ODOM` or laser line has its
/// anchor, and at least one does. The decision is for the whole log: in a
/// raw log a robot standing still can write an `ODOM` equal to the scan's
/// interpolated odometry, which must stay odometry. The anchor's timestamp
/// is not looked at: it is 0 in most corrected lines, but 69 anchors of
/// the Intel log carry leftover values (1.08499e-42, 1.13, 4.39, ...).
pub(crate) fn find_anchors(records: &[Record]) -> Vec<bool> {
    let mut anchors = vec![false; records.len()];
    let mut found = 0usize;
    for (i, record) in records.iter().enumerate() {
        let Record::Laser(scan) = record else {
            continue;
        };
        let next = records[i + 1..]
            .iter()
            .enumerate()
            .find(|(_, r)| matches!(r, Record::Odom(_) | Record::Laser(_)));
        match next {
            Some((offset, Record::Odom(pose))) if near(pose, &scan.robot_pose) => {
                anchors[i + 1 + offset] = true;
                found += 1;
            }
            Some(_) => return vec![false; records.len()],
            None => {}
        }
    }
    if found == 0 {
        anchors.fill(false);
    }
    anchors
}

/// The running raw odometry, in the frame of the first pose it saw.
#[derive(Debug, Default)]
pub(crate) struct Chain {
    /// The chained pose, once there is one.
    pose: Option<Pose2>,
    /// The pose the next motion starts from: the last `ODOM` or anchor.
    base: Option<Pose2>,
}

impl Chain {
    /// An `ODOM` line: its motion from the base joins the chain.
    pub fn odom(&mut self, odom: Pose2) {
        self.pose = Some(match (self.pose, self.base) {
            (Some(pose), Some(base)) => pose.compose(&relative(&base, &odom)),
            _ => odom,
        });
        self.base = Some(odom);
    }

    /// A re-anchoring `ODOM` line: no motion, only a new base.
    pub fn anchor(&mut self, anchor: Pose2) {
        if self.pose.is_none() {
            self.pose = Some(anchor);
        }
        self.base = Some(anchor);
    }

    /// The chained pose at a scan; `fallback`, the scan's own odometry,
    /// starts the chain when no `ODOM` line came before it.
    pub fn at_scan(&mut self, fallback: Pose2) -> Pose2 {
        if self.pose.is_none() {
            self.pose = Some(fallback);
            self.base = Some(fallback);
        }
        self.pose.unwrap_or(fallback)
    }
}

/// Moves chained poses so that the first sits at `start` (exactly),
/// keeping every relative motion.
pub(crate) fn rebase(chained: &mut [Pose2], start: Pose2) {
    let Some((first, rest)) = chained.split_first_mut() else {
        return;
    };
    for pose in rest {
        *pose = start.compose(&relative(first, pose));
    }
    *first = start;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::parse_line;
    use approx::assert_abs_diff_eq;
    use std::f64::consts::PI;

    fn assert_pose(a: Pose2, b: Pose2) {
        assert_abs_diff_eq!(a.x, b.x, epsilon = 1e-9);
        assert_abs_diff_eq!(a.y, b.y, epsilon = 1e-9);
        assert_abs_diff_eq!(normalize_angle(a.theta - b.theta), 0.0, epsilon = 1e-9);
    }

    #[test]
    fn relative_undoes_compose() {
        let a = Pose2::new(1.0, -2.0, 2.5);
        let b = Pose2::new(-0.5, 3.0, -2.9);
        assert_pose(a.compose(&relative(&a, &b)), b);
        assert_pose(a.compose(&inverse(&a)), Pose2::default());
        assert_pose(
            relative(
                &Pose2::new(0.0, 0.0, PI / 2.0),
                &Pose2::new(0.0, 1.0, PI / 2.0),
            ),
            Pose2::new(1.0, 0.0, 0.0),
        );
    }

    #[test]
    fn an_anchor_adds_no_motion() {
        let mut chain = Chain::default();
        chain.odom(Pose2::new(0.0, 0.0, 0.0));
        chain.odom(Pose2::new(1.0, 0.0, 0.0));
        assert_pose(chain.at_scan(Pose2::default()), Pose2::new(1.0, 0.0, 0.0));
        // The corrected pose is far away and turned: no jump.
        chain.anchor(Pose2::new(10.0, 10.0, PI / 2.0));
        assert_pose(chain.at_scan(Pose2::default()), Pose2::new(1.0, 0.0, 0.0));
        // One metre forward from the anchor is one metre forward.
        chain.odom(Pose2::new(10.0, 11.0, PI / 2.0));
        assert_pose(chain.at_scan(Pose2::default()), Pose2::new(2.0, 0.0, 0.0));
    }

    #[test]
    fn a_scan_before_any_odometry_starts_the_chain() {
        let mut chain = Chain::default();
        let own = Pose2::new(3.0, 4.0, 0.0);
        assert_pose(chain.at_scan(own), own);
        chain.odom(Pose2::new(3.5, 4.0, 0.0));
        assert_pose(chain.at_scan(own), Pose2::new(3.5, 4.0, 0.0));
    }

    #[test]
    fn rebase_keeps_relative_motion() {
        let mut poses = vec![Pose2::new(1.0, 1.0, 0.0), Pose2::new(2.0, 1.0, 0.0)];
        rebase(&mut poses, Pose2::new(0.0, 0.0, PI / 2.0));
        assert_pose(poses[0], Pose2::new(0.0, 0.0, PI / 2.0));
        assert_pose(poses[1], Pose2::new(0.0, 1.0, PI / 2.0));
    }

    fn records(text: &str) -> Vec<Record> {
        text.lines().map(|l| parse_line(l).unwrap()).collect()
    }

    #[test]
    fn anchors_need_every_scan_anchored() {
        let corrected = records(
            "ODOM 0 0 0 0 0 0 1 h 1\n\
             FLASER 1 2 5 5 1 5 5 1 1 h 1\n\
             ODOM 5 5 1 0 0 0 1.13 h 1.13\n\
             NEFF 15\n\
             ODOM 5.1 5 1 0 0 0 2 h 2\n\
             FLASER 1 2 6 5 1 6 5 1 2 h 2\n\
             NEFF 14\n\
             ODOM 6 5 1 0 0 0 0 h 0",
        );
        let anchors = find_anchors(&corrected);
        assert_eq!(
            anchors,
            [false, false, true, false, false, false, false, true]
        );
        // A second scan followed by plain odometry: the log is raw.
        let mut raw = corrected.clone();
        raw[7] = parse_line("ODOM 7 5 1 0 0 0 3 h 3").unwrap();
        assert!(find_anchors(&raw).iter().all(|a| !a));
        // A scan followed straight by another scan is not anchored either.
        let mut twice = corrected.clone();
        twice.insert(2, corrected[1].clone());
        assert!(find_anchors(&twice).iter().all(|a| !a));
        // No scan followed by anything: nothing to anchor.
        assert!(find_anchors(&corrected[..2]).iter().all(|a| !a));
    }
}
