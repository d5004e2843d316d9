//! The city written as map files, and the processes of a run started in
//! order: the map server, the import of the city, the simulator, the
//! wanderer and, once the robot's first frame is stored, the localizer.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use deog_grid::Pose2;
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, os};
use deog_mapfile::write_map;
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, SimClient};
use deog_world::city;
use deog_world::city::RESOLUTION_M;

use super::server_reads::last_frame;
use super::{CityPlan, LocalizeMemoryOptions, MAP, ROBOT, SAMPLE_EVERY};

/// A localizer or wanderer ends once no frame came for this long.
const IDLE_EXIT_S: &str = "3";
/// How long the import may take, wall-clock.
const IMPORT_TIMEOUT: Duration = Duration::from_secs(300);

/// The city of a run, on disk.
pub(super) struct CityFiles {
    /// Its map_server YAML (beside its image).
    pub yaml: PathBuf,
    /// Where the robot starts: a street crossing near the middle.
    pub start: Pose2,
    /// Its blocks.
    pub blocks: usize,
}

/// Generates the city `plan` sizes and writes its map files to `work`.
pub(super) fn write_city(
    options: &LocalizeMemoryOptions,
    plan: &CityPlan,
    work: &Path,
) -> Result<CityFiles> {
    let city = city(plan.side_px, options.seed)?;
    let yaml = write_map(work, "city", &city.image).context("writing the city's map files")?;
    let (start, blocks) = (city.start, city.blocks);
    deog_harness::eprintln_above_bars!(
        "city: {:.1} m a side, {} blocks, {} tiles ({:.0} MiB in the localizer, {:.0} times the {} MiB cache); start ({:.2}, {:.2}); work folder {}",
        f64::from(plan.side_px) * RESOLUTION_M,
        blocks,
        plan.tiles,
        plan.map_bytes() as f64 / f64::from(1 << 20),
        plan.map_bytes() as f64 / plan.budget_bytes as f64,
        options.cache_mb,
        start.x,
        start.y,
        work.display()
    );
    // The image is on disk now: the city, dropped here, need not be held.
    Ok(CityFiles {
        yaml,
        start,
        blocks,
    })
}

/// The processes of a run, all started.
pub(super) struct Processes {
    /// Every child; they stop when it is dropped.
    pub children: Supervisor,
    /// A client of the map server.
    pub client: MapClient,
    /// A client of the simulator.
    pub sim: SimClient,
    /// The imported map, as the server describes it.
    pub info: pb::MapInfo,
    /// The localizer's process id.
    pub localizer_pid: u32,
    /// The sampling clock, ticking every [`SAMPLE_EVERY`] since the
    /// wanderer started.
    pub tick: tokio::time::Interval,
}

/// Starts the run's processes with their logs in `work/logs`; fails if
/// one fails, the import takes too long or `shutdown` comes first.
pub(super) async fn start(
    options: &LocalizeMemoryOptions,
    plan: &CityPlan,
    city: &CityFiles,
    work: &Path,
    shutdown: &mut (impl Future<Output = ()> + Unpin),
) -> Result<Processes> {
    let mut children = Supervisor::new(&work.join("logs"))?;
    let server_addr = free_loopback_addr()?;
    let sim_addr = free_loopback_addr()?;
    let server_url = format!("http://{server_addr}");
    let sim_url = format!("http://{sim_addr}");
    let seed = options.seed.to_string();

    children.start(
        "server",
        Role::Service,
        &os(&["server", "--listen", &server_addr.to_string(), "--data"])
            .into_iter()
            .chain([work.join("server-data").into_os_string()])
            .collect::<Vec<_>>(),
    )?;
    let client = connect(&mut children, "map server", || {
        MapClient::connect(ClientConfig::new(server_url.clone()))
    })
    .await?;

    deog_harness::eprintln_above_bars!("importing the city into map {MAP} ...");
    children.start(
        "import",
        Role::Task,
        &os(&["import", "--map", MAP])
            .into_iter()
            .chain([city.yaml.clone().into_os_string()])
            .chain(os(&["--server", &server_url]))
            .collect::<Vec<_>>(),
    )?;
    let importing = Instant::now();
    while !children.all_done("import") {
        ensure!(
            importing.elapsed() < IMPORT_TIMEOUT,
            "the import took over {} s",
            IMPORT_TIMEOUT.as_secs()
        );
        tokio::select! {
            () = &mut *shutdown => bail!("interrupted: every process was stopped"),
            () = tokio::time::sleep(Duration::from_millis(100)) => {}
        }
        children.check()?;
    }
    let info = client
        .map_info(MAP)
        .await
        .context("reading the map's info")?;
    ensure!(
        info.tile_count == plan.tiles,
        "the server holds {} tiles of map {MAP}, the city has {}",
        info.tile_count,
        plan.tiles
    );
    deog_harness::eprintln_above_bars!(
        "imported: {} tiles, {} cells, in {:.1} s",
        info.tile_count,
        info.cell_count,
        importing.elapsed().as_secs_f64()
    );

    let yaml_arg = city.yaml.to_string_lossy().into_owned();
    children.start(
        "sim",
        Role::Service,
        &os(&[
            "sim",
            "--world",
            &yaml_arg,
            "--listen",
            &sim_addr.to_string(),
            "--speed",
            &options.speed.to_string(),
            "--rig",
            &options.rig,
            "--seed",
            &seed,
        ]),
    )?;
    let sim = connect(&mut children, "simulator", || {
        SimClient::connect(ClientConfig::new(sim_url.clone()))
    })
    .await?;
    let start = city.start;
    let pose_arg = format!("{},{},{}", start.x, start.y, start.theta);
    children.start(
        "wander",
        Role::Task,
        &os(&[
            "wander",
            "--robot",
            ROBOT,
            "--spawn",
            "--start",
            &pose_arg,
            "--seed",
            &seed,
            "--duration",
            &options.duration.to_string(),
            "--speed",
            &options.robot_speed.to_string(),
            "--rig",
            &options.rig,
            "--sim",
            &sim_url,
            "--server",
            &server_url,
        ]),
    )?;

    // The localizer starts once the robot's first frame is stored, and
    // reads from frame 1: its idle timer would otherwise run out while the
    // simulator and the wanderer start.
    let mut tick = tokio::time::interval(SAMPLE_EVERY);
    loop {
        tokio::select! {
            () = &mut *shutdown => bail!("interrupted: every process was stopped"),
            _ = tick.tick() => {}
        }
        children.check()?;
        if last_frame(&client).await > 0 {
            break;
        }
        ensure!(
            !children.all_done("wander"),
            "the wanderer ended before publishing a frame"
        );
    }
    children.start(
        "localize",
        Role::Task,
        &os(&[
            "localize",
            "--robot",
            ROBOT,
            "--map",
            MAP,
            "--from",
            "1",
            "--initial-pose",
            &pose_arg,
            "--cache-mb",
            &options.cache_mb.to_string(),
            "--max-particles",
            &options.max_particles.to_string(),
            "--idle-exit",
            IDLE_EXIT_S,
            "--seed",
            &seed,
            "--server",
            &server_url,
        ]),
    )?;
    let localizer_pid = children
        .pid("localize")
        .context("the localizer has no process id")?;
    Ok(Processes {
        children,
        client,
        sim,
        info,
        localizer_pid,
        tick,
    })
}
