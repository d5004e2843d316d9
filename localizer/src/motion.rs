//! The odometry motion model (Probabilistic Robotics, table 5.6,
//! `sample_motion_model_odometry`): the move between two odometry poses is
//! split into a rotation, a translation and a second rotation, and each is
//! perturbed with noise whose spread grows with the size of the move.

use deog_grid::{Pose2, normalize_angle};
use rand::Rng;

use crate::error::{LocalizerError, within};
use crate::gaussian::normal;

/// The four noise parameters, each a standard deviation per unit of motion
/// (so that they read like the simulator's odometry noise):
/// `σ_rot = α1·|δrot| + α2·δtrans` and `σ_trans = α3·δtrans + α4·(|δrot1| + |δrot2|)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionNoise {
    /// α1: rotation error per radian turned, radians.
    pub rot_per_rot: f64,
    /// α2: rotation error per metre travelled, radians.
    pub rot_per_trans: f64,
    /// α3: translation error per metre travelled, metres.
    pub trans_per_trans: f64,
    /// α4: translation error per radian turned, metres.
    pub trans_per_rot: f64,
}

impl Default for MotionNoise {
    /// A few times the simulator's default odometry error, so that its
    /// systematic drift and scale error stay inside the spread.
    fn default() -> Self {
        Self {
            rot_per_rot: 0.1,
            rot_per_trans: 0.05,
            trans_per_trans: 0.1,
            trans_per_rot: 0.02,
        }
    }
}

impl MotionNoise {
    /// The parameters if each is finite and in [0, 10].
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("rot_per_rot", self.rot_per_rot, 0.0, 10.0)?;
        within("rot_per_trans", self.rot_per_trans, 0.0, 10.0)?;
        within("trans_per_trans", self.trans_per_trans, 0.0, 10.0)?;
        within("trans_per_rot", self.trans_per_rot, 0.0, 10.0)?;
        Ok(self)
    }

    /// Every figure times `factor`: wider for odometry worse than these
    /// figures assume.
    pub fn scaled(self, factor: f64) -> Self {
        Self {
            rot_per_rot: self.rot_per_rot * factor,
            rot_per_trans: self.rot_per_trans * factor,
            trans_per_trans: self.trans_per_trans * factor,
            trans_per_rot: self.trans_per_rot * factor,
        }
    }
}

/// Below this translation, metres, the direction of travel between two
/// odometry poses is wheel jitter rather than a heading the robot took: a
/// Scout turning on the spot drifts a millimetre or two per frame in any
/// direction, and counting that direction as a turn (up to a half turn
/// each way) would spread every particle as if the robot had spun round.
const SHORT_MOVE_M: f64 = 0.01;

/// A move between two odometry poses, decomposed once and applied to many
/// particles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryMove {
    rot1: f64,
    trans: f64,
    rot2: f64,
    /// Driving backwards: the translation runs against the heading.
    backwards: bool,
    /// The turns the noise scales with: `|rot1|` and `|rot2|`, except for
    /// a short move, which counts as all turn (`0` and `|rot1 + rot2|`).
    noisy_rot1: f64,
    noisy_rot2: f64,
}

impl OdometryMove {
    /// The move from odometry pose `from` to `to`.
    pub fn between(from: &Pose2, to: &Pose2) -> Self {
        let (dx, dy) = (to.x - from.x, to.y - from.y);
        let trans = dx.hypot(dy);
        let turn = normalize_angle(to.theta - from.theta);
        let mut rot1 = if trans > 0.0 {
            normalize_angle(dy.atan2(dx) - from.theta)
        } else {
            0.0
        };
        // A Scout reversing is not turning round twice: decompose it as a
        // backward translation with small rotations.
        let backwards = rot1.abs() > std::f64::consts::FRAC_PI_2;
        if backwards {
            rot1 = normalize_angle(rot1 + std::f64::consts::PI);
        }
        let rot2 = normalize_angle(turn - rot1);
        let (noisy_rot1, noisy_rot2) = if trans < SHORT_MOVE_M {
            (0.0, turn.abs())
        } else {
            (rot1.abs(), rot2.abs())
        };
        Self {
            rot1,
            trans,
            rot2,
            backwards,
            noisy_rot1,
            noisy_rot2,
        }
    }

    /// The distance travelled, metres.
    pub fn translation(&self) -> f64 {
        self.trans
    }

    /// The total rotation, radians (both turns, absolute; a short move's
    /// direction of travel is not counted as turning).
    pub fn rotation(&self) -> f64 {
        self.noisy_rot1 + self.noisy_rot2
    }

    /// `pose` moved by this move with noise drawn from `noise`.
    pub fn sample(&self, pose: &Pose2, noise: &MotionNoise, rng: &mut impl Rng) -> Pose2 {
        let rot_std1 = noise.rot_per_rot * self.noisy_rot1 + noise.rot_per_trans * self.trans;
        let rot_std2 = noise.rot_per_rot * self.noisy_rot2 + noise.rot_per_trans * self.trans;
        let trans_std = noise.trans_per_trans * self.trans
            + noise.trans_per_rot * (self.noisy_rot1 + self.noisy_rot2);
        let rot1 = self.rot1 + normal(rng, rot_std1);
        let trans = self.trans + normal(rng, trans_std);
        let rot2 = self.rot2 + normal(rng, rot_std2);
        let signed = if self.backwards { -trans } else { trans };
        let heading = pose.theta + rot1;
        Pose2::new(
            pose.x + signed * heading.cos(),
            pose.y + signed * heading.sin(),
            normalize_angle(heading + rot2),
        )
    }

