//! The recipe, step by step: the log imported, the reference map built,
//! tracking over the whole log, then each global start, each judged as
//! soon as it ends.

use std::ffi::OsString;
use std::time::Instant;

use anyhow::{Context, Result, ensure};
use deog_grid::{LogOdds, Occupancy, OccupancyThresholds, Pose2, TileMap};
use deog_harness::run_reads::{read_map, read_robot};
use deog_harness::{Progress, os};
use deog_robot_client::convert::pose_from_wire;

use super::processes::Processes;
use super::report::{MapFigures, RealFigures, StartFigures, TrackingFigures};
use super::starts::pick_starts;
use super::{MAP, RealOptions, judge, logs};

/// A step ends once no frame came for this long, seconds: only when the
/// server holds fewer frames than it was told to read, which the bench
/// checks first.
const IDLE_EXIT_S: &str = "2";

/// The whole run.
pub(super) async fn bench(options: &RealOptions) -> Result<RealFigures> {
    let started = Instant::now();
    let mut shutdown = std::pin::pin!(deog_harness::shutdown_signal());
    let mut processes = Processes::start(&options.out, &logs(&options.out)).await?;
    let robot = options.robot.as_str();

    deog_harness::eprintln_above_bars!(
        "importing {} as robot {robot} (run folder {}) ...",
        options.log.display(),
        options.out.display()
    );
    let import: Vec<OsString> = os(&["import", "--carmen"])
        .into_iter()
        .chain([options.log.clone().into_os_string()])
        .chain(os(&["--robot", robot]))
        .collect();
    processes.step("import", &import, &mut shutdown).await?;
    let log_scans = log_scans(&processes, robot).await?;
    let scans = if options.to > 0 {
        ensure!(
            options.to <= log_scans,
            "--to {}: the log has {log_scans} scans",
            options.to
        );
        options.to
    } else {
        log_scans
    };
    let window = options.window();
    let starts = pick_starts(options.seed, options.starts, scans, window)?;
    // Scans gone through by the child processes: the map's, tracking's
    // and each global start's window, counted as each step ends.
    let progress = Progress::new(
        "real-log recipe",
        "scans",
        2 * scans + starts.len() as u64 * (window + 1),
    );

    deog_harness::eprintln_above_bars!(
        "mapping scans 1 to {scans} at their reference poses into map {MAP} ..."
    );
    let map_time = processes
        .step(
            "map",
            &os(&[
                "map",
                "--robot",
                robot,
                "--map",
                MAP,
                "--pose",
                "reference",
                "--to",
                &scans.to_string(),
                "--resolution",
                &options.resolution.to_string(),
                "--hit-probability",
                &options.hit_probability.to_string(),
                "--miss-probability",
                &options.miss_probability.to_string(),
                "--idle-exit",
                IDLE_EXIT_S,
                // One frame a batch: the server clamps each batch's sum,
                // so batches cut by arrival timing would make the map
                // differ from run to run.
                "--batch-frames",
                "1",
            ]),
            &mut shutdown,
        )
        .await?;
    progress.inc(scans);
    let info = processes
        .client
        .map_info(MAP)
        .await
        .context("reading the reference map's info")?;
    let map = read_map(&processes.client, MAP).await?;
    let map_figures = MapFigures {
        resolution_m: info.resolution_m,
        hit_probability: options.hit_probability,
        miss_probability: options.miss_probability,
        tiles: info.tile_count,
        observed_cells: info.cell_count,
        occupied_cells: occupied_cells(&map),
        seconds: map_time.as_secs_f64(),
    };
    deog_harness::eprintln_above_bars!(
        "map {MAP}: {} tiles, {} cells observed, {} occupied, in {:.1} s",
        map_figures.tiles,
        map_figures.observed_cells,
        map_figures.occupied_cells,
        map_figures.seconds
    );

    let initial_pose = first_reference_pose(&processes, robot).await?;
    deog_harness::eprintln_above_bars!(
        "tracking scans 1 to {scans} from ({:.3}, {:.3}, {:.3}) ...",
        initial_pose.x,
        initial_pose.y,
        initial_pose.theta
    );
    let mut tracking_args = localize_args(options, 1, scans, options.seed);
    tracking_args.extend([
        // The localizer reads the same pose from the first frame itself.
        OsString::from("--initial-pose=reference"),
        "--initial-std-xy".into(),
        options.recipe.initial_std_xy.to_string().into(),
        "--initial-std-theta".into(),
        options.recipe.initial_std_theta.to_string().into(),
    ]);
    let tracking_time = processes
        .step("localize-tracking", &tracking_args, &mut shutdown)
        .await?;
    progress.inc(scans);
    let samples = read_robot(&processes.client, robot, Some(MAP), 1, scans).await?;
    let tracking = judge::tracking(robot, &samples.truth, &samples.estimates)?;
    let tracking = TrackingFigures {
        initial_pose,
        frames: scans,
        tracking,
        seconds: tracking_time.as_secs_f64(),
    };
    deog_harness::eprintln_above_bars!(
        "tracking: RMS {:.3} m, mean |heading error| {:.2}°, {} of {} within the bounds, {:.3} s a frame",
        tracking.tracking.rms_m,
        tracking.tracking.mean_abs_heading_rad.to_degrees(),
        tracking.tracking.within,
        tracking.tracking.paired,
        tracking.seconds_per_frame()
    );

    let mut global = Vec::with_capacity(starts.len());
    let width = starts.len().to_string().len();
    for (i, &scan) in starts.iter().enumerate() {
        let end = scan + window;
        let seed = options.seed + i as u64;
        let before = read_robot(&processes.client, robot, Some(MAP), scan, end).await?;
        let name = format!("localize-global-{:0width$}", i + 1);
        let time = processes
            .step(
                &name,
                &localize_args(options, scan, end, seed),
                &mut shutdown,
            )
            .await?;
        let after = read_robot(&processes.client, robot, Some(MAP), scan, end).await?;
        let made = judge::made_by_the_run(&before.estimates, after.estimates);
        let verdict = judge::window(scan, end, options.settle_scans, &after.truth, &made)?;
        let start = StartFigures {
            scan,
            to: end,
            seed,
            verdict,
            seconds: time.as_secs_f64(),
        };
        deog_harness::eprintln_above_bars!(
            "global start {}/{} at scan {scan}: {}",
            i + 1,
            starts.len(),
            start.summary()
        );
        global.push(start);
        progress.inc(window + 1);
    }
    progress.finish();

    let commands = processes
        .children
        .command_lines()
        .map(|(_, line)| line.to_owned())
        .collect();
    Ok(RealFigures {
        log: options.log.display().to_string(),
        robot: robot.to_owned(),
        scans,
        log_scans,
        seed: options.seed,
        settle_scans: options.settle_scans,
        window,
        recipe: options.recipe.clone(),
        map: map_figures,
        tracking,
        starts: global,
        wall_s: started.elapsed().as_secs_f64(),
        commands,
    })
}

