//! A ROS 2 recording (MCAP, CDR messages) read into a robot's frames:
//! each LaserScan, or each complete round of Range messages, becomes a
//! frame, its odometry interpolated at the scan's stamp, with a rig built
//! from the scans' geometry and the sensors' mounts on `/tf_static`.

use std::collections::BTreeMap;

use deog_grid::Pose2;
use deog_rig::Rig;

use crate::error::RecordingError;
use crate::frame::Frame;
use crate::messages::{
    LaserScan, Odometry, PoseStamped, PoseWithCovarianceStamped, Range, RosMessage, TfMessage,
    Time, decode, names_type,
};
use crate::pose_track::PoseTrack;
use crate::record::{BASE_FRAME, MESSAGE_ENCODING, TF_STATIC_TOPIC};
use crate::scan_rig::{
    LaserLayout, Mount, StaticTransforms, laser_layout, recorded_rig, sonar_sensor,
};

/// Tolerance on a scan's angles against the first scan's, radians.
const ANGLE_TOLERANCE: f64 = 1e-6;

/// What to read and how.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    /// The scans' topic (LaserScan or Range); found when there is one.
    pub scan_topic: Option<String>,
    /// The odometry's topic (Odometry); found when there is one.
    pub odom_topic: Option<String>,
    /// A topic of reference poses (PoseStamped, PoseWithCovarianceStamped
    /// or Odometry), interpolated at each scan's stamp.
    pub reference_topic: Option<String>,
    /// The rig the frames come from, instead of the one the scans and
    /// `/tf_static` describe; its reading count must be the scans'.
    pub rig: Option<Rig>,
    /// The first frame's sequence number.
    pub first_sequence: u64,
}

/// Where the sensors' mounts came from.
#[derive(Debug, Clone, PartialEq)]
pub enum MountSource {
    /// `/tf_static`, from the robot's frame (named here) to each sensor's.
    StaticTransforms(String),
    /// Not found there (no `/tf_static`, or no chain to the robot's frame):
    /// each sensor at the robot's origin, facing forward.
    Identity,
    /// The rig given in the options.
    GivenRig,
}

/// A recording read into frames.
#[derive(Debug, Clone)]
pub struct ImportedRecording {
    /// The rig the frames come from.
    pub rig: Rig,
    /// The frames, in time order, numbered from the first sequence on.
    pub frames: Vec<Frame>,
    /// The scans' topic.
    pub scan_topic: String,
    /// The odometry's topic.
    pub odom_topic: String,
    /// The reference poses' topic, if any.
    pub reference_topic: Option<String>,
    /// Scan messages read (for sonars: Range messages).
    pub scan_messages: usize,
    /// Scans left out because the odometry does not cover their stamp.
    pub outside_odometry: usize,
    /// Rounds of Range messages left out because a sonar was missing.
    pub incomplete: usize,
    /// Where the mounts came from.
    pub mounts: MountSource,
}

/// One channel's messages, as stored.
#[derive(Debug, Default)]
struct Topic {
    schema: String,
    schema_encoding: String,
    message_encoding: String,
    /// (log time in nanoseconds, CDR bytes).
    messages: Vec<(u64, Vec<u8>)>,
}

/// A scan's kind of message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ScanKind {
    Laser,
    Sonar,
}

