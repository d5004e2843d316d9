//! A tracking filter whose frame stops fitting where it tracks looks
//! for where the frame fits, in a small window around that pose.
//!
//! The filter moves its particles by odometry with a noise of a few
//! centimetres a step. Where the wheels and the scans disagree for a
//! stretch (wheels slipping, a robot pushed), the true pose runs away
//! from the particles faster than that noise can follow, every particle
//! fits the frame badly, and the filter slides off while its cluster
//! stays tight. A sharp sensor (a laser's hundreds of echoes) says where
//! the robot is within a few centimetres once the pose is near: so when
//! the frame fits the tracked pose far worse than frames have lately,
//! the poses of a window around it are scored, coarse then fine, with
//! the filter's own sensor model; if one fits as frames usually do, the
//! particles are moved rigidly onto it before they are weighed (a
//! proposal that follows the scan, as in Grisetti et al.'s improved
//! proposal, 2007). The window is a few tens of centimetres: this keeps
//! a tracking filter on its pose, it never relocates a lost one (the
//! global search does that).

use deog_grid::{Pose2, normalize_angle};

use crate::error::{LocalizerError, within};

/// How a tracked pose is realigned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealignSettings {
    /// A frame fitting the tracked pose below this share of the recent
    /// frames' fit (per observation, as the filter's recovery measures
    /// it) starts a realignment.
    pub poor_fit: f64,
    /// For this many sensor updates after a realignment the odometry is
    /// suspect (wheels that slip do so for a stretch) …
    pub suspect_updates: usize,
    /// … and a frame fitting below this share starts one.
    pub suspect_fit: f64,
    /// The best pose of the window is taken if it fits at least this
    /// share of the recent frames' fit …
    pub good_fit: f64,
    /// … and at least this many times as well as the tracked pose.
    pub min_gain: f64,
    /// Half the window's side, metres.
    pub linear_m: f64,
    /// Half the window's heading span, radians.
    pub angular_rad: f64,
    /// The coarse pass's position step, metres; the fine pass steps a
    /// quarter of it over one coarse step around the coarse best.
    pub coarse_step_m: f64,
    /// The coarse pass's heading step, radians; the fine pass as above.
    pub coarse_step_rad: f64,
    /// What a move costs against the fit it gains: a pose `d` metres
    /// from the tracked one must fit `e^(cost_per_m · d)` times as well to
    /// rank level with it. The odometry is right most of the time, and a
    /// corridor fits as well a little ahead as here: without this the
    /// window's best along a corridor's length is noise.
    pub cost_per_m: f64,
    /// Metres of move a radian of turn counts as, for that cost.
    pub m_per_rad: f64,
}

impl Default for RealignSettings {
    /// A frame fitting below half the recent fit, or below 0.95 of it for
    /// 10 updates after a realignment; a window of ±0.5 m and ±0.2 rad in
    /// steps of 0.1 m and 0.05 rad, then 0.025 m and 0.0125 rad; the best
    /// taken at 0.7 of the recent fit and 1.15 times the tracked pose's
    /// once its move's cost (0.5 a metre, a radian as 0.5 m) is paid.
    fn default() -> Self {
        Self {
            poor_fit: 0.7,
            suspect_updates: 10,
            suspect_fit: 0.95,
            good_fit: 0.9,
            min_gain: 1.15,
            linear_m: 0.5,
            angular_rad: 0.2,
            coarse_step_m: 0.1,
            coarse_step_rad: 0.05,
            cost_per_m: 0.5,
            m_per_rad: 0.5,
        }
    }
}

impl RealignSettings {
    /// The settings if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("realign poor_fit", self.poor_fit, 0.0, 1.0)?;
        within("realign suspect_fit", self.suspect_fit, 0.0, 1.0)?;
        within("realign good_fit", self.good_fit, 0.0, 10.0)?;
        within("realign min_gain", self.min_gain, 1.0, 1e6)?;
        within("realign linear_m", self.linear_m, 0.0, 5.0)?;
        within("realign angular_rad", self.angular_rad, 0.0, 1.0)?;
        within("realign coarse_step_m", self.coarse_step_m, 0.005, 1.0)?;
        within("realign coarse_step_rad", self.coarse_step_rad, 0.001, 0.5)?;
        within("realign cost_per_m", self.cost_per_m, 0.0, 1e3)?;
        within("realign m_per_rad", self.m_per_rad, 0.0, 100.0)?;
        Ok(self)
    }

    /// Poses a realignment scores at most: what it costs, in scorings.
    pub fn most_poses(&self) -> usize {
        let steps = |half: f64, step: f64| 2 * (half / step).floor() as usize + 1;
        steps(self.linear_m, self.coarse_step_m).pow(2)
            * steps(self.angular_rad, self.coarse_step_rad)
            + 9 * 9 * 9
    }
}

