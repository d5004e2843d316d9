//! One line of a log, split and checked: a laser scan, odometry, a true
//! pose, a parameter, or something skipped.
//!
//! The layouts (fields separated by white space):
//! - `FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_ts host logger_ts`,
//!   and `RLASER` the same;
//! - `ROBOTLASER1 laser_type start_angle field_of_view angular_resolution
//!   maximum_range accuracy remission_mode n r1..rn k rem1..remk laser_x laser_y
//!   laser_theta robot_x robot_y robot_theta laser_tv laser_rv
//!   forward_safety_dist side_safety_dist turn_axis ipc_ts host logger_ts`;
//! - `ODOM x y theta tv rv accel ts host ts`;
//! - `TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta ts host ts`;
//! - `PARAM name value host ts`.
//!
//! `#` comments, blank lines, `NEFF`, `SYNC`, `RAWLASER1`..`4` and every
//! other first word are skipped.

use deog_grid::Pose2;

use crate::geometry::LaserSource;

/// What a `ROBOTLASER1` line says about its laser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Device {
    /// Radians from the laser's heading.
    pub start_angle: f64,
    /// Radians.
    pub field_of_view: f64,
    /// Radians between readings.
    pub resolution: f64,
    /// Metres.
    pub max_range: f64,
}

/// A laser line's content.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LaserLine {
    pub source: LaserSource,
    /// Metres, in the laser's order.
    pub ranges: Vec<f64>,
    /// The laser's pose as the line states it (world frame); for `FLASER`
    /// and `RLASER` their `x y theta`.
    pub laser_pose: Pose2,
    /// The robot's pose as the line states it: `odom_*` of
    /// `FLASER`/`RLASER`, `robot_*` of `ROBOTLASER1`.
    pub robot_pose: Pose2,
    /// The IPC timestamp, seconds.
    pub time_s: f64,
    /// `ROBOTLASER1` only.
    pub device: Option<Device>,
}

/// One line of a log.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Record {
    Laser(LaserLine),
    /// An `ODOM` line's pose.
    Odom(Pose2),
    /// A `TRUEPOS` line's true pose.
    TruePos(Pose2),
    Param {
        name: String,
        value: String,
    },
    Skip,
}

/// Splits and checks one line; the error says what is wrong with it.
pub(crate) fn parse_line(text: &str) -> Result<Record, String> {
    let tokens: Vec<&str> = text.split_whitespace().collect();
    let Some(&tag) = tokens.first() else {
        return Ok(Record::Skip);
    };
    let line = Fields { tag, tokens };
    match tag {
        "FLASER" => line.flaser(LaserSource::Front).map(Record::Laser),
        "RLASER" => line.flaser(LaserSource::Rear).map(Record::Laser),
        "ROBOTLASER1" => line.robot_laser().map(Record::Laser),
        "ODOM" => {
            line.count(10)?;
            line.numbers(4..8, "velocity, acceleration or timestamp")?;
            line.number(9, "logger timestamp")?;
            line.pose(1, ["x", "y", "theta"]).map(Record::Odom)
        }
        "TRUEPOS" => {
            line.count(10)?;
            line.pose(4, ["odom_x", "odom_y", "odom_theta"])?;
            line.number(7, "timestamp")?;
            line.number(9, "logger timestamp")?;
            line.pose(1, ["true_x", "true_y", "true_theta"])
                .map(Record::TruePos)
        }
        "PARAM" => {
            if line.tokens.len() < 3 {
                return Err(format!(
                    "PARAM needs a name and a value, found {} fields",
                    line.tokens.len()
                ));
            }
            Ok(Record::Param {
                name: line.tokens[1].to_owned(),
                value: line.tokens[2].to_owned(),
            })
        }
        _ => Ok(Record::Skip),
    }
}

/// A line's fields, with checks that name the field at fault.
struct Fields<'a> {
    tag: &'a str,
    tokens: Vec<&'a str>,
}