/// Reads the MCAP bytes `mcap` as a recording of one robot.
pub fn read_recording(
    mcap: &[u8],
    options: &ImportOptions,
) -> Result<ImportedRecording, RecordingError> {
    let topics = read_topics(mcap)?;
    let (scan_topic, kind) = pick_scan_topic(&topics, options.scan_topic.as_deref())?;
    let odom_topic = pick_topic(
        &topics,
        options.odom_topic.as_deref(),
        "odometry",
        "--odom-topic",
        &[Odometry::TYPE_NAME],
    )?;
    let reference_topic = match options.reference_topic.as_deref() {
        Some(name) => Some(pick_topic(
            &topics,
            Some(name),
            "reference pose",
            "--reference-topic",
            &[
                PoseStamped::TYPE_NAME,
                PoseWithCovarianceStamped::TYPE_NAME,
                Odometry::TYPE_NAME,
            ],
        )?),
        None => None,
    };

    let (odometry, base_frame) = odometry_track(&odom_topic, &topics[&odom_topic])?;
    let reference = match &reference_topic {
        Some(name) => Some(pose_track(name, &topics[name])?),
        None => None,
    };
    let mut transforms = StaticTransforms::default();
    if let Some(topic) = topics.get(TF_STATIC_TOPIC)
        && names_type::<TfMessage>(&topic.schema)
    {
        for (index, (_, bytes)) in topic.messages.iter().enumerate() {
            transforms.add(&decode_on::<TfMessage>(
                TF_STATIC_TOPIC,
                topic,
                index,
                bytes,
            )?);
        }
    }
    let scans = match kind {
        ScanKind::Laser => laser_scans(
            &scan_topic,
            &topics[&scan_topic],
            &transforms,
            &base_frame,
            options,
        )?,
        ScanKind::Sonar => sonar_scans(
            &scan_topic,
            &topics[&scan_topic],
            &transforms,
            &base_frame,
            options,
        )?,
    };

    let mut frames = Vec::with_capacity(scans.scans.len());
    let mut outside_odometry = 0;
    for (time, ranges) in scans.scans {
        let Some(odometry) = odometry.at(time) else {
            outside_odometry += 1;
            continue;
        };
        frames.push(Frame {
            sequence: options.first_sequence + frames.len() as u64,
            time_s: time,
            odometry,
            true_pose: None,
            reference_pose: reference.as_ref().and_then(|r| r.at(time)),
            ranges,
        });
    }
    if frames.is_empty() {
        let span = odometry
            .span()
            .map_or("none".to_owned(), |(a, b)| format!("{a:.3} s to {b:.3} s"));
        return Err(RecordingError::Empty(format!(
            "no scan on {scan_topic} falls within the odometry on {odom_topic} ({span}, {} scans outside it)",
            outside_odometry
        )));
    }
    Ok(ImportedRecording {
        rig: scans.rig,
        frames,
        scan_topic,
        odom_topic,
        reference_topic,
        scan_messages: scans.messages,
        outside_odometry,
        incomplete: scans.incomplete,
        mounts: scans.mounts,
    })
}

/// Every channel's messages, for the types read here (others are only
/// named, for the errors that list topics).
fn read_topics(mcap: &[u8]) -> Result<BTreeMap<String, Topic>, RecordingError> {
    if !mcap.starts_with(mcap::MAGIC) {
        return Err(RecordingError::NotMcap);
    }
    let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
    for message in mcap::MessageStream::new(mcap)? {
        let message = message?;
        let channel = &message.channel;
        let topic = topics
            .entry(channel.topic.clone())
            .or_insert_with(|| Topic {
                schema: channel
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                schema_encoding: channel
                    .schema
                    .as_ref()
                    .map(|s| s.encoding.clone())
                    .unwrap_or_default(),
                message_encoding: channel.message_encoding.clone(),
                messages: Vec::new(),
            });
        if is_read_here(&topic.schema) {
            topic
                .messages
                .push((message.log_time, message.data.into_owned()));
        }
    }
    if topics.is_empty() {
        return Err(RecordingError::Empty(
            "the recording holds no message".into(),
        ));
    }
    Ok(topics)
}

fn is_read_here(schema: &str) -> bool {
    names_type::<LaserScan>(schema)
        || names_type::<Range>(schema)
        || names_type::<Odometry>(schema)
        || names_type::<PoseStamped>(schema)
        || names_type::<PoseWithCovarianceStamped>(schema)
        || names_type::<TfMessage>(schema)
}

/// The topics and their schemas, for an error message.
fn inventory(topics: &BTreeMap<String, Topic>) -> String {
    topics
        .iter()
        .map(|(name, t)| format!("{name} ({})", t.schema))
        .collect::<Vec<_>>()
        .join(", ")
}

fn pick_scan_topic(
    topics: &BTreeMap<String, Topic>,
    asked: Option<&str>,
) -> Result<(String, ScanKind), RecordingError> {
    let kind_of = |t: &Topic| {
        if names_type::<LaserScan>(&t.schema) {
            Some(ScanKind::Laser)
        } else if names_type::<Range>(&t.schema) {
            Some(ScanKind::Sonar)
        } else {
            None
        }
    };
    let laser_topics = topics
        .values()
        .filter(|t| names_type::<LaserScan>(&t.schema))
        .count();
    // Asked for by name, either kind; else the one laser, or the one
    // topic of sonars where there is no laser.
    let types: &[&str] = match (asked, laser_topics) {
        (Some(_), _) => &[LaserScan::TYPE_NAME, Range::TYPE_NAME],
        (None, 0) => &[Range::TYPE_NAME],
        (None, _) => &[LaserScan::TYPE_NAME],
    };
    let name = pick_topic(topics, asked, "scan", "--scan-topic", types)?;
    let kind = kind_of(&topics[&name]).ok_or_else(|| {
        RecordingError::Topic(format!("{name} holds neither LaserScan nor Range messages"))
    })?;
    Ok((name, kind))
}

