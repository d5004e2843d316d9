//! A ROS 2 recording (MCAP, CDR messages) read into a robot's frames:
//! each LaserScan, or each complete round of Range messages, becomes a
//! frame, its odometry interpolated at the scan's stamp, with a rig built
//! from the scans' geometry and the sensors' mounts on `/tf_static`.

use deog_grid::Pose2;
use deog_rig::Rig;

use crate::error::RecordingError;
use crate::frame::Frame;
use crate::messages::{
    Odometry, PoseStamped, PoseWithCovarianceStamped, RosMessage, TfMessage, names_type,
};
use crate::pose_track::PoseTrack;
use crate::record::{BASE_FRAME, TF_STATIC_TOPIC};
use crate::scan_rig::StaticTransforms;
use crate::scans::{laser_scans, sonar_scans};
use crate::topics::{
    ScanKind, Topic, bad, decode_on, pick_scan_topic, pick_topic, read_topics, stamp_seconds,
};

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
