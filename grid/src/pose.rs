//! Planar poses and angle arithmetic.

use std::f64::consts::{PI, TAU};

use crate::error::{GridError, finite};

/// A planar pose: position in metres and heading in radians,
/// counter-clockwise from +x, in whatever frame the owner states.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Radians, counter-clockwise from +x.
    pub theta: f64,
}

impl Pose2 {
    /// A pose from its parts.
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    /// Checks every component is finite; `what` names the pose in the error.
    pub fn validate(&self, what: &'static str) -> Result<Self, GridError> {
        finite(what, self.x)?;
        finite(what, self.y)?;
        finite(what, self.theta)?;
        Ok(*self)
    }

    /// The pose `local`, given in this pose's frame, expressed in the frame
    /// this pose is given in (`self ⊕ local`).
    pub fn compose(&self, local: &Pose2) -> Pose2 {
        let (sin, cos) = self.theta.sin_cos();
        Pose2 {
            x: self.x + cos * local.x - sin * local.y,
            y: self.y + sin * local.x + cos * local.y,
            theta: normalize_angle(self.theta + local.theta),
        }
    }

    /// This pose expressed in `origin`'s frame (`origin⁻¹ ⊕ self`): the
    /// inverse of [`Pose2::compose`], so `origin.compose(&p.relative_to(&origin)) == p`.
    pub fn relative_to(&self, origin: &Pose2) -> Pose2 {
        let (sin, cos) = origin.theta.sin_cos();
        let (dx, dy) = (self.x - origin.x, self.y - origin.y);
        Pose2 {
            x: cos * dx + sin * dy,
            y: -sin * dx + cos * dy,
            theta: normalize_angle(self.theta - origin.theta),
        }
    }
}

/// The angle equal to `angle` modulo 2π in (-π, π].
pub fn normalize_angle(angle: f64) -> f64 {
    // Within a turn of zero the remainder below is the angle itself (plus
    // a turn when negative), so it needs no division; worked out the same
    // way, to the last bit, as the remainder would.
    let wrapped = if (0.0..TAU).contains(&angle) {
        angle
    } else if (-TAU..0.0).contains(&angle) {
        angle + TAU
    } else {
        angle.rem_euclid(TAU)
    };
    if wrapped > PI { wrapped - TAU } else { wrapped }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn relative_to_undoes_compose() {
        let origin = Pose2::new(1.0, -2.0, 2.5);
        let local = Pose2::new(0.3, 0.4, -3.0);
        let world = origin.compose(&local);
        let back = world.relative_to(&origin);
        assert_relative_eq!(back.x, local.x, epsilon = 1e-12);
        assert_relative_eq!(back.y, local.y, epsilon = 1e-12);
        assert_relative_eq!(back.theta, local.theta, epsilon = 1e-12);
        let again = origin.compose(&back);
        assert_relative_eq!(again.x, world.x, epsilon = 1e-12);
        assert_relative_eq!(again.theta, world.theta, epsilon = 1e-12);
    }

    #[test]
    fn normalize_keeps_the_half_open_interval() {
        assert_relative_eq!(normalize_angle(PI), PI);
        assert_relative_eq!(normalize_angle(-PI), PI);
        assert_relative_eq!(normalize_angle(3.0 * PI / 2.0), -PI / 2.0, epsilon = 1e-12);
        assert_relative_eq!(normalize_angle(-7.0 * TAU + 0.25), 0.25, epsilon = 1e-9);
    }

    proptest::proptest! {
        #[test]
        fn normalize_agrees_with_the_remainder(angle in -100.0f64..100.0) {
            let wrapped = normalize_angle(angle);
            proptest::prop_assert!(wrapped > -PI && wrapped <= PI);
            let turns = (angle - wrapped) / TAU;
            proptest::prop_assert!((turns - turns.round()).abs() < 1e-9);
            // As the plain remainder gives it, to the last bit.
            let remainder = angle.rem_euclid(TAU);
            let plain = if remainder > PI { remainder - TAU } else { remainder };
            proptest::prop_assert_eq!(wrapped.to_bits(), plain.to_bits());
        }
    }

    #[test]
    fn compose_rotates_then_translates() {
        let robot = Pose2::new(1.0, 2.0, PI / 2.0);
        let sensor = robot.compose(&Pose2::new(0.2, 0.0, 0.0));
        assert_relative_eq!(sensor.x, 1.0, epsilon = 1e-12);
        assert_relative_eq!(sensor.y, 2.2, epsilon = 1e-12);
        assert_relative_eq!(sensor.theta, PI / 2.0);
    }

    #[test]
    fn validate_names_non_finite_pose() {
        let err = Pose2::new(f64::NAN, 0.0, 0.0)
            .validate("odometry")
            .unwrap_err();
        assert!(err.to_string().contains("odometry"), "{err}");
    }
}
