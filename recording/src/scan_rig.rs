//! The rig a ROS 2 recording's sensors make: a laser from a LaserScan's
//! geometry, or sonars from Range messages, each mounted where
//! `/tf_static` puts its frame on the robot's.

use std::collections::HashMap;
use std::f64::consts::PI;

use deog_grid::Pose2;
use deog_rig::{NoEcho, RangeSensor, Rig, SensorKind};

use crate::error::RecordingError;
use crate::messages::{LaserScan, Range, TfMessage, Transform, Vector3};

/// The body radius of a robot known only from its recording, metres.
pub const RECORDED_BODY_RADIUS_M: f64 = 0.25;

/// The longest chain of frames followed from a sensor to the robot's.
const MAX_TF_DEPTH: usize = 64;

/// Fixed transforms: each child frame's parent and where it sits there.
#[derive(Debug, Clone, Default)]
pub struct StaticTransforms {
    parents: HashMap<String, (String, Transform)>,
}

/// Where a sensor sits on the robot, seen from above.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mount {
    /// x, y and the heading of the sensor's x axis, robot frame.
    pub pose: Pose2,
    /// Whether the sensor is upside down (its z axis points down), so its
    /// counter-clockwise angles are the robot's clockwise ones.
    pub upside_down: bool,
}

impl Mount {
    /// The sensor at the robot's origin, facing forward.
    pub const IDENTITY: Mount = Mount {
        pose: Pose2::new(0.0, 0.0, 0.0),
        upside_down: false,
    };
}

impl StaticTransforms {
    /// Adds a `/tf_static` message's transforms (a later one for a child
    /// replaces an earlier one).
    pub fn add(&mut self, message: &TfMessage) {
        for t in &message.transforms {
            self.parents.insert(
                t.child_frame_id.trim_start_matches('/').to_owned(),
                (
                    t.header.frame_id.trim_start_matches('/').to_owned(),
                    t.transform,
                ),
            );
        }
    }

    /// Whether any transform was added.
    pub fn is_empty(&self) -> bool {
        self.parents.is_empty()
    }

    /// Where `frame` sits in `base`, following parents up from `frame`;
    /// `None` if the chain does not reach `base` or a rotation is not one.
    pub fn mount(&self, base: &str, frame: &str) -> Option<Mount> {
        let base = base.trim_start_matches('/');
        let mut current = frame.trim_start_matches('/');
        let mut in_base = Transform::default();
        for _ in 0..MAX_TF_DEPTH {
            if current == base {
                let rotation = in_base.rotation.normalized()?;
                let x_axis = rotation.rotate(Vector3 {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                });
                let z_axis = rotation.rotate(Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: 1.0,
                });
                let pose = Pose2::new(
                    in_base.translation.x,
                    in_base.translation.y,
                    x_axis.y.atan2(x_axis.x),
                );
                let finite = pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite();
                return finite.then_some(Mount {
                    pose,
                    upside_down: z_axis.z < 0.0,
                });
            }
            let (parent, transform) = self.parents.get(current)?;
            in_base = transform.then(&in_base);
            current = parent;
        }
        None
    }
}

/// A laser's geometry in deog's terms: beams counter-clockwise in the
/// robot's frame, and whether a scan's ranges must be reversed to follow
/// them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserLayout {
    /// The laser as a sensor of the rig.
    pub sensor: RangeSensor,
    /// Whether readings come last beam first (a negative increment, or a
    /// laser mounted upside down).
    pub reversed: bool,
}

/// The laser a LaserScan describes, at `mount`.
pub fn laser_layout(scan: &LaserScan, mount: Mount) -> LaserLayout {
    let beams = scan.ranges.len();
    let sign = if mount.upside_down { -1.0 } else { 1.0 };
    let mut first = sign * f64::from(scan.angle_min);
    let mut step = sign * f64::from(scan.angle_increment);
    let reversed = step < 0.0;
    if reversed {
        first += step * (beams.saturating_sub(1)) as f64;
        step = -step;
    }
    // A full turn of beams in float32 may overshoot a turn by rounding.
    let span = step * (beams.saturating_sub(1)) as f64;
    if beams > 1 && span > 2.0 * PI && span < 2.0 * PI + 1e-4 {
        step = 2.0 * PI / (beams - 1) as f64;
    }
    let (min_range, max_range) = (f64::from(scan.range_min), f64::from(scan.range_max));
    LaserLayout {
        sensor: RangeSensor {
            mount: mount.pose,
            kind: SensorKind::Laser {
                first_angle: first,
                angle_step: step,
                beam_count: u32::try_from(beams).unwrap_or(u32::MAX),
            },
            min_range,
            max_range,
            no_echo: NoEcho {
                at_or_beyond: max_range,
                // Drivers that have a minimum range report a failed
                // return as 0.
                zero: min_range > 0.0,
            },
        },
        reversed,
    }
}

/// The sonar a Range message describes, at `mount`.
pub fn sonar_sensor(range: &Range, mount: Mount) -> RangeSensor {
    let max_range = f64::from(range.max_range);
    RangeSensor {
        mount: mount.pose,
        kind: SensorKind::Sonar {
            half_angle: f64::from(range.field_of_view) / 2.0,
        },
        min_range: f64::from(range.min_range),
        max_range,
        no_echo: NoEcho {
            at_or_beyond: max_range,
            zero: false,
        },
    }
}