/// The best pose of the window around `around`, by its fit less the cost
/// of the move ([`RealignSettings::cost_per_m`]). `log_fit` gives each
/// pose's fit, the natural logarithm of a share of the recent fit (higher
/// is better), pushing one per pose onto its output, in order. The
/// window's centre is scored first, and a pose replaces the best only
/// when it ranks strictly higher, so that among equals the nearer one is
/// kept.
pub fn best_in_window(
    around: &Pose2,
    settings: &RealignSettings,
    mut log_fit: impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError>,
) -> Result<Window, LocalizerError> {
    let cost = |p: &Pose2| {
        let turn = normalize_angle(p.theta - around.theta).abs();
        settings.cost_per_m * ((p.x - around.x).hypot(p.y - around.y) + settings.m_per_rad * turn)
    };
    let mut poses = vec![*around];
    push_grid(
        &mut poses,
        around,
        settings.linear_m,
        settings.angular_rad,
        settings.coarse_step_m,
        settings.coarse_step_rad,
    );
    let mut fits = Vec::with_capacity(poses.len());
    log_fit(&poses, &mut fits)?;
    let centre = fits.first().copied().unwrap_or(f64::NEG_INFINITY);
    let mut best = Ranked {
        pose: *around,
        log_fit: centre,
        rank: centre,
    };
    best = best_of(&poses, &fits, &cost, best);
    // The fine pass: a quarter of the coarse steps, over one coarse step
    // either side of the coarse best.
    let coarse_best = best.pose;
    poses.clear();
    push_grid(
        &mut poses,
        &coarse_best,
        settings.coarse_step_m,
        settings.coarse_step_rad,
        settings.coarse_step_m / 4.0,
        settings.coarse_step_rad / 4.0,
    );
    fits.clear();
    log_fit(&poses, &mut fits)?;
    best = best_of(&poses, &fits, &cost, best);
    Ok(Window {
        centre_log_fit: centre,
        best: best.pose,
        best_log_fit: best.log_fit,
        best_rank: best.rank,
    })
}

/// What [`best_in_window`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// The fit at the window's centre (a logarithm, as scored).
    pub centre_log_fit: f64,
    /// The best pose, by fit less the cost of moving there.
    pub best: Pose2,
    /// Its fit.
    pub best_log_fit: f64,
    /// Its fit less the cost of its move: what it is ranked by, and
    /// compared with the centre's fit.
    pub best_rank: f64,
}

/// A pose scored, and its rank: the fit less the cost of the move.
#[derive(Debug, Clone, Copy)]
struct Ranked {
    pose: Pose2,
    log_fit: f64,
    rank: f64,
}

/// Pushes the poses within `half_m` (x and y) and `half_rad` (heading) of
/// `around`, in steps of `step_m` and `step_rad`, nearest first by ring
/// so that ties keep the nearer pose; `around` itself is left out.
fn push_grid(
    out: &mut Vec<Pose2>,
    around: &Pose2,
    half_m: f64,
    half_rad: f64,
    step_m: f64,
    step_rad: f64,
) {
    let n = (half_m / step_m + 1e-9).floor() as i64;
    let m = (half_rad / step_rad + 1e-9).floor() as i64;
    let mut offsets = Vec::with_capacity(((2 * n + 1).pow(2) * (2 * m + 1)) as usize);
    for i in -n..=n {
        for j in -n..=n {
            for k in -m..=m {
                if (i, j, k) != (0, 0, 0) {
                    offsets.push((i, j, k));
                }
            }
        }
    }
    // Nearest first: by the larger of the position and heading steps away.
    offsets.sort_by_key(|&(i, j, k)| (i.abs().max(j.abs()).max(k.abs()), i * i + j * j + k * k));
    out.extend(offsets.into_iter().map(|(i, j, k)| {
        Pose2::new(
            around.x + i as f64 * step_m,
            around.y + j as f64 * step_m,
            normalize_angle(around.theta + k as f64 * step_rad),
        )
    }));
}

/// The best of `poses` (scored `fits`, ranked by fit less `cost`) and
/// `best`: a pose replaces it only when it ranks strictly higher. Fits
/// that are not numbers are passed over.
fn best_of(poses: &[Pose2], fits: &[f64], cost: &impl Fn(&Pose2) -> f64, best: Ranked) -> Ranked {
    poses.iter().zip(fits).fold(best, |best, (p, &fit)| {
        let rank = fit - cost(p);
        if rank > best.rank || (best.rank.is_nan() && !rank.is_nan()) {
            Ranked {
                pose: *p,
                log_fit: fit,
                rank,
            }
        } else {
            best
        }
    })
}

