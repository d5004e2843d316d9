//! Rig files: TOML, one `[[sensor]]` table per sensor (or per ring of
//! like sensors), with an optional `[defaults]` table whose fields every
//! sensor takes unless it sets its own. The format is documented in
//! `rigs/README.md`.

use std::f64::consts::TAU;
use std::path::Path;

use deog_grid::Pose2;
use serde::Deserialize;

use crate::error::RigError;
use crate::rig::{NoEcho, RangeSensor, Rig, SensorKind};

/// Body radius when a file gives none: the Scout's, metres.
pub const DEFAULT_BODY_RADIUS_M: f64 = 0.205;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RigFile {
    name: String,
    body_radius_m: Option<f64>,
    #[serde(default)]
    defaults: SensorEntry,
    #[serde(default)]
    sensor: Vec<SensorEntry>,
}

#[derive(Debug, Default, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorEntry {
    kind: Option<String>,
    x_m: Option<f64>,
    y_m: Option<f64>,
    heading_deg: Option<f64>,
    half_angle_deg: Option<f64>,
    first_angle_deg: Option<f64>,
    angle_step_deg: Option<f64>,
    beam_count: Option<u32>,
    min_range_m: Option<f64>,
    max_range_m: Option<f64>,
    no_echo_m: Option<f64>,
    no_echo_zero: Option<bool>,
    ring_count: Option<u32>,
    ring_radius_m: Option<f64>,
}

impl SensorEntry {
    /// This entry's fields, falling back on `defaults`'.
    fn over(&self, d: &SensorEntry) -> SensorEntry {
        SensorEntry {
            kind: self.kind.clone().or_else(|| d.kind.clone()),
            x_m: self.x_m.or(d.x_m),
            y_m: self.y_m.or(d.y_m),
            heading_deg: self.heading_deg.or(d.heading_deg),
            half_angle_deg: self.half_angle_deg.or(d.half_angle_deg),
            first_angle_deg: self.first_angle_deg.or(d.first_angle_deg),
            angle_step_deg: self.angle_step_deg.or(d.angle_step_deg),
            beam_count: self.beam_count.or(d.beam_count),
            min_range_m: self.min_range_m.or(d.min_range_m),
            max_range_m: self.max_range_m.or(d.max_range_m),
            no_echo_m: self.no_echo_m.or(d.no_echo_m),
            no_echo_zero: self.no_echo_zero.or(d.no_echo_zero),
            ring_count: self.ring_count.or(d.ring_count),
            ring_radius_m: self.ring_radius_m.or(d.ring_radius_m),
        }
    }
}

