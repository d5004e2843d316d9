//! `deog bench localize-memory`: whether the localizer's memory stays
//! within its cache setting on a map far larger than the cache.
//!
//! Every part is a real process of this binary, as in `deog demo`: a map
//! server on a fresh data folder, `deog import` putting a generated city
//! (`deog_world::city`: solid blocks 6 to 12 m a side between streets 2.5
//! to 3 m wide, inside an outer wall) on it, the simulator running the
//! same city, one wanderer driving a robot from a street crossing near
//! the middle, and `deog localize`
//! tracking that robot from its known start pose with a small
//! `--cache-mb`. The map is sized so that holding all of it in the
//! localizer (each tile's cells and its expected-range table, ~1 MB a
//! tile) would take at least `--min-ratio` times the cache; as the robot
//! drives on, the localizer keeps needing tiles it has not got, and the
//! cache must evict.
//!
//! Measured: the localizer's resident set every 100 ms and its `VmHWM`
//! (the peak, read until it exits); its baseline, the resident set once
//! it has started and built the tables of its first tiles; its resident
//! set less the cache size it logs every 100 frames (what it holds beyond
//! the cache); the tiles the robot's true path crossed; the range tables
//! built and the final cache size from the localizer's last line; and the
//! tracking error, estimate by estimate and as `deog eval localize`
//! judges it.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use clap::Args;
use deog_evaluation::localization::{
    self as evaluation, EvalInput, EvalParams, LocalizationReport, TruthSample,
};
use deog_evaluation::tracking::{LostStretch, Tracking, track};
use deog_grid::{Pose2, Resolution, TileKey, TileSize};
use deog_localizer::range_table::ConeGeometry;
use deog_mapfile::write_map;
use deog_robot_client::{ClientConfig, MapClient, SimClient};
use deog_world::city;
use deog_world::city::{MIN_SIDE_M, RESOLUTION_M};

use deog_harness::proc_stats::{cpu_seconds as proc_cpu_seconds, status_kb as proc_status_kb};
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, log_tail, os};

/// The map's name on the server.
const MAP: &str = "bench";
/// The one robot.
const ROBOT: &str = "scout-1";
/// Cells per tile side: the server's default, which `deog import` uses.
const TILE_SIDE: u32 = 64;
/// Largest map side, metres: the image and the server's import must fit
/// comfortably in memory.
const MAX_SIDE_M: f64 = 500.0;
/// A localizer or wanderer ends once no frame came for this long.
const IDLE_EXIT_S: &str = "3";
/// How often the localizer's memory is read.
const SAMPLE_EVERY: Duration = Duration::from_millis(100);
/// The baseline is taken once the localizer has estimated a frame this
/// far, metres, from the start: it has moved, run sensor updates, fetched
/// its first tiles and built their tables by then.
const BASELINE_MOVE_M: f64 = 0.5;
/// How long the localizer may take to work through its last frames after
/// the robot stopped, wall-clock; after that the figures are those of the
/// frames it got through, and the run is reported as not kept up with.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(120);
/// The localizer is given up on, as after [`DRAIN_TIMEOUT`], when it has
/// frames waiting and published no estimate for this long, wall-clock.
const STALL_TIMEOUT: Duration = Duration::from_secs(60);
/// How long the import may take, wall-clock.
const IMPORT_TIMEOUT: Duration = Duration::from_secs(300);
/// A progress line this often, wall-clock.
const PROGRESS_EVERY: Duration = Duration::from_secs(10);

/// Options of `deog bench localize-memory`.
#[derive(Debug, Args)]
pub struct LocalizeMemoryArgs {
    /// The localizer's cache budget, MiB (its --cache-mb; 16 or more).
    #[arg(long, default_value_t = 16)]
    cache_mb: usize,
    /// The localizer's most particles (its --max-particles). The filter's
    /// memory grows with it, apart from the cache: about 0.2 KiB a
    /// particle when a drop in the fit spreads them out.
    #[arg(long, default_value_t = 10_000)]
    max_particles: usize,
    /// Side of the square city, metres. Default: the smallest whole number
    /// of tiles a side whose map, held whole in the localizer, is
    /// --min-ratio times the cache budget.
    #[arg(long)]
    side_m: Option<f64>,
    /// Least ratio of the map's size in the localizer's representation
    /// (tiles × the bytes of a tile and its range table) to the cache
    /// budget; a smaller map is refused.
    #[arg(long, default_value_t = 100.0)]
    min_ratio: f64,
    /// Simulated seconds the robot drives.
    #[arg(long, default_value_t = 300.0)]
    duration: f64,
    /// Simulated seconds per wall-clock second. The localizer must keep
    /// up: every tile the robot reaches costs it a range-table build
    /// (about 0.25 s on one core), and a cache this small rebuilds the
    /// tables of tiles the robot comes back to.
    #[arg(long, default_value_t = 2.0)]
    speed: f64,
    /// The robot's cruising speed, m/s (the Scout tops out at 1).
    #[arg(long, default_value_t = 0.8)]
    robot_speed: f64,
    /// Seed of the city's layout, the simulator, the wanderer and the
    /// localizer.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Work folder, kept: the city's map files, the server's data and the
    /// processes' logs (its earlier server data and logs are replaced).
    /// Default: a temporary folder, removed after a successful run.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    out_json: Option<PathBuf>,
}