    /// `pose` moved by this move exactly.
    pub fn apply(&self, pose: &Pose2) -> Pose2 {
        let signed = if self.backwards {
            -self.trans
        } else {
            self.trans
        };
        let heading = pose.theta + self.rot1;
        Pose2::new(
            pose.x + signed * heading.cos(),
            pose.y + signed * heading.sin(),
            normalize_angle(heading + self.rot2),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn close(a: &Pose2, b: &Pose2) {
        assert_abs_diff_eq!(a.x, b.x, epsilon = 1e-9);
        assert_abs_diff_eq!(a.y, b.y, epsilon = 1e-9);
        assert_abs_diff_eq!(normalize_angle(a.theta - b.theta), 0.0, epsilon = 1e-9);
    }

    proptest! {
        /// Applied without noise to the pose it started from, the move
        /// lands on the pose it ended at, forwards or backwards; applied to
        /// another pose it moves that pose the same way relative to its heading.
        #[test]
        fn exact_move_reproduces_odometry(
            x in -50.0..50.0f64, y in -50.0..50.0f64, t in -4.0..4.0f64,
            dx in -1.0..1.0f64, dy in -1.0..1.0f64, dt in -1.0..1.0f64,
            ox in -5.0..5.0f64, oy in -5.0..5.0f64, ot in -4.0..4.0f64,
        ) {
            let from = Pose2::new(x, y, t);
            let to = Pose2::new(x + dx, y + dy, t + dt);
            let step = OdometryMove::between(&from, &to);
            close(&step.apply(&from), &to);
            // The same move seen from another frame: relative motion is kept.
            let other = Pose2::new(ox, oy, ot);
            let moved = step.apply(&other);
            let rel = |a: &Pose2, b: &Pose2| {
                let (c, s) = (a.theta.cos(), a.theta.sin());
                let (ddx, ddy) = (b.x - a.x, b.y - a.y);
                (c * ddx + s * ddy, -s * ddx + c * ddy, normalize_angle(b.theta - a.theta))
            };
            let (a1, a2, a3) = rel(&from, &to);
            let (b1, b2, b3) = rel(&other, &moved);
            prop_assert!((a1 - b1).abs() < 1e-9 && (a2 - b2).abs() < 1e-9 && (a3 - b3).abs() < 1e-9);
        }
    }

    #[test]
    fn reversing_is_a_backward_translation() {
        let step = OdometryMove::between(&Pose2::new(0.0, 0.0, 0.0), &Pose2::new(-0.5, 0.0, 0.0));
        assert_abs_diff_eq!(step.rotation(), 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(step.translation(), 0.5, epsilon = 1e-12);
    }

    #[test]
    fn spread_grows_with_the_move_and_matches_the_parameters() {
        let noise = MotionNoise {
            rot_per_rot: 0.0,
            rot_per_trans: 0.0,
            trans_per_trans: 0.1,
            trans_per_rot: 0.0,
        };
        let step = OdometryMove::between(&Pose2::new(0.0, 0.0, 0.0), &Pose2::new(2.0, 0.0, 0.0));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let n = 20_000;
        let xs: Vec<f64> = (0..n)
            .map(|_| step.sample(&Pose2::default(), &noise, &mut rng).x)
            .collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let std = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert_abs_diff_eq!(mean, 2.0, epsilon = 0.01);
        // σ_trans = α3 · 2 m = 0.2 m.
        assert_abs_diff_eq!(std, 0.2, epsilon = 0.01);
        // No motion, no spread.
        let still = OdometryMove::between(&Pose2::new(1.0, 1.0, 1.0), &Pose2::new(1.0, 1.0, 1.0));
        let p = still.sample(
            &Pose2::new(3.0, 4.0, 0.5),
            &MotionNoise::default(),
            &mut rng,
        );
        close(&p, &Pose2::new(3.0, 4.0, 0.5));
    }

    #[test]
    fn turning_on_the_spot_spreads_as_a_turn_whatever_the_jitter() {
        // A tenth of a radian turned with 2 mm of sideways jitter: the
        // direction of that jitter is 90° off the heading, and taken as a
        // turn it would add π/2 each way to the rotation noise.
        let from = Pose2::new(1.0, 1.0, 0.3);
        let to = Pose2::new(1.0 - 0.002 * 0.3f64.sin(), 1.0 + 0.002 * 0.3f64.cos(), 0.4);
        let step = OdometryMove::between(&from, &to);
        close(&step.apply(&from), &to);
        assert_abs_diff_eq!(step.rotation(), 0.1, epsilon = 1e-12);
        let noise = MotionNoise::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 20_000;
        let moved: Vec<Pose2> = (0..n)
            .map(|_| step.sample(&from, &noise, &mut rng))
            .collect();
        let spread = |f: &dyn Fn(&Pose2) -> f64| {
            let mean = moved.iter().map(f).sum::<f64>() / n as f64;
            (moved.iter().map(|p| (f(p) - mean).powi(2)).sum::<f64>() / n as f64).sqrt()
        };
        // σ_rot2 = α1 · 0.1 rad = 0.01 rad, plus α2 · 2 mm.
        let heading = spread(&|p: &Pose2| normalize_angle(p.theta - to.theta));
        assert_abs_diff_eq!(heading, 0.0101, epsilon = 0.001);
        // σ_trans = α3 · 2 mm + α4 · 0.1 rad = 2.2 mm.
        let position = spread(&|p: &Pose2| (p.x - from.x).hypot(p.y - from.y));
        assert!(position < 0.003, "position spread {position} m");
    }

    #[test]
    fn bad_parameters_are_named() {
        let bad = MotionNoise {
            trans_per_rot: f64::NAN,
            ..MotionNoise::default()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("trans_per_rot"), "{err}");
    }
}
