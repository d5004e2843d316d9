//! Rigs from a log's laser geometry, and a log's scans checked against a
//! rig.

use deog_rig::{NoEcho, RangeSensor, Rig, SensorKind};

use crate::error::LogError;
use crate::geometry::LaserSource;
use crate::log::CarmenLog;

/// The shortest range a log's laser reports, metres. The logs do not say;
/// the SICK lasers of CARMEN read no nearer than a few centimetres.
pub const LOG_MIN_RANGE_M: f64 = 0.01;

/// The robot body's radius of a rig built from a log, metres. The logs do
/// not say; the Pioneer-class robots that recorded them are about half a
/// metre across.
pub const LOG_BODY_RADIUS_M: f64 = 0.25;

impl CarmenLog {
    /// A rig named `name` holding one laser: `source` as this log saw it.
    /// Its maximum range is the log's no-return value, and readings at or
    /// beyond that value, or exactly 0, mean no return.
    pub fn rig(&self, source: LaserSource, name: &str) -> Result<Rig, LogError> {
        let geometry = self
            .geometry(source)
            .ok_or_else(|| LogError::NoSuchSource {
                origin: self.origin().to_owned(),
                laser: source,
            })?;
        let sensor = RangeSensor {
            mount: geometry.mount,
            kind: SensorKind::Laser {
                first_angle: geometry.first_angle,
                angle_step: geometry.angle_step,
                beam_count: geometry.beam_count,
            },
            min_range: LOG_MIN_RANGE_M,
            max_range: geometry.max_range,
            no_echo: NoEcho {
                at_or_beyond: geometry.max_range,
                zero: true,
            },
        };
        Rig::new(name, LOG_BODY_RADIUS_M, vec![sensor]).map_err(|error| LogError::Rig {
            origin: self.origin().to_owned(),
            laser: source,
            error,
        })
    }

    /// Checks every scan of `source` against `rig` (its reading count, and
    /// that every reading is a range); the error names the first scan's
    /// line that does not fit. A laser the log does not have is an error,
    /// not a check of nothing.
    pub fn check_rig(&self, source: LaserSource, rig: &Rig) -> Result<(), LogError> {
        if self.geometry(source).is_none() {
            return Err(LogError::NoSuchSource {
                origin: self.origin().to_owned(),
                laser: source,
            });
        }
        for scan in self.scans_from(source) {
            rig.check_frame(&scan.ranges)
                .map_err(|error| LogError::RigMismatch {
                    origin: self.origin().to_owned(),
                    line: scan.line,
                    error,
                })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_rig::{BeamShape, Reading};

    fn log(text: &str) -> CarmenLog {
        CarmenLog::parse_str(text, "t.log").unwrap()
    }

    #[test]
    fn the_rig_is_the_logs_laser() {
        let ranges = vec!["2.5"; 180].join(" ");
        let text = format!(
            "FLASER 180 {ranges} 0 0 0 0 0 0 1 h 1\n\
             FLASER 180 {} 0 0 0 0 0 0 2 h 2\n",
            ranges.replacen("2.5", "81.83", 1)
        );
        let log = log(&text);
        let rig = log.rig(LaserSource::Front, "intel-front").unwrap();
        assert_eq!(rig.name(), "intel-front");
        assert_eq!(rig.readings(), 180);
        assert_eq!(rig.max_range(), 81.83);
        let beams = rig.beams();
        assert_eq!(beams[0].shape, BeamShape::Ray);
        assert!((beams[179].mount.theta - 89f64.to_radians()).abs() < 1e-12);
        assert_eq!(beams[0].classify(81.83), Some(Reading::NoEcho));
        assert_eq!(beams[0].classify(0.0), Some(Reading::NoEcho));
        assert_eq!(beams[0].classify(81.8), Some(Reading::Echo(81.8)));
        log.check_rig(LaserSource::Front, &rig).unwrap();
    }

    #[test]
    fn a_missing_laser_or_a_bad_geometry_is_an_error() {
        let log = log("FLASER 2 0 0 0 0 0 0 0 0 1 h 1\n");
        let err = log.rig(LaserSource::Rear, "r").unwrap_err();
        assert_eq!(err.to_string(), "t.log: the log has no RLASER scans");
        let rig = deog_rig::built_in_rig("laser180").unwrap();
        let err = log.check_rig(LaserSource::Rear, &rig).unwrap_err();
        assert_eq!(err.to_string(), "t.log: the log has no RLASER scans");
        // Every reading 0: no range at all, no rig.
        let err = log.rig(LaserSource::Front, "f").unwrap_err();
        assert!(
            err.to_string().starts_with(
                "t.log: the FLASER laser does not make a rig: rig f: sensor[0].max_range_m"
            ),
            "{err}"
        );
    }

    #[test]
    fn a_scan_that_does_not_fit_names_its_line() {
        let log = log("# header\n\
             FLASER 2 1 2 0 0 0 0 0 0 1 h 1\n\
             FLASER 2 1 2 0 0 0 0 0 0 2 h 2\n");
        let rig = deog_rig::built_in_rig("laser180").unwrap();
        let err = log.check_rig(LaserSource::Front, &rig).unwrap_err();
        assert_eq!(
            err.to_string(),
            "t.log:2: rig laser180 reads 180 ranges per frame, the frame has 2"
        );
    }
}
