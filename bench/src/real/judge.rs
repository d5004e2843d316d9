//! The estimates judged against the log's reference poses: tracking over
//! the whole run, and each global start on its window, as the
//! [module docs](super) define them.

use std::f64::consts::PI;

use anyhow::{Context, Result};
use deog_evaluation::localization::{EstimateSample, EvalInput, EvalParams, TruthSample, evaluate};
use deog_evaluation::tracking::{Tracking, track};
use deog_grid::normalize_angle;

use super::MAP;

/// The evaluation's defaults (0.25 m, 0.25 rad) with kidnap detection
/// off: no jump between two scans of a real log is a kidnap, and none
/// may cut a run in segments.
pub(super) fn params() -> EvalParams {
    EvalParams {
        kidnap_jump_m: 1.0e6,
        kidnap_turn_rad: PI,
        ..EvalParams::default()
    }
}

/// Tracking over the whole run: every estimate against its scan's
/// reference pose, lapses included. The evaluation checks the input
/// (sequences in order, finite poses, at least one pairing) first.
pub(super) fn tracking(
    robot: &str,
    truth: &[TruthSample],
    estimates: &[EstimateSample],
) -> Result<Tracking> {
    evaluate(&EvalInput {
        robot,
        map: Some(MAP),
        truth,
        estimates,
        params: params(),
        known_kidnaps: &[],
    })
    .context("judging the tracking run's estimates")?;
    Ok(track(truth, estimates, &params()))
}

/// How one global start did on its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct WindowVerdict {
    /// Estimates the run made for the window's scans.
    pub estimates: u64,
    /// Within the bounds from at most `settle_scans` after the start on,
    /// to the window's last scan.
    pub converged: bool,
    /// Scans from the start to the first of the trailing run of estimates
    /// within the bounds, when that run reaches the window's last scan;
    /// `None` when the last estimate is outside the bounds, or missing.
    pub settled_after_scans: Option<u64>,
    /// Position error of the last estimate, metres.
    pub final_position_error_m: Option<f64>,
    /// |heading error| of the last estimate, radians.
    pub final_abs_error_rad: Option<f64>,
    /// Estimates flagged converged while more than 0.5 m or 0.25 rad off.
    pub false_converged: u64,
}

impl WindowVerdict {
    /// Scans to converge, for a start that converged.
    pub fn scans_to_converge(&self) -> Option<u64> {
        self.settled_after_scans.filter(|_| self.converged)
    }
}

/// Judges a global start at scan `start` whose window ends at scan `end`:
/// `truth` and `estimates` are the window's (other scans are ignored).
pub(super) fn window(
    start: u64,
    end: u64,
    settle_scans: u64,
    truth: &[TruthSample],
    estimates: &[EstimateSample],
) -> Result<WindowVerdict> {
    let in_window = |sequence: u64| (start..=end).contains(&sequence);
    let truth: Vec<TruthSample> = truth
        .iter()
        .filter(|t| in_window(t.sequence))
        .copied()
        .collect();
    let estimates: Vec<EstimateSample> = estimates
        .iter()
        .filter(|e| in_window(e.sequence))
        .copied()
        .collect();
    let mut verdict = WindowVerdict {
        estimates: estimates.len() as u64,
        converged: false,
        settled_after_scans: None,
        final_position_error_m: None,
        final_abs_error_rad: None,
        false_converged: track(&truth, &estimates, &params()).false_converged,
    };
    let Some(last) = estimates.last() else {
        return Ok(verdict);
    };
    if let Ok(i) = truth.binary_search_by_key(&last.sequence, |t| t.sequence) {
        let reference = truth[i].pose;
        verdict.final_position_error_m =
            Some((last.pose.x - reference.x).hypot(last.pose.y - reference.y));
        verdict.final_abs_error_rad =
            Some(normalize_angle(last.pose.theta - reference.theta).abs());
    }
    // The trailing run must reach the window's end: a run that stopped
    // early did not stay anywhere.
    if last.sequence != end {
        return Ok(verdict);
    }
    let report = evaluate(&EvalInput {
        robot: "global start",
        map: Some(MAP),
        truth: &truth,
        estimates: &estimates,
        params: params(),
        known_kidnaps: &[],
    })
    .with_context(|| format!("judging the global start at scan {start}"))?;
    verdict.settled_after_scans = report.convergence.map(|s| s.sequence - start);
    verdict.converged = verdict
        .settled_after_scans
        .is_some_and(|after| after <= settle_scans);
    Ok(verdict)
}

