//! `deog localize`: Monte Carlo Localization of one robot on a map held by
//! the map server. Follows the robot's frames, fetches the tiles its
//! particles need (keeping them current through the watch stream, within a
//! memory budget), and publishes an estimate per frame.

mod carry;
mod follow;
mod server;
mod settings;

use carry::Carrier;
use follow::{Ends, FollowSettings, follow, next_frame};
use server::{EstimateSink, ServerTiles};
use settings::LocalizeSettings;

use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use clap::{Args, ValueEnum};
use deog_grid::{CellBox, CellIndex, Pose2, Resolution, TileSize};
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::preset::Preset;
use deog_localizer::searcher::{Searcher, SearcherSettings};
use deog_localizer::step::{FetchedTile, Localizer};
use deog_robot_client::convert::{cell_box_from_wire, pose_from_wire};
use deog_robot_client::{MapClient, TileWatch};

use crate::connection::ConnectionArgs;
use crate::frame_queue::FrameQueue;
use crate::pose_args::InitialPose;
use crate::rig_args::publish_rig;
use deog_localizer::sensors::{LikelihoodFieldParams, SensorChoice};
use deog_proto::rig::frame_rig_name;
use deog_proto::v1 as pb;

/// Options of `deog localize`.
#[derive(Debug, Args)]
pub struct LocalizeArgs {
    /// The robot whose frames to follow.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// The map to localize on.
    #[arg(long, env = "DEOG_MAP")]
    pub map: String,
    /// Start from this frame (0: the next frame to arrive).
    #[arg(long, default_value_t = 0)]
    pub from: u64,
    /// Stop after this frame (0: no end).
    #[arg(long, default_value_t = 0)]
    pub to: u64,
    /// Stop once no frame has arrived for this many seconds (0: follow until ctrl-c).
    #[arg(long, default_value_t = 0.0)]
    pub idle_exit: f64,
    /// Track from a known pose instead of localizing globally:
    /// "x,y,theta" (metres, radians), or `reference` or `true` for the
    /// first frame's reference pose (a recording's) or true pose (the
    /// simulator's).
    #[arg(long, value_parser = crate::pose_args::parse_initial_pose, allow_hyphen_values = true)]
    pub initial_pose: Option<InitialPose>,
    /// Standard deviation of the initial position, metres (with --initial-pose).
    #[arg(long, default_value_t = 0.25)]
    pub initial_std_xy: f64,
    /// Standard deviation of the initial heading, radians (with --initial-pose).
    #[arg(long, default_value_t = 0.2)]
    pub initial_std_theta: f64,
    /// Most particles (global localization starts with this many).
    #[arg(long, default_value_t = FilterSettings::default().kld.max_particles)]
    pub max_particles: usize,
    /// Fewest particles. Default: the preset's (500 sim, 2000 real-laser).
    #[arg(long)]
    pub min_particles: Option<usize>,
    /// Recovery: how fast the slow average of the frames' fit follows
    /// them (amcl's recovery_alpha_slow). When the fast average falls
    /// below the slow one, particles are drawn from free space anywhere
    /// near: how a kidnapped robot is found again. 0 with
    /// --recovery-alpha-fast 0 turns recovery off (a robot that is never
    /// carried off, on a map that may have changed).
    #[arg(long, default_value_t = FilterSettings::default().alpha_slow)]
    pub recovery_alpha_slow: f64,
    /// Recovery: how fast the fast average follows the frames' fit
    /// (amcl's recovery_alpha_fast); at least --recovery-alpha-slow.
    #[arg(long, default_value_t = FilterSettings::default().alpha_fast)]
    pub recovery_alpha_fast: f64,
    /// Recovery: particles are drawn from free space only when the fast
    /// average has fallen more than this share below the slow one (0:
    /// at any drop, as amcl does). Smaller drops are noise a tracking
    /// filter sees all the time.
    #[arg(long, default_value_t = FilterSettings::default().recovery_threshold)]
    pub recovery_threshold: f64,
    /// Recovery: a settled filter drawing less than this share from free
    /// space adds those particles to its set without growing it; a larger
    /// share (or a filter not settled) searches, growing the set towards
    /// --max-particles.
    #[arg(long, default_value_t = FilterSettings::default().search_share)]
    pub recovery_search_share: f64,
    /// The beam model's tempering τ: the frame counts as 16·τ independent
    /// beams. Default: 0.05, or 0.08 with --specular-angle (a specular
    /// sonar's frames carry fewer echoes; measured best, BENCHMARKS.md).
    #[arg(long)]
    pub tempering: Option<f64>,
    /// The sonar is specular past this incidence, degrees from a wall's
    /// normal: such walls are expected to send no echo (as `deog sim
    /// --specular lost --specular-angle`), and the beam model takes a
    /// specular sonar's τ and weights (more lost echoes, more readings no
    /// prediction explains). Unset: every wall echoes.
    #[arg(long)]
    pub specular_angle: Option<f64>,
    /// The sonars fire one after another in ring order over this many
    /// seconds, ending with the frame (as `deog sim --sonar realistic`'s,
    /// over its 0.1 s period): each reading is scored where the robot
    /// stood when its sonar fired, at the pace its odometry shows between
    /// frames. 0: all fire with the frame.
    #[arg(long, default_value_t = 0.0)]
    pub firing_period: f64,
    /// How far past the near face of the first occupied cell a sonar's
    /// echo is expected, metres. Default: 0.05 for maps the cartographer
    /// built (their occupied cells stand about a cell in front of the
    /// walls), or 0.1 with --specular-angle (a specular sonar's maps,
    /// built by direction, stand a cell further out); about half a cell
    /// for maps whose walls lie inside their occupied cells, as
    /// laser-built map_server maps.
    #[arg(long)]
    pub surface_depth: Option<f64>,
    /// The probability above which a map's cell is taken for a wall.
    /// Default: 0.65 (ROS map_server's `occupied_thresh`), or 0.75 with
    /// --specular-angle: above 0.7, the walls a sonar cartographer
    /// inferred rather than heard (space walled off from every path, what
    /// was seen only through a wall; sent at 0.7) echo nothing in the
    /// range tables.
    #[arg(long)]
    pub occupied_threshold: Option<f64>,
    /// The rig the robot's frames come from (a built-in name or a rig
    /// file): frames of another rig are refused. Without it, the rig the
    /// first frame names, as the map server keeps it.
    #[arg(long)]
    pub rig: Option<String>,
    /// The sensor model: beam (expected ranges over each sonar's cone;
    /// sonar rigs) or likelihood-field (each echo's endpoint against the
    /// distance to the nearest wall; any rig). Default: beam for a rig of
    /// sonars only, likelihood-field otherwise.
    #[arg(long)]
    pub sensor: Option<SensorChoice>,
    /// Likelihood field: σ of an echo's distance from the nearest wall,
    /// metres.
    #[arg(long, default_value_t = LikelihoodFieldParams::default().sigma_hit)]
    pub field_sigma: f64,
    /// Likelihood field: the most echoes of a frame scored, evenly spread.
    /// Default: the preset's (60 sim, 180 real-laser).
    #[arg(long)]
    pub field_beams: Option<usize>,
    /// Likelihood field: the exponent τ on the product of the scored
    /// echoes' likelihoods. Default: the preset's (1/30 sim, 0.5
    /// real-laser).
    #[arg(long)]
    pub field_tempering: Option<f64>,
    /// Likelihood field: τ while the filter has not settled on a pose
    /// (global localization, recovery). Default: the preset's (sim: the
    /// settled τ; real-laser: 0.05).
    #[arg(long)]
    pub field_search_tempering: Option<f64>,
    /// Likelihood field: report the filter's estimate as it is, without
    /// refining it by matching the frame against the map.
    #[arg(long)]
    pub no_refine: bool,
    /// Laser: never move a tracked pose whose scan stops fitting onto
    /// where the scan fits nearby (the filter then follows the wheels
    /// alone between sensor updates).
    #[arg(long)]
    pub no_realign: bool,
    /// Laser: call an estimate converged even where its scan fits as well
    /// half a metre away (along a corridor whose ends it does not see).
    #[arg(long)]
    pub no_ambiguity_check: bool,
    /// Scales the motion model's four noise figures (α1 to α4): above 1 for
    /// odometry worse than the simulator's. Default: the preset's (1 sim,
    /// 2 real-laser).
    #[arg(long)]
    pub motion_noise_scale: Option<f64>,
    /// The tunings for a kind of data: `sim` (the simulator's robots) or
    /// `real-laser` (a real robot's planar laser, as the CARMEN logs:
    /// every beam scored, a softer τ while searching, odometry noise
    /// doubled, 2000 particles at least). A flag given beside it wins.
    #[arg(long, value_enum, default_value_t = PresetChoice::Sim)]
    pub preset: PresetChoice,
    /// How a global start places its particles, and whether its
    /// convergence is checked (a start at --initial-pose is tracked as
    /// with `uniform`): `search` (the default) waits until the robot's recent
    /// echoes outline where it is, searches the whole map for the poses
    /// that explain them (branch and bound, coarse to fine), and starts
    /// the filter around those few; a lost filter searches again; and the
    /// filter says converged only once a search finds no other pose that
    /// explains its recent frames nearly as well. `uniform` spreads
    /// --max-particles over every free cell and believes the filter's
    /// own spread and weight.
    #[arg(long, value_enum, default_value_t = StartChoice::Search)]
    pub start: StartChoice,
    /// Seed of the filter's random draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Memory the map cache (tiles and range tables) may hold, MiB.
    #[arg(long, default_value_t = 256)]
    pub cache_mb: usize,
    /// Least time between two refreshes of tiles the map server reports
    /// changed, seconds: a map still being built changes all the time.
    /// Up to four times longer when the range-table rebuilds a refresh
    /// causes would take more than a fifth of the time.
    #[arg(long, default_value_t = 5.0)]
    pub refresh_s: f64,
    /// Correct with every frame even when following a live robot and
    /// falling behind. By default a localizer following new frames (no
    /// --from, no --to) that finds more frames waiting takes the newest
    /// within --max-skip-s and moves its particles by the odometry of
    /// those it skips, so that its estimate is of now, not of the past;
    /// while a slow update runs, the frames that come get the last
    /// estimate carried by their odometry.
    #[arg(long)]
    pub every_frame: bool,
    /// Most seconds of frames skipped at once to keep up: a longer jump of
    /// odometry spreads the particles over more of the map, which makes
    /// the next update slower still.
    #[arg(long, default_value_t = 1.0)]
    pub max_skip_s: f64,
    /// Wall-clock time each step may take while following a live robot,
    /// milliseconds: the particles are held to what the machine updates
    /// in half of it and a global search runs in slices of a third, both
    /// measured as the steps run, so a busy machine gets fewer particles
    /// and longer searches rather than a localizer that falls behind.
    /// 0 turns it off. Runs with --from, --to or --every-frame do the
    /// settings' work whatever the machine, so that they repeat.
    #[arg(long, default_value_t = 100.0)]
    pub step_budget_ms: f64,
    /// Particles sent with an estimate for viewers (`deog view`, Foxglove),
    /// drawn by weight; 0 sends none.
    #[arg(long, default_value_t = 200)]
    pub particle_sample: usize,
    /// Least time between two estimates sent with particles, seconds of
    /// the frames' time.
    #[arg(long, default_value_t = 0.25)]
    pub particle_sample_every_s: f64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// `deog localize --start`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StartChoice {
    /// From the global search's hypotheses; convergence confirmed by it.
    Search,
    /// Uniform over every free cell.
    Uniform,
}