/// Each of `poses` moved rigidly as `from` moves onto `to`: `to ⊕ from⁻¹ ⊕
/// p`, so that the set keeps its shape about the pose it tracks.
pub fn move_rigidly(poses: &mut [Pose2], from: &Pose2, to: &Pose2) {
    for p in poses {
        *p = to.compose(&p.relative_to(from));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A score peaked at `peak`: minus the squared distance, heading
    /// weighted as a metre per radian.
    fn peaked(peak: Pose2) -> impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError> {
        move |poses, out| {
            out.extend(poses.iter().map(|p| {
                let d = (p.x - peak.x).powi(2) + (p.y - peak.y).powi(2);
                -(d + normalize_angle(p.theta - peak.theta).powi(2))
            }));
            Ok(())
        }
    }

    #[test]
    fn the_window_finds_a_peak_off_its_centre_to_within_a_fine_step() {
        let settings = RealignSettings {
            cost_per_m: 0.0,
            ..RealignSettings::default()
        };
        let around = Pose2::new(3.0, -2.0, 1.0);
        let peak = Pose2::new(2.63, -1.81, 1.13);
        let found = best_in_window(&around, &settings, peaked(peak)).unwrap();
        assert!((found.best.x - peak.x).abs() <= settings.coarse_step_m / 8.0 + 1e-9);
        assert!((found.best.y - peak.y).abs() <= settings.coarse_step_m / 8.0 + 1e-9);
        assert!(
            normalize_angle(found.best.theta - peak.theta).abs()
                <= settings.coarse_step_rad / 8.0 + 1e-9
        );
        assert!(found.best_log_fit > found.centre_log_fit);
    }

    #[test]
    fn a_peak_at_the_centre_keeps_the_centre() {
        let settings = RealignSettings::default();
        let around = Pose2::new(1.0, 1.0, -3.0);
        let found = best_in_window(&around, &settings, peaked(around)).unwrap();
        assert_eq!(found.best, around);
        assert_eq!(found.best_log_fit, found.centre_log_fit);
    }

    #[test]
    fn a_far_pose_must_gain_more_than_its_move_costs() {
        let settings = RealignSettings::default();
        let around = Pose2::new(0.0, 0.0, 0.0);
        // A fit of 0 everywhere but 0.4 m ahead, where it is `gain`.
        let ahead = |gain: f64| {
            move |poses: &[Pose2], out: &mut Vec<f64>| {
                out.extend(poses.iter().map(|p| {
                    if (p.x - 0.4).abs() < 1e-9 && p.y.abs() < 1e-9 && p.theta.abs() < 1e-9 {
                        gain
                    } else {
                        0.0
                    }
                }));
                Ok(())
            }
        };
        let cost = 0.4 * settings.cost_per_m;
        let small = best_in_window(&around, &settings, ahead(cost - 0.05)).unwrap();
        assert_eq!(small.best, around);
        let large = best_in_window(&around, &settings, ahead(cost + 0.05)).unwrap();
        assert!((large.best.x - 0.4).abs() < 1e-9, "{:?}", large.best);
        assert!((large.best_rank - 0.05).abs() < 1e-9);
        assert_eq!(large.best_log_fit, cost + 0.05);
    }

    #[test]
    fn among_equals_the_centre_is_kept() {
        // A corridor along x: the score does not depend on x at all.
        let settings = RealignSettings::default();
        let around = Pose2::new(0.0, 0.0, 0.0);
        let found = best_in_window(&around, &settings, |poses, out| {
            out.extend(poses.iter().map(|p| -(p.y * p.y) - p.theta * p.theta));
            Ok(())
        })
        .unwrap();
        assert_eq!(found.best, around);
    }

    #[test]
    fn the_window_scores_no_more_than_it_says() {
        let settings = RealignSettings::default();
        let mut scored = 0;
        best_in_window(&Pose2::default(), &settings, |poses, out| {
            scored += poses.len();
            out.extend(poses.iter().map(|_| 0.0));
            Ok(())
        })
        .unwrap();
        assert!(scored <= settings.most_poses(), "{scored}");
    }

    #[test]
    fn a_failed_scoring_is_passed_on() {
        let failed = best_in_window(&Pose2::default(), &RealignSettings::default(), |_, _| {
            Err(LocalizerError::Invalid("no map".into()))
        });
        assert!(failed.is_err());
    }

    #[test]
    fn moving_rigidly_keeps_the_set_about_its_pose() {
        let from = Pose2::new(1.0, 2.0, 0.5);
        let to = Pose2::new(-1.0, 0.5, 2.0);
        let mut poses = [from, from.compose(&Pose2::new(0.1, -0.05, 0.02))];
        move_rigidly(&mut poses, &from, &to);
        assert!((poses[0].x - to.x).abs() < 1e-12 && (poses[0].y - to.y).abs() < 1e-12);
        let local = poses[1].relative_to(&poses[0]);
        assert!((local.x - 0.1).abs() < 1e-12);
        assert!((local.y + 0.05).abs() < 1e-12);
        assert!((local.theta - 0.02).abs() < 1e-12);
    }

    #[test]
    fn bad_settings_are_refused() {
        let bad = RealignSettings {
            coarse_step_m: 0.0,
            ..RealignSettings::default()
        };
        assert!(bad.validate().is_err());
        assert!(RealignSettings::default().validate().is_ok());
    }
}
