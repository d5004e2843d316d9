//! Which estimates of a robot's path the plot joins with lines: an
//! estimate is **converged** from its segment's settling on (the first
//! segment's is the convergence, each later one's its kidnap's recovery;
//! see the [module docs](super)), and only consecutive converged estimates
//! of one segment are joined, the line broken wherever two of them lie
//! farther apart than driving between their frames explains
//! ([`JUMP_BREAK_M`] plus the top speed times the time between them).
//! Estimates before convergence are drawn as points alone.

use super::plot::RobotPath;
use super::{DEFAULT_MAX_SPEED_MPS, EstimateSample, Settling};

/// Distance between two consecutive converged estimates, beyond what the
/// robot could drive between their frames, that breaks the line, metres.
/// Settled estimates lie within the bounds of the truth (0.25 m by
/// default), so two of them differ by less than this plus the drive.
pub const JUMP_BREAK_M: f64 = 1.0;

/// A robot's estimates as the plot draws them.
#[derive(Debug, Default, PartialEq)]
pub(crate) struct PathParts<'a> {
    /// Estimates before their segment settled: points, never joined.
    pub before_convergence: Vec<&'a EstimateSample>,
    /// Runs of converged estimates, each joined by a line; a run of one
    /// is drawn as a point.
    pub runs: Vec<Vec<&'a EstimateSample>>,
    /// Each recovery: the first converged estimate after a kidnap.
    pub recoveries: Vec<&'a EstimateSample>,
}

/// Splits `robot`'s estimates as the [module docs](self) say.
pub(crate) fn split_path<'a>(robot: &RobotPath<'a>) -> PathParts<'a> {
    let mut parts = PathParts::default();
    let mut previous: Option<(usize, &EstimateSample)> = None;
    for estimate in robot.estimates {
        let segment = robot
            .kidnaps
            .iter()
            .filter(|k| k.sequence <= estimate.sequence)
            .count();
        let settled = settling(robot, segment).is_some_and(|s| estimate.sequence >= s.sequence);
        if !settled {
            parts.before_convergence.push(estimate);
            previous = None;
            continue;
        }
        let joined =
            previous.is_some_and(|(seg, last)| seg == segment && !is_jump(robot, last, estimate));
        match parts.runs.last_mut() {
            Some(run) if joined => run.push(estimate),
            _ => parts.runs.push(vec![estimate]),
        }
        previous = Some((segment, estimate));
    }
    for kidnap in robot.kidnaps {
        if let Some(recovery) = kidnap.recovery
            && let Some(estimate) = robot
                .estimates
                .iter()
                .find(|e| e.sequence == recovery.sequence)
        {
            parts.recoveries.push(estimate);
        }
    }
    parts
}

/// The settling of segment `index` (0: before the first kidnap).
fn settling(robot: &RobotPath<'_>, index: usize) -> Option<Settling> {
    if index == 0 {
        // The convergence is the first segment's settling only when it
        // falls before the first kidnap; otherwise a later segment's.
        robot.convergence.filter(|c| {
            robot
                .kidnaps
                .first()
                .is_none_or(|k| c.sequence < k.sequence)
        })
    } else {
        robot.kidnaps.get(index - 1).and_then(|k| k.recovery)
    }
}

/// Whether `b` lies farther from `a` than driving between their frames
/// explains.
fn is_jump(robot: &RobotPath<'_>, a: &EstimateSample, b: &EstimateSample) -> bool {
    let time = |sequence: u64| {
        robot
            .truth
            .binary_search_by_key(&sequence, |t| t.sequence)
            .ok()
            .map(|i| robot.truth[i].time_s)
    };
    let seconds = match (time(a.sequence), time(b.sequence)) {
        (Some(ta), Some(tb)) => (tb - ta).max(0.0),
        _ => 0.0,
    };
    let distance = (b.pose.x - a.pose.x).hypot(b.pose.y - a.pose.y);
    distance > JUMP_BREAK_M + DEFAULT_MAX_SPEED_MPS * seconds
}