/// The topic asked for, checked to hold one of `types` in CDR; or the
/// one topic that does.
fn pick_topic(
    topics: &BTreeMap<String, Topic>,
    asked: Option<&str>,
    what: &str,
    option: &str,
    types: &[&str],
) -> Result<String, RecordingError> {
    let fits = |t: &Topic| {
        types
            .iter()
            .any(|ty| t.schema == *ty || t.schema == ty.replacen("/msg/", "/", 1))
    };
    let type_list = types.join(" or ");
    let name = match asked {
        Some(name) => {
            let Some(topic) = topics.get(name) else {
                return Err(RecordingError::Topic(format!(
                    "the recording has no topic {name} (it has {})",
                    inventory(topics)
                )));
            };
            if !fits(topic) {
                return Err(RecordingError::Topic(format!(
                    "{name} holds {} messages, not {type_list}",
                    topic.schema
                )));
            }
            name.to_owned()
        }
        None => {
            let candidates: Vec<&String> = topics
                .iter()
                .filter(|(_, t)| fits(t))
                .map(|(name, _)| name)
                .collect();
            match candidates.as_slice() {
                [one] => (*one).clone(),
                [] => {
                    return Err(RecordingError::Topic(format!(
                        "the recording has no {what} topic ({type_list}); it has {}",
                        inventory(topics)
                    )));
                }
                several => {
                    let names: Vec<&str> = several.iter().map(|s| s.as_str()).collect();
                    return Err(RecordingError::Topic(format!(
                        "the recording has several {what} topics ({}): choose one with {option}",
                        names.join(", ")
                    )));
                }
            }
        }
    };
    let topic = &topics[&name];
    if topic.message_encoding != MESSAGE_ENCODING {
        return Err(RecordingError::Topic(format!(
            "{name}'s messages are in {:?}, not {MESSAGE_ENCODING:?} (a ROS 2 recording's)",
            topic.message_encoding
        )));
    }
    if !topic.schema_encoding.is_empty()
        && topic.schema_encoding != "ros2msg"
        && topic.schema_encoding != "ros2idl"
    {
        return Err(RecordingError::Topic(format!(
            "{name}'s schema is in {:?}, not a ROS 2 one",
            topic.schema_encoding
        )));
    }
    Ok(name)
}

fn decode_on<M: RosMessage>(
    name: &str,
    topic: &Topic,
    index: usize,
    bytes: &[u8],
) -> Result<M, RecordingError> {
    decode::<M>(bytes).map_err(|error| RecordingError::Message {
        topic: name.to_owned(),
        schema: topic.schema.clone(),
        index: index + 1,
        reason: error.to_string(),
    })
}

/// A message's time: its header's stamp, or where that was never set, the
/// time it was logged.
fn stamp_seconds(stamp: Time, log_time: u64) -> f64 {
    if stamp.is_zero() {
        log_time as f64 * 1e-9
    } else {
        stamp.seconds()
    }
}

fn bad(name: &str, topic: &Topic, index: usize, reason: &str) -> RecordingError {
    RecordingError::Message {
        topic: name.to_owned(),
        schema: topic.schema.clone(),
        index: index + 1,
        reason: reason.to_owned(),
    }
}

/// The odometry as a track, and the robot's frame it names.
fn odometry_track(name: &str, topic: &Topic) -> Result<(PoseTrack, String), RecordingError> {
    let mut samples = Vec::with_capacity(topic.messages.len());
    let mut base = None;
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let message = decode_on::<Odometry>(name, topic, index, bytes)?;
        let pose = message.pose.pose.planar().ok_or_else(|| {
            bad(
                name,
                topic,
                index,
                "the pose is not finite or its orientation is no rotation",
            )
        })?;
        if base.is_none() && !message.child_frame_id.is_empty() {
            base = Some(message.child_frame_id.trim_start_matches('/').to_owned());
        }
        samples.push((stamp_seconds(message.header.stamp, *log_time), pose));
    }
    Ok((
        PoseTrack::new(samples),
        base.unwrap_or_else(|| BASE_FRAME.to_owned()),
    ))
}

