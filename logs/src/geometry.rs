//! Which laser a scan came from, and the geometry of each laser: where its
//! beams point, how far it sees and where it sits on the robot.

use std::f64::consts::PI;
use std::fmt;

use deog_grid::Pose2;

/// The laser a scan line came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LaserSource {
    /// `FLASER`: the front laser.
    Front,
    /// `RLASER`: the rear laser, mounted facing backwards.
    Rear,
    /// `ROBOTLASER1`: a laser line that carries its own geometry and its
    /// pose on the robot.
    RobotLaser,
}

impl LaserSource {
    /// Every source, in the order [`crate::CarmenLog::sources`] lists them.
    pub const ALL: [LaserSource; 3] = [Self::Front, Self::Rear, Self::RobotLaser];

    /// The first word of its lines in a log.
    pub fn tag(self) -> &'static str {
        match self {
            Self::Front => "FLASER",
            Self::Rear => "RLASER",
            Self::RobotLaser => "ROBOTLASER1",
        }
    }

    pub(crate) fn index(self) -> usize {
        match self {
            Self::Front => 0,
            Self::Rear => 1,
            Self::RobotLaser => 2,
        }
    }
}

impl fmt::Display for LaserSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.tag())
    }
}

/// One laser's geometry, as the log states it or as CARMEN's defaults
/// imply when it does not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserGeometry {
    /// The first reading's angle from the laser's heading, radians,
    /// counter-clockwise positive.
    pub first_angle: f64,
    /// Between consecutive readings, radians, counter-clockwise.
    pub angle_step: f64,
    /// Readings per scan.
    pub beam_count: u32,
    /// The no-return value, metres: readings at or beyond it heard nothing.
    /// For `FLASER`/`RLASER` the largest reading of that laser in the log;
    /// for `ROBOTLASER1` its `maximum_range` field.
    pub max_range: f64,
    /// Where the laser sits and faces, robot frame (metres, radians).
    pub mount: Pose2,
}

impl LaserGeometry {
    /// The angle of reading `index` from the laser's heading, radians.
    pub fn beam_angle(&self, index: usize) -> f64 {
        self.first_angle + self.angle_step * index as f64
    }
}

/// Where `FLASER`/`RLASER` beams point, which those lines do not say.
///
/// CARMEN's planar lasers (SICK LMS) sweep 180° counter-clockwise from the
/// laser's right, -90°. With an odd count (181, 361) the readings include
/// both ends, so they lie 180°/(n-1) apart and the last is at +90°. With an
/// even count (180, 360: the LMS default in the Intel and ACES logs) the
/// readings lie 180°/n apart from -90°: 180 readings one degree apart, the
/// last at +89°. A single reading points at -90° (its step is nominal).
/// Returns `(first_angle, angle_step)`, radians.
pub fn default_fan(beam_count: u32) -> (f64, f64) {
    let step = match beam_count {
        0 | 1 => PI,
        n if n % 2 == 1 => PI / f64::from(n - 1),
        n => PI / f64::from(n),
    };
    (-PI / 2.0, step)
}

/// The front laser's mount: `robot_frontlaser_offset` metres ahead of the
/// robot's centre, facing forward.
pub fn front_mount(offset: f64) -> Pose2 {
    Pose2::new(offset, 0.0, 0.0)
}

/// The rear laser's mount. CARMEN places it facing backwards (heading
/// +π) and `robot_rearlaser_offset` metres along that heading, so a
/// positive offset puts it behind the robot's centre.
pub fn rear_mount(offset: f64) -> Pose2 {
    Pose2::new(-offset, 0.0, PI)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn an_even_fan_is_one_degree_apart_from_the_right() {
        let (first, step) = default_fan(180);
        let g = LaserGeometry {
            first_angle: first,
            angle_step: step,
            beam_count: 180,
            max_range: 50.0,
            mount: front_mount(0.0),
        };
        assert_abs_diff_eq!(g.beam_angle(0), -PI / 2.0);
        assert_abs_diff_eq!(step, 1f64.to_radians(), epsilon = 1e-15);
        assert_abs_diff_eq!(g.beam_angle(90), 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(g.beam_angle(179), 89f64.to_radians(), epsilon = 1e-12);
    }

    #[test]
    fn an_odd_fan_ends_at_the_left() {
        for n in [181u32, 361] {
            let (first, step) = default_fan(n);
            assert_abs_diff_eq!(first + step * f64::from(n - 1), PI / 2.0, epsilon = 1e-12);
        }
        assert_abs_diff_eq!(default_fan(361).1, 0.5f64.to_radians(), epsilon = 1e-15);
    }

    #[test]
    fn the_rear_laser_faces_back_behind_the_centre() {
        let m = rear_mount(0.2);
        assert_abs_diff_eq!(m.x, -0.2);
        assert_abs_diff_eq!(m.theta, PI);
        assert_eq!(LaserSource::Rear.to_string(), "RLASER");
    }
}
