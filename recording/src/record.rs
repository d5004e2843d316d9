//! A robot's frames, estimates and map written as a ROS 2 recording in
//! MCAP: schemas in `ros2msg`, messages in CDR, as rosbag2 writes them.
//!
//! Topics: the scans (`/scan`, or `/scan_0`, `/scan_1`, ... for several
//! lasers; `sensor_msgs/LaserScan`), the sonars (`/sonar`,
//! `sensor_msgs/Range`, one message per sonar, its frame `sonar_<i>`),
//! `/odom` (`nav_msgs/Odometry`, `base_link` in `odom`), `/tf_static`
//! (each sensor's mount on `base_link`), `/tf` (`odom` to `base_link`,
//! and `map` to `odom` where a true or reference pose places the robot on
//! the map), `/true_pose` and `/reference_pose`
//! (`geometry_msgs/PoseStamped`, map frame), `/estimate`
//! (`geometry_msgs/PoseWithCovarianceStamped`, the localizer's) and `/map`
//! (`nav_msgs/OccupancyGrid`).

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};

use deog_grid::{Pose2, TileMap, normalize_angle};
use deog_rig::{Rig, SensorKind};

use crate::error::RecordingError;
use crate::frame::{Estimate, Frame, inverse};
use crate::messages::{
    Header, LaserScan, Odometry, PoseStamped, PoseWithCovariance, PoseWithCovarianceStamped, Range,
    RosMessage, TfMessage, Time, Transform, TransformStamped, Twist, TwistWithCovariance, Vector3,
    encode,
};
use crate::occupancy::occupancy_grid;
use crate::schemas::schema_text;

/// The map's coordinate frame.
pub const MAP_FRAME: &str = "map";
/// The odometry's coordinate frame.
pub const ODOM_FRAME: &str = "odom";
/// The robot's own coordinate frame.
pub const BASE_FRAME: &str = "base_link";

/// Odometry.
pub const ODOM_TOPIC: &str = "/odom";
/// Moving transforms.
pub const TF_TOPIC: &str = "/tf";
/// Fixed transforms: the sensors' mounts.
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// Sonar readings.
pub const SONAR_TOPIC: &str = "/sonar";
/// The one laser's scans.
pub const SCAN_TOPIC: &str = "/scan";
/// The simulator's true pose.
pub const TRUE_POSE_TOPIC: &str = "/true_pose";
/// The reference pose.
pub const REFERENCE_POSE_TOPIC: &str = "/reference_pose";
/// The localizer's estimates.
pub const ESTIMATE_TOPIC: &str = "/estimate";
/// The map.
pub const MAP_TOPIC: &str = "/map";

/// The schema encoding of ROS 2 `.msg` definitions.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The message encoding of ROS 2 messages.
pub const MESSAGE_ENCODING: &str = "cdr";

/// rosbag2's QoS for a latched topic (reliable, transient local), so that
/// `ros2 bag play` republishes the mounts and the map to late subscribers.
const LATCHED_QOS: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false";

/// What to record.
#[derive(Debug, Clone, Copy)]
pub struct Recording<'a> {
    /// The rig the frames come from.
    pub rig: &'a Rig,
    /// The frames, in sequence order; at least one.
    pub frames: &'a [Frame],
    /// A localizer's estimates, if any.
    pub estimates: &'a [Estimate],
    /// A map to record once, at the first frame's time.
    pub map: Option<&'a TileMap>,
}

/// Messages written per topic.
pub type TopicCounts = BTreeMap<String, u64>;

/// Where a sensor's readings go.
#[derive(Debug, Clone)]
struct SensorOutput {
    /// Its coordinate frame.
    frame_id: String,
    /// Its topic.
    topic: String,
    /// Its first reading's place in a frame.
    first_reading: usize,
}

/// Writes `recording` as MCAP into `out`; returns the messages per topic.
pub fn write_recording<W: Write + Seek>(
    out: W,
    recording: &Recording<'_>,
) -> Result<TopicCounts, RecordingError> {
    let Some(first) = recording.frames.first() else {
        return Err(RecordingError::Empty(
            "there are no frames to record".into(),
        ));
    };
    let start = Time::from_seconds(first.time_s)?;
    let options = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(Some(mcap::Compression::Zstd));
    let mut mcap = McapOut::new(options.create(out)?);
    let sensors = sensor_outputs(recording.rig);

    let mounts = TfMessage {
        transforms: recording
            .rig
            .sensors()
            .iter()
            .zip(&sensors)
            .map(|(sensor, output)| TransformStamped {
                header: Header::new(start, BASE_FRAME),
                child_frame_id: output.frame_id.clone(),
                transform: Transform::from_planar(sensor.mount),
            })
            .collect(),
    };
    mcap.write(TF_STATIC_TOPIC, true, start, &mounts)?;
    if let Some(map) = recording.map {
        mcap.write(
            MAP_TOPIC,
            true,
            start,
            &occupancy_grid(map, start, MAP_FRAME)?,
        )?;
    }

    let mut estimates: Vec<&Estimate> = recording.estimates.iter().collect();
    estimates.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    let mut estimates = estimates.into_iter().peekable();
    let mut previous: Option<&Frame> = None;
    for frame in recording.frames {
        recording.rig.check_frame(&frame.ranges).map_err(|error| {
            RecordingError::Unrecordable(format!("frame {}: {error}", frame.sequence))
        })?;
        while let Some(estimate) = estimates.next_if(|e| e.time_s < frame.time_s) {
            write_estimate(&mut mcap, estimate)?;
        }
        write_frame(&mut mcap, recording.rig, &sensors, frame, previous)?;
        previous = Some(frame);
    }
    for estimate in estimates {
        write_estimate(&mut mcap, estimate)?;
    }
    mcap.writer.finish()?;
    Ok(mcap.counts)
}

