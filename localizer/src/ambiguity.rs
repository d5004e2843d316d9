//! A pose whose frame fits as well half a metre away is not a pose the
//! filter has found.
//!
//! A laser's likelihood is sharp across a corridor and flat along it:
//! where the scan sees no door, no corner and no end, every pose along
//! the corridor explains it about as well. The particles then follow the
//! wheels, their cluster stays as tight as the motion noise keeps it, and
//! when the wheels slip (Freiburg 079, scans 1,709 to 1,763) the cluster
//! slides half a metre off the robot while it still fits the scan as
//! well as ever. Spread and fit cannot tell; the scan's own shape can: the
//! poses of a ring around the estimate, from [`AmbiguitySettings::near_m`]
//! to [`AmbiguitySettings::far_m`] away, are scored with the filter's
//! sensor model, coarse then fine, and if the best of them fits nearly as
//! well as the estimate, the frame does not pin the robot to within the
//! ring's inner radius, and the estimate is not called converged. Rivals
//! further off are the global search's to find ([`crate::searcher`]).

use deog_grid::{Pose2, normalize_angle};

use crate::error::{LocalizerError, within};

/// How the ring around an estimate is searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbiguitySettings {
    /// The ring's inner radius, metres: a rival nearer than this is the
    /// same pose, as the judges count it (0.5 m is off).
    pub near_m: f64,
    /// The ring's outer radius, metres.
    pub far_m: f64,
    /// Half the heading span scored at each position, radians.
    pub half_rad: f64,
    /// The coarse pass's position step, metres; the fine pass steps a
    /// quarter of it over one coarse step around the coarse best.
    pub step_m: f64,
    /// The coarse pass's heading step, radians; the fine pass as above.
    pub step_rad: f64,
    /// A pose of the ring fitting at least this share of the estimate's
    /// fit (per observation, as [`crate::realign`] measures fits) makes
    /// the estimate ambiguous.
    pub rival_fit: f64,
}

impl Default for AmbiguitySettings {
    /// A ring from 0.4 to 0.8 m, ±0.1 rad, in steps of 0.1 m and 0.05 rad
    /// (about 750 poses, then 125 fine ones); a rival at 0.95 of the
    /// estimate's fit. On Freiburg 079 the best of the ring fits 0.78 to
    /// 0.95 of a right estimate's fit (5th to 95th percentile), and 1.03
    /// to 1.21 of each estimate 0.4 m or more off (BENCHMARKS.md).
    fn default() -> Self {
        Self {
            near_m: 0.4,
            far_m: 0.8,
            half_rad: 0.1,
            step_m: 0.1,
            step_rad: 0.05,
            rival_fit: 0.95,
        }
    }
}

impl AmbiguitySettings {
    /// The settings if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("ambiguity near_m", self.near_m, 0.01, 5.0)?;
        within("ambiguity far_m", self.far_m, self.near_m, 10.0)?;
        within("ambiguity half_rad", self.half_rad, 0.0, 1.0)?;
        within("ambiguity step_m", self.step_m, 0.01, 1.0)?;
        within("ambiguity step_rad", self.step_rad, 0.001, 0.5)?;
        within("ambiguity rival_fit", self.rival_fit, 0.0, 1.0)?;
        Ok(self)
    }

    /// The coarse pass's poses around `around`: every grid position of
    /// the ring, at every heading step of the span.
    fn coarse(&self, around: &Pose2) -> Vec<Pose2> {
        let n = (self.far_m / self.step_m + 1e-9).floor() as i64;
        let m = (self.half_rad / self.step_rad + 1e-9).floor() as i64;
        let mut poses = Vec::new();
        for i in -n..=n {
            for j in -n..=n {
                let (dx, dy) = (i as f64 * self.step_m, j as f64 * self.step_m);
                if !self.in_ring(dx, dy) {
                    continue;
                }
                for k in -m..=m {
                    poses.push(Pose2::new(
                        around.x + dx,
                        around.y + dy,
                        normalize_angle(around.theta + k as f64 * self.step_rad),
                    ));
                }
            }
        }
        poses
    }

    /// The fine pass's poses: a quarter step over one coarse step either
    /// side of `best`, those still in the ring around `around`.
    fn fine(&self, around: &Pose2, best: &Pose2) -> Vec<Pose2> {
        let (step_m, step_rad) = (self.step_m / 4.0, self.step_rad / 4.0);
        let mut poses = Vec::new();
        for i in -2i32..=2 {
            for j in -2i32..=2 {
                let (x, y) = (best.x + i as f64 * step_m, best.y + j as f64 * step_m);
                if !self.in_ring(x - around.x, y - around.y) {
                    continue;
                }
                for k in -2i32..=2 {
                    if (i, j, k) != (0, 0, 0) {
                        poses.push(Pose2::new(
                            x,
                            y,
                            normalize_angle(best.theta + k as f64 * step_rad),
                        ));
                    }
                }
            }
        }
        poses
    }

    fn in_ring(&self, dx: f64, dy: f64) -> bool {
        let d = dx.hypot(dy);
        d >= self.near_m - 1e-9 && d <= self.far_m + 1e-9
    }

    /// Poses a check scores at most.
    pub fn most_poses(&self) -> usize {
        let n = 2 * (self.far_m / self.step_m + 1e-9).floor() as usize + 1;
        let m = 2 * (self.half_rad / self.step_rad + 1e-9).floor() as usize + 1;
        n * n * m + 1 + 125
    }
}

/// What [`rival_in_ring`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ring {
    /// The estimate's fit (a logarithm, as scored).
    pub centre_log_fit: f64,
    /// The best pose of the ring.
    pub rival: Pose2,
    /// Its fit.
    pub rival_log_fit: f64,
}