/// A rig of `sensors`, named by kind, reading count and a hash of the
/// geometry: the same recording always makes the same name, and
/// different geometries different ones.
pub fn recorded_rig(
    kind: &str,
    sensors: Vec<RangeSensor>,
    topic: &str,
) -> Result<Rig, RecordingError> {
    let readings: usize = sensors.iter().map(RangeSensor::readings).sum();
    let name = format!("ros2-{kind}-{readings}-{:08x}", geometry_hash(&sensors));
    Rig::new(name, RECORDED_BODY_RADIUS_M, sensors).map_err(|source| RecordingError::Rig {
        topic: topic.to_owned(),
        source,
    })
}

/// FNV-1a over every figure of the sensors.
fn geometry_hash(sensors: &[RangeSensor]) -> u32 {
    let mut hash: u32 = 0x811c_9dc5;
    let mut feed = |value: f64| {
        for byte in value.to_bits().to_le_bytes() {
            hash ^= u32::from(byte);
            hash = hash.wrapping_mul(0x0100_0193);
        }
    };
    for s in sensors {
        for v in [s.mount.x, s.mount.y, s.mount.theta] {
            feed(v);
        }
        match s.kind {
            SensorKind::Sonar { half_angle } => feed(half_angle),
            SensorKind::Laser {
                first_angle,
                angle_step,
                beam_count,
            } => {
                feed(first_angle);
                feed(angle_step);
                feed(f64::from(beam_count));
            }
        }
        for v in [s.min_range, s.max_range, s.no_echo.at_or_beyond] {
            feed(v);
        }
        feed(if s.no_echo.zero { 1.0 } else { 0.0 });
    }
    hash
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{Header, Quaternion, TransformStamped};
    use approx::assert_abs_diff_eq;

    fn stamped(parent: &str, child: &str, transform: Transform) -> TransformStamped {
        TransformStamped {
            header: Header::new(Default::default(), parent),
            child_frame_id: child.into(),
            transform,
        }
    }

    #[test]
    fn a_mount_follows_the_chain_of_frames_up_to_the_robots() {
        let mut tf = StaticTransforms::default();
        tf.add(&TfMessage {
            transforms: vec![
                stamped(
                    "base_footprint",
                    "base_link",
                    Transform::from_planar(Pose2::new(0.1, 0.0, 0.0)),
                ),
                stamped(
                    "base_link",
                    "laser",
                    Transform::from_planar(Pose2::new(0.2, 0.0, PI / 2.0)),
                ),
            ],
        });
        let mount = tf.mount("base_footprint", "laser").unwrap();
        assert_abs_diff_eq!(mount.pose.x, 0.3, epsilon = 1e-12);
        assert_abs_diff_eq!(mount.pose.theta, PI / 2.0, epsilon = 1e-12);
        assert!(!mount.upside_down);
        assert!(tf.mount("odom", "laser").is_none());
    }

    #[test]
    fn an_upside_down_laser_reads_clockwise() {
        let mut tf = StaticTransforms::default();
        // Rolled half a turn about x.
        let flipped = Transform {
            translation: Vector3::default(),
            rotation: Quaternion {
                x: 1.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            },
        };
        tf.add(&TfMessage {
            transforms: vec![stamped("base_link", "laser", flipped)],
        });
        let mount = tf.mount("base_link", "laser").unwrap();
        assert!(mount.upside_down);
        let scan = LaserScan {
            angle_min: -1.0,
            angle_increment: 0.5,
            ranges: vec![1.0; 5],
            range_min: 0.1,
            range_max: 10.0,
            ..LaserScan::default()
        };
        let layout = laser_layout(&scan, mount);
        assert!(layout.reversed);
        let SensorKind::Laser {
            first_angle,
            angle_step,
            ..
        } = layout.sensor.kind
        else {
            panic!("a laser");
        };
        // Beam 4 (at +1 in the laser) comes first, at -1 on the robot.
        assert_abs_diff_eq!(first_angle, -1.0, epsilon = 1e-6);
        assert_abs_diff_eq!(angle_step, 0.5, epsilon = 1e-6);
    }

    #[test]
    fn one_geometry_one_name_and_a_bad_one_is_refused() {
        let scan = LaserScan {
            angle_min: -1.5,
            angle_increment: 0.01,
            ranges: vec![1.0; 300],
            range_min: 0.1,
            range_max: 10.0,
            ..LaserScan::default()
        };
        let a = recorded_rig(
            "laser",
            vec![laser_layout(&scan, Mount::IDENTITY).sensor],
            "/scan",
        )
        .unwrap();
        let b = recorded_rig(
            "laser",
            vec![laser_layout(&scan, Mount::IDENTITY).sensor],
            "/scan",
        )
        .unwrap();
        assert_eq!(a.name(), b.name());
        assert!(a.name().starts_with("ros2-laser-300-"));
        let moved = Mount {
            pose: Pose2::new(0.1, 0.0, 0.0),
            upside_down: false,
        };
        let c = recorded_rig("laser", vec![laser_layout(&scan, moved).sensor], "/scan").unwrap();
        assert_ne!(a.name(), c.name());
        let bad = LaserScan {
            range_max: -1.0,
            ..scan
        };
        let err = recorded_rig(
            "laser",
            vec![laser_layout(&bad, Mount::IDENTITY).sensor],
            "/scan",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("/scan"), "{err}");
    }
}