/// Runs `deog bench localize-memory`.
pub fn run(args: LocalizeMemoryArgs) -> Result<()> {
    let plan = Plan::new(&args)?;
    // A JSON file that cannot be written fails now, not after the run.
    if let Some(parent) = args.out_json.as_deref().and_then(Path::parent)
        && !parent.as_os_str().is_empty()
    {
        ensure!(
            parent.is_dir(),
            "--out-json {}: folder {} does not exist",
            args.out_json.as_deref().unwrap_or(parent).display(),
            parent.display()
        );
    }
    let (work, temporary) = match &args.out {
        Some(dir) => {
            prepare_out(dir)?;
            (dir.clone(), None)
        }
        None => {
            let dir = tempfile::Builder::new()
                .prefix("deog-localize-memory-")
                .tempdir()
                .context("creating a temporary work folder")?;
            (dir.path().to_path_buf(), Some(dir))
        }
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(bench(&args, &plan, &work));
    let figures = match result {
        Ok(figures) => figures,
        Err(error) => {
            // The logs say why: keep them.
            if let Some(dir) = temporary {
                let kept = dir.keep();
                eprintln!("the work folder is kept for its logs: {}", kept.display());
            }
            return Err(error);
        }
    };
    print!("{}", figures.table());
    if figures.gave_up.is_some()
        && let Some(dir) = temporary
    {
        let kept = dir.keep();
        eprintln!(
            "the work folder is kept for the localizer's log and the server's data: {}",
            kept.display()
        );
    }
    if let Some(path) = &args.out_json {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("figures written to {}", path.display());
    }
    Ok(())
}

/// The run's settings, checked, and the size of the city.
struct Plan {
    /// The cache budget, bytes.
    budget_bytes: usize,
    /// Pixels (cells) a side of the city.
    side_px: u32,
    /// Bytes one tile costs the localizer: cells, reference bits, table.
    tile_bytes: usize,
    /// Tiles the city covers.
    tiles: u64,
}

impl Plan {
    fn new(args: &LocalizeMemoryArgs) -> Result<Self> {
        ensure!(
            (16..=1 << 20).contains(&args.cache_mb),
            "--cache-mb must be in [16, 1048576] MiB (what deog localize takes), got {}",
            args.cache_mb
        );
        ensure!(
            (1..=10_000_000).contains(&args.max_particles),
            "--max-particles must be in [1, 10000000] (what deog localize takes), got {}",
            args.max_particles
        );
        ensure!(
            args.min_ratio.is_finite() && args.min_ratio > 0.0,
            "--min-ratio must be a positive number, got {}",
            args.min_ratio
        );
        ensure!(
            args.duration.is_finite() && args.duration >= 10.0,
            "--duration must be at least 10 simulated seconds, got {}",
            args.duration
        );
        ensure!(
            args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0,
            "--speed must be above 0 and at most 100 simulated seconds per second, got {}",
            args.speed
        );
        ensure!(
            args.robot_speed.is_finite() && args.robot_speed > 0.0 && args.robot_speed <= 1.0,
            "--robot-speed must be above 0 and at most 1 m/s, got {}",
            args.robot_speed
        );
        let budget_bytes = args.cache_mb << 20;
        let tile_bytes = localizer_tile_bytes();
        let side_px = match args.side_m {
            Some(side) => {
                ensure!(
                    side.is_finite() && (MIN_SIDE_M..=MAX_SIDE_M).contains(&side),
                    "--side-m must be within {MIN_SIDE_M} and {MAX_SIDE_M} m, got {side}"
                );
                (side / RESOLUTION_M).round() as u32
            }
            None => {
                let needed = (args.min_ratio * budget_bytes as f64 / tile_bytes as f64).ceil();
                let tiles_a_side = needed.sqrt().ceil().max(1.0);
                let side_px = tiles_a_side * f64::from(TILE_SIDE);
                let side_m = side_px * RESOLUTION_M;
                ensure!(
                    side_m <= MAX_SIDE_M,
                    "a map {:.0} times a {} MiB cache would be {side_m:.0} m a side, more than {MAX_SIDE_M} m: lower --cache-mb or --min-ratio",
                    args.min_ratio,
                    args.cache_mb
                );
                (side_px as u32).max((MIN_SIDE_M / RESOLUTION_M) as u32)
            }
        };
        let tiles = u64::from(side_px.div_ceil(TILE_SIDE)).pow(2);
        let ratio = (tiles * tile_bytes as u64) as f64 / budget_bytes as f64;
        ensure!(
            ratio >= args.min_ratio,
            "a city {:.1} m a side has {tiles} tiles, {:.0} MiB in the localizer: {ratio:.1} times the {} MiB cache, under --min-ratio {}; make --side-m larger",
            f64::from(side_px) * RESOLUTION_M,
            (tiles * tile_bytes as u64) as f64 / f64::from(1 << 20),
            args.cache_mb,
            args.min_ratio
        );
        Ok(Self {
            budget_bytes,
            side_px,
            tile_bytes,
            tiles,
        })
    }
}

/// What one tile costs the localizer when it holds all of it, as
/// `LocalMap` counts it against the budget: a byte per cell, the bitmap of
/// its occupied cells, and its expected-range table.
fn localizer_tile_bytes() -> usize {
    let area = (TILE_SIDE * TILE_SIDE) as usize;
    area + area.div_ceil(64) * 8 + ConeGeometry::default().table_bytes(area)
}

/// Creates `out` and clears the server data and logs of an earlier run.
fn prepare_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for folder in ["server-data", "logs"] {
        let path = out.join(folder);
        if path.exists() {
            std::fs::remove_dir_all(&path)
                .with_context(|| format!("clearing {} of an earlier run", path.display()))?;
        }
    }
    Ok(())
}

/// The localizer's memory, read from `/proc` as it runs.
#[derive(Debug, Default)]
struct MemorySamples {
    /// Readings of `VmRSS` that succeeded.
    samples: u64,
    /// The largest `VmRSS` read, kB.
    peak_rss_kb: u64,
    /// The last `VmRSS` read, kB.
    last_rss_kb: u64,
    /// The last `VmHWM` read, kB: the peak of the whole process life up
    /// to then. The process is idle (waiting out --idle-exit) between the
    /// last reading and its exit, so this is its final peak.
    hwm_kb: u64,
    /// Resident set per second of the run: (wall seconds, kB).
    series: Vec<(f64, u64)>,
    /// User plus system CPU seconds the process had used at the last
    /// reading.
    cpu_s: f64,
}

