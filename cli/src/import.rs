//! `deog import`: brings recorded data into the map server. With `--robot`,
//! a wanderer data file (the thesis's `x y theta s1 ... s16` lines) becomes
//! that robot's frames; with `--map`, a ROS map_server map (YAML + image)
//! becomes that map's cells.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{ArgGroup, Args};
use deog_grid::{ClampLimits, Resolution, TileSize};
use deog_mapfile::MapImage;
use deog_mapping::{ImportTarget, image_origin_cell, import_map};
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_to_wire;
use deog_robot_client::{MapClient, UpdateSenderConfig};
use deog_simulator::data_file::{self, DataUnits};

use crate::connection::ConnectionArgs;
use crate::pose_args::PoseSource;

/// Frames sent per request.
const FRAMES_PER_REQUEST: usize = 1000;

/// Options of `deog import`: one of `--robot` (a data file) and `--map` (a
/// map_server map).
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("target").required(true).args(["robot", "map"])))]
pub struct ImportArgs {
    /// Import a data file as this robot's frames.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: Option<String>,
    /// Import a map_server map (FILE is its YAML) into this map, created
    /// with the image's resolution if it does not exist. Excludes --robot,
    /// also when that is set through DEOG_ROBOT.
    #[arg(long)]
    pub map: Option<String>,
    /// The file to import: a data file with --robot, a map_server YAML with
    /// --map.
    pub file: PathBuf,
    /// Units of the data file: si (metres, radians) or nomad (tenths of an
    /// inch, tenths of a degree, inches).
    #[arg(long, default_value = "si", conflicts_with = "map")]
    pub units: DataUnits,
    /// What the file's poses are: the true pose (stored as both the frame's
    /// true pose and its odometry) or odometry only.
    #[arg(long, value_enum, default_value_t = PoseSource::True, conflicts_with = "map")]
    pub pose: PoseSource,
    /// Sequence number of the first line's frame; the rest follow on.
    /// Importing the same file again stores nothing twice.
    #[arg(long, default_value_t = 1, conflicts_with = "map")]
    pub first_sequence: u64,
    /// Seconds between two frames (the file holds no times).
    #[arg(long, default_value_t = 0.1, conflicts_with = "map")]
    pub period: f64,
    /// With --map: import even into a map that already holds observed
    /// cells. The image's evidence is then added to theirs (importing the
    /// same file twice makes its cells surer, up to the clamp limits).
    #[arg(long, conflicts_with = "robot")]
    pub force: bool,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// Runs the import.
pub fn run(args: ImportArgs) -> Result<()> {
    match (&args.robot, &args.map) {
        (Some(robot), None) => import_frames(&args, robot),
        (None, Some(map)) => import_image(&args, map),
        // clap's "target" group makes exactly one of them present.
        _ => bail!("give exactly one of --robot and --map"),
    }
}

/// `--robot`: a data file's lines become the robot's frames.
fn import_frames(args: &ImportArgs, robot: &str) -> Result<()> {
    check_robot_name(robot).context("--robot")?;
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
            let pose = pose_to_wire(line.pose);
            pb::SonarFrame {
                robot: robot.to_string(),
                sequence: args.first_sequence + i as u64,
                time_s: i as f64 * args.period,
                odometry: Some(pose),
                true_pose: (args.pose == PoseSource::True).then_some(pose),
                ranges: line.ranges.clone(),
                rig: String::new(),
                reference_pose: None,
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
        robot,
        args.first_sequence,
        args.first_sequence + count as u64 - 1
    );
    Ok(())
}

/// `--map`: a map_server map's known pixels become the map's cells.
fn import_image(args: &ImportArgs, name: &str) -> Result<()> {
    let file = args.file.display().to_string();
    let image = MapImage::load(&args.file)?;
    // Everything about the image alone is checked before the map is
    // created, so a bad file leaves the server as it was.
    let resolution = Resolution::new(image.resolution)
        .with_context(|| format!("{file}: resolution {} m", image.resolution))?;
    image_origin_cell(&image, resolution).with_context(|| format!("{file} cannot be imported"))?;
    let client_id = client_id(&args.file);

    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (import, acks) = runtime.block_on(async {
        let client = MapClient::connect(args.connection.client_config()?)
            .await
            .with_context(|| {
                format!("connecting to the map server at {}", args.connection.server)
            })?;
        let info = client
            .ensure_map(pb::CreateMapRequest {
                name: name.to_string(),
                resolution_m: image.resolution,
                // The server's defaults: tile size 64, clamp limits 0.12 and 0.97.
                ..pb::CreateMapRequest::default()
            })
            .await
            .with_context(|| format!("creating map {name:?}"))?;
        if (info.resolution_m - image.resolution).abs()
            > deog_mapping::map_import::RESOLUTION_TOLERANCE * info.resolution_m
        {
            bail!(
                "map {name:?} exists with cells of {} m, but {file} has pixels of {} m: import it into a new map",
                info.resolution_m,
                image.resolution
            );
        }
        if info.tile_count > 0 && !args.force {
            bail!(
                "map {name:?} already holds {} observed cells; importing {file} would add its evidence to theirs. \
                 Import into a new map, clear this one first, or pass --force to add anyway",
                info.cell_count
            );
        }
        let target = ImportTarget {
            resolution: Resolution::new(info.resolution_m).context("the map's resolution_m")?,
            tile_size: TileSize::new(info.tile_size).context("the map's tile_size")?,
            limits: ClampLimits::from_probabilities(
                info.clamp_min_probability,
                info.clamp_max_probability,
            )
            .context("the map's clamp limits")?,
        };
        let import = import_map(&image, &target)
            .with_context(|| format!("{file} cannot be imported into map {name:?}"))?;
        let mut sender = client
            .updates(name, &client_id, UpdateSenderConfig::default())
            .await
            .with_context(|| format!("opening an update stream to map {name:?}"))?;
        for delta in &import.deltas {
            sender.push(delta.clone()).await?;
        }
        let acks = sender
            .close()
            .await
            .with_context(|| format!("writing the cells of {file} to map {name:?}"))?;
        anyhow::Ok((import, acks))
    })?;
    println!(
        "{file}: {} x {} pixels, {} occupied and {} free cells written to map {name} in {} tiles ({} unknown pixels left unobserved); map version {}",
        image.width,
        image.height,
        import.occupied,
        import.free,
        import.deltas.len(),
        import.unknown,
        acks.map_version
    );
    Ok(())
}

/// The update client id of an import: `import/<file stem>`, with every
/// character the server does not take in a client id replaced by `_` and
/// the whole kept to its 128 characters. The same file imported again
/// continues the same client's sequence.
fn client_id(file: &Path) -> String {
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut id: String = "import/"
        .chars()
        .chain(stem.chars().map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') {
                c
            } else {
                '_'
            }
        }))
        .take(128)
        .collect();
    if id.len() == "import/".len() {
        id.push_str("map");
    }
    id
}