/// Each sensor's frame and topic: lasers `laser` on `/scan` (numbered
/// when there are several), sonars `sonar_<i>` on `/sonar`.
fn sensor_outputs(rig: &Rig) -> Vec<SensorOutput> {
    let lasers = rig
        .sensors()
        .iter()
        .filter(|s| matches!(s.kind, SensorKind::Laser { .. }))
        .count();
    let (mut laser, mut sonar, mut reading) = (0, 0, 0);
    rig.sensors()
        .iter()
        .map(|sensor| {
            let first_reading = reading;
            reading += sensor.readings();
            let (frame_id, topic) = match sensor.kind {
                SensorKind::Laser { .. } if lasers == 1 => ("laser".to_owned(), SCAN_TOPIC.into()),
                SensorKind::Laser { .. } => {
                    laser += 1;
                    (
                        format!("laser_{}", laser - 1),
                        format!("{SCAN_TOPIC}_{}", laser - 1),
                    )
                }
                SensorKind::Sonar { .. } => {
                    sonar += 1;
                    (format!("sonar_{}", sonar - 1), SONAR_TOPIC.into())
                }
            };
            SensorOutput {
                frame_id,
                topic,
                first_reading,
            }
        })
        .collect()
}

fn write_frame<W: Write + Seek>(
    mcap: &mut McapOut<W>,
    rig: &Rig,
    sensors: &[SensorOutput],
    frame: &Frame,
    previous: Option<&Frame>,
) -> Result<(), RecordingError> {
    let stamp = Time::from_seconds(frame.time_s)?;
    let mut transforms = vec![TransformStamped {
        header: Header::new(stamp, ODOM_FRAME),
        child_frame_id: BASE_FRAME.into(),
        transform: Transform::from_planar(frame.odometry),
    }];
    if let Some(on_map) = frame.true_pose.or(frame.reference_pose) {
        // Where the odometry frame lies on the map, so that the robot
        // shows where it truly was.
        transforms.insert(
            0,
            TransformStamped {
                header: Header::new(stamp, MAP_FRAME),
                child_frame_id: ODOM_FRAME.into(),
                transform: Transform::from_planar(on_map.compose(&inverse(frame.odometry))),
            },
        );
    }
    mcap.write(TF_TOPIC, false, stamp, &TfMessage { transforms })?;
    mcap.write(ODOM_TOPIC, false, stamp, &odometry(frame, previous, stamp))?;
    for (sensor, output) in rig.sensors().iter().zip(sensors) {
        let header = Header::new(stamp, &output.frame_id);
        let ranges = &frame.ranges[output.first_reading..output.first_reading + sensor.readings()];
        match sensor.kind {
            SensorKind::Laser {
                first_angle,
                angle_step,
                beam_count,
            } => {
                let scan = LaserScan {
                    header,
                    angle_min: first_angle as f32,
                    angle_max: (first_angle + angle_step * f64::from(beam_count - 1)) as f32,
                    angle_increment: angle_step as f32,
                    time_increment: 0.0,
                    scan_time: 0.0,
                    range_min: sensor.min_range as f32,
                    range_max: sensor.max_range as f32,
                    ranges: ranges.iter().map(|&r| r as f32).collect(),
                    intensities: Vec::new(),
                };
                mcap.write(&output.topic, false, stamp, &scan)?;
            }
            SensorKind::Sonar { half_angle } => {
                let range = Range {
                    header,
                    radiation_type: Range::ULTRASOUND,
                    field_of_view: (2.0 * half_angle) as f32,
                    min_range: sensor.min_range as f32,
                    max_range: sensor.max_range as f32,
                    range: ranges[0] as f32,
                };
                mcap.write(&output.topic, false, stamp, &range)?;
            }
        }
    }
    for (topic, pose) in [
        (TRUE_POSE_TOPIC, frame.true_pose),
        (REFERENCE_POSE_TOPIC, frame.reference_pose),
    ] {
        if let Some(pose) = pose {
            let message = PoseStamped {
                header: Header::new(stamp, MAP_FRAME),
                pose: crate::messages::Pose::from_planar(pose),
            };
            mcap.write(topic, false, stamp, &message)?;
        }
    }
    Ok(())
}