/// `deog localize --preset`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PresetChoice {
    /// The simulator's robots.
    Sim,
    /// A real robot's planar laser.
    RealLaser,
}

impl From<PresetChoice> for Preset {
    fn from(choice: PresetChoice) -> Self {
        match choice {
            PresetChoice::Sim => Preset::Simulator,
            PresetChoice::RealLaser => Preset::RealLaser,
        }
    }
}

/// Runs `deog localize`.
pub fn run(args: LocalizeArgs) -> Result<()> {
    let LocalizeSettings {
        filter: mut settings,
        field,
        sonar_cone,
        firing,
        thresholds,
        expected_rig,
    } = args.settings()?;
    // The filter runs on this thread, synchronously; one worker thread
    // drives the connection meanwhile, so the streams keep reading and
    // the server's keepalive pings are answered however long a table
    // build or an update takes (a current-thread runtime would stall the
    // connection until the next wait on I/O, and the server drops a peer
    // silent for 50 s). The filter's allocations stay on this one thread.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("deog-localize-io")
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let _context = runtime.enter();
    // Until the frames are followed nothing listens for the signal all the
    // time (the table build runs on this thread) and nothing needs a flush.
    let until_following = deog_harness::ExitOnSignal::during(
        "connecting, waiting for the first frame or building the map's range tables",
        runtime.handle(),
    );
    let client = runtime.block_on(MapClient::connect(
        args.connection.client_config()?.retrying_forever(),
    ))?;
    let info = runtime
        .block_on(client.map_info(&args.map))
        .with_context(|| format!("opening map {}", args.map))?;
    if let Some(rig) = &expected_rig {
        runtime.block_on(publish_rig(&client, rig))?;
    }
    // The rig is the first frame's: wait for it before building the filter.
    let mut queue = runtime.block_on(FrameQueue::follow(
        &client,
        &args.robot,
        args.from,
        args.idle_exit,
    ))?;
    let progress = queue.replay_progress("localizing frames", args.from, args.to, args.idle_exit);
    let mut shutdown = Box::pin(deog_harness::shutdown_signal());
    let Some(first) = next_frame(&runtime, &mut queue, &mut shutdown)? else {
        println!("{} on {}: no frame arrived", args.robot, args.map);
        return Ok(());
    };
    let rig_name = frame_rig_name(&first.rig).to_owned();
    if let Some(rig) = &expected_rig {
        ensure!(
            rig.name() == rig_name,
            "frame {} comes from rig {rig_name}, not {} (--rig)",
            first.sequence,
            rig.name()
        );
    }
    let rig = runtime
        .block_on(client.rig(&rig_name))
        .with_context(|| format!("reading rig {rig_name} of frame {}", first.sequence))?;
    let choice = args.sensor.unwrap_or(SensorChoice::for_rig(&rig));
    let cone = choice
        .cone_geometry(&rig, sonar_cone)
        .context("--sensor beam")?;
    settings.beam.max_range = cone.max_range;
    let sensor = choice
        .build(&rig, settings.beam, field)
        .with_context(|| format!("the {choice} model for rig {}", rig.name()))?;
    tracing::info!(
        rig = rig.name(),
        readings = rig.readings(),
        sensor = %choice,
        walls_above = format!("{:.3}", thresholds.occupied().probability()),
        "localizing with the frames' rig"
    );
    let mut mcl = Mcl::with_sensor(settings, sensor).context("the filter's settings")?;
    mcl.set_firing(firing);
    let resolution = Resolution::new(info.resolution_m)?;
    let tile_size = TileSize::new(info.tile_size)?;
    let map = LocalMap::new(MapSettings {
        resolution,
        tile_size,
        thresholds,
        geometry: cone,
        budget_bytes: args.cache_mb << 20,
    })?;
    // Watch first, so no change between the first read and the stream is missed.
    // The whole plane: the map may grow anywhere.
    let plane = CellBox {
        min: CellIndex::new(i32::MIN, i32::MIN),
        max: CellIndex::new(i32::MAX, i32::MAX),
    };
    let watch = runtime
        .block_on(client.watch_tiles(&args.map, plane, false))
        .context("watching the map's tiles")?;
    let changes = TileWatch::spawn(watch);
    let mut tiles = ServerTiles {
        runtime: &runtime,
        client: &client,
        map: &args.map,
        tile_size,
    };
    let around = initial_pose(args.initial_pose, &first, &args.robot)?.map(|pose| AroundPose {
        pose,
        std_xy: args.initial_std_xy,
        std_theta: args.initial_std_theta,
    });
    let refresh = Duration::from_secs_f64(args.refresh_s);
    let searcher = match args.start {
        StartChoice::Search => {
            let beams = rig.beams().to_vec();
            let settings = SearcherSettings::for_beams(&beams);
            Some(Searcher::new(beams, settings).context("the global search's settings")?)
        }
        StartChoice::Uniform => None,
    };
    let mut localizer = start(mcl, map, around, searcher, refresh, &info, &tiles)?;
    let keep_up = !args.every_frame && args.from == 0 && args.to == 0;
    if keep_up && args.step_budget_ms > 0.0 {
        localizer =
            localizer.with_step_budget(Duration::from_secs_f64(args.step_budget_ms / 1000.0));
    }
    // The tables the first correction needs are built before it takes its
    // frame: with a global start that is the whole map's.
    let started = Instant::now();
    localizer
        .prepare(&first.ranges, &mut tiles)
        .context("building the map's range tables")?;
    tracing::info!(
        ms = started.elapsed().as_millis() as u64,
        tables = localizer.map().stats().tables_built,
        "range tables ready"
    );
    let settings = FollowSettings {
        keep_up,
        to: args.to,
        max_skip_s: args.max_skip_s,
        particle_sample: args.particle_sample,
        particle_sample_every_s: args.particle_sample_every_s,
    };
    let ends = Ends {
        runtime: &runtime,
        queue,
        tiles,
        changes,
        sink: EstimateSink {
            runtime: &runtime,
            client: &client,
            robot: &args.robot,
            map: &args.map,
        },
        carrier: Carrier {
            client: &client,
            robot: &args.robot,
            map: &args.map,
        },
        progress,
    };
    drop(until_following);
    let followed = follow(&mut localizer, first, ends, settings, &mut shutdown)?;
    let map = localizer.map();
    println!(
        "{} on {}: {} frames, {} sensor updates, {} realigned, {} ambiguous, {} frames skipped to keep up (the filter at most {:.2} s of frames behind while carried), {} range tables built, cache {:.1} MiB",
        args.robot,
        args.map,
        followed.processed,
        followed.corrections,
        followed.realigned,
        followed.ambiguous,
        followed.skipped,
        followed.filter_lag_s,
        map.stats().tables_built,
        map.bytes() as f64 / f64::from(1 << 20)
    );
    if followed.unusable > 0 {
        println!(
            "{} frames skipped whose values cannot be localized (see the warnings)",
            followed.unusable
        );
    }
    Ok(())
}

