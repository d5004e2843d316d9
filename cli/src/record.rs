//! `deog record --robot R --mcap FILE`: a robot's frames, odometry, true
//! and reference poses, its localizer's estimates and optionally a map,
//! written as a ROS 2 recording in MCAP for ROS 2 and Foxglove tools.

use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::TileMap;
use deog_proto::names::check_robot_name;
use deog_proto::rig::frame_rig_name;
use deog_proto::v1 as pb;
use deog_recording::{Estimate, Frame, Recording, write_recording};
use deog_rig::Rig;
use deog_robot_client::convert::{pose_from_wire, pose_or_origin};
use deog_robot_client::{ClientError, MapClient};

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// Options of `deog record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// The robot whose frames and estimates to record.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long, value_name = "FILE")]
    pub mcap: PathBuf,
    /// Also record this map, once, as a nav_msgs/OccupancyGrid on /map.
    #[arg(long)]
    pub map: Option<String>,
    /// First frame sequence to record.
    #[arg(long, default_value_t = 1)]
    pub from: u64,
    /// Last frame sequence to record (0: the last there is).
    #[arg(long, default_value_t = 0)]
    pub to: u64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// What the server holds for the recording.
struct Fetched {
    frames: Vec<pb::SonarFrame>,
    estimates: Vec<pb::PoseEstimate>,
    rig: Rig,
    map: Option<TileMap>,
}

/// Runs the recording.
pub fn run(args: RecordArgs) -> Result<()> {
    check_robot_name(&args.robot).context("--robot")?;
    if args.to != 0 && args.to < args.from {
        bail!("--to {} comes before --from {}", args.to, args.from);
    }
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let fetched = runtime.block_on(fetch(&args))?;
    let frames: Vec<Frame> = fetched
        .frames
        .iter()
        .map(|f| Frame {
            sequence: f.sequence,
            time_s: f.time_s,
            odometry: pose_or_origin(f.odometry),
            true_pose: f.true_pose.map(pose_from_wire),
            reference_pose: f.reference_pose.map(pose_from_wire),
            ranges: f.ranges.clone(),
        })
        .collect();
    let estimates: Vec<Estimate> = fetched
        .estimates
        .iter()
        .map(|e| Estimate {
            frame_sequence: e.frame_sequence,
            time_s: e.time_s,
            pose: pose_or_origin(e.pose),
            covariance: e.covariance.as_slice().try_into().unwrap_or([0.0; 9]),
        })
        .collect();
    let recording = Recording {
        rig: &fetched.rig,
        frames: &frames,
        estimates: &estimates,
        map: fetched.map.as_ref(),
    };
    let counts = write_file(&args.mcap, &recording)?;
    let topics: Vec<String> = counts
        .iter()
        .map(|(topic, count)| format!("{topic} {count}"))
        .collect();
    println!(
        "{}: robot {}, {} frames (sequences {}..={}, rig {}), {} estimates{}; messages per topic: {}",
        args.mcap.display(),
        args.robot,
        frames.len(),
        frames.first().map_or(0, |f| f.sequence),
        frames.last().map_or(0, |f| f.sequence),
        fetched.rig.name(),
        estimates.len(),
        args.map
            .as_ref()
            .map_or(String::new(), |m| format!(", map {m}")),
        topics.join(", ")
    );
    Ok(())
}

/// Writes the recording to `path`; a file left half-written by an error
/// is removed.
fn write_file(path: &Path, recording: &Recording<'_>) -> Result<deog_recording::TopicCounts> {
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let written = write_recording(BufWriter::new(file), recording)
        .with_context(|| format!("writing {}", path.display()));
    if written.is_err() {
        let _ = std::fs::remove_file(path);
    }
    written
}

async fn fetch(args: &RecordArgs) -> Result<Fetched> {
    let client = MapClient::connect(args.timeout.apply(args.connection.client_config()?)?).await?;
    let frames = client
        .read_frames(&args.robot, args.from, args.to)
        .await
        .with_context(|| format!("reading robot {}'s frames", args.robot))?;
    let Some(first) = frames.first() else {
        bail!(
            "the map server holds no frame of robot {:?}{}",
            args.robot,
            if args.from > 1 || args.to > 0 {
                " in the range asked for"
            } else {
                ""
            }
        );
    };
    let rig_name = frame_rig_name(&first.rig).to_owned();
    if let Some(other) = frames
        .iter()
        .find(|f| frame_rig_name(&f.rig) != rig_name.as_str())
    {
        bail!(
            "robot {}'s frames come from more than one rig ({rig_name} at {}, {} at {}): record a run of one rig with --from and --to",
            args.robot,
            first.sequence,
            frame_rig_name(&other.rig),
            other.sequence
        );
    }
    let rig = client
        .rig(&rig_name)
        .await
        .with_context(|| format!("reading rig {rig_name}"))?;
    let (from, to) = (
        first.sequence,
        frames.last().map_or(first.sequence, |f| f.sequence),
    );
    let estimates = client
        .read_poses(&args.robot, from, to)
        .await
        .with_context(|| format!("reading robot {}'s pose estimates", args.robot))?;
    let map = match &args.map {
        Some(name) => {
            if let Err(ClientError::Status(status)) = client.map_info(name).await
                && status.code() == tonic::Code::NotFound
            {
                bail!(
                    "no map named {name:?} on the map server at {}",
                    args.connection.server
                );
            }
            let (_, map) = client
                .download(name)
                .await
                .with_context(|| format!("reading the tiles of map {name:?}"))?;
            Some(map)
        }
        None => None,
    };
    Ok(Fetched {
        frames,
        estimates,
        rig,
        map,
    })
}
