//! Rigs on the wire: [`deog_rig::Rig`] to and from [`v1::Rig`], and the
//! rule for a frame that names no rig.

use deog_grid::Pose2;
use deog_rig::{NoEcho, RangeSensor, Rig, RigError, SensorKind};

use crate::v1;

/// The rig a frame's `rig` field names: empty means the Scout's, the rig
/// every frame had before frames named theirs.
pub fn frame_rig_name(field: &str) -> &str {
    if field.is_empty() {
        deog_rig::DEFAULT_RIG
    } else {
        field
    }
}

/// A rig as the wire carries it.
pub fn rig_to_wire(rig: &Rig) -> v1::Rig {
    v1::Rig {
        name: rig.name().to_owned(),
        body_radius_m: rig.body_radius(),
        sensors: rig
            .sensors()
            .iter()
            .map(|s| v1::RangeSensor {
                mount: Some(v1::Pose2 {
                    x: s.mount.x,
                    y: s.mount.y,
                    theta: s.mount.theta,
                }),
                kind: Some(match s.kind {
                    SensorKind::Sonar { half_angle } => {
                        v1::range_sensor::Kind::Sonar(v1::SonarCone {
                            half_angle_rad: half_angle,
                        })
                    }
                    SensorKind::Laser {
                        first_angle,
                        angle_step,
                        beam_count,
                    } => v1::range_sensor::Kind::Laser(v1::PlanarLaser {
                        first_angle_rad: first_angle,
                        angle_step_rad: angle_step,
                        beam_count,
                    }),
                }),
                min_range_m: s.min_range,
                max_range_m: s.max_range,
                no_echo_m: s.no_echo.at_or_beyond,
                no_echo_zero: s.no_echo.zero,
            })
            .collect(),
    }
}

/// A rig from the wire, every figure checked as a rig file's are.
pub fn rig_from_wire(wire: &v1::Rig) -> Result<Rig, RigError> {
    let mut sensors = Vec::with_capacity(wire.sensors.len());
    for (i, s) in wire.sensors.iter().enumerate() {
        let missing = |field: &str| RigError::Invalid {
            rig: wire.name.clone(),
            field: format!("sensors[{i}].{field}"),
            reason: "is missing".into(),
        };
        let mount = s.mount.as_ref().ok_or_else(|| missing("mount"))?;
        let kind = match s.kind.as_ref().ok_or_else(|| missing("kind"))? {
            v1::range_sensor::Kind::Sonar(c) => SensorKind::Sonar {
                half_angle: c.half_angle_rad,
            },
            v1::range_sensor::Kind::Laser(l) => SensorKind::Laser {
                first_angle: l.first_angle_rad,
                angle_step: l.angle_step_rad,
                beam_count: l.beam_count,
            },
        };
        sensors.push(RangeSensor {
            mount: Pose2::new(mount.x, mount.y, mount.theta),
            kind,
            min_range: s.min_range_m,
            max_range: s.max_range_m,
            no_echo: NoEcho {
                at_or_beyond: s.no_echo_m,
                zero: s.no_echo_zero,
            },
        });
    }
    Rig::new(wire.name.clone(), wire.body_radius_m, sensors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_rig_crosses_the_wire_unchanged() {
        for (name, _) in deog_rig::BUILT_IN_RIGS {
            let rig = deog_rig::load_rig_spec(name).unwrap();
            assert_eq!(rig_from_wire(&rig_to_wire(&rig)).unwrap(), rig);
        }
    }

    #[test]
    fn a_wire_rig_is_checked() {
        let mut wire = rig_to_wire(&deog_rig::scout());
        wire.sensors[3].max_range_m = f64::NAN;
        let err = rig_from_wire(&wire).unwrap_err().to_string();
        assert!(err.contains("sensor[3].max_range_m"), "{err}");
        wire.sensors[3].kind = None;
        let err = rig_from_wire(&wire).unwrap_err().to_string();
        assert!(err.contains("sensors[3].kind"), "{err}");
        assert_eq!(frame_rig_name(""), "scout");
        assert_eq!(frame_rig_name("laser180"), "laser180");
    }
}
