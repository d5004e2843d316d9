//! `deog bench real`: the whole real-data recipe on one CARMEN log, with
//! the real processes, on a map server of its own.
//!
//! Every part is a process of this binary, as in `deog demo`, run one
//! after the other, with its log in `<out>/logs`:
//! 1. `deog server` on a free loopback port, its data in
//!    `<out>/server-data`;
//! 2. `deog import --carmen LOG --robot R`; the scan count `N` read back
//!    from the server (or `--to`, a prefix of the log);
//! 3. `deog map --robot R --map reference --pose reference --to N
//!    --hit-probability H --miss-probability M`: the reference map, from
//!    the log's reference (corrected) poses, its laser ray model's beliefs
//!    the bench's `--hit-probability` and `--miss-probability`;
//! 4. tracking: `deog localize --from 1 --to N` from the first scan's
//!    reference pose (`--initial-pose`, `--initial-std-xy`,
//!    `--initial-std-theta`) with the [`Recipe`]'s flags, every estimate
//!    then judged against its scan's reference pose;
//! 5. global localization: `--starts` start scans `k` drawn without
//!    repetition (seeded by `--seed`) from `1..=N - W`, where the window
//!    `W` is `--settle-scans` + `--hold-scans`; for each, `deog localize
//!    --from k --to k+W` with no initial pose, the same recipe and
//!    `--seed` the bench's seed plus the start's index (0 for the first
//!    start scan, in increasing order of scans). Each run is judged as soon as it
//!    ends, on its window alone.
//!
//! # Judging
//! Against each scan's reference pose, with `deog-evaluation`; an estimate
//! is within the bounds when its position error is at most 0.25 m and its
//! heading error at most 0.25 rad. A real log has no kidnap: the
//! evaluation's kidnap detection is turned off, so no pair of scans cuts
//! a run in segments.
//! - Tracking: every estimate of the whole run, lapses included
//!   ([`deog_evaluation::tracking::track`]).
//! - A global start at scan `k` **converged** when, from some scan `j ≤ k +
//!   settle_scans` on, every estimate up to the window's last scan is within
//!   the bounds, and the window's last scan has an estimate; `j - k` is
//!   its scans to converge ([`deog_evaluation::localization::evaluate`]'s
//!   settling). Estimates of a window's scans stored by an earlier run
//!   (the server keeps one estimate per robot and scan) and not replaced by
//!   this run are left out.
//!
//! The localizer's seconds per frame are the wall-clock time of its
//! process, start to exit (connecting, reading the map and building its
//! tables included), over the frames it was given.
//!
//! # The JSON (`--json`)
//! Stable keys; figures that do not exist are `null`.
//! - `log`, `robot`, `scans` (the scans localized: `N`), `log_scans` (the
//!   log's), `seed`, `settle_scans`, `window_scans` (`W`);
//! - `recipe`: the localizer's flags, `field_tempering`,
//!   `field_search_tempering`, `no_refine`, `no_realign`, `no_ambiguity_check`, `field_beams`,
//!   `motion_noise_scale`, `min_particles`, `max_particles`,
//!   `initial_std_xy`, `initial_std_theta`;
//! - `bounds`: `position_m`, `heading_rad`;
//! - `map`: `name`, `resolution_m`, `hit_probability`,
//!   `miss_probability`, `tiles`, `observed_cells`,
//!   `occupied_cells` (above the localizer's occupied threshold, 0.65),
//!   `seconds` (the cartographer's wall-clock time);
//! - `tracking`: `initial_pose` (`x`, `y`, `theta`), `frames`,
//!   `estimates`, `rms_position_m`, `mean_position_m`,
//!   `max_position_error_m`, `mean_abs_error_deg`, `max_abs_error_deg`,
//!   `within_bounds_fraction`, `stretches_outside_bounds`,
//!   `last_estimate_within_bounds`, `seconds`, `seconds_per_frame`;
//! - `global`: `starts` (a list: `scan`, `to`, `seed`, `estimates`,
//!   `converged`, `scans_to_converge` (`null` unless converged),
//!   `settled_after_scans` (the settling, converged or later; `null` if the
//!   window ends outside the bounds), `final_position_error_m`,
//!   `final_abs_error_deg`, `seconds`), `converged`, `converged_fraction`
//!   (0 to 1; `null` without starts), `median_scans_to_converge`,
//!   `seconds_per_frame`;
//! - `targets`: `rms_position_m`, `mean_abs_error_deg`,
//!   `converged_fraction`, and `met` (each `true` or `false`);
//! - `wall_s`, `commands` (each process's command line).
//!
//! Its parts: `starts` (the start scans drawn), `judge` (the estimates
//! judged), `processes` (the server, the steps run as processes),
//! `run` (the recipe, step by step), `report` (the table and the JSON).

