//! A rig: a robot's range sensors, each mounted somewhere on it, and the
//! same sensors flattened into beams, one per reading of a frame.

use std::f64::consts::PI;

use deog_grid::{Pose2, SensorRing};

use crate::error::RigError;

/// The most readings a frame of one rig may hold.
pub const MAX_READINGS: usize = 4096;

/// The longest rig name.
pub const MAX_NAME_LEN: usize = 128;

/// What a sensor is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SensorKind {
    /// An ultrasonic ranger: one reading, the nearest echo anywhere in its
    /// cone.
    Sonar {
        /// Half the cone's opening angle, radians.
        half_angle: f64,
    },
    /// A planar scanning laser: `beam_count` readings along rays
    /// `first_angle + i * angle_step` from the sensor's heading.
    Laser {
        /// The first beam's angle from the sensor's heading, radians
        /// (counter-clockwise positive).
        first_angle: f64,
        /// Between consecutive beams, radians, positive (counter-clockwise).
        angle_step: f64,
        /// Readings per scan.
        beam_count: u32,
    },
}

/// What a reading that heard nothing looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoEcho {
    /// Readings at or beyond this range, metres, mean no echo.
    pub at_or_beyond: f64,
    /// Whether a reading of exactly 0 means no echo (some lasers report
    /// a failed return so).
    pub zero: bool,
}

/// One range sensor on the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeSensor {
    /// Where it sits and faces, robot frame.
    pub mount: Pose2,
    /// Sonar or laser.
    pub kind: SensorKind,
    /// The shortest range it reports, metres; nearer echoes read this.
    pub min_range: f64,
    /// The longest range it reports, metres.
    pub max_range: f64,
    /// How a no-echo reading looks.
    pub no_echo: NoEcho,
}

impl RangeSensor {
    /// Readings per frame.
    pub fn readings(&self) -> usize {
        match self.kind {
            SensorKind::Sonar { .. } => 1,
            SensorKind::Laser { beam_count, .. } => beam_count as usize,
        }
    }
}

/// The shape a beam covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BeamShape {
    /// A sonar's cone.
    Cone {
        /// Half the opening angle, radians.
        half_angle: f64,
    },
    /// A laser's ray.
    Ray,
}

/// One reading's geometry: a sonar, or one ray of a laser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    /// Where the reading starts and which way it points, robot frame.
    pub mount: Pose2,
    /// Cone or ray.
    pub shape: BeamShape,
    /// The shortest range reported, metres.
    pub min_range: f64,
    /// The longest range reported, metres.
    pub max_range: f64,
    /// How a no-echo reading looks.
    pub no_echo: NoEcho,
    /// Which sensor of the rig the beam belongs to.
    pub sensor: usize,
}

/// A reading judged against its beam.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reading {
    /// An echo at this range, metres, clamped to the beam's limits.
    Echo(f64),
    /// Nothing heard.
    NoEcho,
}

impl Beam {
    /// What `range` says, or `None` for a value that is not a range (NaN,
    /// negative, or infinite without meaning no echo).
    pub fn classify(&self, range: f64) -> Option<Reading> {
        if range.is_nan() || range < 0.0 {
            return None;
        }
        if range >= self.no_echo.at_or_beyond || (self.no_echo.zero && range == 0.0) {
            return Some(Reading::NoEcho);
        }
        if !range.is_finite() {
            return None;
        }
        Some(Reading::Echo(range.clamp(self.min_range, self.max_range)))
    }
}

/// A robot's range sensors, checked, with their beams.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    name: String,
    body_radius: f64,
    sensors: Vec<RangeSensor>,
    beams: Vec<Beam>,
}

impl Rig {
    /// A rig from its parts, every figure checked.
    pub fn new(
        name: impl Into<String>,
        body_radius: f64,
        sensors: Vec<RangeSensor>,
    ) -> Result<Self, RigError> {
        let name = name.into();
        check_name(&name)?;
        let bad = |field: String, reason: String| RigError::invalid(&name, field, reason);
        if !(body_radius.is_finite() && (0.01..=10.0).contains(&body_radius)) {
            return Err(bad(
                "body_radius_m".into(),
                format!("must be within [0.01, 10], got {body_radius}"),
            ));
        }
        if sensors.is_empty() {
            return Err(bad("sensor".into(), "the rig has no sensor".into()));
        }
        let mut beams = Vec::new();
        for (i, s) in sensors.iter().enumerate() {
            check_sensor(s)
                .map_err(|(field, reason)| bad(format!("sensor[{i}].{field}"), reason))?;
            push_beams(i, s, &mut beams);
            if beams.len() > MAX_READINGS {
                return Err(bad(
                    "sensor".into(),
                    format!("more than {MAX_READINGS} readings per frame"),
                ));
            }
        }
        Ok(Self {
            name,
            body_radius,
            sensors,
            beams,
        })
    }