impl MemorySamples {
    /// Reads the process's memory once; a process that has exited (its
    /// status no longer has the fields) leaves the figures as they were.
    fn sample(&mut self, pid: u32, since: Instant) {
        let Ok(rss) = proc_status_kb(pid, "VmRSS") else {
            return;
        };
        if let Ok(hwm) = proc_status_kb(pid, "VmHWM") {
            self.hwm_kb = hwm;
        }
        if let Ok(cpu) = proc_cpu_seconds(pid) {
            self.cpu_s = cpu;
        }
        self.samples += 1;
        self.peak_rss_kb = self.peak_rss_kb.max(rss);
        self.last_rss_kb = rss;
        let t = since.elapsed().as_secs_f64();
        if self.series.last().is_none_or(|(last, _)| t - last >= 1.0) {
            self.series.push((t, rss));
        }
    }
}

/// Finding the baseline: the first frame past [`BASELINE_MOVE_M`] from the
/// start, then the localizer's estimate of it.
#[derive(Debug)]
enum Baseline {
    /// Reading frames after this sequence for one far enough out.
    FindFrame { after: u64 },
    /// Waiting for the estimate of this frame.
    AwaitEstimate { sequence: u64 },
    /// The resident set then, kB, and the simulated time of that frame.
    Taken { rss_kb: u64, time_s: f64 },
}

/// What the localizer's last line says.
#[derive(Debug, Clone, Copy)]
struct LocalizerSummary {
    frames: u64,
    sensor_updates: u64,
    tables_built: u64,
    cache_mib: f64,
}

/// Everything measured.
struct Figures {
    cache_mb: usize,
    max_particles: usize,
    budget_bytes: usize,
    side_px: u32,
    blocks: usize,
    tiles: u64,
    tile_bytes: usize,
    start: Pose2,
    duration_s: f64,
    speed: f64,
    robot_speed: f64,
    seed: u64,
    memory: MemorySamples,
    beyond_cache: BeyondCache,
    baseline_kb: u64,
    baseline_time_s: f64,
    tiles_crossed: usize,
    /// Tiles crossed up to the frame of the localizer's last estimate.
    tiles_estimated: usize,
    distance_m: f64,
    frames_on_server: usize,
    /// The localizer's last line; `None` when it was given up on.
    summary: Option<LocalizerSummary>,
    /// Why the localizer was given up on, if it was.
    gave_up: Option<String>,
    filter: FilterFigures,
    /// The largest cache size the localizer logged, MiB, if it logged any.
    logged_cache_max_mib: Option<f64>,
    max_lag_frames: u64,
    report: LocalizationReport,
    tracking: Tracking,
    wall_s: f64,
    /// The work folder, when it is kept (--out).
    work: Option<PathBuf>,
    commands: Vec<String>,
}