mod judge;
mod processes;
mod report;
mod run;
mod starts;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use deog_localizer::preset::{Preset, Tuning};
use serde::Serialize;

use crate::option_error::{OptionError, require, require_folder_of};

/// The recipe's defaults.
fn real_laser() -> Tuning {
    Preset::RealLaser.tuning()
}

/// The robot's name when none is given.
const ROBOT: &str = "log";
/// The reference map's name on the server.
const MAP: &str = "reference";

/// The localizer's flags of the real-log recipe (its defaults those of
/// `deog localize --preset real-laser`), the same for tracking and for
/// every global start.
#[derive(Debug, Clone, Args, Serialize)]
pub struct Recipe {
    /// The localizer's --field-tempering: the exponent on the product of
    /// a scan's scored echo likelihoods.
    #[arg(long, default_value_t = real_laser().field_tempering)]
    pub field_tempering: f64,
    /// The localizer's --field-search-tempering: τ while the filter has
    /// not settled on a pose (a global start), softer so that look-alike
    /// places live until the scans tell them apart.
    #[arg(long, default_value_t = real_laser().field_search_tempering.unwrap_or(real_laser().field_tempering))]
    pub field_search_tempering: f64,
    /// The localizer's --no-refine: report the particle filter's estimate
    /// as it is (the recipe refines it against the map).
    #[arg(long)]
    pub no_refine: bool,
    /// The localizer's --no-realign: a tracked pose whose scan stops
    /// fitting follows the wheels alone (the recipe realigns it).
    #[arg(long)]
    pub no_realign: bool,
    /// The localizer's --no-ambiguity-check: an estimate is called
    /// converged even where its scan fits as well half a metre away.
    #[arg(long)]
    pub no_ambiguity_check: bool,
    /// The localizer's --field-beams: echoes of a scan scored.
    #[arg(long, default_value_t = real_laser().field_beams)]
    pub field_beams: usize,
    /// The localizer's --motion-noise-scale: a real robot's odometry is
    /// worse than the simulator's.
    #[arg(long, default_value_t = real_laser().motion_noise_scale)]
    pub motion_noise_scale: f64,
    /// The localizer's --min-particles.
    #[arg(long, default_value_t = real_laser().min_particles)]
    pub min_particles: usize,
    /// The localizer's --max-particles: global localization starts with
    /// this many.
    #[arg(long, default_value_t = 100_000)]
    pub max_particles: usize,
    /// Tracking's --initial-std-xy, metres.
    #[arg(long, default_value_t = 0.05)]
    pub initial_std_xy: f64,
    /// Tracking's --initial-std-theta, radians.
    #[arg(long, default_value_t = 0.05)]
    pub initial_std_theta: f64,
    /// The localizer's --start: `search` (global starts from the global
    /// search's hypotheses, convergence confirmed by it) or `uniform`.
    #[arg(long, default_value = "search")]
    pub start: String,
}

