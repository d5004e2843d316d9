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

    /// The ring as it fired: each mount moved to where it stood when its
    /// sensor fired, `robot_at[k]` being the robot's pose then in the
    /// frame pose's frame ([`RingFiring::robot_at_readings`]). A list of
    /// the wrong length changes nothing.
    pub fn as_fired(&self, robot_at: &[Pose2]) -> SensorRing {
        if robot_at.len() != self.mounts.len() {
            return self.clone();
        }
        SensorRing {
            mounts: self
                .mounts
                .iter()
                .zip(robot_at)
                .map(|(m, at)| at.compose(m))
                .collect(),
        }
    }
}

/// When a ring's sensors fire within one frame. A real ring fires its
/// sonars one after another (their echoes would mix), while the robot
/// moves: a reading belongs where the robot stood when its sensor fired,
/// not where it stands when the frame is reported.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RingFiring {
    /// All at once, with the frame.
    #[default]
    Together,
    /// One at a time in ring order over `period_s` seconds ending with the
    /// frame: of n sensors, sensor k fires (k + 1) / n of the way through
    /// (the last with the frame), as `deog sim`'s realistic sonar fires.
    Sequential {
        /// The ring's firing period, seconds.
        period_s: f64,
    },
}

impl RingFiring {
    /// A ring firing in turn over `period_s` seconds, or together for 0.
    pub fn over(period_s: f64) -> Result<Self, GridError> {
        within("firing period", period_s, 0.0, 10.0)?;
        Ok(if period_s == 0.0 {
            Self::Together
        } else {
            Self::Sequential { period_s }
        })
    }

    /// How many seconds before the frame sensor `k` of `n` fired.
    pub fn lead_s(&self, k: usize, n: usize) -> f64 {
        match *self {
            Self::Together => 0.0,
            Self::Sequential { period_s } if n > 0 && k < n => {
                period_s * (1.0 - (k + 1) as f64 / n as f64)
            }
            Self::Sequential { .. } => 0.0,
        }
    }

    /// Where the robot stood when each of `n` sensors fired, in the frame
    /// pose's own frame, for a robot that moves `back_per_s` (its pose a
    /// second earlier, seen from now: [`FrameMotion`]) at a steady pace;
    /// `None` when they all fired with the frame or the robot stands still.
    pub fn robot_at_readings(&self, n: usize, back_per_s: Option<&Pose2>) -> Option<Vec<Pose2>> {
        let back = back_per_s?;
        if *self == Self::Together || (back.x == 0.0 && back.y == 0.0 && back.theta == 0.0) {
            return None;
        }
        Some(
            (0..n)
                .map(|k| {
                    let t = self.lead_s(k, n);
                    Pose2::new(back.x * t, back.y * t, back.theta * t)
                })
                .collect(),
        )
    }
}

/// The robot's pace between consecutive frames, from their poses (the
/// odometry, or whichever pose places the readings) and times.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameMotion {
    last: Option<(Pose2, f64)>,
}

impl FrameMotion {
    /// Frames further apart than this, seconds, give no pace: a gap in the
    /// stream says nothing of how the robot moved within the frame.
    pub const MAX_GAP_S: f64 = 1.0;

    /// Takes the next frame's `pose` at `time_s` and returns the robot's
    /// pose one second earlier seen from this frame's pose, at the pace of
    /// the step since the last frame: `(last ⊖ pose) / Δt`. `None` for the
    /// first frame, a gap past [`Self::MAX_GAP_S`] or time not moving on.
    pub fn observe(&mut self, pose: &Pose2, time_s: f64) -> Option<Pose2> {
        let last = self.last.replace((*pose, time_s));
        let (then, then_s) = last?;
        let dt = time_s - then_s;
        if !(dt > 0.0 && dt <= Self::MAX_GAP_S) {
            return None;
        }
        let back = then.relative_to(pose);
        Some(Pose2::new(back.x / dt, back.y / dt, back.theta / dt))
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
    fn a_ring_fired_in_turn_places_each_reading_where_the_robot_stood() {
        let firing = RingFiring::over(0.1).unwrap();
        assert_abs_diff_eq!(firing.lead_s(15, 16), 0.0);
        assert_abs_diff_eq!(firing.lead_s(0, 16), 0.09375, epsilon = 1e-12);
        assert_eq!(RingFiring::over(0.0).unwrap(), RingFiring::Together);
        assert!(RingFiring::over(-0.1).is_err());
        assert!(RingFiring::over(f64::NAN).is_err());
        // Driving forward at 1 m/s while turning left at 1 rad/s.
        let mut motion = FrameMotion::default();
        assert_eq!(motion.observe(&Pose2::new(0.0, 0.0, 0.0), 0.0), None);
        let now = Pose2::new(0.0, 0.0, 0.0).compose(&Pose2::new(0.1, 0.0, 0.1));
        let back = motion.observe(&now, 0.1).unwrap();
        assert_abs_diff_eq!(back.theta, -1.0, epsilon = 1e-12);
        assert!(back.x < -0.99 && back.x > -1.01, "{back:?}");
        let at = firing.robot_at_readings(16, Some(&back)).unwrap();
        assert_abs_diff_eq!(at[15].theta, 0.0);
        assert_abs_diff_eq!(at[0].theta, -0.09375, epsilon = 1e-12);
        // Sonar 4 faced left when the frame was taken; it fired 0.06875 s
        // earlier, when it faced that much further right.
        let fired = SensorRing::scout().as_fired(&at);
        assert_abs_diff_eq!(
            fired.mounts()[4].theta,
            std::f64::consts::FRAC_PI_2 - 0.06875,
            epsilon = 1e-12
        );
        let (last, mount) = (fired.mounts()[15], SensorRing::scout().mounts()[15]);
        assert_abs_diff_eq!(last.x, mount.x, epsilon = 1e-12);
        assert_abs_diff_eq!(last.y, mount.y, epsilon = 1e-12);
        assert_abs_diff_eq!(
            crate::pose::normalize_angle(last.theta - mount.theta),
            0.0,
            epsilon = 1e-12
        );
        // Together, standing still, a gap or time going back: as reported.
        assert_eq!(
            RingFiring::Together.robot_at_readings(16, Some(&back)),
            None
        );
        assert_eq!(
            firing.robot_at_readings(16, Some(&Pose2::new(0.0, 0.0, 0.0))),
            None
        );
        assert_eq!(motion.observe(&now, 2.0), None);
        assert_eq!(motion.observe(&now, 1.9), None);
        assert_eq!(SensorRing::scout().as_fired(&at[..3]), SensorRing::scout());
    }

    #[test]
    fn empty_or_bad_rings_are_errors() {
        assert!(SensorRing::uniform(0, 0.2).is_err());
        assert!(SensorRing::uniform(16, f64::NAN).is_err());
        assert!(SensorRing::from_mounts(vec![]).is_err());
    }
}
