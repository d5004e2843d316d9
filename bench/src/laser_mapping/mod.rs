//! `deog bench laser-mapping`: deog's laser mapping beside OctoMap's on the
//! same scans of a real CARMEN log, in one run.
//!
//! deog's side runs in this process: every scan at its reference pose
//! through [`deog_mapping::Cartographer::for_rig`] with the log's rig and
//! the ray model set to OctoMap's figures (hit 0.7, miss 0.4, clamping
//! 0.12 and 0.97), the deltas applied to a [`deog_grid::TileMap`] as the map
//! server merges them; integration and application are timed apart. One
//! thread.
//!
//! OctoMap's side is `bench/octomap_insert.py`, run as a child of
//! `--python`: the same scans as world-frame points on the plane z = 0
//! with their sensor origins go to it through a temporary file, it inserts
//! each with `OcTree.insertPointCloud(points, origin, maxrange)` and times
//! only that (the octomap-python wheel is built without OpenMP: one
//! thread), then exports its final map's cells. Both sides skip beams
//! without a return and cut rays at `--max-range`. Each side maps the whole
//! log `--passes` times into one map.
//!
//! When the interpreter or its `octomap` or numpy module is missing, the
//! run says how to install them and reports deog alone, unless `--octomap`
//! demands OctoMap's side: then it is an error.
//!
//! Its parts: `laser_log` (the log's scans, placed, and as point clouds),
//! `deog_side`, `agreement` (the two maps compared) and `report` (the table
//! and the JSON, whose keys its docs list); the scans file, the script as a
//! child process and the cells file it writes back are
//! the `octomap` module's, which `deog bench sonar-mapping` shares.

mod agreement;
mod deog_side;
mod laser_log;
mod report;

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::{ClampLimits, Resolution};

use crate::octomap::{OctomapScript, OctomapSettings, point_cloud};
use crate::option_error::{OptionError, require};
use laser_log::LaserLog;
use report::{ConfigRecord, LaserMappingFigures};

/// Options of `deog bench laser-mapping`.
#[derive(Debug, Clone, Args)]
pub struct LaserMappingOptions {
    /// The CARMEN log to map (plain or gzip; a corrected log, whose
    /// reference poses place the scans), relative to the working directory.
    #[arg(long, default_value = "data/carmen/intel-corrected.log.gz")]
    pub log: PathBuf,
    /// Metres per cell (deog) and per voxel (OctoMap).
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Metres mapped along each ray on both sides: an echo farther marks
    /// its ray free out to here and adds no hit.
    #[arg(long, default_value_t = 20.0)]
    pub max_range: f64,
    /// Times the whole log is mapped, into one map per side, for stable
    /// timing.
    #[arg(long, default_value_t = 3)]
    pub passes: u32,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// The Python interpreter that runs OctoMap's side (it needs
    /// `pip install octomap-python numpy`).
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
    /// Map with deog alone.
    #[arg(long, conflicts_with = "octomap")]
    pub no_octomap: bool,
    /// Fail when OctoMap's side cannot run, rather than reporting deog
    /// alone.
    #[arg(long)]
    pub octomap: bool,
}

