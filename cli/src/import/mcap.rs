//! `deog import --mcap FILE --robot R`: a ROS 2 recording's laser scans
//! (or sonar ranges) with its odometry become the robot's frames, with the
//! rig their geometry and `/tf_static` describe.

use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_recording::{ImportOptions, MountSource, read_recording};
use deog_robot_client::convert::pose_to_wire;

use super::{ImportArgs, connect, publish_all};
use crate::rig_args::{load_rig, publish_rig};

/// Imports the ROS 2 recording `file` as `robot`'s frames. The whole
/// recording is read and checked before anything is stored.
pub fn import(args: &ImportArgs, file: &Path) -> Result<()> {
    let Some(robot) = args.robot.as_deref() else {
        bail!("--mcap imports a robot's frames: give --robot");
    };
    check_robot_name(robot).context("--robot")?;
    if args.first_sequence == 0 {
        bail!("--first-sequence must be at least 1");
    }
    let rig = args.rig.as_deref().map(load_rig).transpose()?;
    let bytes = std::fs::read(file).with_context(|| format!("reading {}", file.display()))?;
    let options = ImportOptions {
        scan_topic: args.scan_topic.clone(),
        odom_topic: args.odom_topic.clone(),
        reference_topic: args.reference_topic.clone(),
        rig,
        first_sequence: args.first_sequence,
    };
    let recording =
        read_recording(&bytes, &options).with_context(|| format!("{}", file.display()))?;
    let rig = &recording.rig;
    let frames: Vec<pb::SonarFrame> = recording
        .frames
        .iter()
        .map(|frame| pb::SonarFrame {
            robot: robot.to_owned(),
            sequence: frame.sequence,
            time_s: frame.time_s,
            odometry: Some(pose_to_wire(frame.odometry)),
            true_pose: None,
            ranges: frame.ranges.clone(),
            rig: rig.name().to_owned(),
            reference_pose: frame.reference_pose.map(pose_to_wire),
        })
        .collect();
    let count = frames.len();
    tracing::info!(
        recording = %file.display(),
        scans = recording.scan_messages,
        frames = count,
        rig = rig.name(),
        mounts = ?recording.mounts,
        "read the recording"
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (stored, duplicates) = runtime.block_on(async {
        let client = connect(args).await?;
        publish_rig(&client, rig).await?;
        publish_all(&client, &frames).await
    })?;
    let mounts = match &recording.mounts {
        MountSource::StaticTransforms(base) => format!("mounts from /tf_static on {base}"),
        MountSource::Identity => "no mount on /tf_static: sensors at the robot's origin".into(),
        MountSource::GivenRig => "mounts from --rig".into(),
    };
    let mut left_out = Vec::new();
    if recording.outside_odometry > 0 {
        left_out.push(format!(
            "{} scans outside the odometry left out",
            recording.outside_odometry
        ));
    }
    if recording.incomplete > 0 {
        left_out.push(format!(
            "{} incomplete rounds of sonars left out",
            recording.incomplete
        ));
    }
    let first = args.first_sequence;
    let last = first + count as u64 - 1;
    println!(
        "{}: {} messages on {} and odometry from {} read, {count} frames, {stored} stored, {duplicates} already there (robot {robot}, rig {}, {} readings each, sequences {first}..={last}; {mounts}; reference poses: {}){}",
        file.display(),
        recording.scan_messages,
        recording.scan_topic,
        recording.odom_topic,
        rig.name(),
        rig.readings(),
        recording.reference_topic.as_deref().unwrap_or("none"),
        if left_out.is_empty() {
            String::new()
        } else {
            format!("; {}", left_out.join(", "))
        }
    );
    let pose = if recording.reference_topic.is_some() {
        "reference"
    } else {
        "odometry"
    };
    println!(
        "next: deog map --robot {robot} --map {robot} --pose {pose} --to {last}, then \
         deog localize --robot {robot} --map {robot} --from {first} --to {last}"
    );
    Ok(())
}