/// The frame's odometry, with the velocity since the frame before in the
/// robot's frame.
fn odometry(frame: &Frame, previous: Option<&Frame>, stamp: Time) -> Odometry {
    let mut twist = Twist::default();
    if let Some(before) = previous {
        let dt = frame.time_s - before.time_s;
        if dt > 0.0 {
            let moved = inverse(before.odometry).compose(&frame.odometry);
            twist.linear = Vector3 {
                x: moved.x / dt,
                y: moved.y / dt,
                z: 0.0,
            };
            twist.angular.z = normalize_angle(frame.odometry.theta - before.odometry.theta) / dt;
        }
    }
    Odometry {
        header: Header::new(stamp, ODOM_FRAME),
        child_frame_id: BASE_FRAME.into(),
        pose: PoseWithCovariance::from_planar(frame.odometry, &[0.0; 9]),
        twist: TwistWithCovariance {
            twist,
            covariance: [0.0; 36],
        },
    }
}

fn write_estimate<W: Write + Seek>(
    mcap: &mut McapOut<W>,
    estimate: &Estimate,
) -> Result<(), RecordingError> {
    let stamp = Time::from_seconds(estimate.time_s)?;
    let message = PoseWithCovarianceStamped {
        header: Header::new(stamp, MAP_FRAME),
        pose: PoseWithCovariance::from_planar(
            Pose2::new(estimate.pose.x, estimate.pose.y, estimate.pose.theta),
            &estimate.covariance,
        ),
    };
    mcap.write(ESTIMATE_TOPIC, false, stamp, &message)
}

/// The MCAP writer with a channel per topic, made on first use.
struct McapOut<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<&'static str, u16>,
    channels: HashMap<String, (u16, u32)>,
    counts: TopicCounts,
}

impl<W: Write + Seek> McapOut<W> {
    fn new(writer: mcap::Writer<W>) -> Self {
        Self {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            counts: TopicCounts::new(),
        }
    }

    fn add_channel<M: RosMessage>(
        &mut self,
        topic: &str,
        latched: bool,
    ) -> Result<u16, RecordingError> {
        let schema = match self.schemas.get(M::TYPE_NAME) {
            Some(&id) => id,
            None => {
                // Every type written here has its definition in the
                // schema table (a unit test checks them all).
                let text = schema_text(M::TYPE_NAME).unwrap_or_default();
                let id = self
                    .writer
                    .add_schema(M::TYPE_NAME, SCHEMA_ENCODING, text.as_bytes())?;
                self.schemas.insert(M::TYPE_NAME, id);
                id
            }
        };
        let mut metadata = BTreeMap::new();
        if latched {
            metadata.insert("offered_qos_profiles".to_owned(), LATCHED_QOS.to_owned());
        }
        Ok(self
            .writer
            .add_channel(schema, topic, MESSAGE_ENCODING, &metadata)?)
    }

    fn write<M: RosMessage>(
        &mut self,
        topic: &str,
        latched: bool,
        stamp: Time,
        message: &M,
    ) -> Result<(), RecordingError> {
        if !self.channels.contains_key(topic) {
            let channel = self.add_channel::<M>(topic, latched)?;
            self.channels.insert(topic.to_owned(), (channel, 0));
        }
        let Some((channel_id, sequence)) = self.channels.get_mut(topic) else {
            return Err(RecordingError::Unrecordable(format!(
                "no channel for {topic}"
            )));
        };
        *sequence += 1;
        // Times were checked non-negative when the stamp was made.
        let time = stamp.nanos().unwrap_or(0);
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: *channel_id,
                sequence: *sequence,
                log_time: time,
                publish_time: time,
            },
            &encode(message),
        )?;
        *self.counts.entry(topic.to_owned()).or_default() += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scouts_sonars_each_get_a_frame_on_one_topic() {
        let rig = deog_rig::scout();
        let outputs = sensor_outputs(&rig);
        assert_eq!(outputs.len(), 16);
        assert_eq!(outputs[3].frame_id, "sonar_3");
        assert!(outputs.iter().all(|o| o.topic == SONAR_TOPIC));
        assert_eq!(outputs[15].first_reading, 15);
    }

    #[test]
    fn no_frames_is_an_error() {
        let rig = deog_rig::scout();
        let recording = Recording {
            rig: &rig,
            frames: &[],
            estimates: &[],
            map: None,
        };
        let err = write_recording(std::io::Cursor::new(Vec::new()), &recording).unwrap_err();
        assert!(err.to_string().contains("no frames"), "{err}");
    }
}
