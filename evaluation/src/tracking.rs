//! Tracking over a whole run: every estimate paired with its frame's true
//! pose, lapses included. [`crate::localization::evaluate`] describes the
//! estimates once settled, which a lapse late in a run moves to its end;
//! a tracking benchmark wants the whole run.

use deog_grid::normalize_angle;
use serde::Serialize;

use crate::localization::{
    EstimateSample, EvalParams, FALSE_CONVERGED_M, FALSE_CONVERGED_RAD, TruthSample,
};

/// How the estimates followed the true poses, estimate by estimate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Tracking {
    /// Estimates with a true pose of the same frame.
    pub paired: u64,
    /// Of those, within the bounds (`converge_m`, `converge_rad`).
    pub within: u64,
    /// Mean position error, metres.
    pub mean_m: f64,
    /// Root mean square of the position error, metres.
    pub rms_m: f64,
    /// Largest position error, metres.
    pub max_m: f64,
    /// Mean absolute heading error, radians (each in [0, π]).
    pub mean_abs_heading_rad: f64,
    /// Largest absolute heading error, radians.
    pub max_abs_heading_rad: f64,
    /// Runs of consecutive estimates outside the bounds.
    pub lost_stretches: u64,
    /// The longest such run: its first frame's time and its length,
    /// seconds, and its estimates.
    pub longest_lost: Option<LostStretch>,
    /// Whether the last estimate was within the bounds.
    pub last_within: bool,
    /// Estimates the filter flagged converged while more than
    /// [`FALSE_CONVERGED_M`] or [`FALSE_CONVERGED_RAD`] off: wrong and
    /// sure of it.
    pub false_converged: u64,
}

/// A run of consecutive estimates outside the bounds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LostStretch {
    /// Time of its first estimate's frame, seconds.
    pub from_s: f64,
    /// From its first to its last estimate's frame, seconds.
    pub duration_s: f64,
    /// Estimates in it.
    pub estimates: u64,
}

/// Pairs each estimate with its frame's true pose (`truth` sorted by
/// sequence) and sums up the errors; estimates without one are skipped.
pub fn track(truth: &[TruthSample], estimates: &[EstimateSample], params: &EvalParams) -> Tracking {
    let mut t = Tracking::default();
    let (mut sum, mut square_sum, mut heading_sum) = (0.0, 0.0, 0.0);
    // The current run outside the bounds: (start time, last time, count).
    let mut lost: Option<(f64, f64, u64)> = None;
    let close = |lost: &mut Option<(f64, f64, u64)>, t: &mut Tracking| {
        if let Some((from, to, n)) = lost.take() {
            t.lost_stretches += 1;
            if t.longest_lost.is_none_or(|l| n > l.estimates) {
                t.longest_lost = Some(LostStretch {
                    from_s: from,
                    duration_s: to - from,
                    estimates: n,
                });
            }
        }
    };
    for estimate in estimates {
        let Ok(i) = truth.binary_search_by_key(&estimate.sequence, |s| s.sequence) else {
            continue;
        };
        let (truth, pose) = (&truth[i], estimate.pose);
        let position = (pose.x - truth.pose.x).hypot(pose.y - truth.pose.y);
        let heading = normalize_angle(pose.theta - truth.pose.theta).abs();
        let within = position <= params.converge_m && heading <= params.converge_rad;
        t.paired += 1;
        if estimate.filter_converged
            && (position > FALSE_CONVERGED_M || heading > FALSE_CONVERGED_RAD)
        {
            t.false_converged += 1;
        }
        sum += position;
        square_sum += position * position;
        heading_sum += heading;
        t.max_m = t.max_m.max(position);
        t.max_abs_heading_rad = t.max_abs_heading_rad.max(heading);
        if within {
            t.within += 1;
            close(&mut lost, &mut t);
        } else {
            let run = lost.get_or_insert((truth.time_s, truth.time_s, 0));
            run.1 = truth.time_s;
            run.2 += 1;
        }
        t.last_within = within;
    }
    close(&mut lost, &mut t);
    if t.paired > 0 {
        let n = t.paired as f64;
        t.mean_m = sum / n;
        t.rms_m = (square_sum / n).sqrt();
        t.mean_abs_heading_rad = heading_sum / n;
    }
    t
}

#[cfg(test)]
mod tests {
    use deog_grid::Pose2;

    use super::*;

    #[test]
    fn a_lapse_is_one_stretch_and_counts_in_the_mean() {
        let truth: Vec<TruthSample> = (1..=10)
            .map(|s| TruthSample::new(s, s as f64 * 0.1, Pose2::new(s as f64 * 0.1, 0.0, 0.0)))
            .collect();
        // Frames 4 to 6 a metre off, the rest exact; frame 8 has no estimate.
        let estimates: Vec<EstimateSample> = truth
            .iter()
            .filter(|t| t.sequence != 8)
            .map(|t| {
                let off = if (4..=6).contains(&t.sequence) {
                    1.0
                } else {
                    0.0
                };
                let mut e = EstimateSample::new(t.sequence, Pose2::new(t.pose.x, off, 0.0));
                // Sure of itself throughout: the lapse is false convergence.
                e.filter_converged = true;
                e
            })
            .collect();
        let t = track(&truth, &estimates, &EvalParams::default());
        assert_eq!(t.false_converged, 3);
        assert_eq!((t.paired, t.within), (9, 6));
        assert_eq!(t.lost_stretches, 1);
        let lost = t.longest_lost.expect("a lapse");
        assert_eq!(lost.estimates, 3);
        approx::assert_relative_eq!(lost.from_s, 0.4, epsilon = 1e-12);
        approx::assert_relative_eq!(lost.duration_s, 0.2, epsilon = 1e-12);
        approx::assert_relative_eq!(t.mean_m, 3.0 / 9.0, epsilon = 1e-12);
        approx::assert_relative_eq!(t.max_m, 1.0, epsilon = 1e-12);
        approx::assert_relative_eq!(t.rms_m, (3.0f64 / 9.0).sqrt(), epsilon = 1e-12);
        assert!(t.last_within);
    }

    #[test]
    fn heading_errors_are_taken_across_the_wrap() {
        let truth: Vec<TruthSample> = (1..=2)
            .map(|s| TruthSample::new(s, s as f64, Pose2::new(0.0, 0.0, 3.1)))
            .collect();
        // 0.1 rad on one side, and 0.2 rad across ±π on the other.
        let estimates = [
            EstimateSample::new(1, Pose2::new(0.0, 0.0, 3.0)),
            EstimateSample::new(2, Pose2::new(0.0, 0.0, 3.3 - 2.0 * std::f64::consts::PI)),
        ];
        let t = track(&truth, &estimates, &EvalParams::default());
        approx::assert_relative_eq!(t.mean_abs_heading_rad, 0.15, epsilon = 1e-9);
        approx::assert_relative_eq!(t.max_abs_heading_rad, 0.2, epsilon = 1e-9);
        approx::assert_relative_eq!(t.rms_m, 0.0);
    }
}
