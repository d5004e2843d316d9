//! `deog bench localize-peers`: deog's localizer beside nav2's amcl on the
//! same sonar frames and the same sonar-built map, in one run.
//!
//! Per world (`--worlds`): one robot wanders for `--map-minutes` while the
//! cartographer builds the map from its true poses (as `deog bench
//! localize` does); then a run of the wanderer records `--frames` frames
//! with odometry and true poses. Both filters read those frames:
//! - tracking from the true initial pose (± 0.1 m, 0.1 rad) at each of
//!   `--tracking-particles`, fixed (fewest = most);
//! - global localization: deog from its uniform prior over the map's free
//!   cells (its default particle bounds); amcl cannot start so (the
//!   package binds no uniform start), so both also run from amcl's only
//!   start, a Gaussian, here a broad one: centred on the map, σ half its
//!   larger side, σθ = π, at each side's default particle bounds.
//!
//! deog runs `deog_localizer::step::Localizer` with the Scout's beam model
//! in this process; amcl runs in `bench/localize_peers_amcl.py`, a child
//! Python process, on the frames as laser beams from the robot's centre
//! and the map as a ROS occupancy grid (deog's map_server export), with
//! nav2's defaults and its beam model. CPU time is the thread's
//! (CLOCK_THREAD_CPUTIME_ID here, `time.thread_time` there), of the filter
//! updates alone.
//!
//! Its parts: `recording` (the frames), `deog_side`, `amcl_input` (the
//! frames as beams from the centre, the grid, their files), `amcl_side`
//! (the script, its settings and report), `judge` (settling and errors
//! against the true poses), `report` (the table and the JSON) and
//! `cpu_clock`.

mod amcl_input;
mod amcl_side;
mod cpu_clock;
mod deog_side;
mod judge;
mod recording;
mod report;

use std::f64::consts::PI;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::Pose2;
use deog_harness::Progress;
use deog_localizer::filter::FilterSettings;
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::sensors::SensorChoice;
use deog_mapfile::MapImage;
use deog_simulator::SonarPreset;
use deog_world::load_world_spec;

use crate::localize::map_build;
use crate::option_error::{OptionError, require, require_folder_of};
use amcl_input::CentreBeams;
use amcl_side::{AmclScript, AmclSettings};
use cpu_clock::thread_cpu_s;
use deog_side::{FilterRun, Prior, RunSpec};
use report::{PeersReport, RunRow, SideFigures, WorldFigures};

/// The tracking prior's spread: metres in x and y, radians in heading.
const TRACKING_STD_XY: f64 = 0.1;
const TRACKING_STD_THETA: f64 = 0.1;
/// nav2 amcl's default particle bounds (`min_particles`, `max_particles`).
const AMCL_PARTICLES: (usize, usize) = (500, 2000);

/// Options of `deog bench localize-peers`.
#[derive(Debug, Clone, Args)]
pub struct LocalizePeersOptions {
    /// Worlds to run in, comma-separated.
    #[arg(long, default_value = "map2", value_delimiter = ',')]
    pub worlds: Vec<String>,
    /// Simulated minutes of wandering that build each world's map.
    #[arg(long, default_value_t = 10.0)]
    pub map_minutes: f64,
    /// Frames recorded per world, both filters reading them all.
    #[arg(long, default_value_t = 1802)]
    pub frames: usize,
    /// Seed of the recorded run (the robot's start and wandering) and of
    /// deog's filter.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Particle counts of the tracking runs, comma-separated, each fixed on
    /// both sides.
    #[arg(long, default_value = "500,5000", value_delimiter = ',')]
    pub tracking_particles: Vec<usize>,
    /// Metres driven before amcl's next filter update (nav2's
    /// `update_min_d`).
    #[arg(long, default_value_t = 0.25)]
    pub amcl_update_min_d: f64,
    /// Radians turned before amcl's next filter update (nav2's
    /// `update_min_a`).
    #[arg(long, default_value_t = 0.2)]
    pub amcl_update_min_a: f64,
    /// amcl's slow likelihood average's rate in the global run (nav2's
    /// `recovery_alpha_slow`; 0 with 0 fast: no random particles).
    #[arg(long, default_value_t = 0.0)]
    pub amcl_alpha_slow: f64,
    /// amcl's fast likelihood average's rate in the global run (nav2's
    /// `recovery_alpha_fast`).
    #[arg(long, default_value_t = 0.0)]
    pub amcl_alpha_fast: f64,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// The Python interpreter that runs amcl's side (it needs
    /// `pip install amcl numpy`).
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
    /// Run deog alone.
    #[arg(long, conflicts_with = "amcl")]
    pub no_amcl: bool,
    /// Fail when amcl's side cannot run, rather than reporting deog alone.
    #[arg(long)]
    pub amcl: bool,
}