impl Fields<'_> {
    fn count(&self, expected: usize) -> Result<(), String> {
        if self.tokens.len() == expected {
            Ok(())
        } else {
            Err(format!(
                "{} needs {expected} fields, found {}",
                self.tag,
                self.tokens.len()
            ))
        }
    }

    /// Field `i` (0 is the tag) as a finite number.
    fn number(&self, i: usize, name: &str) -> Result<f64, String> {
        let text = self.tokens[i];
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!(
                "{} field {i} ({name}): {text:?} is not a finite number",
                self.tag
            )),
        }
    }

    fn numbers(&self, range: std::ops::Range<usize>, name: &str) -> Result<Vec<f64>, String> {
        range.map(|i| self.number(i, name)).collect()
    }

    fn pose(&self, i: usize, names: [&str; 3]) -> Result<Pose2, String> {
        Ok(Pose2::new(
            self.number(i, names[0])?,
            self.number(i + 1, names[1])?,
            self.number(i + 2, names[2])?,
        ))
    }

    /// Field `i` as a count of what follows.
    fn count_at(&self, i: usize, name: &str) -> Result<usize, String> {
        let Some(text) = self.tokens.get(i) else {
            return Err(format!(
                "{} ends after {} fields, before its {name}",
                self.tag,
                self.tokens.len()
            ));
        };
        text.parse::<usize>().map_err(|_| {
            format!(
                "{} field {i} ({name}): {text:?} is not a whole number",
                self.tag
            )
        })
    }

    /// Readings `first..first + n`: finite and not negative.
    fn ranges(&self, first: usize, n: usize) -> Result<Vec<f64>, String> {
        (first..first + n)
            .map(|i| {
                let v = self.number(i, "a reading")?;
                if v < 0.0 {
                    return Err(format!(
                        "{} field {i} (reading {}): {v} is negative",
                        self.tag,
                        i - first + 1
                    ));
                }
                Ok(v)
            })
            .collect()
    }

    fn flaser(&self, source: LaserSource) -> Result<LaserLine, String> {
        let n = self.count_at(1, "reading count")?;
        let expected = n + 11;
        if self.tokens.len() != expected {
            return Err(format!(
                "{} with {n} readings needs {expected} fields, found {} \
                 (the reading count does not match the line)",
                self.tag,
                self.tokens.len()
            ));
        }
        if n == 0 {
            return Err(format!("{} with no readings", self.tag));
        }
        let ranges = self.ranges(2, n)?;
        let laser_pose = self.pose(n + 2, ["x", "y", "theta"])?;
        let robot_pose = self.pose(n + 5, ["odom_x", "odom_y", "odom_theta"])?;
        let time_s = self.number(n + 8, "ipc timestamp")?;
        self.number(n + 10, "logger timestamp")?;
        Ok(LaserLine {
            source,
            ranges,
            laser_pose,
            robot_pose,
            time_s,
            device: None,
        })
    }

    fn robot_laser(&self) -> Result<LaserLine, String> {
        let n = self.count_at(8, "num_readings")?;
        let k = self.count_at(n + 9, "num_remissions")?;
        let expected = n + k + 24;
        if self.tokens.len() != expected {
            return Err(format!(
                "{} with {n} readings and {k} remissions needs {expected} fields, found {} \
                 (a count does not match the line)",
                self.tag,
                self.tokens.len()
            ));
        }
        if n == 0 {
            return Err(format!("{} with no readings", self.tag));
        }
        self.number(1, "laser_type")?;
        let device = Device {
            start_angle: self.number(2, "start_angle")?,
            field_of_view: self.number(3, "field_of_view")?,
            resolution: self.number(4, "angular_resolution")?,
            max_range: self.number(5, "maximum_range")?,
        };
        self.number(6, "accuracy")?;
        self.number(7, "remission_mode")?;
        let ranges = self.ranges(9, n)?;
        self.numbers(n + 10..n + k + 10, "a remission")?;
        let at = n + k + 10;
        let laser_pose = self.pose(at, ["laser_x", "laser_y", "laser_theta"])?;
        let robot_pose = self.pose(at + 3, ["robot_x", "robot_y", "robot_theta"])?;
        self.numbers(at + 6..at + 11, "velocity, safety distance or turn axis")?;
        let time_s = self.number(at + 11, "ipc timestamp")?;
        self.number(at + 13, "logger timestamp")?;
        Ok(LaserLine {
            source: LaserSource::RobotLaser,
            ranges,
            laser_pose,
            robot_pose,
            time_s,
            device: Some(device),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn laser(text: &str) -> LaserLine {
        match parse_line(text).unwrap() {
            Record::Laser(l) => l,
            other => panic!("not a laser line: {other:?}"),
        }
    }

    #[test]
    fn a_front_laser_line_splits_into_its_parts() {
        let l = laser("FLASER 3 1.5 2 50 0.1 0.2 0.3 1 2 3 12.5 host 12.6");
        assert_eq!(l.source, LaserSource::Front);
        assert_eq!(l.ranges, vec![1.5, 2.0, 50.0]);
        assert_eq!(l.laser_pose, Pose2::new(0.1, 0.2, 0.3));
        assert_eq!(l.robot_pose, Pose2::new(1.0, 2.0, 3.0));
        assert_eq!(l.time_s, 12.5);
        assert_eq!(l.device, None);
        let r = laser("RLASER 1 4 0 0 0 0 0 0 1 h 1");
        assert_eq!(r.source, LaserSource::Rear);
    }

    #[test]
    fn a_robot_laser_line_carries_its_device() {
        let l = laser(
            "ROBOTLASER1 0 -1.5 3.0 1.5 8.0 0.01 0 3 1 2 3 2 9 9 \
             1.1 0 0 1 0 0 0.5 0.1 1 0.3 1e6 7.25 host 7.3",
        );
        assert_eq!(l.source, LaserSource::RobotLaser);
        assert_eq!(l.ranges, vec![1.0, 2.0, 3.0]);
        assert_eq!(l.laser_pose, Pose2::new(1.1, 0.0, 0.0));
        assert_eq!(l.robot_pose, Pose2::new(1.0, 0.0, 0.0));
        assert_eq!(l.time_s, 7.25);
        let d = l.device.unwrap();
        assert_eq!(
            (d.start_angle, d.field_of_view, d.resolution, d.max_range),
            (-1.5, 3.0, 1.5, 8.0)
        );
    }

    #[test]
    fn odometry_true_poses_and_params() {
        assert_eq!(
            parse_line("ODOM 1 2 0.5 0 0 0 3.5 pippo 3.5"),
            Ok(Record::Odom(Pose2::new(1.0, 2.0, 0.5)))
        );
        assert_eq!(
            parse_line("TRUEPOS 1 2 0.5 0 0 0 3.5 sim 3.5"),
            Ok(Record::TruePos(Pose2::new(1.0, 2.0, 0.5)))
        );
        assert_eq!(
            parse_line("PARAM robot_frontlaser_offset 0.25 nohost 0"),
            Ok(Record::Param {
                name: "robot_frontlaser_offset".into(),
                value: "0.25".into()
            })
        );
    }

    #[test]
    fn comments_blanks_and_unknown_lines_are_skipped() {
        for text in [
            "",
            "   ",
            "# a comment",
            "#ODOM 1 2",
            "NEFF 15",
            "SYNC tag",
            "RAWLASER1 whatever",
            "ROBOTLASER2 1 2 3",
            "GPSNMEA x",
        ] {
            assert_eq!(parse_line(text), Ok(Record::Skip), "{text:?}");
        }
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        let cases = [
            ("FLASER", "before its reading count"),
            (
                "FLASER x 1 0 0 0 0 0 0 1 h 1",
                "\"x\" is not a whole number",
            ),
            (
                "FLASER 3 1 2 0 0 0 0 0 0 1 h 1",
                "needs 14 fields, found 13",
            ),
            ("FLASER 0 0 0 0 0 0 0 1 h 1", "no readings"),
            ("FLASER 2 1 abc 0 0 0 0 0 0 1 h 1", "field 3 (a reading)"),
            (
                "FLASER 2 1 -2 0 0 0 0 0 0 1 h 1",
                "(reading 2): -2 is negative",
            ),
            ("FLASER 2 1 2 0 nan 0 0 0 0 1 h 1", "field 5 (y)"),
            ("RLASER 1 1 0 0 0 0 0 0 t h 1", "(ipc timestamp)"),
            ("ODOM 1 2 3 0 0 0 1 h", "ODOM needs 10 fields, found 9"),
            ("ODOM 1 2 q 0 0 0 1 h 1", "field 3 (theta)"),
            ("TRUEPOS 1 2 3 0 0 0 1 h 1 9", "TRUEPOS needs 10 fields"),
            ("PARAM lonely", "needs a name and a value"),
            (
                "ROBOTLASER1 0 0 3 1 8 0 0 2 1 2",
                "before its num_remissions",
            ),
            (
                "ROBOTLASER1 0 0 3 1 8 0 0 1 1 0 0 0 0 0 0 0 0 0 0 0 0 1 h",
                "needs 25 fields, found 24",
            ),
        ];
        for (text, want) in cases {
            let err = parse_line(text).unwrap_err();
            assert!(err.contains(want), "{text:?}: {err}");
        }
    }
}
