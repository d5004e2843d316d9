//! `deog import --robot R FILE`: a wanderer data file's lines become the
//! robot's frames.

use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_to_wire;
use deog_simulator::data_file;

use super::{ImportArgs, connect, publish_all};
use crate::pose_args::PoseSource;
use crate::rig_args::{load_rig, publish_rig};

/// Imports the data file `file` as `robot`'s frames.
pub fn import(args: &ImportArgs, robot: &str, file: &Path) -> Result<()> {
    check_robot_name(robot).context("--robot")?;
    if args.first_sequence == 0 {
        bail!("--first-sequence must be at least 1");
    }
    if !(args.period.is_finite() && args.period > 0.0) {
        bail!("--period must be positive, got {}", args.period);
    }
    let rig = load_rig(args.rig.as_deref().unwrap_or(deog_rig::DEFAULT_RIG))?;
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let lines = data_file::parse(&text, &file.display().to_string(), args.units)?;
    if lines.is_empty() {
        bail!("{} holds no frames", file.display());
    }
    for line in &lines {
        rig.check_frame(&line.ranges)
            .with_context(|| format!("{}:{}", file.display(), line.line))?;
    }
    let frames: Vec<pb::SonarFrame> = lines
        .iter()
        .enumerate()
        .map(|(i, line)| {
            let pose = pose_to_wire(line.pose);
            pb::SonarFrame {
                robot: robot.to_string(),
                sequence: args.first_sequence + i as u64,
                time_s: i as f64 * args.period,
                odometry: Some(pose),
                true_pose: (args.pose == PoseSource::True).then_some(pose),
                ranges: line.ranges.clone(),
                rig: rig.name().to_owned(),
                reference_pose: None,
            }
        })
        .collect();
    let count = frames.len();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (stored, duplicates) = runtime.block_on(async {
        let client = connect(args).await?;
        publish_rig(&client, &rig).await?;
        publish_all(&client, &frames).await
    })?;
    println!(
        "{}: {count} frames read, {stored} stored, {duplicates} already there (robot {}, rig {}, sequences {}..={})",
        file.display(),
        robot,
        rig.name(),
        args.first_sequence,
        args.first_sequence + count as u64 - 1
    );
    Ok(())
}