impl LocalizePeersOptions {
    /// Checks the options a run cannot start with.
    pub fn validate(&self) -> Result<(), OptionError> {
        require(!self.worlds.is_empty(), "--worlds", || {
            "--worlds takes at least one world".into()
        })?;
        for world in &self.worlds {
            load_world_spec(world).map_err(|e| OptionError {
                flag: "--worlds",
                message: format!("--worlds {world}: {e}"),
            })?;
        }
        require(
            self.map_minutes.is_finite() && self.map_minutes > 0.0 && self.map_minutes <= 600.0,
            "--map-minutes",
            || "--map-minutes takes simulated minutes above 0, at most 600".into(),
        )?;
        require((2..=1_000_000).contains(&self.frames), "--frames", || {
            "--frames takes 2 to 1000000 frames".into()
        })?;
        require(
            !self.tracking_particles.is_empty()
                && self
                    .tracking_particles
                    .iter()
                    .all(|n| (10..=1_000_000).contains(n)),
            "--tracking-particles",
            || "--tracking-particles takes counts from 10 to 1000000, comma-separated".into(),
        )?;
        for (flag, value, most) in [
            ("--amcl-update-min-d", self.amcl_update_min_d, 10.0),
            ("--amcl-update-min-a", self.amcl_update_min_a, PI),
            ("--amcl-alpha-slow", self.amcl_alpha_slow, 1.0),
            ("--amcl-alpha-fast", self.amcl_alpha_fast, 1.0),
        ] {
            require(
                value.is_finite() && (0.0..=most).contains(&value),
                flag,
                || format!("{flag} takes a value from 0 to {most:.4}"),
            )?;
        }
        // A JSON file that cannot be written fails now, not after the runs.
        require_folder_of(self.json.as_deref(), "--json")?;
        Ok(())
    }
}

/// The runs of a world whose map spans `image` and whose frames start at
/// `start` (true pose).
fn run_specs(options: &LocalizePeersOptions, start: Pose2, image: &MapImage) -> Vec<RunSpec> {
    let mut specs: Vec<RunSpec> = options
        .tracking_particles
        .iter()
        .map(|&n| RunSpec {
            name: format!("tracking-{n}"),
            min_particles: n,
            max_particles: n,
            prior: Prior::Gaussian {
                centre: [start.x, start.y, start.theta],
                std_xy: TRACKING_STD_XY,
                std_theta: TRACKING_STD_THETA,
            },
        })
        .collect();
    let kld = FilterSettings::default().kld;
    specs.push(RunSpec {
        name: "global-uniform".into(),
        min_particles: kld.min_particles,
        max_particles: kld.max_particles,
        prior: Prior::Uniform,
    });
    let (w, h) = (
        f64::from(image.width) * image.resolution,
        f64::from(image.height) * image.resolution,
    );
    specs.push(RunSpec {
        name: "global-gaussian".into(),
        min_particles: kld.min_particles,
        max_particles: kld.max_particles,
        prior: Prior::Gaussian {
            centre: [image.origin.0 + w / 2.0, image.origin.1 + h / 2.0, 0.0],
            std_xy: w.max(h) / 2.0,
            std_theta: PI,
        },
    });
    specs
}

