//! Where a robot's sonars sit: the Scout's ring of 16, or any other ring.

use std::f64::consts::TAU;

use crate::error::{GridError, within};
use crate::pose::Pose2;

/// Number of sonars on the Nomad Super Scout II.
pub const SCOUT_SONAR_COUNT: usize = 16;
/// Distance from the Scout's centre to its sonars, metres (its body is
/// about 41 cm across).
pub const SCOUT_RING_RADIUS_M: f64 = 0.2;
/// The Scout's body radius, metres.
pub const SCOUT_BODY_RADIUS_M: f64 = 0.205;

/// The mounting poses of a robot's range sensors in the robot frame, in the
/// order their readings arrive.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorRing {
    mounts: Vec<Pose2>,
}

impl SensorRing {
    /// The Scout's ring: 16 sonars 22.5° apart, sonar 0 facing forward, then
    /// counter-clockwise, each facing outwards.
    pub fn scout() -> Self {
        Self::uniform(SCOUT_SONAR_COUNT, SCOUT_RING_RADIUS_M)
            .expect("the Scout's figures are valid")
    }

    /// `count` sensors evenly spaced on a circle of `radius` metres, the
    /// first facing forward.
    pub fn uniform(count: usize, radius: f64) -> Result<Self, GridError> {
        within("sensor count", count as f64, 1.0, 1024.0)?;
        within("ring radius", radius, 0.0, 100.0)?;
        let mounts = (0..count)
            .map(|i| {
                let angle = TAU * i as f64 / count as f64;
                Pose2::new(radius * angle.cos(), radius * angle.sin(), angle)
            })
            .collect();
        Ok(Self { mounts })
    }

    /// A ring of arbitrary mounts.
    pub fn from_mounts(mounts: Vec<Pose2>) -> Result<Self, GridError> {
        within("sensor count", mounts.len() as f64, 1.0, 1024.0)?;
        for m in &mounts {
            m.validate("sensor mount")?;
        }
        Ok(Self { mounts })
    }

    /// The mounts, robot frame.
    pub fn mounts(&self) -> &[Pose2] {
        &self.mounts
    }

    /// Number of sensors.
    pub fn len(&self) -> usize {
        self.mounts.len()
    }

    /// Always false: a ring has at least one sensor.
    pub fn is_empty(&self) -> bool {
        self.mounts.is_empty()
    }

    /// Each sensor's pose in the world for a robot at `robot`.
    pub fn sensor_poses<'a>(&'a self, robot: &'a Pose2) -> impl Iterator<Item = Pose2> + 'a {
        self.mounts.iter().map(move |m| robot.compose(m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn scout_ring_faces_out_22_5_degrees_apart() {
        let ring = SensorRing::scout();
        assert_eq!(ring.len(), 16);
        let robot = Pose2::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
        let poses: Vec<_> = ring.sensor_poses(&robot).collect();
        // Sonar 0 faces the robot's heading, sonar 4 its left.
        assert_abs_diff_eq!(poses[0].x, 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(poses[0].y, 1.2, epsilon = 1e-12);
        assert_abs_diff_eq!(poses[0].theta, std::f64::consts::FRAC_PI_2, epsilon = 1e-12);
        assert_abs_diff_eq!(poses[4].x, 0.8, epsilon = 1e-12);
        assert_abs_diff_eq!(
            poses[1].theta - poses[0].theta,
            22.5f64.to_radians(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn empty_or_bad_rings_are_errors() {
        assert!(SensorRing::uniform(0, 0.2).is_err());
        assert!(SensorRing::uniform(16, f64::NAN).is_err());
        assert!(SensorRing::from_mounts(vec![]).is_err());
    }
}