/// The whole run: processes, sampling, judging.
async fn bench(args: &LocalizeMemoryArgs, plan: &Plan, work: &Path) -> Result<Figures> {
    let started = Instant::now();
    let city = city(plan.side_px, args.seed)?;
    let yaml = write_map(work, "city", &city.image).context("writing the city's map files")?;
    let (start, blocks) = (city.start, city.blocks);
    eprintln!(
        "city: {:.1} m a side, {} blocks, {} tiles ({:.0} MiB in the localizer, {:.0} times the {} MiB cache); start ({:.2}, {:.2}); work folder {}",
        f64::from(plan.side_px) * RESOLUTION_M,
        blocks,
        plan.tiles,
        (plan.tiles * plan.tile_bytes as u64) as f64 / f64::from(1 << 20),
        (plan.tiles * plan.tile_bytes as u64) as f64 / plan.budget_bytes as f64,
        args.cache_mb,
        start.x,
        start.y,
        work.display()
    );
    // The image is on disk now; the bench process need not hold it.
    drop(city);

    let mut children = Supervisor::new(&work.join("logs"))?;
    let server_addr = free_loopback_addr()?;
    let sim_addr = free_loopback_addr()?;
    let server_url = format!("http://{server_addr}");
    let sim_url = format!("http://{sim_addr}");
    let seed = args.seed.to_string();
    let mut shutdown = std::pin::pin!(crate::signal::shutdown());

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

    eprintln!("importing the city into map {MAP} ...");
    children.start(
        "import",
        Role::Task,
        &os(&["import", "--map", MAP])
            .into_iter()
            .chain([yaml.clone().into_os_string()])
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
            () = &mut shutdown => bail!("interrupted: every process was stopped"),
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
    eprintln!(
        "imported: {} tiles, {} cells, in {:.1} s",
        info.tile_count,
        info.cell_count,
        importing.elapsed().as_secs_f64()
    );

    let yaml_arg = yaml.to_string_lossy().into_owned();
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
            &args.speed.to_string(),
            "--seed",
            &seed,
        ]),
    )?;
    let sim = connect(&mut children, "simulator", || {
        SimClient::connect(ClientConfig::new(sim_url.clone()))
    })
    .await?;
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
            &args.duration.to_string(),
            "--speed",
            &args.robot_speed.to_string(),
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
            () = &mut shutdown => bail!("interrupted: every process was stopped"),
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
            &args.cache_mb.to_string(),
            "--max-particles",
            &args.max_particles.to_string(),
            "--idle-exit",
            IDLE_EXIT_S,
            "--seed",
            &seed,
            "--server",
            &server_url,
        ]),
    )?;
    let pid = children
        .pid("localize")
        .context("the localizer has no process id")?;
    let sampling_since = Instant::now();
    let mut memory = MemorySamples::default();
    let mut log = LogFollower::new(work.join("logs").join("localize.log"));
    let mut beyond_cache = BeyondCache::default();
    let mut baseline = Baseline::FindFrame { after: 0 };
    let (mut estimated, mut max_lag_frames) = (0u64, 0u64);
    let mut last_progress = Instant::now();
    let mut robot_done_at: Option<Instant> = None;
    // Why the localizer was given up on, if it was.
    let mut gave_up: Option<String> = None;
    let mut estimate_seen_at = Instant::now();
    let drive_limit = Duration::from_secs_f64(args.duration / args.speed * 3.0 + 120.0);
    while !(children.all_done("wander") && children.all_done("localize")) {
        tokio::select! {
            () = &mut shutdown => bail!("interrupted: every process was stopped"),
            _ = tick.tick() => {}
        }
        // Read before `check`, which reaps an exited localizer: until then
        // its process id cannot be anyone else's.
        let localizing = !children.all_done("localize");
        if localizing {
            // The log first: a line is then paired with a reading taken
            // after it was written.
            let caches: Vec<f64> = log
                .new_lines()
                .iter()
                .filter_map(|line| line_cache_mb(line))
                .collect();
            memory.sample(pid, sampling_since);
            for cache in caches {
                beyond_cache.note(memory.last_rss_kb, cache);
            }
        }
        children.check()?;
        if children.all_done("wander") {
            let done = *robot_done_at.get_or_insert_with(Instant::now);
            if done.elapsed() >= DRAIN_TIMEOUT {
                gave_up = Some(format!(
                    "it still had frames to work through {} s after the robot stopped",
                    DRAIN_TIMEOUT.as_secs()
                ));
            }
        } else {
            ensure!(
                sampling_since.elapsed() < drive_limit,
                "the robot drove for over {} s of wall-clock time",
                drive_limit.as_secs()
            );
        }
        if let Some(latest) = latest_estimate(&client, estimated).await {
            estimated = latest;
            estimate_seen_at = Instant::now();
        }
        let last = last_frame(&client).await;
        max_lag_frames = max_lag_frames.max(last.saturating_sub(estimated));
        if localizing && last > estimated && estimate_seen_at.elapsed() >= STALL_TIMEOUT {
            gave_up = Some(format!(
                "it published no estimate for {} s with frames waiting",
                STALL_TIMEOUT.as_secs()
            ));
        }
        if let Some(why) = &gave_up {
            // What it did until now is the result; the supervisor stops
            // it with the others.
            eprintln!("giving up on the localizer: {why}");
            break;
        }
        if localizing && !matches!(baseline, Baseline::Taken { .. }) {
            baseline = step_baseline(&client, baseline, start, pid).await?;
        }
        if last_progress.elapsed() >= PROGRESS_EVERY {
            last_progress = Instant::now();
            let time_s = sim
                .robots()
                .await
                .ok()
                .and_then(|robots| robots.iter().map(|r| r.time_s).reduce(f64::max))
                .unwrap_or(0.0);
            eprintln!(
                "{time_s:5.0}/{:.0} s | localizer RSS {:.1} MiB (peak {:.1}) | frame {last}, estimated {estimated}",
                args.duration,
                mib(memory.last_rss_kb),
                mib(memory.hwm_kb.max(memory.peak_rss_kb)),
            );
        }
    }
    if gave_up.is_none() {
        children.check()?;
    }
    let (baseline_kb, baseline_time_s) = match baseline {
        Baseline::Taken { rss_kb, time_s } => (rss_kb, time_s),
        _ => bail!(
            "the localizer never estimated a frame {BASELINE_MOVE_M} m from the start: no baseline"
        ),
    };
    ensure!(
        memory.samples > 0 && memory.hwm_kb > 0,
        "the localizer's memory could not be read from /proc/{pid}/status"
    );

    let log = log.path;
    let text =
        std::fs::read_to_string(&log).with_context(|| format!("reading {}", log.display()))?;
    let summary = parse_summary(&text);
    ensure!(
        summary.is_some() || gave_up.is_some(),
        "the localizer's log {} has no final summary line; its end:\n{}",
        log.display(),
        log_tail(&log, 10)
    );
    let filter = filter_figures(&client).await?;
    let logged_cache_max_mib = logged_cache_max(&text);

    let samples = deog_harness::run_reads::read_robot(&client, ROBOT, Some(MAP), 0, 0).await?;
    let report = evaluation::evaluate(&EvalInput {
        robot: ROBOT,
        map: Some(MAP),
        truth: &samples.truth,
        estimates: &samples.estimates,
        params: EvalParams::default(),
        known_kidnaps: &[],
    })
    .context("judging the localizer's estimates")?;
    let tracking = track(&samples.truth, &samples.estimates, &EvalParams::default());
    let (tiles_crossed, distance_m) = path_tiles(&samples.truth, info.tile_size)?;
    let estimated_part = samples
        .truth
        .partition_point(|s| s.sequence <= filter.last_frame);
    let (tiles_estimated, _) = path_tiles(&samples.truth[..estimated_part], info.tile_size)?;
    let commands = children
        .command_lines()
        .map(|(_, line)| line.to_string())
        .collect();
    Ok(Figures {
        cache_mb: args.cache_mb,
        max_particles: args.max_particles,
        budget_bytes: plan.budget_bytes,
        side_px: plan.side_px,
        blocks,
        tiles: info.tile_count,
        tile_bytes: plan.tile_bytes,
        start,
        duration_s: args.duration,
        speed: args.speed,
        robot_speed: args.robot_speed,
        seed: args.seed,
        memory,
        beyond_cache,
        baseline_kb,
        baseline_time_s,
        tiles_crossed,
        tiles_estimated,
        distance_m,
        frames_on_server: samples.truth.len(),
        summary,
        gave_up,
        filter,
        logged_cache_max_mib,
        max_lag_frames,
        report,
        tracking,
        wall_s: started.elapsed().as_secs_f64(),
        work: args.out.clone(),
        commands,
    })
}