/// Parses a rig file's text; `origin` names it in errors.
pub fn parse_rig(text: &str, origin: &str) -> Result<Rig, RigError> {
    let file: RigFile = toml::from_str(text).map_err(|e| RigError::Parse {
        origin: origin.to_owned(),
        reason: e.to_string().trim_end().to_owned(),
    })?;
    let mut sensors = Vec::new();
    for (i, own) in file.sensor.iter().enumerate() {
        // Fields of the other kind are errors when the sensor sets them
        // itself; from [defaults] (shared by sonars and lasers) they are
        // ignored.
        let entry = own.over(&file.defaults);
        let field = |f: &str| format!("sensor[{i}].{f}");
        let missing = |f: &str| RigError::invalid(&file.name, field(f), "is missing");
        let kind = match entry.kind.as_deref() {
            Some("sonar") => {
                for (name, set) in [
                    ("first_angle_deg", own.first_angle_deg.is_some()),
                    ("angle_step_deg", own.angle_step_deg.is_some()),
                    ("beam_count", own.beam_count.is_some()),
                ] {
                    if set {
                        return Err(RigError::invalid(
                            &file.name,
                            field(name),
                            "belongs to a laser, and this sensor is a sonar",
                        ));
                    }
                }
                SensorKind::Sonar {
                    half_angle: entry
                        .half_angle_deg
                        .ok_or_else(|| missing("half_angle_deg"))?
                        .to_radians(),
                }
            }
            Some("laser") => {
                if own.half_angle_deg.is_some() {
                    return Err(RigError::invalid(
                        &file.name,
                        field("half_angle_deg"),
                        "belongs to a sonar, and this sensor is a laser",
                    ));
                }
                SensorKind::Laser {
                    first_angle: entry
                        .first_angle_deg
                        .ok_or_else(|| missing("first_angle_deg"))?
                        .to_radians(),
                    angle_step: entry
                        .angle_step_deg
                        .ok_or_else(|| missing("angle_step_deg"))?
                        .to_radians(),
                    beam_count: entry.beam_count.ok_or_else(|| missing("beam_count"))?,
                }
            }
            Some(other) => {
                return Err(RigError::invalid(
                    &file.name,
                    field("kind"),
                    format!("must be \"sonar\" or \"laser\", got {other:?}"),
                ));
            }
            None => return Err(missing("kind")),
        };
        let min_range = entry.min_range_m.ok_or_else(|| missing("min_range_m"))?;
        let max_range = entry.max_range_m.ok_or_else(|| missing("max_range_m"))?;
        let no_echo = NoEcho {
            at_or_beyond: entry.no_echo_m.unwrap_or(max_range),
            zero: entry.no_echo_zero.unwrap_or(false),
        };
        let heading = entry.heading_deg.unwrap_or(0.0).to_radians();
        let (x, y) = (entry.x_m.unwrap_or(0.0), entry.y_m.unwrap_or(0.0));
        let sensor = |mount| RangeSensor {
            mount,
            kind,
            min_range,
            max_range,
            no_echo,
        };
        match (entry.ring_count, entry.ring_radius_m) {
            (None, None) => sensors.push(sensor(Pose2::new(x, y, heading))),
            (Some(count), radius) => {
                if !(1..=1024).contains(&count) {
                    return Err(RigError::invalid(
                        &file.name,
                        field("ring_count"),
                        format!("must be within [1, 1024], got {count}"),
                    ));
                }
                let radius = radius.unwrap_or(0.0);
                // Evenly round a circle centred on (x, y), the first facing
                // `heading`, each facing out (headings as the grid's
                // `SensorRing::uniform` gives them, so the Scout's ring is
                // the same to the last bit).
                for k in 0..count {
                    let angle = heading + TAU * f64::from(k) / f64::from(count);
                    let (sin, cos) = angle.sin_cos();
                    sensors.push(sensor(Pose2::new(
                        x + radius * cos,
                        y + radius * sin,
                        angle,
                    )));
                }
            }
            (None, Some(_)) => {
                return Err(RigError::invalid(
                    &file.name,
                    field("ring_radius_m"),
                    "needs ring_count",
                ));
            }
        }
    }
    Rig::new(
        file.name,
        file.body_radius_m.unwrap_or(DEFAULT_BODY_RADIUS_M),
        sensors,
    )
}

/// Reads and parses a rig file.
pub fn load_rig_file(path: &Path) -> Result<Rig, RigError> {
    let text = std::fs::read_to_string(path).map_err(|e| RigError::Read {
        file: path.display().to_string(),
        reason: e.to_string(),
    })?;
    parse_rig(&text, &path.display().to_string())
}