impl LaserMappingOptions {
    /// Checks the options a run cannot start with.
    pub fn validate(&self) -> Result<(), OptionError> {
        require(
            self.resolution.is_finite()
                && (Resolution::MIN_METRES..=Resolution::MAX_METRES).contains(&self.resolution),
            "--resolution",
            || {
                format!(
                    "--resolution takes metres per cell from {} to {}",
                    Resolution::MIN_METRES,
                    Resolution::MAX_METRES
                )
            },
        )?;
        require(
            self.max_range.is_finite() && self.max_range > 0.0,
            "--max-range",
            || "--max-range takes a positive number of metres".into(),
        )?;
        require(self.passes > 0, "--passes", || {
            "--passes must be at least 1".into()
        })
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

/// Runs `deog bench laser-mapping`: prints the figures as a table, and
/// writes them as JSON to `--json` if given.
pub fn run(options: LaserMappingOptions) -> Result<()> {
    options.validate()?;
    options.check_log()?;
    let resolution = Resolution::new(options.resolution)?;
    let log = LaserLog::load(&options.log)?;
    // Both sides cut rays where deog's model does: at --max-range, or at
    // the laser's own maximum range if that is shorter.
    let mapped_range = options.max_range.min(
        log.rig
            .beams()
            .iter()
            .map(|b| b.max_range)
            .fold(f64::INFINITY, f64::min),
    );
    let clouds = log.clouds()?;
    let ray = deog_side::ray_params(mapped_range);
    let clamp = ClampLimits::DEFAULT_PROBABILITIES;
    let config = ConfigRecord {
        log: options.log.display().to_string(),
        laser: log.source.to_string(),
        beams_per_scan: log.beams_per_scan(),
        echoes_per_pass: clouds.iter().map(|c| c.points.len() as u64).sum(),
        scans_per_pass: log.scans.len(),
        passes: options.passes,
        resolution_m: options.resolution,
        max_range_m: mapped_range,
        prob_hit: ray.hit_probability,
        prob_miss: ray.miss_probability,
        clamp_min: clamp.0,
        clamp_max: clamp.1,
    };

    deog_harness::eprintln_above_bars!(
        "deog: {} scans x {} pass(es) ...",
        log.scans.len(),
        options.passes
    );
    let deog = deog_side::map_log(&log, resolution, mapped_range, options.passes)?;

    let work = tempfile::tempdir().context("creating a temporary directory")?;
    let octomap = if options.no_octomap {
        Err("--no-octomap".to_owned())
    } else {
        let script = OctomapScript::new(options.python.as_os_str(), work.path())?;
        match script.probe() {
            Ok(versions) => {
                deog_harness::eprintln_above_bars!(
                    "OctoMap: octomap-python {} on Python {} (numpy {}), {} scans x {} pass(es) ...",
                    versions.octomap,
                    versions.python,
                    versions.numpy,
                    log.scans.len(),
                    options.passes
                );
                let scans_file = work.path().join("scans.bin");
                let cells_file = work.path().join("cells.bin");
                let file = File::create(&scans_file)
                    .with_context(|| format!("creating {}", scans_file.display()))?;
                point_cloud::write_clouds(BufWriter::new(file), &clouds)
                    .with_context(|| format!("writing {}", scans_file.display()))?;
                let settings = OctomapSettings {
                    resolution: options.resolution,
                    prob_hit: ray.hit_probability,
                    prob_miss: ray.miss_probability,
                    clamp,
                    max_range: mapped_range,
                    passes: options.passes,
                    time_empty_calls: false,
                };
                Ok(script.run(&scans_file, &cells_file, &settings)?)
            }
            Err(reason) if options.octomap => {
                bail!("--octomap: OctoMap's side cannot run: {reason}")
            }
            Err(reason) => {
                deog_harness::eprintln_above_bars!(
                    "OctoMap: not run: {reason}; reporting deog alone"
                );
                Err(reason)
            }
        }
    };
    let agreement = octomap
        .as_ref()
        .ok()
        .map(|o| agreement::compare(&deog.map, &o.cells));
    let figures = LaserMappingFigures {
        config,
        deog,
        octomap,
        agreement,
    };
    deog_harness::print_above_bars!("{}", figures.table());
    if let Some(path) = &options.json {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
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
        options: LaserMappingOptions,
    }

    fn try_parse(args: &[&str]) -> Result<LaserMappingOptions, clap::Error> {
        Cli::try_parse_from(std::iter::once("laser-mapping").chain(args.iter().copied()))
            .map(|cli| cli.options)
    }

    fn parse(args: &[&str]) -> LaserMappingOptions {
        try_parse(args).expect("options parse")
    }

    #[test]
    fn the_defaults_are_valid() {
        let options = parse(&[]);
        assert_eq!(
            options.log,
            PathBuf::from("data/carmen/intel-corrected.log.gz")
        );
        assert_eq!(
            (options.resolution, options.max_range, options.passes),
            (0.05, 20.0, 3)
        );
        assert_eq!(options.python, PathBuf::from("python3"));
        assert!(!options.no_octomap && !options.octomap && options.json.is_none());
        assert_eq!(options.validate(), Ok(()));
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        for (flag, args) in [
            ("--resolution", &["--resolution", "0"][..]),
            ("--resolution", &["--resolution", "NaN"][..]),
            ("--resolution", &["--resolution", "200"][..]),
            ("--max-range", &["--max-range", "0"][..]),
            ("--max-range", &["--max-range", "inf"][..]),
            ("--passes", &["--passes", "0"][..]),
        ] {
            let err = parse(args).validate().expect_err(flag);
            assert_eq!(err.flag, flag);
            assert!(err.to_string().starts_with(flag), "{err}");
        }
    }

    #[test]
    fn octomap_cannot_be_both_demanded_and_refused() {
        assert!(try_parse(&["--octomap", "--no-octomap"]).is_err());
        assert!(parse(&["--octomap"]).octomap);
        assert!(parse(&["--no-octomap"]).no_octomap);
    }

    #[test]
    fn a_missing_log_is_named() {
        let err = parse(&["--log", "/nonexistent/intel.log.gz"])
            .check_log()
            .expect_err("missing");
        assert_eq!(err.flag, "--log");
        assert!(
            err.to_string().contains("/nonexistent/intel.log.gz"),
            "{err}"
        );
    }
}