impl Recipe {
    /// The flags as `deog localize` takes them (tracking adds its initial
    /// pose and the two deviations).
    fn localize_args(&self) -> Vec<String> {
        [
            ("--field-tempering", self.field_tempering.to_string()),
            (
                "--field-search-tempering",
                self.field_search_tempering.to_string(),
            ),
            ("--field-beams", self.field_beams.to_string()),
            ("--motion-noise-scale", self.motion_noise_scale.to_string()),
            ("--min-particles", self.min_particles.to_string()),
            ("--max-particles", self.max_particles.to_string()),
            ("--start", self.start.clone()),
        ]
        .into_iter()
        .flat_map(|(flag, value)| [flag.to_owned(), value])
        .chain(self.no_refine.then(|| "--no-refine".to_owned()))
        .chain(self.no_realign.then(|| "--no-realign".to_owned()))
        .chain(
            self.no_ambiguity_check
                .then(|| "--no-ambiguity-check".to_owned()),
        )
        .collect()
    }

    /// Checks the flags' ranges that the bench can tell before the
    /// localizer starts (the localizer checks them all again).
    fn validate(&self) -> Result<(), OptionError> {
        require(
            matches!(self.start.as_str(), "search" | "uniform"),
            "--start",
            || format!("--start takes search or uniform, not {:?}", self.start),
        )?;
        require(
            self.field_tempering.is_finite() && self.field_tempering > 0.0,
            "--field-tempering",
            || "--field-tempering takes a positive number".into(),
        )?;
        require(
            self.field_search_tempering.is_finite() && self.field_search_tempering > 0.0,
            "--field-search-tempering",
            || "--field-search-tempering takes a positive number".into(),
        )?;
        require(self.field_beams > 0, "--field-beams", || {
            "--field-beams must be at least 1".into()
        })?;
        require(
            self.motion_noise_scale.is_finite() && (0.0..=100.0).contains(&self.motion_noise_scale),
            "--motion-noise-scale",
            || "--motion-noise-scale takes a number in [0, 100]".into(),
        )?;
        require(self.min_particles > 0, "--min-particles", || {
            "--min-particles must be at least 1".into()
        })?;
        require(
            self.max_particles >= self.min_particles,
            "--max-particles",
            || {
                format!(
                    "--max-particles ({}) must be at least --min-particles ({})",
                    self.max_particles, self.min_particles
                )
            },
        )?;
        for (flag, value) in [
            ("--initial-std-xy", self.initial_std_xy),
            ("--initial-std-theta", self.initial_std_theta),
        ] {
            require(value.is_finite() && value >= 0.0, flag, || {
                format!("{flag} takes zero or a positive number, got {value}")
            })?;
        }
        Ok(())
    }
}