/// One step towards the baseline; takes it when the localizer has
/// estimated the first frame past [`BASELINE_MOVE_M`] from the start.
async fn step_baseline(
    client: &MapClient,
    state: Baseline,
    start: Pose2,
    pid: u32,
) -> Result<Baseline> {
    Ok(match state {
        Baseline::FindFrame { after } => {
            let frames = client
                .read_frames(ROBOT, after + 1, 0)
                .await
                .context("reading the robot's frames")?;
            let far = frames.iter().find(|f| {
                f.true_pose
                    .is_some_and(|p| (p.x - start.x).hypot(p.y - start.y) >= BASELINE_MOVE_M)
            });
            match far {
                Some(frame) => Baseline::AwaitEstimate {
                    sequence: frame.sequence,
                },
                None => Baseline::FindFrame {
                    after: frames.last().map_or(after, |f| f.sequence),
                },
            }
        }
        Baseline::AwaitEstimate { sequence } => {
            let poses = client
                .read_poses(ROBOT, sequence, 0)
                .await
                .context("reading the localizer's estimates")?;
            match poses.iter().find(|p| p.map == MAP) {
                Some(estimate) => Baseline::Taken {
                    rss_kb: proc_status_kb(pid, "VmRSS")?,
                    time_s: estimate.time_s,
                },
                None => Baseline::AwaitEstimate { sequence },
            }
        }
        taken @ Baseline::Taken { .. } => taken,
    })
}

/// What the published estimates say of the filter itself.
#[derive(Debug, Default)]
struct FilterFigures {
    /// Estimates published.
    estimates: u64,
    /// The frame of the last one.
    last_frame: u64,
    /// Particles of the first estimate (the filter starts with its most).
    first_particles: u32,
    /// The most particles an estimate had once the count had first fallen
    /// below that, and the frame: a burst of injected particles.
    max_particles_later: Option<(u32, u64)>,
    /// The largest lost score (the share of particles the filter would
    /// inject from free space: `1 − w_fast / w_slow`). An injection resets
    /// it, so the estimates published after one show none.
    max_lost_score: f64,
    /// Estimates with a lost score above zero, and the first such frame.
    lost: u64,
    first_lost_frame: Option<u64>,
}

/// Reads the localizer's estimates as published, particle counts and lost
/// scores included.
async fn filter_figures(client: &MapClient) -> Result<FilterFigures> {
    let poses = client
        .read_poses(ROBOT, 0, 0)
        .await
        .context("reading the localizer's estimates")?;
    let mut f = FilterFigures::default();
    let mut settled = false;
    for estimate in poses.iter().filter(|p| p.map == MAP) {
        if f.estimates == 0 {
            f.first_particles = estimate.particle_count;
        }
        f.estimates += 1;
        f.last_frame = f.last_frame.max(estimate.frame_sequence);
        settled |= estimate.particle_count < f.first_particles;
        if settled
            && f.max_particles_later
                .is_none_or(|(most, _)| estimate.particle_count > most)
        {
            f.max_particles_later = Some((estimate.particle_count, estimate.frame_sequence));
        }
        f.max_lost_score = f.max_lost_score.max(estimate.lost_score);
        if estimate.lost_score > 0.0 {
            f.lost += 1;
            f.first_lost_frame.get_or_insert(estimate.frame_sequence);
        }
    }
    Ok(f)
}

/// The last frame sequence the server holds for the robot (0: none yet).
async fn last_frame(client: &MapClient) -> u64 {
    client
        .robots()
        .await
        .map(|robots| {
            robots
                .iter()
                .find(|r| r.robot == ROBOT)
                .map_or(0, |r| r.last_sequence)
        })
        .unwrap_or(0)
}

/// The frame of the localizer's latest estimate after frame `after`.
async fn latest_estimate(client: &MapClient, after: u64) -> Option<u64> {
    let poses = client.read_poses(ROBOT, after + 1, 0).await.ok()?;
    poses
        .iter()
        .filter(|p| p.map == MAP)
        .map(|p| p.frame_sequence)
        .max()
}

/// The distinct tiles under the robot's true positions, and the distance
/// it drove, metres.
fn path_tiles(truth: &[TruthSample], tile_size: u32) -> Result<(usize, f64)> {
    let resolution = Resolution::new(RESOLUTION_M)?;
    let size = TileSize::new(tile_size)?;
    let mut tiles: HashSet<TileKey> = HashSet::new();
    let mut distance = 0.0;
    for (i, sample) in truth.iter().enumerate() {
        let cell = resolution.cell_of(sample.pose.x, sample.pose.y)?;
        tiles.insert(size.split(cell).0);
        if i > 0 {
            let before = truth[i - 1].pose;
            distance += (sample.pose.x - before.x).hypot(sample.pose.y - before.y);
        }
    }
    Ok((tiles.len(), distance))
}

/// The localizer's last line: "R on M: N frames, U sensor updates, T range
/// tables built, cache X MiB".
fn parse_summary(log: &str) -> Option<LocalizerSummary> {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains(" range tables built, cache "))?;
    let (_, figures) = line.split_once(": ")?;
    let number = |label: &str| -> Option<f64> {
        figures
            .split(", ")
            .find_map(|part| part.strip_suffix(label))
            .and_then(|n| n.trim().parse().ok())
    };
    let cache = figures
        .split(", ")
        .find_map(|part| part.strip_prefix("cache "))?
        .strip_suffix(" MiB")?
        .parse()
        .ok()?;
    Some(LocalizerSummary {
        frames: number(" frames")? as u64,
        sensor_updates: number(" sensor updates")? as u64,
        tables_built: number(" range tables built")? as u64,
        cache_mib: cache,
    })
}