    /// The rig's name, which frames carry.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The robot body's radius, metres (what the simulator collides).
    pub fn body_radius(&self) -> f64 {
        self.body_radius
    }

    /// The sensors, in the order their readings arrive.
    pub fn sensors(&self) -> &[RangeSensor] {
        &self.sensors
    }

    /// One beam per reading, in the frame's order.
    pub fn beams(&self) -> &[Beam] {
        &self.beams
    }

    /// Readings per frame.
    pub fn readings(&self) -> usize {
        self.beams.len()
    }

    /// The beams' mounts as a ring (one mount per reading).
    pub fn ring(&self) -> SensorRing {
        SensorRing::from_mounts(self.beams.iter().map(|b| b.mount).collect())
            .expect("a rig's mounts were checked")
    }

    /// Whether every sensor is a sonar.
    pub fn all_sonar(&self) -> bool {
        self.sensors
            .iter()
            .all(|s| matches!(s.kind, SensorKind::Sonar { .. }))
    }

    /// Whether every sensor is a laser.
    pub fn all_laser(&self) -> bool {
        self.sensors
            .iter()
            .all(|s| matches!(s.kind, SensorKind::Laser { .. }))
    }

    /// How far the farthest sensor sits from the robot's centre, metres.
    pub fn reach(&self) -> f64 {
        self.sensors
            .iter()
            .map(|s| s.mount.x.hypot(s.mount.y))
            .fold(0.0, f64::max)
    }

    /// The longest range any beam reports, metres.
    pub fn max_range(&self) -> f64 {
        self.sensors.iter().map(|s| s.max_range).fold(0.0, f64::max)
    }

    /// Refuses a frame that does not fit the rig: the wrong number of
    /// readings, or a reading that is not a range.
    pub fn check_frame(&self, ranges: &[f64]) -> Result<(), RigError> {
        if ranges.len() != self.readings() {
            return Err(RigError::WrongReadingCount {
                rig: self.name.clone(),
                expected: self.readings(),
                got: ranges.len(),
            });
        }
        for (index, (beam, &value)) in self.beams.iter().zip(ranges).enumerate() {
            if beam.classify(value).is_none() {
                return Err(RigError::BadReading {
                    rig: self.name.clone(),
                    index,
                    value,
                });
            }
        }
        Ok(())
    }
}

/// Checks a rig name: 1 to 128 characters of `[A-Za-z0-9_.-]`, as robot
/// and map names.
pub fn check_name(name: &str) -> Result<(), RigError> {
    let ok = !name.is_empty()
        && name.len() <= MAX_NAME_LEN
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-'));
    if ok {
        Ok(())
    } else {
        Err(RigError::invalid(
            name,
            "name",
            format!("must be 1 to {MAX_NAME_LEN} characters of [A-Za-z0-9_.-]"),
        ))
    }
}