impl Ring {
    /// The rival's fit as a share of the estimate's.
    pub fn rival_share(&self) -> f64 {
        (self.rival_log_fit - self.centre_log_fit).exp()
    }

    /// Whether the rival fits at least `rival_fit` of the estimate's fit:
    /// the frame does not tell the two apart.
    pub fn ambiguous(&self, rival_fit: f64) -> bool {
        self.rival_log_fit >= self.centre_log_fit + rival_fit.ln()
    }
}

/// The best pose of the ring around `around` and the fit of `around`
/// itself. `log_fit` gives each pose's fit (per observation, a natural
/// logarithm; higher is better), pushing one per pose onto its output, in
/// order. `None` when the ring holds no pose.
pub fn rival_in_ring(
    around: &Pose2,
    settings: &AmbiguitySettings,
    mut log_fit: impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError>,
) -> Result<Option<Ring>, LocalizerError> {
    let mut poses = vec![*around];
    poses.extend(settings.coarse(around));
    let mut fits = Vec::with_capacity(poses.len());
    log_fit(&poses, &mut fits)?;
    let Some(&centre) = fits.first() else {
        return Ok(None);
    };
    let Some((mut rival, mut rival_fit)) = best(&poses[1..], &fits[1..]) else {
        return Ok(None);
    };
    let fine = settings.fine(around, &rival);
    fits.clear();
    log_fit(&fine, &mut fits)?;
    if let Some((pose, fit)) = best(&fine, &fits)
        && fit > rival_fit
    {
        (rival, rival_fit) = (pose, fit);
    }
    Ok(Some(Ring {
        centre_log_fit: centre,
        rival,
        rival_log_fit: rival_fit,
    }))
}

/// The best-fitting of `poses`; fits that are not numbers are passed over.
fn best(poses: &[Pose2], fits: &[f64]) -> Option<(Pose2, f64)> {
    poses
        .iter()
        .zip(fits)
        .filter(|(_, fit)| !fit.is_nan())
        .fold(None, |best, (p, &fit)| match best {
            Some((_, b)) if b >= fit => best,
            _ => Some((*p, fit)),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A corridor along x: the fit falls with the distance across it and
    /// with the heading, and along it as `along` says (0: not at all, the
    /// corridor's ends out of sight).
    fn corridor(along: f64) -> impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError> {
        move |poses, out| {
            out.extend(
                poses
                    .iter()
                    .map(|p| -(p.y * p.y) * 10.0 - p.theta * p.theta * 10.0 - along * p.x * p.x),
            );
            Ok(())
        }
    }

    #[test]
    fn a_corridor_without_an_end_is_ambiguous_along_it() {
        let settings = AmbiguitySettings::default();
        let ring = rival_in_ring(&Pose2::default(), &settings, corridor(0.0))
            .unwrap()
            .unwrap();
        assert!(ring.ambiguous(settings.rival_fit), "{ring:?}");
        assert!(ring.rival.y.abs() < 1e-9 && ring.rival.theta.abs() < 1e-9);
        let d = ring.rival.x.hypot(ring.rival.y);
        assert!(d >= settings.near_m - 1e-9, "{ring:?}");
    }

    #[test]
    fn a_frame_that_pins_the_pose_is_not_ambiguous() {
        let settings = AmbiguitySettings::default();
        let ring = rival_in_ring(&Pose2::default(), &settings, corridor(10.0))
            .unwrap()
            .unwrap();
        assert!(!ring.ambiguous(settings.rival_fit), "{ring:?}");
        assert!(ring.rival_share() < 0.25, "{}", ring.rival_share());
    }

    #[test]
    fn the_fine_pass_finds_a_rival_between_the_coarse_steps() {
        let settings = AmbiguitySettings::default();
        let peak = Pose2::new(0.537, -0.212, 0.031);
        let ring = rival_in_ring(&Pose2::default(), &settings, |poses, out| {
            out.extend(poses.iter().map(|p| {
                -((p.x - peak.x).powi(2) + (p.y - peak.y).powi(2) + (p.theta - peak.theta).powi(2))
            }));
            Ok(())
        })
        .unwrap()
        .unwrap();
        assert!(
            (ring.rival.x - peak.x).abs() <= settings.step_m / 8.0 + 1e-9,
            "{ring:?}"
        );
        assert!(
            (ring.rival.y - peak.y).abs() <= settings.step_m / 8.0 + 1e-9,
            "{ring:?}"
        );
        assert!(ring.ambiguous(settings.rival_fit));
    }

    #[test]
    fn the_check_scores_no_more_than_it_says() {
        let settings = AmbiguitySettings::default();
        let mut scored = 0;
        rival_in_ring(&Pose2::default(), &settings, |poses, out| {
            scored += poses.len();
            out.extend(poses.iter().map(|_| 0.0));
            Ok(())
        })
        .unwrap();
        assert!(scored <= settings.most_poses(), "{scored}");
        assert!(scored > 500, "{scored}");
    }

    #[test]
    fn a_failed_scoring_is_passed_on_and_bad_settings_refused() {
        let failed = rival_in_ring(&Pose2::default(), &AmbiguitySettings::default(), |_, _| {
            Err(LocalizerError::Invalid("no map".into()))
        });
        assert!(failed.is_err());
        let bad = AmbiguitySettings {
            far_m: 0.1,
            ..AmbiguitySettings::default()
        };
        assert!(bad.validate().is_err());
        assert!(AmbiguitySettings::default().validate().is_ok());
    }
}
