//! One run's estimates against the true poses: when it settled, and its
//! errors from then on.

use deog_grid::{Pose2, normalize_angle};
use serde::Serialize;

/// Within this distance of the truth, metres, an estimate counts as right…
pub(super) const SETTLE_POSITION_M: f64 = 0.25;
/// … and within this heading, radians.
pub(super) const SETTLE_HEADING_RAD: f64 = 0.25;

/// A run's accuracy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(super) struct Accuracy {
    /// Seconds from the first frame to the first frame after which every
    /// estimate stays within the bounds to the end (null: the last frame's
    /// is out of them, or there is none).
    pub settle_s: Option<f64>,
    /// Root mean square position error from settling on, metres.
    pub rms_position_m: Option<f64>,
    /// Mean absolute heading error from settling on, degrees.
    pub mean_heading_deg: Option<f64>,
    /// Root mean square position error over every frame with an estimate,
    /// metres.
    pub rms_position_whole_m: Option<f64>,
}

/// Judges `estimates` (one per frame; `None` before the filter has one)
/// against `truth` (time in seconds and true pose per frame).
pub(super) fn judge(truth: &[(f64, Pose2)], estimates: &[Option<Pose2>]) -> Accuracy {
    let errors: Vec<Option<(f64, f64)>> = truth
        .iter()
        .zip(estimates)
        .map(|((_, t), e)| {
            e.map(|e| {
                (
                    (e.x - t.x).hypot(e.y - t.y),
                    normalize_angle(e.theta - t.theta).abs(),
                )
            })
        })
        .collect();
    let within = |e: &Option<(f64, f64)>| matches!(e, Some((p, h)) if *p <= SETTLE_POSITION_M && *h <= SETTLE_HEADING_RAD);
    // The first frame of the last unbroken stretch within bounds.
    let settle = match errors.iter().rposition(|e| !within(e)) {
        None if !errors.is_empty() => Some(0),
        None => None,
        Some(last_out) if last_out + 1 < errors.len() => Some(last_out + 1),
        Some(_) => None,
    };
    let rms = |from: usize| {
        let squares: Vec<f64> = errors[from..]
            .iter()
            .flatten()
            .map(|(p, _)| p * p)
            .collect();
        (!squares.is_empty()).then(|| (squares.iter().sum::<f64>() / squares.len() as f64).sqrt())
    };
    let t0 = truth.first().map_or(0.0, |(t, _)| *t);
    Accuracy {
        settle_s: settle.map(|i| truth[i].0 - t0),
        rms_position_m: settle.and_then(rms),
        mean_heading_deg: settle.map(|i| {
            let tail = &errors[i..];
            tail.iter()
                .flatten()
                .map(|(_, h)| h.to_degrees())
                .sum::<f64>()
                / tail.len() as f64
        }),
        rms_position_whole_m: rms(0),
    }
}

#[cfg(test)]
mod tests {
    use approx::assert_abs_diff_eq;

    use super::*;

    fn truth(n: usize) -> Vec<(f64, Pose2)> {
        (0..n)
            .map(|i| (10.0 + i as f64 * 0.1, Pose2::new(i as f64, 0.0, 3.1)))
            .collect()
    }

    #[test]
    fn settling_is_the_start_of_the_last_stretch_within_bounds() {
        let t = truth(6);
        let at = |i: usize, dx: f64, dtheta: f64| {
            Some(Pose2::new(
                t[i].1.x + dx,
                0.0,
                normalize_angle(3.1 + dtheta),
            ))
        };
        let estimates = vec![
            None,
            at(1, 0.1, 0.0),
            at(2, 1.0, 0.0), // out: position
            at(3, 0.0, 0.1), // heading across ±π still counts as 0.1
            at(4, 0.2, 0.0),
            at(5, 0.0, -0.2),
        ];
        let a = judge(&t, &estimates);
        assert_abs_diff_eq!(a.settle_s.expect("settled"), 0.3, epsilon = 1e-9);
        assert_abs_diff_eq!(
            a.rms_position_m.expect("some"),
            (0.04f64 / 3.0).sqrt(),
            epsilon = 1e-9
        );
        assert_abs_diff_eq!(
            a.mean_heading_deg.expect("some"),
            (0.1f64.to_degrees() + 0.2f64.to_degrees()) / 3.0,
            epsilon = 1e-6
        );
        assert_abs_diff_eq!(
            a.rms_position_whole_m.expect("some"),
            ((0.01 + 1.0 + 0.04) / 5.0f64).sqrt(),
            epsilon = 1e-9
        );
    }

    #[test]
    fn a_run_out_of_bounds_at_its_end_never_settled() {
        let t = truth(3);
        let good = Some(t[0].1);
        let a = judge(&t, &[good, good, Some(Pose2::new(9.0, 9.0, 0.0))]);
        assert_eq!(
            (a.settle_s, a.rms_position_m, a.mean_heading_deg),
            (None, None, None)
        );
        assert!(a.rms_position_whole_m.is_some());
        let none = judge(&t, &[None, None, None]);
        assert_eq!((none.settle_s, none.rms_position_whole_m), (None, None));
        let always = judge(&t, &[Some(t[0].1), Some(t[1].1), Some(t[2].1)]);
        assert_eq!(always.settle_s, Some(0.0));
        assert_eq!(always.rms_position_m, Some(0.0));
    }
}