fn check_sensor(s: &RangeSensor) -> Result<(), (String, String)> {
    let within = |field: &str, v: f64, lo: f64, hi: f64| {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(())
        } else {
            Err((
                field.to_owned(),
                format!("must be within [{lo}, {hi}], got {v}"),
            ))
        }
    };
    within("x_m", s.mount.x, -10.0, 10.0)?;
    within("y_m", s.mount.y, -10.0, 10.0)?;
    within("heading_deg", s.mount.theta.to_degrees(), -360.0, 360.0)?;
    within("max_range_m", s.max_range, 0.01, 1000.0)?;
    within("min_range_m", s.min_range, 0.0, s.max_range)?;
    if s.min_range >= s.max_range {
        return Err((
            "min_range_m".into(),
            format!(
                "must be below max_range_m ({}), got {}",
                s.max_range, s.min_range
            ),
        ));
    }
    if s.no_echo.at_or_beyond.is_nan() || s.no_echo.at_or_beyond <= s.min_range {
        return Err((
            "no_echo_m".into(),
            format!(
                "must be above min_range_m ({}), got {}",
                s.min_range, s.no_echo.at_or_beyond
            ),
        ));
    }
    match s.kind {
        SensorKind::Sonar { half_angle } => {
            within("half_angle_deg", half_angle.to_degrees(), 0.1, 80.0)?;
        }
        SensorKind::Laser {
            first_angle,
            angle_step,
            beam_count,
        } => {
            within("first_angle_deg", first_angle.to_degrees(), -360.0, 360.0)?;
            within("angle_step_deg", angle_step.to_degrees(), 1e-3, 90.0)?;
            within(
                "beam_count",
                f64::from(beam_count),
                1.0,
                MAX_READINGS as f64,
            )?;
            let span = angle_step * f64::from(beam_count - 1);
            if span > 2.0 * PI + 1e-9 {
                return Err((
                    "angle_step_deg".into(),
                    format!(
                        "{beam_count} beams {:.4} degrees apart span more than a turn",
                        angle_step.to_degrees()
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn push_beams(sensor: usize, s: &RangeSensor, beams: &mut Vec<Beam>) {
    let beam = |mount: Pose2, shape: BeamShape| Beam {
        mount,
        shape,
        min_range: s.min_range,
        max_range: s.max_range,
        no_echo: s.no_echo,
        sensor,
    };
    match s.kind {
        SensorKind::Sonar { half_angle } => {
            beams.push(beam(s.mount, BeamShape::Cone { half_angle }));
        }
        SensorKind::Laser {
            first_angle,
            angle_step,
            beam_count,
        } => {
            for i in 0..beam_count {
                let angle = first_angle + angle_step * f64::from(i);
                let mount = s.mount.compose(&Pose2::new(0.0, 0.0, angle));
                beams.push(beam(mount, BeamShape::Ray));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn laser(count: u32) -> RangeSensor {
        RangeSensor {
            mount: Pose2::new(0.1, 0.0, 0.0),
            kind: SensorKind::Laser {
                first_angle: -PI / 2.0,
                angle_step: PI / 180.0,
                beam_count: count,
            },
            min_range: 0.02,
            max_range: 50.0,
            no_echo: NoEcho {
                at_or_beyond: 50.0,
                zero: true,
            },
        }
    }

    #[test]
    fn a_laser_flattens_into_one_ray_per_beam() {
        let rig = Rig::new("l", 0.2, vec![laser(180)]).unwrap();
        assert_eq!(rig.readings(), 180);
        assert!(rig.all_laser() && !rig.all_sonar());
        let beams = rig.beams();
        assert_abs_diff_eq!(beams[0].mount.theta, -PI / 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(beams[90].mount.theta, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(beams[179].mount.theta, 89f64.to_radians(), epsilon = 1e-12);
        assert_abs_diff_eq!(beams[37].mount.x, 0.1, epsilon = 1e-12);
        assert_eq!(beams[5].shape, BeamShape::Ray);
    }

    #[test]
    fn readings_are_judged_by_their_beam() {
        let rig = Rig::new("l", 0.2, vec![laser(3)]).unwrap();
        let beam = rig.beams()[0];
        assert_eq!(beam.classify(1.5), Some(Reading::Echo(1.5)));
        assert_eq!(beam.classify(0.001), Some(Reading::Echo(0.02)));
        assert_eq!(beam.classify(0.0), Some(Reading::NoEcho));
        assert_eq!(beam.classify(50.0), Some(Reading::NoEcho));
        assert_eq!(beam.classify(f64::INFINITY), Some(Reading::NoEcho));
        assert_eq!(beam.classify(-1.0), None);
        assert_eq!(beam.classify(f64::NAN), None);
        assert!(rig.check_frame(&[1.0, 2.0, 80.0]).is_ok());
        let err = rig.check_frame(&[1.0, 2.0]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "rig l reads 3 ranges per frame, the frame has 2"
        );
        let err = rig.check_frame(&[1.0, f64::NAN, 2.0]).unwrap_err();
        assert!(err.to_string().contains("ranges[1]"), "{err}");
    }

    #[test]
    fn bad_rigs_name_the_field() {
        let mut s = laser(10);
        s.min_range = 60.0;
        let err = Rig::new("l", 0.2, vec![laser(10), s]).unwrap_err();
        assert!(err.to_string().contains("sensor[1].min_range_m"), "{err}");
        let err = Rig::new("l", 0.2, vec![]).unwrap_err();
        assert!(err.to_string().contains("no sensor"), "{err}");
        let err = Rig::new("bad name", 0.2, vec![laser(1)]).unwrap_err();
        assert!(err.to_string().contains("name"), "{err}");
        let err = Rig::new("l", 0.2, vec![laser(5000)]).unwrap_err();
        assert!(err.to_string().contains("beam_count"), "{err}");
        let mut wide = laser(720);
        wide.kind = SensorKind::Laser {
            first_angle: 0.0,
            angle_step: 1f64.to_radians(),
            beam_count: 720,
        };
        let err = Rig::new("l", 0.2, vec![wide]).unwrap_err();
        assert!(err.to_string().contains("more than a turn"), "{err}");
    }
}