/// Options of `deog bench real`.
#[derive(Debug, Clone, Args)]
pub struct RealOptions {
    /// The CARMEN log (plain or gzip, with reference poses: a corrected
    /// log), relative to the working directory.
    #[arg(long, default_value = "data/carmen/intel-corrected.log.gz")]
    pub log: PathBuf,
    /// The robot's name on the bench's map server.
    #[arg(long, default_value = ROBOT)]
    pub robot: String,
    /// Use the log's first this many scans only (0: all of them).
    #[arg(long, default_value_t = 0)]
    pub to: u64,
    /// Cell side of the reference map, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// The reference map's belief in the cell a laser echo ends in
    /// (`deog map --hit-probability`). Stronger than the cartographer's
    /// default (OctoMap's 0.7): along a corridor the rays to its far end
    /// graze the side walls, and at 0.7 against 0.4 their crossings wear
    /// holes in walls every scan sees.
    #[arg(long, default_value_t = 0.85)]
    pub hit_probability: f64,
    /// The reference map's belief in each cell a laser ray crosses
    /// (`deog map --miss-probability`; the cartographer's default 0.4).
    #[arg(long, default_value_t = 0.45)]
    pub miss_probability: f64,
    /// Global starts, each a localizer of its own on a window of scans
    /// (0: no global localization).
    #[arg(long, default_value_t = 20)]
    pub starts: usize,
    /// Seed of the start scans' draw; the localizers' seeds follow from it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A global start converged if it is within the bounds from at most
    /// this many scans after its start on.
    #[arg(long, default_value_t = 30)]
    pub settle_scans: u64,
    /// Scans after --settle-scans through which the estimate must stay
    /// within the bounds: a window is --settle-scans + --hold-scans.
    #[arg(long, default_value_t = 10)]
    pub hold_scans: u64,
    /// The localizer's flags.
    #[command(flatten)]
    pub recipe: Recipe,
    /// The run folder: the server's data and every process's log (the
    /// ones an earlier run left there are replaced).
    #[arg(long, default_value = "bench-real-out")]
    pub out: PathBuf,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl RealOptions {
    /// Scans in a global start's window after its first: the localizer
    /// runs `--from k --to k + window`.
    pub fn window(&self) -> u64 {
        self.settle_scans + self.hold_scans
    }

    /// Checks the options a run cannot start with (the log's length is
    /// checked once it is imported).
    pub fn validate(&self) -> Result<(), OptionError> {
        require(
            deog_proto::names::check_robot_name(&self.robot).is_ok(),
            "--robot",
            || format!("--robot {:?} is not a valid robot name", self.robot),
        )?;
        require(
            self.resolution.is_finite() && (0.01..=1.0).contains(&self.resolution),
            "--resolution",
            || {
                format!(
                    "--resolution takes a cell side in [0.01, 1] m, got {}",
                    self.resolution
                )
            },
        )?;
        require(
            self.hit_probability.is_finite() && (0.5..=0.9999).contains(&self.hit_probability),
            "--hit-probability",
            || {
                format!(
                    "--hit-probability takes a probability in [0.5, 0.9999], got {}",
                    self.hit_probability
                )
            },
        )?;
        require(
            self.miss_probability.is_finite() && (0.0001..=0.5).contains(&self.miss_probability),
            "--miss-probability",
            || {
                format!(
                    "--miss-probability takes a probability in [0.0001, 0.5], got {}",
                    self.miss_probability
                )
            },
        )?;
        require(self.hold_scans > 0, "--hold-scans", || {
            "--hold-scans must be at least 1: a start must stay within the bounds".into()
        })?;
        require(self.settle_scans <= 10_000, "--settle-scans", || {
            "--settle-scans takes at most 10000 scans".into()
        })?;
        require(self.hold_scans <= 10_000, "--hold-scans", || {
            "--hold-scans takes at most 10000 scans".into()
        })?;
        require(self.starts <= 1000, "--starts", || {
            "--starts takes at most 1000 starts".into()
        })?;
        require(
            self.to == 0 || self.starts == 0 || self.to > self.window(),
            "--to",
            || {
                format!(
                    "--to {} leaves no room for a global start's window of {} scans after its first (--settle-scans + --hold-scans)",
                    self.to,
                    self.window()
                )
            },
        )?;
        self.recipe.validate()
    }

    /// Checks the log is there, naming the flag (the default is relative
    /// to the working directory).
    fn check_log(&self) -> Result<(), OptionError> {
        require(self.log.is_file(), "--log", || {
            format!(
                "--log {}: no such file (a relative path is taken from the working directory; the default's is the repository's root)",
                self.log.display()
            )
        })
    }
}

/// Runs `deog bench real`: prints the figures as a table, and writes them
/// as JSON to `--json` if given.
pub fn run(options: RealOptions) -> Result<()> {
    options.validate()?;
    options.check_log()?;
    // A JSON file that cannot be written fails now, not after the run.
    require_folder_of(options.json.as_deref(), "--json")?;
    deog_harness::prepare_run_folder(&options.out)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let figures = runtime
        .block_on(run::bench(&options))
        .with_context(|| format!("the run's logs are in {}", logs(&options.out).display()))?;
    deog_harness::print_above_bars!("{}", figures.table());
    if let Some(path) = &options.json {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
    }
    Ok(())
}

/// The processes' log folder of the run folder `out`.
fn logs(out: &Path) -> PathBuf {
    out.join("logs")
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: RealOptions,
    }

    fn parse(args: &[&str]) -> RealOptions {
        Cli::try_parse_from(std::iter::once("real").chain(args.iter().copied()))
            .expect("the arguments parse")
            .options
    }