/// The estimates of `after` that a run made: those not also in `before`
/// (read before the run) with the same pose. The server keeps one
/// estimate per scan; one an earlier run stored for a scan this run made
/// none for would otherwise be taken for this run's.
pub(super) fn made_by_the_run(
    before: &[EstimateSample],
    after: Vec<EstimateSample>,
) -> Vec<EstimateSample> {
    after
        .into_iter()
        .filter(|e| {
            before
                .binary_search_by_key(&e.sequence, |b| b.sequence)
                .map_or(true, |i| before[i] != *e)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use deog_grid::Pose2;

    use super::*;

    /// Scans `from..=to` driving along x at 0.1 m a scan, a second apart.
    fn truth(from: u64, to: u64) -> Vec<TruthSample> {
        (from..=to)
            .map(|s| TruthSample::new(s, s as f64, Pose2::new(s as f64 * 0.1, 0.0, 0.0)))
            .collect()
    }

    /// An estimate per truth sample, `off(s)` metres off in y.
    fn estimates(truth: &[TruthSample], off: impl Fn(u64) -> f64) -> Vec<EstimateSample> {
        truth
            .iter()
            .map(|t| EstimateSample::new(t.sequence, Pose2::new(t.pose.x, off(t.sequence), 0.0)))
            .collect()
    }

    #[test]
    fn a_start_that_settles_in_time_and_stays_converged() {
        let truth = truth(100, 140);
        // Lost for the first 12 scans, then 5 cm off.
        let e = estimates(&truth, |s| if s < 112 { 3.0 } else { 0.05 });
        let v = window(100, 140, 30, &truth, &e).expect("judged");
        assert!(v.converged);
        assert_eq!(v.scans_to_converge(), Some(12));
        assert_eq!(v.estimates, 41);
        approx::assert_relative_eq!(v.final_position_error_m.unwrap(), 0.05, epsilon = 1e-12);
        approx::assert_relative_eq!(v.final_abs_error_rad.unwrap(), 0.0);
    }

    #[test]
    fn the_first_estimate_within_the_bounds_converges_at_once() {
        let truth = truth(1, 41);
        let v = window(1, 41, 30, &truth, &estimates(&truth, |_| 0.0)).expect("judged");
        assert_eq!((v.converged, v.scans_to_converge()), (true, Some(0)));
    }

    #[test]
    fn settling_late_or_leaving_the_bounds_is_not_converging() {
        let truth = truth(100, 140);
        // Settles after 31 scans: too late.
        let late = estimates(&truth, |s| if s < 131 { 3.0 } else { 0.0 });
        let v = window(100, 140, 30, &truth, &late).expect("judged");
        assert!(!v.converged);
        assert_eq!(
            (v.settled_after_scans, v.scans_to_converge()),
            (Some(31), None)
        );
        // In at once, out at the last scan: it did not stay.
        let left = estimates(&truth, |s| if s == 140 { 0.3 } else { 0.0 });
        let v = window(100, 140, 30, &truth, &left).expect("judged");
        assert_eq!((v.converged, v.settled_after_scans), (false, None));
        approx::assert_relative_eq!(v.final_position_error_m.unwrap(), 0.3, epsilon = 1e-12);
        // A heading off by more than 0.25 rad counts as outside too.
        let mut turned = estimates(&truth, |_| 0.0);
        turned[40].pose.theta = 0.3;
        let v = window(100, 140, 30, &truth, &turned).expect("judged");
        assert!(!v.converged);
        approx::assert_relative_eq!(v.final_abs_error_rad.unwrap(), 0.3, epsilon = 1e-12);
    }

    #[test]
    fn a_run_that_stops_before_the_windows_end_did_not_converge() {
        let truth = truth(100, 140);
        let mut e = estimates(&truth, |_| 0.0);
        e.truncate(30);
        let v = window(100, 140, 30, &truth, &e).expect("judged");
        assert_eq!((v.converged, v.estimates), (false, 30));
        let v = window(100, 140, 30, &truth, &[]).expect("judged");
        assert_eq!(
            (v.converged, v.estimates, v.final_position_error_m),
            (false, 0, None)
        );
    }

    #[test]
    fn only_the_windows_scans_count() {
        let truth = truth(1, 200);
        // Far off outside the window, exact inside it.
        let e = estimates(&truth, |s| if (50..=90).contains(&s) { 0.0 } else { 5.0 });
        let v = window(50, 90, 30, &truth, &e).expect("judged");
        assert_eq!(
            (v.converged, v.scans_to_converge(), v.estimates),
            (true, Some(0), 41)
        );
    }

    #[test]
    fn a_jump_between_scans_is_no_kidnap() {
        // The reference jumps 2 m in a second: with kidnaps detected, the
        // run would be cut in two segments and converge on the second.
        let mut truth = truth(1, 41);
        for t in &mut truth[20..] {
            t.pose.x += 2.0;
        }
        let e = estimates(&truth, |s| if s < 25 { 1.0 } else { 0.0 });
        let v = window(1, 41, 30, &truth, &e).expect("judged");
        assert_eq!(v.scans_to_converge(), Some(24));
    }

    #[test]
    fn tracking_takes_every_estimate_lapses_included() {
        let truth = truth(1, 10);
        let e = estimates(&truth, |s| if s == 5 { 1.0 } else { 0.0 });
        let t = tracking("log", &truth, &e).expect("judged");
        assert_eq!((t.paired, t.within), (10, 9));
        approx::assert_relative_eq!(t.rms_m, 0.1f64.sqrt(), epsilon = 1e-12);
        approx::assert_relative_eq!(t.max_m, 1.0);
        assert!(tracking("log", &truth, &[]).is_err());
    }

    #[test]
    fn estimates_left_from_an_earlier_run_are_not_the_runs() {
        let truth = truth(1, 5);
        let before = estimates(&truth[..3], |_| 0.5);
        let mut after = estimates(&truth, |_| 0.0);
        // Scan 2: this run made none, the earlier one's stands.
        after[1] = before[1];
        let made = made_by_the_run(&before, after);
        let scans: Vec<u64> = made.iter().map(|e| e.sequence).collect();
        assert_eq!(scans, [1, 3, 4, 5]);
    }
}