/// Reference poses as a track, from any of the stamped pose types.
fn pose_track(name: &str, topic: &Topic) -> Result<PoseTrack, RecordingError> {
    let mut samples = Vec::with_capacity(topic.messages.len());
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let (stamp, pose) = if names_type::<PoseStamped>(&topic.schema) {
            let m = decode_on::<PoseStamped>(name, topic, index, bytes)?;
            (m.header.stamp, m.pose)
        } else if names_type::<PoseWithCovarianceStamped>(&topic.schema) {
            let m = decode_on::<PoseWithCovarianceStamped>(name, topic, index, bytes)?;
            (m.header.stamp, m.pose.pose)
        } else {
            let m = decode_on::<Odometry>(name, topic, index, bytes)?;
            (m.header.stamp, m.pose.pose)
        };
        let pose: Pose2 = pose.planar().ok_or_else(|| {
            bad(
                name,
                topic,
                index,
                "the pose is not finite or its orientation is no rotation",
            )
        })?;
        samples.push((stamp_seconds(stamp, *log_time), pose));
    }
    Ok(PoseTrack::new(samples))
}

/// Scans with their times, and the rig they make.
struct Scans {
    rig: Rig,
    /// (seconds, ranges in the rig's order), in time order.
    scans: Vec<(f64, Vec<f64>)>,
    messages: usize,
    incomplete: usize,
    mounts: MountSource,
}

/// Where the frame `frame_id` sits on the robot, and what that says of
/// the mounts.
fn find_mount(transforms: &StaticTransforms, base: &str, frame_id: &str) -> (Mount, MountSource) {
    match transforms.mount(base, frame_id) {
        Some(mount) => (mount, MountSource::StaticTransforms(base.to_owned())),
        None => (Mount::IDENTITY, MountSource::Identity),
    }
}

/// A reading as deog stores it: finite and non-negative. NaN, negative
/// and +inf readings (REP 117's "no valid return") become the beam's
/// no-echo value; -inf ("too close") its minimum range.
fn stored_range(value: f32, beam: &deog_rig::Beam) -> f64 {
    let value = f64::from(value);
    let no_echo = if beam.no_echo.at_or_beyond.is_finite() {
        beam.no_echo.at_or_beyond
    } else {
        beam.max_range
    };
    if value == f64::NEG_INFINITY {
        beam.min_range
    } else if value.is_nan() || value < 0.0 || !value.is_finite() {
        no_echo
    } else {
        value
    }
}

fn laser_scans(
    name: &str,
    topic: &Topic,
    transforms: &StaticTransforms,
    base: &str,
    options: &ImportOptions,
) -> Result<Scans, RecordingError> {
    let mut messages = Vec::with_capacity(topic.messages.len());
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let scan = decode_on::<LaserScan>(name, topic, index, bytes)?;
        messages.push((stamp_seconds(scan.header.stamp, *log_time), index, scan));
    }
    let Some((_, _, first)) = messages.first() else {
        return Err(RecordingError::Empty(format!("{name} holds no scan")));
    };
    let (mount, mut mounts) = find_mount(transforms, base, &first.header.frame_id);
    let layout: LaserLayout = laser_layout(first, mount);
    let rig = match &options.rig {
        Some(rig) => {
            mounts = MountSource::GivenRig;
            rig.clone()
        }
        None => recorded_rig("laser", vec![layout.sensor], name)?,
    };
    let (count, angle_min, increment) = (
        first.ranges.len(),
        f64::from(first.angle_min),
        f64::from(first.angle_increment),
    );
    let mut scans = Vec::with_capacity(messages.len());
    for (time, index, scan) in &messages {
        if scan.ranges.len() != count
            || (f64::from(scan.angle_min) - angle_min).abs() > ANGLE_TOLERANCE
            || (f64::from(scan.angle_increment) - increment).abs() > ANGLE_TOLERANCE
        {
            return Err(RecordingError::Geometry(format!(
                "scan {} on {name} has {} beams from {} rad {} rad apart; the first had {count} from {angle_min} rad {increment} rad apart",
                index + 1,
                scan.ranges.len(),
                scan.angle_min,
                scan.angle_increment
            )));
        }
        if scan.ranges.len() != rig.readings() {
            return Err(RecordingError::Geometry(format!(
                "scan {} on {name} has {} ranges; rig {} reads {}",
                index + 1,
                scan.ranges.len(),
                rig.name(),
                rig.readings()
            )));
        }
        let mut values: Vec<f32> = scan.ranges.clone();
        if layout.reversed && options.rig.is_none() {
            values.reverse();
        }
        let ranges: Vec<f64> = values
            .iter()
            .zip(rig.beams())
            .map(|(&v, beam)| stored_range(v, beam))
            .collect();
        check_ranges(&rig, &ranges, name, *index)?;
        scans.push((*time, ranges));
    }
    scans.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(Scans {
        rig,
        scans,
        messages: messages.len(),
        incomplete: 0,
        mounts,
    })
}