/// The largest `cache_mb` in the localizer's periodic info lines.
fn logged_cache_max(log: &str) -> Option<f64> {
    log.lines().filter_map(line_cache_mb).reduce(f64::max)
}

/// The `cache_mb` field of one of the localizer's info lines, MiB.
fn line_cache_mb(line: &str) -> Option<f64> {
    let (_, rest) = line.split_once("cache_mb=")?;
    rest.trim_start_matches('"')
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .next()?
        .parse::<f64>()
        .ok()
}

/// The lines a growing log file gained since the last call.
struct LogFollower {
    path: PathBuf,
    offset: u64,
    partial: String,
}

impl LogFollower {
    fn new(path: PathBuf) -> Self {
        Self {
            path,
            offset: 0,
            partial: String::new(),
        }
    }

    /// Whole lines written since the last call; none if the file cannot
    /// be read (yet).
    fn new_lines(&mut self) -> Vec<String> {
        use std::io::{Read as _, Seek as _, SeekFrom};
        let Ok(mut file) = std::fs::File::open(&self.path) else {
            return Vec::new();
        };
        let mut bytes = Vec::new();
        if file.seek(SeekFrom::Start(self.offset)).is_err() || file.read_to_end(&mut bytes).is_err()
        {
            return Vec::new();
        }
        self.offset += bytes.len() as u64;
        self.partial.push_str(&String::from_utf8_lossy(&bytes));
        let Some(end) = self.partial.rfind('\n') else {
            return Vec::new();
        };
        let rest = self.partial.split_off(end + 1);
        let lines = std::mem::replace(&mut self.partial, rest);
        lines.lines().map(str::to_string).collect()
    }
}

/// The localizer's resident set beyond its cache: at each of its periodic
/// info lines (every 100 frames, carrying `cache_mb`), the resident set
/// read right after the line less that cache.
#[derive(Debug, Default)]
struct BeyondCache {
    /// Lines seen.
    count: u64,
    /// At the first line: (resident set kB, cache MiB).
    first: Option<(u64, f64)>,
    /// The largest resident set less cache, kB.
    max_kb: u64,
}

impl BeyondCache {
    fn note(&mut self, rss_kb: u64, cache_mib: f64) {
        let beyond = rss_kb.saturating_sub((cache_mib * 1024.0) as u64);
        self.count += 1;
        self.first.get_or_insert((rss_kb, cache_mib));
        self.max_kb = self.max_kb.max(beyond);
    }

    /// The resident set less cache at the first line, kB.
    fn first_kb(&self) -> Option<u64> {
        self.first
            .map(|(rss, cache)| rss.saturating_sub((cache * 1024.0) as u64))
    }
}

