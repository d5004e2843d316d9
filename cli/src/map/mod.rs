//! `deog map`: the cartographer process. Follows one robot's frames from the
//! map server, turns each into tile deltas and streams them back as update
//! batches, each numbered by the last frame it holds, so that a restart
//! resumes after the last frame the server applied and none is applied twice.

mod by_rig;
mod estimates;
mod follow;
mod settings;

use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use deog_grid::{RayModelParams, Resolution, TileSize};
use deog_mapping::{MapViewSettings, PoseChoice, SonarMethod, mapping_sonar_model};
use deog_proto::v1 as pb;
use deog_robot_client::{MapClient, UpdateSenderConfig};

use crate::connection::ConnectionArgs;
use crate::frame_queue::FrameQueue;
use crate::pose_args::MapPoseSource;
use crate::rig_args::publish_rig;
use by_rig::{CartographerByRig, ModelSettings};
use estimates::EstimateFollower;
use follow::{Mapping, MappingEnds};
use settings::MapSettings;

/// Options of `deog map`.
#[derive(Debug, Args)]
pub struct MapArgs {
    /// The robot whose frames to map.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// The map to build; created with --resolution and --tile-size if it
    /// does not exist.
    #[arg(long, env = "DEOG_MAP")]
    pub map: String,
    /// The pose to map from.
    #[arg(long, value_enum, default_value_t = MapPoseSource::True)]
    pub pose: MapPoseSource,
    /// With --pose estimate: the map whose estimates place the frames
    /// (default: the map being built, which the localizer then keeps
    /// current).
    #[arg(long)]
    pub estimate_map: Option<String>,
    /// With --pose estimate: how long a frame waits for the localizer to
    /// publish its estimate before it is skipped, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub estimate_wait: f64,
    /// Start from this frame (frames the server already applied for this
    /// robot and map are skipped whatever this says).
    #[arg(long, default_value_t = 1)]
    pub from: u64,
    /// Stop after this frame (0: no end).
    #[arg(long, default_value_t = 0)]
    pub to: u64,
    /// Stop once no frame has arrived for this many seconds (0: follow
    /// until ctrl-c).
    #[arg(long, default_value_t = 0.0)]
    pub idle_exit: f64,
    /// Cell size of a new map, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Cells per tile side of a new map.
    #[arg(long, default_value_t = 64)]
    pub tile_size: u32,
    /// Frames per update batch at most (fewer when frames arrive slowly).
    #[arg(long, default_value_t = 20)]
    pub batch_frames: usize,
    /// Update batches in flight before the cartographer waits for the
    /// server (backpressure).
    #[arg(long, default_value_t = 8)]
    pub window: usize,
    /// Write each batch's acknowledgement (batch sequence, map version,
    /// applied) to this file, one line each. Each batch then waits for its
    /// acknowledgement before the next is sent, so the log is complete and
    /// in order: for auditing and for replaying the map in the server's
    /// commit order.
    #[arg(long)]
    pub ack_log: Option<std::path::PathBuf>,
    /// The sonar model's strongest occupied belief from one reading
    /// (thesis eq. 3.1's Max_occupied). The thesis's 0.98 lets one echo's
    /// whole 30° arc read as a wall; 0.6 lets many readings decide, which
    /// measured far better maps (BENCHMARKS.md, map quality).
    #[arg(long, default_value_t = mapping_sonar_model().max_occupied)]
    pub max_occupied: f64,
    /// The sonar model's strongest empty belief from one reading.
    #[arg(long, default_value_t = mapping_sonar_model().max_empty)]
    pub max_empty: f64,
    /// The sonar model's weakest empty belief worth recording: cells of a
    /// cone where one reading says less are left as unobserved (0.5
    /// records all).
    #[arg(long, default_value_t = mapping_sonar_model().min_empty)]
    pub min_empty: f64,
    /// The sonar model's weakest occupied belief worth recording: cells of
    /// a region I where one reading says less are left alone.
    #[arg(long, default_value_t = mapping_sonar_model().min_occupied)]
    pub min_occupied: f64,
    /// Half the depth of the sonar model's region I, metres.
    #[arg(long, default_value_t = mapping_sonar_model().region_i_tolerance)]
    pub region_tolerance: f64,
    /// The sonar model's angle factor for region I on the cone's axis, 0 to
    /// 1 (thesis eq. 3.1's (β − α)/β is 1 there). With
    /// --occupied-edge-factor, the factor runs linearly from the axis to
    /// the edge; a specular sonar hears most walls at its cone's edges
    /// (0.4 and 1 make its ten-minute maps the most right; BENCHMARKS.md).
    #[arg(long, default_value_t = mapping_sonar_model().occupied_axis_factor)]
    pub occupied_axis_factor: f64,
    /// The sonar model's angle factor for region I at the cone's edge, 0
    /// to 1 (the thesis's is 0).
    #[arg(long, default_value_t = mapping_sonar_model().occupied_edge_factor)]
    pub occupied_edge_factor: f64,
    /// How far a no-echo reading marks its cone free, metres (0: no-echo
    /// readings are ignored). With a specular sonar, lost echoes are
    /// common, and marking them free erases the walls they missed.
    #[arg(long, default_value_t = mapping_sonar_model().no_echo_free_range)]
    pub no_echo_free_range: f64,
    /// How far any reading's cone is mapped, metres: an echo farther than
    /// this marks its cone free out to here and no wall (10.668, the
    /// sonar's range, maps all).
    #[arg(long, default_value_t = mapping_sonar_model().max_mapped_range)]
    pub max_mapped_range: f64,
    /// How far a sonar reading's empty evidence reaches, metres (its
    /// occupied arc is still marked out to --max-mapped-range): a specular
    /// sonar's echo may come from past a wall it glanced off.
    #[arg(long, default_value_t = mapping_sonar_model().max_free_range)]
    pub max_free_range: f64,
    /// The rig the robot's frames come from (a built-in name or a rig
    /// file): frames of another rig are refused. Without it, each frame is
    /// mapped with the rig it names, as the map server keeps it.
    #[arg(long)]
    pub rig: Option<String>,
    /// The laser ray model's belief in the cell an echo ends in
    /// (OctoMap's prob_hit).
    #[arg(long, default_value_t = RayModelParams::default().hit_probability)]
    pub hit_probability: f64,
    /// The laser ray model's belief in each cell a ray crosses (OctoMap's
    /// prob_miss).
    #[arg(long, default_value_t = RayModelParams::default().miss_probability)]
    pub miss_probability: f64,
    /// How far a laser beam with no return marks its ray free, metres (0:
    /// beams without a return are ignored).
    #[arg(long, default_value_t = RayModelParams::default().no_echo_free_range)]
    pub ray_no_echo_free_range: f64,
    /// How far a laser ray is mapped, metres: an echo farther than this
    /// frees its ray out to here and adds no hit.
    #[arg(long, default_value_t = RayModelParams::default().max_mapped_range)]
    pub ray_max_mapped_range: f64,
    /// The sonars fire one after another in ring order over this many
    /// seconds, ending with the frame (as `deog sim --sonar realistic`'s,
    /// over its 0.1 s period): each reading is mapped from where the robot
    /// stood when its sonar fired, at the pace its odometry shows between
    /// frames. 0: all fire with the frame.
    #[arg(long, default_value_t = 0.0)]
    pub firing_period: f64,
    /// How sonar readings become evidence: `thesis` (the thesis's model
    /// alone), `directional` (evidence kept per direction of the surface
    /// normal, so that a reading that glanced off a wall cannot erase the
    /// echoes it returned head-on, its cones stopping also at the walls
    /// the map holds, other robots' among them: for a specular sonar, best
    /// with --no-echo-free-range 0 --max-free-range 2) or `keep-walls` (each
    /// cone stopping at the cells the map already holds as walls).
    #[arg(long, value_enum, default_value_t = SonarMethodChoice::Thesis)]
    pub sonar_method: SonarMethodChoice,
    /// With --sonar-method keep-walls or directional: the probability of
    /// occupancy from which a cell is a wall that cones stop at.
    #[arg(long, default_value_t = MapViewSettings::default().wall_probability)]
    pub wall_probability: f64,
    /// With --sonar-method keep-walls or directional: tiles of the map
    /// kept in memory around the robot, least recently used forgotten
    /// first (for 64-cell tiles, keep-walls: 8 KiB each, 4,096 by default;
    /// directional: 108 KiB each, 1,024 by default).
    #[arg(long)]
    pub view_tiles: Option<usize>,
    /// With --sonar-method directional: every this many frames, the
    /// cells held free that no path from where the robot stood reaches
    /// without crossing a wall (the inside of an obstacle, the space past
    /// an outer wall, freed through a face the sonar met at a grazing
    /// angle) are sent as walls, and sent back as they were if a later
    /// path reaches them. 0: never.
    #[arg(long, default_value_t = MapViewSettings::default().enclosure_period)]
    pub enclosure_period: u32,
    /// With --sonar-method directional: how far behind a wall, once it is
    /// heard, the free evidence that reached cells through it is taken
    /// back, metres (a specular sonar frees an obstacle's inside through
    /// a face it grazed before that face became a wall); a cell left with
    /// nothing else is sent as a wall. 0: never.
    #[arg(long, default_value_t = MapViewSettings::default().shadow_depth)]
    pub shadow_depth: f64,
    /// With --sonar-method keep-walls or directional: how often the tiles
    /// of the map kept are read again from the map server, seconds, so
    /// that other robots' walls count too.
    #[arg(long, default_value_t = 5.0)]
    pub view_refresh_s: f64,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// `deog map --sonar-method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SonarMethodChoice {
    /// Cones stop at the walls the map already holds.
    KeepWalls,
    /// Evidence kept per direction of the surface normal.
    Directional,
    /// The thesis's model alone.
    Thesis,
}

