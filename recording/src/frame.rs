//! What a recording holds of a robot, in deog's own terms: its frames
//! and a localizer's estimates.

use deog_grid::Pose2;

/// One frame of a robot: its readings with the poses known at the time.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// The robot's sequence number of the frame, from 1.
    pub sequence: u64,
    /// When the readings were taken, seconds (non-negative to record).
    pub time_s: f64,
    /// The robot's odometry, odometry frame.
    pub odometry: Pose2,
    /// The simulator's true pose, map frame, when known.
    pub true_pose: Option<Pose2>,
    /// A reference pose from outside the robot, map frame, when known.
    pub reference_pose: Option<Pose2>,
    /// One range per reading of the rig, metres, in the rig's order.
    pub ranges: Vec<f64>,
}

/// A localizer's estimate of the robot's pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// The frame it follows.
    pub frame_sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// The estimate, map frame.
    pub pose: Pose2,
    /// Its 3 x 3 covariance over (x, y, theta), row-major; zeros when the
    /// localizer gave none.
    pub covariance: [f64; 9],
}

/// The inverse of a planar pose: `inverse(p).compose(p)` is the identity.
pub fn inverse(pose: Pose2) -> Pose2 {
    let (s, c) = pose.theta.sin_cos();
    Pose2::new(
        -(c * pose.x + s * pose.y),
        s * pose.x - c * pose.y,
        -pose.theta,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn a_pose_composed_with_its_inverse_is_the_identity() {
        let p = Pose2::new(1.5, -0.3, 2.0);
        let i = inverse(p).compose(&p);
        assert_abs_diff_eq!(i.x, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(i.y, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(i.theta.sin(), 0.0, epsilon = 1e-12);
        let j = p.compose(&inverse(p));
        assert_abs_diff_eq!(j.x, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(j.y, 0.0, epsilon = 1e-12);
    }
}
