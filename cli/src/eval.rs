//! `deog eval`: evaluation reports. `deog eval map` judges a map on the
//! server against the ground truth of the world it was built in
//! (definitions in `deog_evaluation::map_quality`); `deog eval localize` judges a
//! localizer's pose estimates against the robot's true poses, with the
//! thesis's error table, convergence and kidnap recovery, and plots the
//! paths (definitions in `deog_evaluation::localization`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use deog_evaluation::localization::{
    self as evaluation, DEFAULT_CONVERGE_M, DEFAULT_CONVERGE_RAD, DEFAULT_KIDNAP_JUMP_M, EvalInput,
    EvalParams, LocalizationReport, PlotInput, RobotPath,
};
use deog_evaluation::map_quality::{
    DEFAULT_ROBOT_RADIUS_M, QualityInput, map_quality, verdict_png,
};
use deog_harness::Progress;
use deog_harness::run_reads::{read_map, read_robot, robot_starts};
use deog_robot_client::MapClient;
use deog_world::load_world_spec;

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// Options of `deog eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// What to evaluate.
    #[command(subcommand)]
    pub target: EvalTarget,
}

/// What `deog eval` evaluates.
#[derive(Debug, Subcommand)]
pub enum EvalTarget {
    /// Judges a map on the server against a world's ground truth: cells
    /// classified right, occupied precision and recall within one cell,
    /// coverage of the free space the robots could reach.
    Map(EvalMapArgs),
    /// Judges a localizer's pose estimates against the robots' true poses:
    /// the thesis's mean error and standard deviation of x, y and theta
    /// after convergence, the time to converge, and recovery from kidnaps;
    /// optionally plots the true path (red) against the estimated one
    /// (green).
    Localize(EvalLocalizeArgs),
}