/// `deog localize` on the reference map for scans `from..=to`, with the
/// recipe's flags.
fn localize_args(options: &RealOptions, from: u64, to: u64, seed: u64) -> Vec<OsString> {
    os(&[
        "localize",
        "--robot",
        &options.robot,
        "--map",
        MAP,
        "--from",
        &from.to_string(),
        "--to",
        &to.to_string(),
        "--idle-exit",
        IDLE_EXIT_S,
        "--seed",
        &seed.to_string(),
    ])
    .into_iter()
    .chain(
        options
            .recipe
            .localize_args()
            .into_iter()
            .map(OsString::from),
    )
    .collect()
}

/// The robot's scans on the server, numbered from 1 as the import does.
async fn log_scans(processes: &Processes, robot: &str) -> Result<u64> {
    let robots = processes
        .client
        .robots()
        .await
        .context("listing the robots whose frames the server holds")?;
    let frames = robots
        .iter()
        .find(|r| r.robot == robot)
        .with_context(|| format!("the import stored no frame of robot {robot}"))?;
    ensure!(
        frames.first_sequence == 1 && frames.frame_count == frames.last_sequence,
        "robot {robot}'s frames are not numbered 1 to {} (from {}, {} frames)",
        frames.frame_count,
        frames.first_sequence,
        frames.frame_count
    );
    Ok(frames.last_sequence)
}

/// The reference pose of the robot's first scan: where tracking starts.
async fn first_reference_pose(processes: &Processes, robot: &str) -> Result<Pose2> {
    let first = processes
        .client
        .read_frames(robot, 1, 1)
        .await
        .with_context(|| format!("reading the first frame of robot {robot}"))?;
    let pose = first
        .first()
        .and_then(|f| f.reference_pose)
        .with_context(|| {
            format!("the first scan of robot {robot} has no reference pose: is the log corrected?")
        })?;
    Ok(pose_from_wire(pose))
}

/// Cells of `map` above the localizer's occupied threshold.
fn occupied_cells(map: &TileMap) -> u64 {
    let thresholds = OccupancyThresholds::default();
    map.tiles()
        .flat_map(|(_, tile)| tile.raw_cells())
        .filter(|&&raw| thresholds.classify(LogOdds::from_raw(raw)) == Occupancy::Occupied)
        .count() as u64
}