/// Writes a rig as a rig file, one `[[sensor]]` per sensor, which
/// [`parse_rig`] reads back to the same rig.
pub fn rig_to_toml(rig: &Rig) -> String {
    use std::fmt::Write as _;
    let mut out = format!(
        "name = {:?}\nbody_radius_m = {}\n",
        rig.name(),
        rig.body_radius()
    );
    for s in rig.sensors() {
        out.push_str("\n[[sensor]]\n");
        let kind = match s.kind {
            SensorKind::Sonar { .. } => "sonar",
            SensorKind::Laser { .. } => "laser",
        };
        let _ = writeln!(out, "kind = {kind:?}");
        let _ = writeln!(out, "x_m = {:?}", s.mount.x);
        let _ = writeln!(out, "y_m = {:?}", s.mount.y);
        let _ = writeln!(out, "heading_deg = {:?}", s.mount.theta.to_degrees());
        match s.kind {
            SensorKind::Sonar { half_angle } => {
                let _ = writeln!(out, "half_angle_deg = {:?}", half_angle.to_degrees());
            }
            SensorKind::Laser {
                first_angle,
                angle_step,
                beam_count,
            } => {
                let _ = writeln!(out, "first_angle_deg = {:?}", first_angle.to_degrees());
                let _ = writeln!(out, "angle_step_deg = {:?}", angle_step.to_degrees());
                let _ = writeln!(out, "beam_count = {beam_count}");
            }
        }
        let _ = writeln!(out, "min_range_m = {:?}", s.min_range);
        let _ = writeln!(out, "max_range_m = {:?}", s.max_range);
        if s.no_echo.at_or_beyond.is_finite() {
            let _ = writeln!(out, "no_echo_m = {:?}", s.no_echo.at_or_beyond);
        }
        let _ = writeln!(out, "no_echo_zero = {}", s.no_echo.zero);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn defaults_fill_what_a_sensor_leaves_out() {
        let rig = parse_rig(
            r#"
            name = "two"
            [defaults]
            kind = "sonar"
            half_angle_deg = 12.5
            min_range_m = 0.1
            max_range_m = 4.0
            [[sensor]]
            heading_deg = 90
            x_m = 0.1
            [[sensor]]
            kind = "laser"
            half_angle_deg = 0
            "#,
            "t",
        );
        let err = rig.unwrap_err().to_string();
        assert!(err.contains("sensor[1].half_angle_deg"), "{err}");

        let rig = parse_rig(
            r#"
            name = "two"
            [defaults]
            kind = "sonar"
            half_angle_deg = 12.5
            min_range_m = 0.1
            max_range_m = 4.0
            [[sensor]]
            heading_deg = 90
            x_m = 0.1
            [[sensor]]
            max_range_m = 6.0
            no_echo_m = 5.5
            "#,
            "t",
        )
        .unwrap();
        assert_eq!(rig.readings(), 2);
        assert_abs_diff_eq!(rig.body_radius(), DEFAULT_BODY_RADIUS_M);
        let s = rig.sensors();
        assert_abs_diff_eq!(s[0].mount.theta, std::f64::consts::FRAC_PI_2);
        assert_abs_diff_eq!(s[0].mount.x, 0.1);
        assert_eq!(s[0].max_range, 4.0);
        assert_eq!(s[0].no_echo.at_or_beyond, 4.0);
        assert_eq!(s[1].max_range, 6.0);
        assert_eq!(s[1].no_echo.at_or_beyond, 5.5);
    }

    #[test]
    fn mistakes_are_named() {
        let cases = [
            (
                "name = \"x\"\n[[sensor]]\nkind = \"radar\"",
                "sensor[0].kind",
            ),
            (
                "name = \"x\"\n[[sensor]]\nkind = \"sonar\"",
                "sensor[0].half_angle_deg",
            ),
            ("name = \"x\"\ncolour = 1", "colour"),
            ("name = \"x\"", "no sensor"),
            (
                "name = \"x\"\n[[sensor]]\nkind = \"sonar\"\nhalf_angle_deg = 15\nmin_range_m = 0.1\nmax_range_m = 3\nbeam_count = 4",
                "sensor[0].beam_count",
            ),
            (
                "name = \"x\"\n[[sensor]]\nkind = \"sonar\"\nhalf_angle_deg = 15\nmin_range_m = 0.1\nmax_range_m = 3\nring_count = 0",
                "sensor[0].ring_count",
            ),
            ("name = 3", "t"),
        ];
        for (text, expected) in cases {
            let err = parse_rig(text, "t").unwrap_err().to_string();
            assert!(err.contains(expected), "{text:?}: {err}");
        }
    }

    #[test]
    fn the_readme_example_is_a_valid_rig() {
        let readme = include_str!("../../rigs/README.md");
        let start = readme.find("```toml").expect("a TOML example") + "```toml".len();
        let end = start + readme[start..].find("```").expect("its end");
        let rig = parse_rig(&readme[start..end], "rigs/README.md").unwrap();
        assert_eq!(rig.name(), "mybot");
        assert_eq!(rig.sensors().len(), 1 + 1 + 8);
        assert_eq!(rig.readings(), 1 + 361 + 8);
        assert!(!rig.all_laser() && !rig.all_sonar());
    }

    #[test]
    fn a_written_rig_reads_back_the_same() {
        for (name, _) in crate::BUILT_IN_RIGS {
            let rig = crate::load_rig_spec(name).unwrap();
            let back = parse_rig(&rig_to_toml(&rig), "written").unwrap();
            assert_eq!(back.readings(), rig.readings());
            for (a, b) in back.beams().iter().zip(rig.beams()) {
                assert_abs_diff_eq!(a.mount.x, b.mount.x, epsilon = 1e-12);
                assert_abs_diff_eq!(a.mount.y, b.mount.y, epsilon = 1e-12);
                assert_abs_diff_eq!(a.mount.theta, b.mount.theta, epsilon = 1e-12);
                assert_eq!(a.shape, b.shape);
                assert_eq!(a.max_range, b.max_range);
            }
        }
    }
}