/// Options of `deog eval map`.
#[derive(Debug, Args)]
pub struct EvalMapArgs {
    /// The map to judge.
    #[arg(long, env = "DEOG_MAP")]
    pub map: String,
    /// The world it was built in: a built-in name (map1, map2, office), a
    /// world file (.toml) or a map_server map (.yaml).
    #[arg(long)]
    pub world: String,
    /// Also write the figures to this file as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw where the map is right and wrong, as a PNG: white free and
    /// black occupied where right; yellow free but uncertain, red free but
    /// occupied, blue occupied but free, purple occupied but uncertain;
    /// light grey never observed, dark grey the world's walls there.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// The robots' radius, metres: free space closer to a wall than this is
    /// not counted as reachable. Default: the --rig's body radius, or the
    /// Scout's (0.205 m).
    #[arg(long)]
    pub robot_radius: Option<f64>,
    /// The rig the robots carried (a built-in name or a rig file): its
    /// body radius is the default --robot-radius.
    #[arg(long)]
    pub rig: Option<String>,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// Options of `deog eval localize`.
#[derive(Debug, Args)]
pub struct EvalLocalizeArgs {
    /// The robot whose pose estimates to judge; repeat for several.
    #[arg(long = "robot", required = true)]
    pub robots: Vec<String>,
    /// Only estimates made on this map count, and the plot is drawn over
    /// it; without it, estimates on any map count.
    #[arg(long, env = "DEOG_MAP")]
    pub map: Option<String>,
    /// First frame sequence to judge; default: the first stored.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub from: Option<u64>,
    /// Last frame sequence to judge; default: the last stored.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub to: Option<u64>,
    /// Also write the figures to this file as JSON: {"robots": [...]}.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the true and estimated paths to this PNG file, over the
    /// map when --map is given.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Largest position error, metres, of an estimate that counts as
    /// localized.
    #[arg(long, default_value_t = DEFAULT_CONVERGE_M)]
    pub converge_m: f64,
    /// Largest heading error, radians, of an estimate that counts as
    /// localized.
    #[arg(long, default_value_t = DEFAULT_CONVERGE_RAD)]
    pub converge_rad: f64,
    /// A jump of the true pose between consecutive frames longer than
    /// this, metres, beyond what driving explains, is a kidnap (as is a
    /// turn of more than 45 degrees beyond what turning explains).
    #[arg(long, default_value_t = DEFAULT_KIDNAP_JUMP_M)]
    pub kidnap_jump_m: f64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// Runs the evaluation asked for.
pub fn run(args: EvalArgs) -> Result<()> {
    match args.target {
        EvalTarget::Map(args) => run_map(args),
        EvalTarget::Localize(args) => run_localize(args),
    }
}

/// Fetches the map and the robots' start poses, judges the map, prints the
/// table and writes the JSON.
fn run_map(args: EvalMapArgs) -> Result<()> {
    // The world first: a misspelt world name fails before any network call.
    let world = load_world_spec(&args.world)?;
    let robot_radius = match (args.robot_radius, &args.rig) {
        (Some(radius), _) => radius,
        (None, Some(spec)) => crate::rig_args::load_rig(spec)?.body_radius(),
        (None, None) => DEFAULT_ROBOT_RADIUS_M,
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (map, seeds) = runtime.block_on(async {
        let client =
            MapClient::connect(args.timeout.apply(args.connection.client_config()?)?).await?;
        let map = read_map(&client, &args.map).await?;
        let seeds = robot_starts(&client).await?;
        anyhow::Ok((map, seeds))
    })?;
    let input = QualityInput {
        map: &map,
        world: &world,
        seeds: &seeds,
        robot_radius_m: robot_radius,
    };
    let quality = map_quality(&input)
        .with_context(|| format!("judging map {} against world {}", args.map, args.world))?;
    println!("map {} against world {}", args.map, world.name());
    print!("{}", quality.table());
    if let Some(path) = &args.json {
        std::fs::write(path, quality.to_json())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.png {
        let png = verdict_png(&input).context("drawing where the map is right and wrong")?;
        std::fs::write(path, png).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Reads the robots' frames and estimates (and the map, to plot over),
/// judges each robot, prints the tables and writes the JSON and the plot.
fn run_localize(args: EvalLocalizeArgs) -> Result<()> {
    let params = EvalParams {
        converge_m: args.converge_m,
        converge_rad: args.converge_rad,
        kidnap_jump_m: args.kidnap_jump_m,
        ..EvalParams::default()
    };
    // Bad options fail before any network call.
    params.validate().context("checking the bounds")?;
    if let (Some(from), Some(to)) = (args.from, args.to)
        && from > to
    {
        anyhow::bail!("--from {from} is after --to {to}: no frame to judge");
    }
    let (from, to) = (args.from.unwrap_or(0), args.to.unwrap_or(0));
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (robots, map) = runtime.block_on(async {
        let client =
            MapClient::connect(args.timeout.apply(args.connection.client_config()?)?).await?;
        let mut robots = Vec::with_capacity(args.robots.len());
        let progress = Progress::new("reading robots", "robots", args.robots.len() as u64);
        for name in &args.robots {
            robots.push(read_robot(&client, name, args.map.as_deref(), from, to).await?);
            progress.inc(1);
        }
        progress.finish();
        let map = match (&args.plot, &args.map) {
            (Some(_), Some(name)) => Some(read_map(&client, name).await?),
            _ => None,
        };
        anyhow::Ok((robots, map))
    })?;

    let mut reports: Vec<LocalizationReport> = Vec::with_capacity(robots.len());
    for (i, robot) in robots.iter().enumerate() {
        let input = EvalInput {
            robot: &robot.name,
            map: args.map.as_deref(),
            truth: &robot.truth,
            estimates: &robot.estimates,
            params,
            known_kidnaps: &[],
        };
        let report = evaluation::evaluate(&input)
            .with_context(|| format!("judging the pose estimates of robot {}", robot.name))?;
        if i > 0 {
            println!();
        }
        print!("{}", report.table());
        reports.push(report);
    }
    if let Some(path) = &args.json {
        std::fs::write(path, evaluation::reports_to_json(&reports))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.plot {
        let paths: Vec<RobotPath<'_>> = robots
            .iter()
            .zip(&reports)
            .map(|(robot, report)| RobotPath {
                truth: &robot.truth,
                estimates: &robot.estimates,
                kidnaps: &report.kidnaps,
                convergence: report.convergence,
            })
            .collect();
        let raster = evaluation::render_plot(&PlotInput {
            map: map.as_ref(),
            robots: &paths,
        })
        .context("drawing the plot")?;
        let png = raster.to_png().context("drawing the plot")?;
        std::fs::write(path, png).with_context(|| format!("writing {}", path.display()))?;
        println!(
            "\nplot: {} ({} x {} px, {:.1} px per metre)",
            path.display(),
            raster.width,
            raster.height,
            raster.px_per_m
        );
    }
    Ok(())
}