    fn blamed(args: &[&str]) -> &'static str {
        parse(args).validate().expect_err("refused").flag
    }

    #[test]
    fn the_defaults_are_the_real_log_recipe() {
        let options = parse(&[]);
        options.validate().expect("the defaults are valid");
        assert_eq!(options.window(), 40);
        assert_eq!((options.starts, options.seed), (20, 1));
        assert_eq!(
            options.recipe.localize_args(),
            [
                "--field-tempering",
                "0.5",
                "--field-search-tempering",
                "0.05",
                "--field-beams",
                "180",
                "--motion-noise-scale",
                "2",
                "--min-particles",
                "2000",
                "--max-particles",
                "100000",
                "--start",
                "search",
            ]
        );
        assert_eq!(
            (
                options.recipe.initial_std_xy,
                options.recipe.initial_std_theta
            ),
            (0.05, 0.05)
        );
        assert_eq!(options.out, PathBuf::from("bench-real-out"));
        assert_eq!(
            (options.hit_probability, options.miss_probability),
            (0.85, 0.45)
        );
    }

    #[test]
    fn the_map_beliefs_must_be_probabilities_on_their_side_of_a_half() {
        assert_eq!(blamed(&["--hit-probability", "0.4"]), "--hit-probability");
        assert_eq!(blamed(&["--hit-probability", "NaN"]), "--hit-probability");
        assert_eq!(blamed(&["--miss-probability", "0.6"]), "--miss-probability");
        assert_eq!(blamed(&["--miss-probability", "0"]), "--miss-probability");
        parse(&["--hit-probability", "0.7", "--miss-probability", "0.4"])
            .validate()
            .expect("the cartographer's defaults are valid");
    }

    #[test]
    fn each_recipe_flag_can_be_overridden() {
        let options = parse(&[
            "--field-tempering",
            "0.3",
            "--field-search-tempering",
            "0.2",
            "--field-beams",
            "60",
            "--motion-noise-scale",
            "1.5",
            "--min-particles",
            "500",
            "--max-particles",
            "5000",
            "--no-refine",
        ]);
        options.validate().expect("valid");
        assert_eq!(
            options.recipe.localize_args().join(" "),
            "--field-tempering 0.3 --field-search-tempering 0.2 --field-beams 60 --motion-noise-scale 1.5 --min-particles 500 --max-particles 5000 --start search --no-refine"
        );
    }

    #[test]
    fn bad_options_name_their_flag() {
        assert_eq!(blamed(&["--robot", "no spaces"]), "--robot");
        assert_eq!(blamed(&["--hold-scans", "0"]), "--hold-scans");
        assert_eq!(blamed(&["--settle-scans", "20000"]), "--settle-scans");
        assert_eq!(blamed(&["--starts", "1001"]), "--starts");
        assert_eq!(blamed(&["--field-tempering", "0"]), "--field-tempering");
        assert_eq!(blamed(&["--field-beams", "0"]), "--field-beams");
        assert_eq!(
            blamed(&["--motion-noise-scale", "101"]),
            "--motion-noise-scale"
        );
        assert_eq!(blamed(&["--min-particles", "0"]), "--min-particles");
        assert_eq!(
            blamed(&["--min-particles", "3000", "--max-particles", "2000"]),
            "--max-particles"
        );
        assert_eq!(blamed(&["--initial-std-xy=-0.1"]), "--initial-std-xy");
        assert_eq!(
            blamed(&["--initial-std-theta", "NaN"]),
            "--initial-std-theta"
        );
    }

    #[test]
    fn a_prefix_must_hold_a_window() {
        // A window of 40 scans after its first needs 41.
        assert_eq!(blamed(&["--to", "40"]), "--to");
        parse(&["--to", "41"]).validate().expect("one start fits");
        parse(&["--to", "41", "--settle-scans", "10", "--hold-scans", "5"])
            .validate()
            .expect("valid");
        // Without global starts, any prefix does.
        parse(&["--to", "5", "--starts", "0"])
            .validate()
            .expect("tracking only");
    }

    #[test]
    fn a_missing_log_is_blamed_on_log() {
        let options = parse(&["--log", "/nonexistent/x.log.gz"]);
        let error = options.check_log().expect_err("refused");
        assert_eq!(error.flag, "--log");
        assert!(error.message.contains("/nonexistent/x.log.gz"));
    }
}
