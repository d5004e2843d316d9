//! `deog refit`: a map on the server refitted to every sonar frame that
//! built it, through the specular sonar's forward model
//! (`deog_mapping::fit_forward`), and written as map_server files (PGM +
//! YAML) and a PNG, as `deog export` writes a map. The map on the server
//! is the first guess and stays as it is; `deog import --map` loads the
//! refitted files as a map of their own.
//!
//! A batch step for after a run: the cartographer's inverse model maps
//! each frame as it comes, while the fit weighs all of them at once, so
//! that the walls a specular sonar only grazed stay and the arcs it
//! marked where no wall was go.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use deog_grid::{ClampLimits, FrameMotion, Pose2, RingFiring, TileMap};
use deog_harness::Progress;
use deog_mapfile::{to_png_with_scale_bar, write_map};
use deog_mapping::{
    ForwardSettings, ForwardStats, SonarReading, export_map, fit_forward, ring_readings,
};
use deog_proto::v1 as pb;
use deog_rig::{Reading, Rig, SensorKind};
use deog_robot_client::convert::pose_from_wire;

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// Which of a frame's poses places its readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RefitPose {
    /// The best a frame has: its true pose, else its reference pose, else
    /// its odometry.
    Best,
    /// The simulator's true pose; a frame without one is an error.
    True,
    /// A recording's corrected pose; a frame without one is an error.
    Reference,
    /// The odometry.
    Odometry,
}

