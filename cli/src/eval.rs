//! `deog eval`: evaluation reports. `deog eval map` judges a map on the
//! server against the ground truth of the world it was built in
//! (definitions in `deog_mapping::quality`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use deog_grid::TileMap;
use deog_mapping::quality::DEFAULT_ROBOT_RADIUS_M;
use deog_mapping::{QualityInput, map_quality};
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_simulator::Point2;

use crate::connection::ConnectionArgs;

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
    /// The robots' radius, metres: free space closer to a wall than this is
    /// not counted as reachable.
    #[arg(long, default_value_t = DEFAULT_ROBOT_RADIUS_M)]
    pub robot_radius: f64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// Runs the evaluation asked for.
pub fn run(args: EvalArgs) -> Result<()> {
    match args.target {
        EvalTarget::Map(args) => run_map(args),
    }
}

/// Fetches the map and the robots' start poses, judges the map, prints the
/// table and writes the JSON.
fn run_map(args: EvalMapArgs) -> Result<()> {
    // The world first: a misspelt world name fails before any network call.
    let world = crate::sim::load_world(&args.world)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (map, seeds) = runtime.block_on(async {
        let client = MapClient::connect(args.connection.client_config()?)
            .await
            .with_context(|| {
                format!("connecting to the map server at {}", args.connection.server)
            })?;
        let map = fetch_map(&client, &args.map).await?;
        let seeds = robot_starts(&client).await?;
        anyhow::Ok((map, seeds))
    })?;
    let input = QualityInput {
        map: &map,
        world: &world,
        seeds: &seeds,
        robot_radius_m: args.robot_radius,
    };
    let quality = map_quality(&input)
        .with_context(|| format!("judging map {} against world {}", args.map, args.world))?;
    println!("map {} against world {}", args.map, world.name());
    print!("{}", quality.table());
    if let Some(path) = &args.json {
        std::fs::write(path, quality.to_json())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Every stored tile of `name`, as a tile map with the map's settings.
async fn fetch_map(client: &MapClient, name: &str) -> Result<TileMap> {
    let (_, map) = client
        .download(name)
        .await
        .with_context(|| format!("reading map {name}"))?;
    Ok(map)
}

/// Where each robot whose frames the server holds started: the true pose
/// of its first frame. Robots whose first frame has no true pose (frames
/// imported with odometry only) give none; with no seed at all the whole
/// free space of the world counts as reachable.
async fn robot_starts(client: &MapClient) -> Result<Vec<Point2>> {
    let robots = client
        .raw()
        .list_robots(pb::ListRobotsRequest {})
        .await
        .context("listing the robots whose frames the server holds")?
        .into_inner()
        .robots;
    let mut seeds = Vec::new();
    for robot in robots {
        let first = client
            .read_frames(&robot.robot, robot.first_sequence, robot.first_sequence)
            .await
            .with_context(|| format!("reading the first frame of robot {}", robot.robot))?;
        match first.first().and_then(|f| f.true_pose) {
            Some(p) => seeds.push(Point2::new(p.x, p.y)),
            None => {
                tracing::warn!(robot = %robot.robot, "first frame has no true pose: not a seed")
            }
        }
    }
    Ok(seeds)
}