/// amcl's run of `spec`: the same, but a global run at nav2's particle
/// bounds and recovery rates.
fn amcl_spec(options: &LocalizePeersOptions, spec: &RunSpec) -> (RunSpec, (f64, f64)) {
    if spec.min_particles == spec.max_particles {
        (spec.clone(), (0.0, 0.0))
    } else {
        (
            RunSpec {
                min_particles: AMCL_PARTICLES.0,
                max_particles: AMCL_PARTICLES.1,
                ..spec.clone()
            },
            (options.amcl_alpha_slow, options.amcl_alpha_fast),
        )
    }
}

/// Runs `deog bench localize-peers`: per world a line when its map is
/// built and when its frames are recorded, a line per filter run, and a
/// table per run.
pub fn run(options: LocalizePeersOptions) -> Result<()> {
    options.validate()?;
    let rig = deog_rig::scout();
    let beams = CentreBeams::new(&rig)?;
    let work = tempfile::tempdir().context("creating a temporary directory")?;
    let script = if options.no_amcl {
        None
    } else {
        let script = AmclScript::new(options.python.as_os_str(), work.path())?;
        match script.probe() {
            Ok(versions) => Some((script, versions)),
            Err(reason) if options.amcl => bail!("--amcl: amcl's side cannot run: {reason}"),
            Err(reason) => {
                deog_harness::eprintln_above_bars!("amcl: not run: {reason}; reporting deog alone");
                None
            }
        }
    };
    let update = (options.amcl_update_min_d, options.amcl_update_min_a);
    let mut report = PeersReport {
        cpu_clock: "thread CPU time of the filter updates alone: \
                    clock_gettime(CLOCK_THREAD_CPUTIME_ID) around Localizer::step for deog, \
                    time.thread_time() around AMCL.update for amcl"
            .into(),
        beams: beams.bearings.len(),
        map_minutes: options.map_minutes,
        settle_position_m: judge::SETTLE_POSITION_M,
        settle_heading_rad: judge::SETTLE_HEADING_RAD,
        amcl_versions: script.as_ref().map(|(_, v)| v.clone()),
        amcl_settings: None,
        worlds: Vec::new(),
    };
    // Each world's map, its recording, each of deog's runs and amcl's
    // script; the runs are counted once the first world's are known.
    let progress = Progress::new("localizer runs", "steps", 0);
    for world_name in &options.worlds {
        let started = Instant::now();
        let world = load_world_spec(world_name)?;
        let config = map_build::sim_config(&rig, SonarPreset::Default);
        let (mut tiles, mut map) = map_build::build_map(
            world.clone(),
            &config,
            &config,
            SensorChoice::Beam,
            map_build::MapPlan {
                minutes: options.map_minutes,
                forward_fit: false,
                true_map: false,
            },
            ConeGeometry::default().surface_depth,
            deog_grid::OccupancyThresholds::default(),
        )?;
        let export = deog_mapping::export_map(&tiles)?;
        deog_harness::println_above_bars!(
            "{world_name}: map built in {:.1} s ({} tiles; grid {} x {}: {} occupied, {} free, {} unknown)",
            started.elapsed().as_secs_f64(),
            map.tile_count(),
            export.image.width,
            export.image.height,
            export.counts.occupied,
            export.counts.free,
            export.counts.unknown()
        );
        let frames = recording::record_frames(world, &config, options.seed, options.frames)?;
        let truth: Vec<(f64, Pose2)> = frames.iter().map(|f| (f.time_s, f.true_pose)).collect();
        let seconds = truth.last().map_or(0.0, |l| l.0) - truth[0].0;
        deog_harness::println_above_bars!(
            "{world_name}: {} frames recorded ({seconds:.1} simulated s)",
            frames.len()
        );
        let specs = run_specs(&options, frames[0].true_pose, &export.image);
        if progress.done() == 0 {
            let per_world = 1 + specs.len() as u64 + u64::from(script.is_some());
            progress.set_total(per_world * options.worlds.len() as u64);
        }
        progress.inc(1);

        // The map builds its range tables on first use and keeps them: a
        // few frames from the uniform prior (every free tile) build them
        // all, timed apart, so that no run's figures pay for them. A real
        // process pays for them once per tile it visits: the table line
        // says what that adds.
        let mut table_cpu_s = None;
        if let Some(uniform) = specs.iter().find(|s| s.prior == Prior::Uniform) {
            let start = thread_cpu_s()?;
            let (_, held) =
                deog_side::run_deog(&rig, map, &mut tiles, &frames[..2], uniform, options.seed)?;
            map = held;
            let cpu = thread_cpu_s()? - start;
            deog_harness::println_above_bars!(
                "{world_name}: range tables of all {} tiles (with two global updates) in {cpu:.2} s CPU",
                map.tile_count()
            );
            table_cpu_s = Some(cpu);
        }
        let mut deog_runs = Vec::new();
        for spec in &specs {
            let t0 = Instant::now();
            let (run, held) =
                deog_side::run_deog(&rig, map, &mut tiles, &frames, spec, options.seed)?;
            map = held;
            progress.inc(1);
            deog_harness::println_above_bars!(
                "  deog {}: {} updates, {:.2} s CPU, {:.1} s",
                spec.name,
                run.updates,
                run.update_cpu_s,
                t0.elapsed().as_secs_f64()
            );
            deog_runs.push(run);
        }

        let mut amcl_runs: Vec<Option<(RunSpec, FilterRun)>> = vec![None; specs.len()];
        if let Some((script, _)) = &script {
            let mut settings = AmclSettings::nav2_defaults(beams.bearings.len() as u32, update);
            let mut asked = Vec::new();
            for (i, spec) in specs.iter().enumerate() {
                let (spec, alpha) = amcl_spec(&options, spec);
                if settings.add_run(&spec, alpha) {
                    asked.push((i, spec));
                }
            }
            let frames_file = work.path().join("frames.bin");
            let grid_file = work.path().join("grid.bin");
            let runs_file = work.path().join("runs.json");
            let file = File::create(&frames_file)
                .with_context(|| format!("creating {}", frames_file.display()))?;
            amcl_input::write_frames(BufWriter::new(file), &beams, &frames)
                .with_context(|| format!("writing {}", frames_file.display()))?;
            let file = File::create(&grid_file)
                .with_context(|| format!("creating {}", grid_file.display()))?;
            amcl_input::write_grid(BufWriter::new(file), &export.image)
                .with_context(|| format!("writing {}", grid_file.display()))?;
            std::fs::write(&runs_file, serde_json::to_vec_pretty(&settings)?)
                .with_context(|| format!("writing {}", runs_file.display()))?;
            let t0 = Instant::now();
            let script_report = script.run(&frames_file, &grid_file, &runs_file, frames.len())?;
            progress.inc(1);
            deog_harness::println_above_bars!(
                "  amcl: {} runs in {:.1} s",
                settings.runs.len(),
                t0.elapsed().as_secs_f64()
            );
            for ((i, spec), amcl_run) in asked.into_iter().zip(&settings.runs) {
                let run = script_report
                    .filter_run(amcl_run)
                    .with_context(|| format!("the script did not report run {}", spec.name))?;
                amcl_runs[i] = Some((spec, run));
            }
            settings.runs.clear();
            report.amcl_settings = Some(settings);
        }

        let n_beams = beams.bearings.len();
        let mut rows = Vec::new();
        for ((spec, deog), amcl) in specs.iter().zip(&deog_runs).zip(amcl_runs) {
            let row = RunRow {
                name: spec.name.clone(),
                min_particles: spec.min_particles,
                max_particles: spec.max_particles,
                deog_prior: spec.prior,
                amcl_prior: amcl.as_ref().map(|(s, _)| s.prior),
                deog: SideFigures::new(deog, n_beams, judge::judge(&truth, &deog.estimates)),
                amcl: amcl.map(|(_, run)| {
                    SideFigures::new(&run, n_beams, judge::judge(&truth, &run.estimates))
                }),
            };
            deog_harness::println_above_bars!(
                "{world_name}, {} (deog {}..{} particles{}):",
                row.name,
                row.min_particles,
                row.max_particles,
                match &row.amcl_prior {
                    Some(_) if row.min_particles != row.max_particles =>
                        format!("; amcl {}..{}", AMCL_PARTICLES.0, AMCL_PARTICLES.1),
                    Some(_) => String::new(),
                    None => "; amcl cannot start from this prior".into(),
                }
            );
            deog_harness::print_above_bars!("{}", report::table(&row));
            rows.push(row);
        }
        report.worlds.push(WorldFigures {
            world: world_name.clone(),
            frames: frames.len(),
            seconds,
            grid_width: export.image.width,
            grid_height: export.image.height,
            grid_occupied: export.counts.occupied,
            grid_free: export.counts.free,
            grid_unknown: export.counts.unknown(),
            table_cpu_s,
            runs: rows,
        });
    }
    progress.finish();
    if let Some(path) = &options.json {
        std::fs::write(path, report.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::println_above_bars!("figures written to {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: LocalizePeersOptions,
    }

    fn parse(args: &[&str]) -> LocalizePeersOptions {
        Cli::try_parse_from(std::iter::once("localize-peers").chain(args.iter().copied()))
            .expect("parses")
            .options
    }

    fn refused(args: &[&str]) -> OptionError {
        parse(args).validate().expect_err("refused")
    }

    #[test]
    fn the_defaults_are_map2_and_tracking_at_500_and_5000() {
        let options = parse(&[]);
        options.validate().expect("the defaults are valid");
        assert_eq!(options.worlds, ["map2"]);
        assert_eq!(options.frames, 1802);
        assert_eq!(options.tracking_particles, [500, 5000]);
        assert_eq!(
            (options.amcl_update_min_d, options.amcl_update_min_a),
            (0.25, 0.2)
        );
        assert!(!options.no_amcl && !options.amcl);
        let both = parse(&["--worlds", "map1,map2", "--tracking-particles", "100"]);
        both.validate().expect("valid");
        assert_eq!(both.worlds, ["map1", "map2"]);
        assert!(Cli::try_parse_from(["localize-peers", "--no-amcl", "--amcl"]).is_err());
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        for (args, flag) in [
            (&["--worlds", "map1,nowhere"][..], "--worlds"),
            (&["--map-minutes", "0"][..], "--map-minutes"),
            (&["--map-minutes", "NaN"][..], "--map-minutes"),
            (&["--frames", "1"][..], "--frames"),
            (
                &["--tracking-particles", "500,5"][..],
                "--tracking-particles",
            ),
            (&["--amcl-update-min-d=-0.1"][..], "--amcl-update-min-d"),
            (&["--amcl-update-min-a", "4"][..], "--amcl-update-min-a"),
            (&["--amcl-alpha-slow", "2"][..], "--amcl-alpha-slow"),
            (&["--amcl-alpha-fast", "inf"][..], "--amcl-alpha-fast"),
            (&["--json", "/no/such/folder/peers.json"][..], "--json"),
        ] {
            let err = refused(args);
            assert_eq!(err.flag, flag, "{args:?}");
            assert!(err.message.starts_with(flag), "{err}");
        }
    }

    #[test]
    fn global_runs_cover_the_map_and_amcl_gets_its_own_bounds() {
        let options = parse(&[]);
        let image = MapImage {
            width: 200,
            height: 100,
            resolution: 0.05,
            origin: (-1.0, -2.0, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: deog_mapfile::Mode::Trinary,
            pixels: vec![205; 20_000],
        };
        let specs = run_specs(&options, Pose2::new(1.0, 2.0, 0.3), &image);
        let names: Vec<&str> = specs.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "tracking-500",
                "tracking-5000",
                "global-uniform",
                "global-gaussian"
            ]
        );
        assert_eq!(
            specs[1].prior,
            Prior::Gaussian {
                centre: [1.0, 2.0, 0.3],
                std_xy: TRACKING_STD_XY,
                std_theta: TRACKING_STD_THETA
            }
        );
        let Prior::Gaussian { centre, std_xy, .. } = specs[3].prior else {
            panic!("a Gaussian");
        };
        assert_eq!((centre[0], centre[1], std_xy), (4.0, 0.5, 5.0));
        let (tracking, alpha) = amcl_spec(&options, &specs[0]);
        assert_eq!((tracking.max_particles, alpha), (500, (0.0, 0.0)));
        let (global, _) = amcl_spec(&options, &specs[3]);
        assert_eq!((global.min_particles, global.max_particles), AMCL_PARTICLES);
    }
}
