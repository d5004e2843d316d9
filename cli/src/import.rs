//! `deog import`: brings recorded data into the map server. With `--robot`,
//! a wanderer data file (the thesis's `x y theta s1 ... s16` lines) becomes
//! that robot's frames.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_simulator::data_file::{self, DataUnits};

use crate::connection::ConnectionArgs;
use crate::wander::PoseSource;

/// Frames sent per request.
const FRAMES_PER_REQUEST: usize = 1000;

/// Options of `deog import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// Import a data file as this robot's frames.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// The file to import.
    pub file: PathBuf,
    /// Units of the data file: si (metres, radians) or nomad (tenths of an
    /// inch, tenths of a degree, inches).
    #[arg(long, default_value = "si")]
    pub units: DataUnits,
    /// What the file's poses are: the true pose (stored as both the frame's
    /// true pose and its odometry) or odometry only.
    #[arg(long, value_enum, default_value_t = PoseSource::True)]
    pub pose: PoseSource,
    /// Sequence number of the first line's frame; the rest follow on.
    /// Importing the same file again stores nothing twice.
    #[arg(long, default_value_t = 1)]
    pub first_sequence: u64,
    /// Seconds between two frames (the file holds no times).
    #[arg(long, default_value_t = 0.1)]
    pub period: f64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// Runs the import.
pub fn run(args: ImportArgs) -> Result<()> {
    deog_simulator::convert::robot_name("--robot", &args.robot)?;
    if args.first_sequence == 0 {
        bail!("--first-sequence must be at least 1");
    }
    if !(args.period.is_finite() && args.period > 0.0) {
        bail!("--period must be positive, got {}", args.period);
    }
    let text = std::fs::read_to_string(&args.file)
        .with_context(|| format!("reading {}", args.file.display()))?;
    let lines = data_file::parse(&text, &args.file.display().to_string(), args.units)?;
    if lines.is_empty() {
        bail!("{} holds no frames", args.file.display());
    }
    let frames: Vec<pb::SonarFrame> = lines
        .iter()
        .enumerate()
        .map(|(i, line)| {
            let pose = pb::Pose2 {
                x: line.pose.x,
                y: line.pose.y,
                theta: line.pose.theta,
            };
            pb::SonarFrame {
                robot: args.robot.clone(),
                sequence: args.first_sequence + i as u64,
                time_s: i as f64 * args.period,
                odometry: Some(pose),
                true_pose: (args.pose == PoseSource::True).then_some(pose),
                ranges: line.ranges.clone(),
            }
        })
        .collect();
    let count = frames.len();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (stored, duplicates) = runtime.block_on(async {
        let map = MapClient::connect(args.connection.client_config()?)
            .await
            .with_context(|| {
                format!("connecting to the map server at {}", args.connection.server)
            })?;
        let (mut stored, mut duplicates) = (0u64, 0u64);
        for chunk in frames.chunks(FRAMES_PER_REQUEST) {
            let (s, d) = map.publish_frames(chunk.to_vec()).await?;
            stored += u64::from(s);
            duplicates += u64::from(d);
        }
        anyhow::Ok((stored, duplicates))
    })?;
    println!(
        "{}: {count} frames read, {stored} stored, {duplicates} already there (robot {}, sequences {}..={})",
        args.file.display(),
        args.robot,
        args.first_sequence,
        args.first_sequence + count as u64 - 1
    );
    Ok(())
}
