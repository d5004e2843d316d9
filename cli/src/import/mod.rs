//! `deog import`: brings recorded data into the map server. With `--robot`,
//! a wanderer data file (the thesis's `x y theta s1 ... s16` lines) or a
//! CARMEN log (`--carmen`) or a ROS 2 recording (`--mcap`) becomes that
//! robot's frames; with `--map`, a ROS map_server map (YAML + image)
//! becomes that map's cells.

mod carmen;
mod data_file;
mod image;
mod mcap;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{ArgGroup, Args, ValueEnum};
use deog_harness::Progress;
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_simulator::data_file::DataUnits;

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};
use crate::pose_args::PoseSource;

/// Frames sent per request.
const FRAMES_PER_REQUEST: usize = 500;

/// Options of `deog import`: one of `--robot` (a data file or, with
/// `--carmen`, a CARMEN log) and `--map` (a map_server map).
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("target").required(true).args(["robot", "map"])))]
#[command(group(ArgGroup::new("source").required(true).args(["file", "carmen", "mcap"])))]
pub struct ImportArgs {
    /// Import a data file, a CARMEN log or a ROS 2 recording as this
    /// robot's frames.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: Option<String>,
    /// Import a map_server map (FILE is its YAML) into this map, created
    /// with the image's resolution if it does not exist. Excludes --robot,
    /// also when that is set through DEOG_ROBOT.
    #[arg(long)]
    pub map: Option<String>,
    /// The file to import: a data file with --robot, a map_server YAML with
    /// --map.
    pub file: Option<PathBuf>,
    /// Import this CARMEN log (plain or .gz) as the robot's frames: its
    /// laser scans with the robot's raw odometry and, where the log has
    /// one, its reference pose (a corrected log's pose, or TRUEPOS).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["map", "units", "pose", "period"])]
    pub carmen: Option<PathBuf>,
    /// Import this ROS 2 recording (MCAP) as the robot's frames: each
    /// sensor_msgs/LaserScan (or each round of sensor_msgs/Range) with the
    /// nav_msgs/Odometry interpolated at its stamp, the rig built from the
    /// scans' geometry and the mounts on /tf_static.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["map", "units", "pose", "period"])]
    pub mcap: Option<PathBuf>,
    /// With --mcap: the topic of the scans (LaserScan or Range); needed
    /// only when the recording has several.
    #[arg(long, value_name = "TOPIC", requires = "mcap")]
    pub scan_topic: Option<String>,
    /// With --mcap: the topic of the odometry (nav_msgs/Odometry); needed
    /// only when the recording has several.
    #[arg(long, value_name = "TOPIC", requires = "mcap")]
    pub odom_topic: Option<String>,
    /// With --mcap: a topic of reference poses (PoseStamped,
    /// PoseWithCovarianceStamped or Odometry, map frame), stored as each
    /// frame's reference pose.
    #[arg(long, value_name = "TOPIC", requires = "mcap")]
    pub reference_topic: Option<String>,
    /// With --carmen: which laser's scans to import (default: the front
    /// laser, or the only one the log has).
    #[arg(long, value_enum, requires = "carmen")]
    pub laser: Option<LaserChoice>,
    /// The rig the frames come from: a built-in name (scout, pioneer3dx,
    /// laser180) or a rig file. Data files default to scout; a CARMEN log
    /// to the geometry the log itself gives, a ROS 2 recording to its
    /// scans' with the mounts on /tf_static. Every frame's count of ranges
    /// must be the rig's.
    #[arg(long, conflicts_with = "map")]
    pub rig: Option<String>,
    /// Units of the data file: si (metres, radians) or nomad (tenths of an
    /// inch, tenths of a degree, inches).
    #[arg(long, default_value = "si", conflicts_with = "map")]
    pub units: DataUnits,
    /// What the data file's poses are: the true pose (stored as both the
    /// frame's true pose and its odometry) or odometry only.
    #[arg(long, value_enum, default_value_t = PoseSource::True, conflicts_with = "map")]
    pub pose: PoseSource,
    /// Sequence number of the first frame; the rest follow on. Importing
    /// the same file again stores nothing twice.
    #[arg(long, default_value_t = 1, conflicts_with = "map")]
    pub first_sequence: u64,
    /// Seconds between two frames of a data file (it holds no times).
    #[arg(long, default_value_t = 0.1, conflicts_with = "map")]
    pub period: f64,
    /// With --map: import even into a map that already holds observed
    /// cells. The image's evidence is then added to theirs (importing the
    /// same file twice makes its cells surer, up to the clamp limits).
    #[arg(long, conflicts_with = "robot")]
    pub force: bool,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// A CARMEN log's lasers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LaserChoice {
    /// FLASER lines.
    Front,
    /// RLASER lines.
    Rear,
    /// ROBOTLASER1 lines.
    Robot,
}

/// Runs the import.
pub fn run(args: ImportArgs) -> Result<()> {
    if let Some(recording) = &args.mcap {
        return mcap::import(&args, recording);
    }
    match (&args.robot, &args.map, &args.file, &args.carmen) {
        (Some(robot), None, None, Some(log)) => carmen::import(&args, robot, log),
        (Some(robot), None, Some(file), None) => data_file::import(&args, robot, file),
        (None, Some(map), Some(file), None) => image::import(&args, map, file),
        (None, Some(_), None, Some(_)) => bail!("--carmen imports a robot's frames: give --robot"),
        // clap's groups make exactly one target and one source present.
        _ => bail!("give exactly one of --robot and --map, and one file"),
    }
}

/// Stores `frames` on the server in requests of a bounded size, showing
/// the progress; returns (stored, duplicates).
async fn publish_all(client: &MapClient, frames: &[pb::SonarFrame]) -> Result<(u64, u64)> {
    let (mut stored, mut duplicates) = (0u64, 0u64);
    let progress = Progress::new("importing frames", "frames", frames.len() as u64);
    for chunk in frames.chunks(FRAMES_PER_REQUEST) {
        let (s, d) = client
            .publish_frames(chunk.to_vec())
            .await
            .context("storing the frames")?;
        stored += u64::from(s);
        duplicates += u64::from(d);
        progress.inc(chunk.len() as u64);
    }
    progress.finish();
    Ok((stored, duplicates))
}

/// Connects to the map server the options name.
async fn connect(args: &ImportArgs) -> Result<MapClient> {
    Ok(MapClient::connect(args.timeout.apply(args.connection.client_config()?)?).await?)
}