fn mib(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

impl Figures {
    /// The map held whole in the localizer, bytes.
    fn map_bytes(&self) -> u64 {
        self.tiles * self.tile_bytes as u64
    }

    fn ratio(&self) -> f64 {
        self.map_bytes() as f64 / self.budget_bytes as f64
    }

    /// The localizer's peak: `VmHWM`, or a larger sampled `VmRSS`.
    fn peak_kb(&self) -> u64 {
        self.memory.hwm_kb.max(self.memory.peak_rss_kb)
    }

    /// Baseline plus budget, kB.
    fn allowed_kb(&self) -> u64 {
        self.baseline_kb + (self.budget_bytes / 1024) as u64
    }

    fn within(&self) -> bool {
        self.peak_kb() <= self.allowed_kb()
    }

    fn table(&self) -> String {
        let mut out = String::new();
        let m = &self.memory;
        let side_m = f64::from(self.side_px) * RESOLUTION_M;
        let _ = writeln!(
            out,
            "\nlocalizer memory: one robot, {:.0} simulated s at {}x, cruising at {} m/s, seed {}",
            self.duration_s, self.speed, self.robot_speed, self.seed
        );
        let _ = writeln!(out, "\n| figure | value |");
        let _ = writeln!(out, "|---|---|");
        let _ = writeln!(
            out,
            "| map | city {side_m:.1} m a side ({} px at {RESOLUTION_M} m), {} blocks, {} tiles of {TILE_SIDE}x{TILE_SIDE} |",
            self.side_px, self.blocks, self.tiles
        );
        let _ = writeln!(
            out,
            "| map in the localizer's representation | {:.2} GiB ({} tiles x {:.1} KiB: cells, occupied bits, range table) |",
            self.map_bytes() as f64 / f64::from(1 << 30),
            self.tiles,
            self.tile_bytes as f64 / 1024.0
        );
        let _ = writeln!(out, "| cache budget (--cache-mb) | {} MiB |", self.cache_mb);
        let _ = writeln!(
            out,
            "| the localizer's --max-particles | {} |",
            self.max_particles
        );
        let _ = writeln!(out, "| map / budget | {:.1} |", self.ratio());
        let _ = writeln!(
            out,
            "| localizer RSS baseline (first tiles built, {:.1} simulated s) | {:.1} MiB |",
            self.baseline_time_s,
            mib(self.baseline_kb)
        );
        let _ = writeln!(
            out,
            "| localizer peak RSS (VmHWM) | {:.1} MiB |",
            mib(m.hwm_kb)
        );
        let _ = writeln!(
            out,
            "| localizer peak VmRSS sampled ({} samples, every {} ms) | {:.1} MiB |",
            m.samples,
            SAMPLE_EVERY.as_millis(),
            mib(m.peak_rss_kb)
        );
        let _ = writeln!(
            out,
            "| localizer RSS at the end | {:.1} MiB |",
            mib(m.last_rss_kb)
        );
        let _ = writeln!(
            out,
            "| peak - baseline | {:.1} MiB (budget {} MiB) |",
            mib(self.peak_kb().saturating_sub(self.baseline_kb)),
            self.cache_mb
        );
        let _ = writeln!(
            out,
            "| peak within baseline + budget ({:.1} MiB) | {} |",
            mib(self.allowed_kb()),
            if self.within() { "yes" } else { "no" }
        );
        let b = &self.beyond_cache;
        match (b.first, b.first_kb()) {
            (Some((rss, cache)), Some(first)) => {
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache at the first logged cache size | {:.1} MiB (RSS {:.1} MiB, cache {cache:.1} MiB) |",
                    mib(first),
                    mib(rss)
                );
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache, largest over {} logged cache sizes | {:.1} MiB |",
                    b.count,
                    mib(b.max_kb)
                );
                let strict = first + (self.budget_bytes / 1024) as u64;
                let _ = writeln!(
                    out,
                    "| peak within that first RSS beyond the cache + budget ({:.1} MiB) | {} |",
                    mib(strict),
                    if self.peak_kb() <= strict {
                        "yes"
                    } else {
                        "no"
                    }
                );
            }
            _ => {
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache | - (no cache_mb in the localizer's log: RUST_LOG hides its info lines) |"
                );
            }
        }
        let _ = writeln!(
            out,
            "| path | {:.1} m driven, {} frames, {} tiles crossed ({} up to the localizer's last estimate) |",
            self.distance_m, self.frames_on_server, self.tiles_crossed, self.tiles_estimated
        );
        match &self.summary {
            Some(s) => {
                let _ = writeln!(
                    out,
                    "| localizer | {} frames, {} sensor updates, {} range tables built, {:.1} CPU s, most {} frames behind |",
                    s.frames, s.sensor_updates, s.tables_built, m.cpu_s, self.max_lag_frames
                );
                let _ = writeln!(
                    out,
                    "| cache at the end (largest logged) | {:.1} MiB ({}) |",
                    s.cache_mib,
                    self.logged_cache_max_mib
                        .map_or("-".to_string(), |c| format!("{c:.1} MiB"))
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "| localizer | DID NOT KEEP UP ({}): its last estimate was for frame {} of {}; {:.1} CPU s |",
                    self.gave_up.as_deref().unwrap_or("stopped"),
                    self.filter.last_frame,
                    self.frames_on_server,
                    m.cpu_s
                );
                let _ = writeln!(
                    out,
                    "| largest cache logged | {} |",
                    self.logged_cache_max_mib
                        .map_or("-".to_string(), |c| format!("{c:.1} MiB"))
                );
            }
        }
        let f = &self.filter;
        let _ = writeln!(
            out,
            "| filter particles | {} at the start; once fewer, at most {} |",
            f.first_particles,
            f.max_particles_later
                .map_or("-".to_string(), |(n, frame)| format!("{n} (frame {frame})")),
        );
        let t = &self.tracking;
        let _ = writeln!(
            out,
            "| tracking, every estimate | position error mean {:.1} cm, max {:.1} cm; {} of {} within 0.25 m and 0.25 rad |",
            100.0 * t.mean_m,
            100.0 * t.max_m,
            t.within,
            t.paired
        );
        match t.longest_lost {
            Some(LostStretch {
                from_s: from,
                duration_s: seconds,
                estimates: n,
            }) => {
                let _ = writeln!(
                    out,
                    "| outside those bounds | {} stretches, the longest {n} estimates ({seconds:.1} s) from {from:.1} s; last estimate {} |",
                    t.lost_stretches,
                    if t.last_within { "within" } else { "outside" }
                );
            }
            None => {
                let _ = writeln!(out, "| outside those bounds | never |");
            }
        }
        match &self.report.stats {
            Some(st) => {
                let _ = writeln!(
                    out,
                    "| error after convergence (deog eval localize) | mean {:.1} cm x, {:.1} cm y, {:.2} deg; RMS {:.1} cm, max {:.1} cm |",
                    100.0 * st.x_m.mean_abs,
                    100.0 * st.y_m.mean_abs,
                    st.theta_rad.mean_abs.to_degrees(),
                    100.0 * st.rms_position_m,
                    100.0 * st.max_position_m
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "| error after convergence (deog eval localize) | - (not within the bounds at the end) |"
                );
            }
        }
        let _ = writeln!(out, "| wall-clock time | {:.0} s |", self.wall_s);
        let _ = writeln!(
            out,
            "\nrequirement (memory within the cache setting on a map >= 100x the cache): {}",
            if self.ratio() < 100.0 {
                "not tested (map under 100x the cache)"
            } else if !self.within() {
                "NOT met"
            } else if self.summary.is_none() {
                "not shown (the localizer did not finish the run)"
            } else {
                "met"
            }
        );
        if let Some(work) = &self.work {
            let _ = writeln!(
                out,
                "work folder (map files, server data, logs): {}",
                work.display()
            );
        }
        out
    }

    fn json(&self) -> Result<String> {
        let m = &self.memory;
        let s = self.summary.as_ref();
        let f = &self.filter;
        let r = &self.report;
        let stats = r.stats.as_ref().map(|st| {
            serde_json::json!({
                "mean_abs_x_m": st.x_m.mean_abs,
                "mean_abs_y_m": st.y_m.mean_abs,
                "mean_abs_theta_rad": st.theta_rad.mean_abs,
                "rms_position_m": st.rms_position_m,
                "max_position_m": st.max_position_m,
            })
        });
        let value = serde_json::json!({
            "config": {
                "cache_mb": self.cache_mb,
                "max_particles": self.max_particles,
                "duration_s": self.duration_s,
                "speed": self.speed,
                "robot_speed_mps": self.robot_speed,
                "seed": self.seed,
                "start": {"x": self.start.x, "y": self.start.y, "theta": self.start.theta},
            },
            "map": {
                "side_m": f64::from(self.side_px) * RESOLUTION_M,
                "side_px": self.side_px,
                "resolution_m": RESOLUTION_M,
                "blocks": self.blocks,
                "tiles": self.tiles,
                "localizer_bytes_per_tile": self.tile_bytes,
                "localizer_bytes": self.map_bytes(),
                "ratio_to_budget": self.ratio(),
            },
            "memory": {
                "budget_bytes": self.budget_bytes,
                "baseline_rss_kb": self.baseline_kb,
                "baseline_time_s": self.baseline_time_s,
                "vm_hwm_kb": m.hwm_kb,
                "peak_rss_sampled_kb": m.peak_rss_kb,
                "end_rss_kb": m.last_rss_kb,
                "samples": m.samples,
                "peak_minus_baseline_kb": self.peak_kb().saturating_sub(self.baseline_kb),
                "within_baseline_plus_budget": self.within(),
                "beyond_cache_first_kb": self.beyond_cache.first_kb(),
                "beyond_cache_first_rss_kb": self.beyond_cache.first.map(|(rss, _)| rss),
                "beyond_cache_first_cache_mib": self.beyond_cache.first.map(|(_, cache)| cache),
                "beyond_cache_max_kb": (self.beyond_cache.count > 0).then_some(self.beyond_cache.max_kb),
                "rss_per_second_kb": m.series.iter().map(|(t, kb)| serde_json::json!([t, kb])).collect::<Vec<_>>(),
            },
            "path": {
                "distance_m": self.distance_m,
                "frames": self.frames_on_server,
                "tiles_crossed": self.tiles_crossed,
                "tiles_crossed_until_last_estimate": self.tiles_estimated,
            },
            "localizer": {
                "kept_up": s.is_some(),
                "given_up_because": self.gave_up,
                "frames": s.map(|s| s.frames),
                "sensor_updates": s.map(|s| s.sensor_updates),
                "tables_built": s.map(|s| s.tables_built),
                "cache_end_mib": s.map(|s| s.cache_mib),
                "estimates": f.estimates,
                "last_estimated_frame": f.last_frame,
                "first_particles": f.first_particles,
                "max_particles_later": f.max_particles_later.map(|(n, _)| n),
                "max_particles_later_frame": f.max_particles_later.map(|(_, frame)| frame),
                "max_lost_score": f.max_lost_score,
                "estimates_with_lost_score": f.lost,
                "first_lost_frame": f.first_lost_frame,
                "cache_logged_max_mib": self.logged_cache_max_mib,
                "max_lag_frames": self.max_lag_frames,
                "cpu_s": self.memory.cpu_s,
            },
            "tracking": {
                "estimates_paired": self.tracking.paired,
                "estimates_within_bounds": self.tracking.within,
                "mean_position_error_m": self.tracking.mean_m,
                "max_position_error_m": self.tracking.max_m,
                "stretches_outside_bounds": self.tracking.lost_stretches,
                "longest_outside": self.tracking.longest_lost.map(|l| serde_json::json!({"from_s": l.from_s, "seconds": l.duration_s, "estimates": l.estimates})),
                "last_estimate_within_bounds": self.tracking.last_within,
                "converge_s": r.converge_s(),
                "after_convergence": stats,
            },
            "wall_s": self.wall_s,
            "commands": self.commands,
        });
        let mut text = serde_json::to_string_pretty(&value).context("assembling the JSON")?;
        text.push('\n');
        Ok(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defaults() -> LocalizeMemoryArgs {
        LocalizeMemoryArgs {
            cache_mb: 16,
            max_particles: 10_000,
            side_m: None,
            min_ratio: 100.0,
            duration: 300.0,
            speed: 4.0,
            robot_speed: 0.8,
            seed: 1,
            out: None,
            out_json: None,
        }
    }

    #[test]
    fn default_city_is_a_hundred_times_the_smallest_cache() {
        let plan = Plan::new(&defaults()).unwrap();
        assert!(plan.tiles * plan.tile_bytes as u64 >= 100 * (16 << 20));
        assert_eq!(plan.side_px % TILE_SIDE, 0);
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        type Spoil = fn(&mut LocalizeMemoryArgs);
        let cases: [(&str, Spoil); 6] = [
            ("--cache-mb", |a| a.cache_mb = 8),
            ("--max-particles", |a| a.max_particles = 0),
            ("--min-ratio", |a| a.min_ratio = f64::NAN),
            ("--duration", |a| a.duration = 5.0),
            ("--speed", |a| a.speed = 0.0),
            ("--robot-speed", |a| a.robot_speed = 2.0),
        ];
        for (flag, spoil) in cases {
            let mut args = defaults();
            spoil(&mut args);
            let err = Plan::new(&args).err().map(|e| e.to_string());
            assert!(
                err.as_deref().is_some_and(|e| e.starts_with(flag)),
                "{flag}: {err:?}"
            );
        }
    }

    #[test]
    fn the_summary_line_is_read() {
        let log = "2026 INFO estimate cache_mb=\"12.5\"\n\
                   2026 INFO estimate cache_mb=15.9 x=1\n\
                   scout-1 on bench: 3000 frames, 2900 sensor updates, 57 range tables built, cache 15.2 MiB\n";
        let s = parse_summary(log).unwrap();
        assert_eq!(
            (s.frames, s.sensor_updates, s.tables_built),
            (3000, 2900, 57)
        );
        assert!((s.cache_mib - 15.2).abs() < 1e-9);
        assert_eq!(logged_cache_max(log), Some(15.9));
    }
}