/// The pose `--initial-pose` names (`choice`), read from the robot's first
/// frame where it names the frame's reference or true pose; `None` for a
/// global start.
fn initial_pose(
    choice: Option<InitialPose>,
    first: &pb::SonarFrame,
    robot: &str,
) -> Result<Option<Pose2>> {
    Ok(match choice {
        None => None,
        Some(InitialPose::Given(pose)) => Some(pose),
        Some(InitialPose::Reference) => Some(first.reference_pose.map(pose_from_wire).with_context(|| {
            format!(
                "--initial-pose reference: frame {} of {robot} has no reference pose (only recordings with corrected poses have one)",
                first.sequence
            )
        })?),
        Some(InitialPose::True) => Some(first.true_pose.map(pose_from_wire).with_context(|| {
            format!(
                "--initial-pose true: frame {} of {robot} has no true pose (only the simulator's frames have one)",
                first.sequence
            )
        })?),
    })
}

/// A start around a known pose: the particles' spread about it.
struct AroundPose {
    pose: Pose2,
    /// Standard deviation of x and y, metres.
    std_xy: f64,
    /// Standard deviation of the heading, radians.
    std_theta: f64,
}

/// The localizer, its particles spread: `around` a pose if given, else
/// over every known-free cell of the whole map as `tiles` serves it now
/// (`info` says where its observed cells lie). Tiles the server reports
/// changed are read again at most every `refresh`.
fn start(
    mut mcl: Mcl,
    map: LocalMap,
    around: Option<AroundPose>,
    searcher: Option<Searcher>,
    refresh: Duration,
    info: &pb::MapInfo,
    tiles: &ServerTiles<'_>,
) -> Result<Localizer> {
    if let Some(AroundPose {
        pose,
        std_xy,
        std_theta,
    }) = around
    {
        mcl.start_at(pose, std_xy, std_theta)
            .context("--initial-pose")?;
        tracing::info!(
            x = pose.x,
            y = pose.y,
            theta = pose.theta,
            "tracking from the given pose"
        );
        // A pose given is tracked, its flag checked by the search as any
        // (more leniently: a prior the search does not overrule), so that
        // a filter that slides off its pose does not stay sure of it.
        let localizer = Localizer::new(mcl, map, refresh, Instant::now());
        return Ok(match searcher {
            Some(searcher) => localizer.with_searcher(searcher),
            None => localizer,
        });
    }
    let Some(region) = info.bounds_cells else {
        bail!(
            "map {} has no observed cell yet: nothing to localize on",
            tiles.map
        );
    };
    let region = cell_box_from_wire("bounds_cells", region)?;
    let whole = tiles
        .runtime
        .block_on(
            tiles
                .client
                .tiles_in_region(tiles.map, tiles.tile_size, region),
        )
        .context("reading the map")?
        .into_iter()
        .map(|(key, version, tile)| FetchedTile { key, version, tile });
    let mut localizer = Localizer::new(mcl, map, refresh, Instant::now());
    let searching = searcher.is_some();
    if let Some(searcher) = searcher {
        localizer = localizer.with_searcher(searcher);
    }
    localizer
        .start_global(whole)
        .context("spreading particles over the map")?;
    if searching {
        tracing::info!(
            tiles = localizer.map().tile_count(),
            free_cells = localizer.map().free_cell_count(),
            "global localization: searching the map once the robot's recent echoes outline where it is"
        );
    } else {
        tracing::info!(
            tiles = localizer.map().tile_count(),
            free_cells = localizer.map().free_cell_count(),
            particles = localizer.mcl().particles().len(),
            "global localization: particles spread over every known-free cell"
        );
    }
    Ok(localizer)
}