impl From<SonarMethodChoice> for SonarMethod {
    fn from(choice: SonarMethodChoice) -> Self {
        match choice {
            SonarMethodChoice::KeepWalls => SonarMethod::KeepWalls,
            SonarMethodChoice::Directional => SonarMethod::Directional,
            SonarMethodChoice::Thesis => SonarMethod::Thesis,
        }
    }
}

/// Runs the cartographer.
pub fn run(args: MapArgs) -> Result<()> {
    let MapSettings {
        sonar: params,
        ray,
        view,
        view_refresh,
        firing,
        expected_rig,
    } = args.settings()?;
    let client_id = format!("carto/{}", args.robot);
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async {
        // Deaf to the signal no more while it connects and waits to start:
        // until the loop below listens, the signal ends the process.
        let until_running = deog_harness::ExitOnSignal::during("connecting or waiting for the first frames", &tokio::runtime::Handle::current());
        let client =
            MapClient::connect(args.connection.client_config()?.retrying_forever()).await?;
        let info = client
            .ensure_map(pb::CreateMapRequest {
                name: args.map.clone(),
                resolution_m: args.resolution,
                tile_size: args.tile_size,
                ..Default::default()
            })
            .await
            .with_context(|| format!("opening map {}", args.map))?;
        let resolution = Resolution::new(info.resolution_m)?;
        let tile_size = TileSize::new(info.tile_size)?;
        if let Some(rig) = &expected_rig {
            publish_rig(&client, rig).await?;
        }
        let settings = ModelSettings {
            pose: PoseChoice::from(args.pose),
            sonar: params,
            ray,
            resolution,
            tile_size,
            method: SonarMethod::from(args.sonar_method),
            view,
            firing,
        };
        let cartographers = CartographerByRig::new(client.clone(), settings, expected_rig);
        let sender = client
            .updates(
                &args.map,
                &client_id,
                UpdateSenderConfig {
                    // Batches are cut here, at frame boundaries only.
                    max_batch_tiles: usize::MAX,
                    window: args.window.max(1),
                },
            )
            .await?;
        let applied = sender.next_sequence() - 1;
        let start = args.from.max(applied + 1);
        if applied > 0 {
            tracing::info!(robot = %args.robot, map = %args.map, last_applied = applied, "resuming after the last frame the server applied");
        }
        let ack_log = match &args.ack_log {
            Some(path) => Some(std::io::BufWriter::new(
                std::fs::File::create(path)
                    .with_context(|| format!("creating {}", path.display()))?,
            )),
            None => None,
        };
        let mut queue = FrameQueue::follow(&client, &args.robot, start, args.idle_exit).await?;
        let progress = queue.replay_progress("mapping frames", start, args.to, args.idle_exit);
        // Cancelled on SIGTERM or ctrl-c: the loop below and a frame's wait
        // for its estimate both end on it.
        let shutdown = tokio_util::sync::CancellationToken::new();
        tokio::spawn({
            let shutdown = shutdown.clone();
            let signal = deog_harness::shutdown_signal();
            async move {
                signal.await;
                shutdown.cancel();
            }
        });
        drop(until_running);
        let estimates = (args.pose == MapPoseSource::Estimate).then(|| {
            let map = args.estimate_map.as_deref().unwrap_or(&args.map);
            tracing::info!(robot = %args.robot, estimates_on = map, "mapping from the localizer's converged estimates");
            EstimateFollower::new(
                client.clone(),
                &args.robot,
                map,
                std::time::Duration::from_secs_f64(args.estimate_wait),
                shutdown.clone(),
            )
        });

        let mut mapping = Mapping::new(MappingEnds {
            client: &client,
            map: &args.map,
            tile_size,
            cartographers,
            sender,
            ack_log,
            estimates,
            start,
            to: args.to,
            view_refresh,
        });
        // Timed from the first frame to the last acknowledgement: the
        // rate of the pipeline, not of waiting for frames.
        let mut began: Option<Instant> = None;
        let mut worked_until = Instant::now();
        let mut batch = Vec::new();
        loop {
            let first = tokio::select! {
                () = shutdown.cancelled() => break,
                frame = queue.next() => match frame? {
                    Some(frame) => frame,
                    None => break,
                },
            };
            began.get_or_insert_with(Instant::now);
            // One batch: this frame and those already waiting, up to
            // --batch-frames, so a slow robot's frames reach the map at once
            // and a fast one's go in bulk.
            batch.push(first);
            while batch.len() < args.batch_frames {
                match queue.try_next() {
                    Some(frame) => batch.push(frame),
                    None => break,
                }
            }
            let flow = mapping.batch(batch.drain(..)).await?;
            if mapping.last > 0 {
                progress.reached(mapping.last);
            }
            worked_until = Instant::now();
            if flow.is_break() {
                break;
            }
        }
        let closing = Instant::now();
        let (integrated, cells, unusable) = (mapping.integrated, mapping.cells, mapping.unusable);
        let estimates = mapping.take_estimates();
        let state = mapping.close().await?;
        progress.finish();
        let seconds = began.map_or(0.0, |t| {
            (worked_until - t + closing.elapsed()).as_secs_f64()
        });
        if unusable > 0 {
            println!(
                "{}: {unusable} frames skipped whose values cannot be mapped (each named in a warning)",
                args.robot
            );
        }
        if let Some(follower) = &estimates {
            println!(
                "{}: {} frames skipped without a converged estimate, {} the localizer passed over or did not reach in time",
                args.robot, follower.not_converged, follower.missed
            );
        }
        println!(
            "{} -> {}: {integrated} frames integrated ({:.0} frames/s), {cells} cell updates, {} batches applied, {} already applied, map version {}",
            args.robot,
            args.map,
            integrated as f64 / seconds.max(1e-9),
            state.applied,
            state.duplicates,
            state.map_version
        );
        Ok(())
    })
}