fn check_ranges(rig: &Rig, ranges: &[f64], name: &str, index: usize) -> Result<(), RecordingError> {
    rig.check_frame(ranges).map_err(|error| {
        RecordingError::Geometry(format!("scan {} on {name}: {error}", index + 1))
    })?;
    Ok(())
}

fn sonar_scans(
    name: &str,
    topic: &Topic,
    transforms: &StaticTransforms,
    base: &str,
    options: &ImportOptions,
) -> Result<Scans, RecordingError> {
    let mut messages = Vec::with_capacity(topic.messages.len());
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let range = decode_on::<Range>(name, topic, index, bytes)?;
        messages.push((stamp_seconds(range.header.stamp, *log_time), index, range));
    }
    if messages.is_empty() {
        return Err(RecordingError::Empty(format!("{name} holds no reading")));
    }
    messages.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The sonars, in the order they first report.
    let mut sonars: Vec<&Range> = Vec::new();
    for (_, _, range) in &messages {
        if !sonars
            .iter()
            .any(|s| s.header.frame_id == range.header.frame_id)
        {
            sonars.push(range);
        }
    }
    let mut mounts = MountSource::StaticTransforms(base.to_owned());
    let mut sensors = Vec::with_capacity(sonars.len());
    for sonar in &sonars {
        let (mount, source) = find_mount(transforms, base, &sonar.header.frame_id);
        if source == MountSource::Identity {
            mounts = MountSource::Identity;
        }
        sensors.push(sonar_sensor(sonar, mount));
    }
    let rig = match &options.rig {
        Some(rig) => {
            mounts = MountSource::GivenRig;
            rig.clone()
        }
        None => recorded_rig("sonar", sensors, name)?,
    };
    if rig.readings() != sonars.len() {
        return Err(RecordingError::Geometry(format!(
            "{name} has {} sonars; rig {} reads {}",
            sonars.len(),
            rig.name(),
            rig.readings()
        )));
    }
    // A round is one reading of each sonar; a sonar heard twice before
    // the round is whole ends it unfinished.
    let mut scans = Vec::new();
    let mut incomplete = 0;
    let mut round: Vec<Option<f32>> = vec![None; sonars.len()];
    let mut round_time = f64::NEG_INFINITY;
    for (time, index, range) in &messages {
        let Some(slot) = sonars
            .iter()
            .position(|s| s.header.frame_id == range.header.frame_id)
        else {
            continue;
        };
        if round[slot].is_some() {
            incomplete += 1;
            round.iter_mut().for_each(|r| *r = None);
            round_time = f64::NEG_INFINITY;
        }
        round[slot] = Some(range.range);
        round_time = round_time.max(*time);
        if round.iter().all(Option::is_some) {
            let ranges: Vec<f64> = round
                .iter()
                .zip(rig.beams())
                .map(|(v, beam)| stored_range(v.unwrap_or(f32::NAN), beam))
                .collect();
            check_ranges(&rig, &ranges, name, *index)?;
            scans.push((round_time, ranges));
            round.iter_mut().for_each(|r| *r = None);
            round_time = f64::NEG_INFINITY;
        }
    }
    if round.iter().any(Option::is_some) {
        incomplete += 1;
    }
    Ok(Scans {
        rig,
        scans,
        messages: messages.len(),
        incomplete,
        mounts,
    })
}