/// Options of `deog refit`.
#[derive(Debug, Args)]
pub struct RefitArgs {
    /// The map to refit: the first guess, left as it is.
    #[arg(long, env = "DEOG_MAP")]
    pub map: String,
    /// The robots whose frames built the map, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub robots: Vec<String>,
    /// Folder to write into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// File name stem: writes STEM.pgm, STEM.yaml and STEM.png. Defaults to
    /// the map's name and `-refit`.
    #[arg(long)]
    pub name: Option<String>,
    /// Which pose places each frame's readings.
    #[arg(long, value_enum, default_value_t = RefitPose::Best)]
    pub pose: RefitPose,
    /// Past this angle between a sonar's ray and a wall's normal, degrees,
    /// the wall sends no echo back (30 for `deog sim --sonar realistic`;
    /// 90: every wall echoes).
    #[arg(long, default_value_t = 30.0)]
    pub critical_incidence_deg: f64,
    /// The sonars fire one after another in ring order over this many
    /// seconds, ending with the frame, as `deog map --firing-period`
    /// (0.1 for `deog sim --sonar realistic`; 0: all with the frame).
    #[arg(long, default_value_t = 0.0)]
    pub firing_period: f64,
    /// Rounds of the fit.
    #[arg(long, default_value_t = ForwardSettings::default().iterations)]
    pub iterations: usize,
    /// How far from a sonar cells are judged, metres.
    #[arg(long, default_value_t = ForwardSettings::default().reach)]
    pub reach: f64,
    /// Keep the map's belief in cells no ray reached (inside obstacles,
    /// behind walls), rather than leaving them unknown.
    #[arg(long)]
    pub keep_unreached: bool,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// Runs the refit.
pub fn run(args: RefitArgs) -> Result<()> {
    let firing = RingFiring::over(args.firing_period).context("--firing-period")?;
    if !(0.0..=90.0).contains(&args.critical_incidence_deg) {
        bail!(
            "--critical-incidence-deg takes 0 to 90 degrees, got {}",
            args.critical_incidence_deg
        );
    }
    if !(1..=50).contains(&args.iterations) {
        bail!("--iterations takes 1 to 50 rounds, got {}", args.iterations);
    }
    if !(args.reach > 0.0 && args.reach <= 20.0) {
        bail!("--reach takes (0, 20] metres, got {}", args.reach);
    }
    let stem = args
        .name
        .clone()
        .unwrap_or_else(|| format!("{}-refit", args.map));
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (first_guess, frames, rig) = runtime.block_on(fetch(&args))?;
    if first_guess.observed_count() == 0 {
        bail!(
            "map {:?} is empty: no cell has been observed yet, so there is no first guess to refit",
            args.map
        );
    }
    let readings = readings_of(&frames, &rig, args.pose, firing)?;
    let settings = ForwardSettings {
        iterations: args.iterations,
        reach: args.reach,
        keep_unreached: args.keep_unreached,
        ..sonar_model(&rig, args.critical_incidence_deg.to_radians())?
    };
    let started = std::time::Instant::now();
    let (map, stats) = fit_forward(&first_guess, &readings, &settings, ClampLimits::default())
        .context("fitting the map to the frames")?;
    let seconds = started.elapsed().as_secs_f64();
    write(&args, &stem, &map, &stats, seconds)
}

/// The map's tiles, every frame of the robots, and their rig.
async fn fetch(args: &RefitArgs) -> Result<(TileMap, Vec<pb::SonarFrame>, Rig)> {
    let client = crate::export::open_map(&args.connection, &args.timeout, &args.map).await?;
    let (_, map) = client
        .download(&args.map)
        .await
        .with_context(|| format!("reading the tiles of map {:?}", args.map))?;
    let progress = Progress::new("reading frames", "robots", args.robots.len() as u64);
    let mut frames = Vec::new();
    for robot in &args.robots {
        let read = client
            .read_frames(robot, 0, 0)
            .await
            .with_context(|| format!("reading the frames of robot {robot:?}"))?;
        if read.is_empty() {
            bail!("the map server holds no frame of robot {robot:?}");
        }
        frames.extend(read);
        progress.inc(1);
    }
    progress.finish();
    // Each robot's rig, asked once per name.
    let mut rigs: Vec<(String, Rig)> = Vec::new();
    for frame in &frames {
        if !rigs.iter().any(|(name, _)| *name == frame.rig) {
            let rig = client.rig(&frame.rig).await.with_context(|| {
                format!("reading rig {:?} of robot {:?}", frame.rig, frame.robot)
            })?;
            rigs.push((frame.rig.clone(), rig));
        }
    }
    if rigs.len() > 1 {
        bail!(
            "the robots' frames come from {} rigs ({}); a refit fits one sonar ring",
            rigs.len(),
            rigs.iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let (_, rig) = rigs.pop().context("frames without a rig")?;
    Ok((map, frames, rig))
}

/// Every frame's readings where its sonars fired, each robot's frames in
/// order, placed by `pose`.
fn readings_of(
    frames: &[pb::SonarFrame],
    rig: &Rig,
    pose: RefitPose,
    firing: RingFiring,
) -> Result<Vec<SonarReading>> {
    if !rig.all_sonar() {
        bail!(
            "rig {:?} is not all sonar: a refit fits a sonar ring's cones",
            rig.name()
        );
    }
    let ring = rig.ring();
    let mut readings = Vec::with_capacity(frames.len() * rig.readings());
    let mut motions: Vec<(String, FrameMotion)> = Vec::new();
    for frame in frames {
        let placed = frame_pose(frame, pose)?;
        let odometry = pose_from_wire(frame.odometry.unwrap_or_default());
        let motion = match motions.iter_mut().position(|(r, _)| *r == frame.robot) {
            Some(i) => &mut motions[i].1,
            None => {
                motions.push((frame.robot.clone(), FrameMotion::default()));
                &mut motions.last_mut().expect("just pushed").1
            }
        };
        let pace = motion.observe(&odometry, frame.time_s);
        if frame.ranges.len() != rig.readings() {
            bail!(
                "frame {} of robot {:?} has {} readings; rig {:?} has {}",
                frame.sequence,
                frame.robot,
                frame.ranges.len(),
                rig.name(),
                rig.readings()
            );
        }
        let ranges = frame
            .ranges
            .iter()
            .zip(rig.beams())
            .map(|(&range, beam)| match beam.classify(range) {
                Some(Reading::Echo(r)) => Ok(Some(r)),
                Some(Reading::NoEcho) => Ok(None),
                None => Err(anyhow::anyhow!(
                    "frame {} of robot {:?} has a reading that is not a range: {range}",
                    frame.sequence,
                    frame.robot
                )),
            })
            .collect::<Result<Vec<_>>>()?;
        ring_readings(&ring, firing, &placed, pace.as_ref(), ranges, &mut readings);
    }
    Ok(readings)
}

/// The pose `choice` names in `frame`.
fn frame_pose(frame: &pb::SonarFrame, choice: RefitPose) -> Result<Pose2> {
    let missing = |what: &str| {
        anyhow::anyhow!(
            "frame {} of robot {:?} has no {what} (--pose)",
            frame.sequence,
            frame.robot
        )
    };
    let wire = match choice {
        RefitPose::Best => frame
            .true_pose
            .or(frame.reference_pose)
            .or(frame.odometry)
            .ok_or_else(|| missing("pose"))?,
        RefitPose::True => frame.true_pose.ok_or_else(|| missing("true pose"))?,
        RefitPose::Reference => frame
            .reference_pose
            .ok_or_else(|| missing("reference pose"))?,
        RefitPose::Odometry => frame.odometry.ok_or_else(|| missing("odometry"))?,
    };
    Ok(pose_from_wire(wire))
}

/// The forward model of `rig`'s sonars, silent past `critical_incidence`
/// radians.
fn sonar_model(rig: &Rig, critical_incidence: f64) -> Result<ForwardSettings> {
    let half_angle = rig
        .sensors()
        .iter()
        .map(|s| match s.kind {
            SensorKind::Sonar { half_angle } => half_angle,
            SensorKind::Laser { .. } => 0.0,
        })
        .fold(0.0, f64::max);
    Ok(ForwardSettings::for_sonar(
        half_angle,
        rig.max_range(),
        Some(critical_incidence),
    ))
}

/// The refitted map's files, and a line saying what they hold.
fn write(
    args: &RefitArgs,
    stem: &str,
    map: &TileMap,
    stats: &ForwardStats,
    seconds: f64,
) -> Result<()> {
    if map.observed_count() == 0 {
        bail!("the fit decided no cell: the frames do not reach the map's cells");
    }
    let export = export_map(map).context("exporting the refitted map")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let yaml = write_map(&args.out, stem, &export.image)?;
    to_png_with_scale_bar(args.out.join(format!("{stem}.png")), &export.image)?;
    let counts = &export.counts;
    println!(
        "map {} refitted to {} readings in {seconds:.1} s ({} cells reached): {} cells occupied, {} free, {} unknown; wrote {} with its .pgm and .png",
        args.map,
        stats.readings,
        stats.cells_reached,
        counts.occupied,
        counts.free,
        counts.unknown(),
        yaml.display()
    );
    Ok(())
}
