//! One run of `deog bench localize-memory`: the processes started, the
//! localizer watched and sampled until the robot and it are done (or it
//! is given up on), and what the server and the logs then hold judged.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use deog_evaluation::localization::{self as evaluation, EvalInput, EvalParams};
use deog_evaluation::tracking::track;
use deog_grid::Pose2;
use deog_harness::run_reads::read_robot;
use deog_harness::{Progress, log_tail};

use super::figures::{LocalizerMemoryFigures, mib};
use super::log::{LogFollower, line_cache_mb, logged_cache_max, parse_summary};
use super::processes::{self, Processes};
use super::sampling::{BASELINE_MOVE_M, Baseline, BeyondCache, MemorySamples};
use super::server_reads::{filter_figures, last_frame, latest_estimate, path_tiles};
use super::{CityPlan, LocalizeMemoryOptions, MAP, ROBOT};

/// How long the localizer may take to work through its last frames after
/// the robot stopped, wall-clock; after that the figures are those of the
/// frames it got through, and the run is reported as not kept up with.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(120);
/// The localizer is given up on, as after [`DRAIN_TIMEOUT`], when it has
/// frames waiting and published no estimate for this long, wall-clock.
const STALL_TIMEOUT: Duration = Duration::from_secs(60);
/// A progress line this often, wall-clock.
const PROGRESS_EVERY: Duration = Duration::from_secs(10);

/// The whole run: processes, sampling, judging.
pub(super) async fn bench(
    options: &LocalizeMemoryOptions,
    plan: &CityPlan,
    work: &Path,
) -> Result<LocalizerMemoryFigures> {
    let started = Instant::now();
    let city = processes::write_city(options, plan, work)?;
    let mut shutdown = std::pin::pin!(deog_harness::shutdown_signal());
    let mut processes = processes::start(options, plan, &city, work, &mut shutdown).await?;
    let watched = watch(options, &mut processes, city.start, work, &mut shutdown).await?;
    let Processes {
        children,
        client,
        info,
        ..
    } = &processes;

    let log = &watched.log;
    let text =
        std::fs::read_to_string(log).with_context(|| format!("reading {}", log.display()))?;
    let summary = parse_summary(&text);
    ensure!(
        summary.is_some() || watched.gave_up.is_some(),
        "the localizer's log {} has no final summary line; its end:\n{}",
        log.display(),
        log_tail(log, 10)
    );
    let filter = filter_figures(client).await?;
    let logged_cache_max_mib = logged_cache_max(&text);

    let samples = read_robot(client, ROBOT, Some(MAP), 0, 0).await?;
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
    Ok(LocalizerMemoryFigures {
        cache_mb: options.cache_mb,
        max_particles: options.max_particles,
        budget_bytes: plan.budget_bytes,
        side_px: plan.side_px,
        blocks: city.blocks,
        tiles: info.tile_count,
        tile_bytes: plan.tile_bytes,
        start: city.start,
        duration_s: options.duration,
        speed: options.speed,
        robot_speed: options.robot_speed,
        seed: options.seed,
        memory: watched.memory,
        beyond_cache: watched.beyond_cache,
        baseline_kb: watched.baseline_kb,
        baseline_time_s: watched.baseline_time_s,
        tiles_crossed,
        tiles_estimated,
        distance_m,
        frames_on_server: samples.truth.len(),
        summary,
        gave_up: watched.gave_up,
        filter,
        logged_cache_max_mib,
        max_lag_frames: watched.max_lag_frames,
        report,
        tracking,
        wall_s: started.elapsed().as_secs_f64(),
        work: options.out.clone(),
        commands,
    })
}

/// What watching the localizer gave.
struct Watched {
    memory: MemorySamples,
    beyond_cache: BeyondCache,
    baseline_kb: u64,
    baseline_time_s: f64,
    max_lag_frames: u64,
    /// Why the localizer was given up on, if it was.
    gave_up: Option<String>,
    /// The localizer's log.
    log: PathBuf,
}

/// Samples the localizer every tick until the wanderer and it are done,
/// or it falls too far behind; fails if a process fails, the robot drives
/// for too long, no baseline was taken or `shutdown` comes first.
async fn watch(
    options: &LocalizeMemoryOptions,
    processes: &mut Processes,
    start: Pose2,
    work: &Path,
    shutdown: &mut (impl Future<Output = ()> + Unpin),
) -> Result<Watched> {
    let Processes {
        children,
        client,
        sim,
        localizer_pid: pid,
        tick,
        ..
    } = processes;
    let pid = *pid;
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
    let drive_limit = Duration::from_secs_f64(options.duration / options.speed * 3.0 + 120.0);
    let progress = Progress::new(
        "localizing while driving",
        "simulated s",
        options.duration.ceil() as u64,
    );
    while !(children.all_done("wander") && children.all_done("localize")) {
        tokio::select! {
            () = &mut *shutdown => bail!("interrupted: every process was stopped"),
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
        if let Some(latest) = latest_estimate(client, estimated).await {
            estimated = latest;
            estimate_seen_at = Instant::now();
        }
        let last = last_frame(client).await;
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
            deog_harness::eprintln_above_bars!("giving up on the localizer: {why}");
            break;
        }
        if localizing && !matches!(baseline, Baseline::Taken { .. }) {
            baseline = baseline.step(client, start, pid).await?;
        }
        let time_s = sim
            .robots()
            .await
            .ok()
            .and_then(|robots| robots.iter().map(|r| r.time_s).reduce(f64::max))
            .unwrap_or(0.0);
        progress.set_done(time_s as u64);
        if last_progress.elapsed() >= PROGRESS_EVERY {
            last_progress = Instant::now();
            deog_harness::eprintln_above_bars!(
                "{time_s:5.0}/{:.0} s | localizer RSS {:.1} MiB (peak {:.1}) | frame {last}, estimated {estimated}",
                options.duration,
                mib(memory.last_rss_kb),
                mib(memory.hwm_kb.max(memory.peak_rss_kb)),
            );
        }
    }
    progress.finish();
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
    Ok(Watched {
        memory,
        beyond_cache,
        baseline_kb,
        baseline_time_s,
        max_lag_frames,
        gave_up,
        log: log.path,
    })
}
