//! `deog bench fuzz`: every decoder of outside input fed mutated bytes for
//! a fixed budget, on stable Rust without coverage feedback.
//!
//! Each target (`targets`) feeds bytes to the decoder a server or command
//! uses on what it is sent or given: the packed tile cells, the wire
//! requests the map server and the simulator accept (prost's decoding and
//! then the servers' own checks), rig files, map_server YAML and PGM, the
//! thesis data file, world files and CARMEN logs. A decoder must refuse bad
//! bytes with an error; a panic is a crash and an input slower than
//! `--hang-seconds` a hang. Crashing inputs are saved under `--crashes`
//! named by target and hash, and any crash makes the command fail, so it
//! can gate a release.
//!
//! Its parts: `mutate` (the seeded mutations), `engine` (one target run
//! for its budget, panics caught and saved), `targets` and `seeds` (the
//! decoders and the valid inputs they start from).

mod engine;
mod mutate;
mod seeds;
mod targets;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_harness::Progress;
use serde::Serialize;

use crate::option_error::{require, require_folder_of};

pub use engine::{Budget, Target, TargetRun, fuzz};
pub use targets::TARGETS;

/// Options of `deog bench fuzz`.
#[derive(Debug, Clone, Args)]
pub struct FuzzOptions {
    /// Targets to run, comma-separated. Default: all of them.
    #[arg(long, value_delimiter = ',')]
    pub targets: Vec<String>,
    /// Wall-clock seconds each target runs.
    #[arg(long, default_value_t = 600.0)]
    pub seconds_per_target: f64,
    /// Seed of the mutations: the same seed runs the same inputs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Folder the crashing and hanging inputs are written to.
    #[arg(long, default_value = "fuzz-crashes")]
    pub crashes: PathBuf,
    /// An input that takes longer than this many seconds is a hang.
    #[arg(long, default_value_t = 1.0)]
    pub hang_seconds: f64,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl FuzzOptions {
    /// The targets to run, in their order; an unknown name is an error
    /// that lists the known ones.
    pub fn selected(&self) -> Result<Vec<&'static Target>, crate::OptionError> {
        if self.targets.is_empty() {
            return Ok(TARGETS.iter().collect());
        }
        let mut chosen = Vec::new();
        for name in &self.targets {
            let target = targets::target(name.trim()).ok_or_else(|| crate::OptionError {
                flag: "--targets",
                message: format!(
                    "--targets: no target {name:?}; the targets are {}",
                    TARGETS
                        .iter()
                        .map(|t| t.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
            if !chosen.iter().any(|t: &&Target| t.name == target.name) {
                chosen.push(target);
            }
        }
        Ok(chosen)
    }

    /// Checks the options a run cannot start with.
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        require(
            self.seconds_per_target.is_finite() && self.seconds_per_target > 0.0,
            "--seconds-per-target",
            || {
                format!(
                    "--seconds-per-target must be a positive number of seconds, got {}",
                    self.seconds_per_target
                )
            },
        )?;
        require(
            self.hang_seconds.is_finite() && self.hang_seconds > 0.0,
            "--hang-seconds",
            || {
                format!(
                    "--hang-seconds must be a positive number of seconds, got {}",
                    self.hang_seconds
                )
            },
        )?;
        require(!self.crashes.is_file(), "--crashes", || {
            format!(
                "--crashes {}: is a file, not a folder",
                self.crashes.display()
            )
        })?;
        require_folder_of(self.json.as_deref(), "--json")?;
        self.selected().map(drop)
    }
}

/// Runs `deog bench fuzz`: prints a table of every target's execs, rate,
/// crashes and hangs, writes it as JSON to `--json` if given, and fails
/// when any target crashed.
pub fn run(options: FuzzOptions) -> Result<()> {
    options.validate()?;
    let budget = Budget {
        time: Duration::from_secs_f64(options.seconds_per_target),
        max_execs: None,
        hang_after: Duration::from_secs_f64(options.hang_seconds),
    };
    let mut runs = Vec::new();
    let targets = options.selected()?;
    let progress = Progress::new("fuzzing", "targets", targets.len() as u64);
    for target in targets {
        deog_harness::eprintln_above_bars!(
            "fuzzing {} for {} s",
            target.name,
            options.seconds_per_target
        );
        runs.push(fuzz(target, &budget, options.seed, &options.crashes)?);
        progress.inc(1);
    }
    progress.finish();
    deog_harness::print_above_bars!("{}", table(&runs));
    if let Some(path) = &options.json {
        std::fs::write(path, json(&options, &runs)?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
    }
    let crashed: Vec<_> = runs
        .iter()
        .filter(|r| r.crashes > 0)
        .map(|r| r.target)
        .collect();
    if !crashed.is_empty() {
        bail!(
            "crashes in {}; their inputs are in {}",
            crashed.join(", "),
            options.crashes.display()
        );
    }
    Ok(())
}

/// The figures as a table, one row a target, then each first crash.
pub fn table(runs: &[TargetRun]) -> String {
    let mut out = format!(
        "{:<22} {:>12} {:>10} {:>8} {:>6} {:>11}\n",
        "target", "execs", "execs/s", "crashes", "hangs", "slowest ms"
    );
    for r in runs {
        out.push_str(&format!(
            "{:<22} {:>12} {:>10.0} {:>8} {:>6} {:>11.1}\n",
            r.target,
            r.execs,
            r.execs_per_s(),
            r.crashes,
            r.hangs,
            r.slowest.as_secs_f64() * 1e3
        ));
    }
    for r in runs {
        if let (Some(message), Some(file)) = (&r.first_crash, &r.first_crash_file) {
            out.push_str(&format!(
                "{}: first crash {}: {message}\n",
                r.target,
                file.display()
            ));
        }
    }
    out
}

#[derive(Serialize)]
struct FuzzRecord<'a> {
    seed: u64,
    seconds_per_target: f64,
    hang_seconds: f64,
    targets: Vec<TargetRecord<'a>>,
}

#[derive(Serialize)]
struct TargetRecord<'a> {
    target: &'a str,
    execs: u64,
    seconds: f64,
    execs_per_s: f64,
    crashes: u64,
    hangs: u64,
    slowest_ms: f64,
    first_crash: Option<&'a str>,
    first_crash_file: Option<String>,
}

fn json(options: &FuzzOptions, runs: &[TargetRun]) -> Result<String> {
    let record = FuzzRecord {
        seed: options.seed,
        seconds_per_target: options.seconds_per_target,
        hang_seconds: options.hang_seconds,
        targets: runs
            .iter()
            .map(|r| TargetRecord {
                target: r.target,
                execs: r.execs,
                seconds: r.elapsed.as_secs_f64(),
                execs_per_s: r.execs_per_s(),
                crashes: r.crashes,
                hangs: r.hangs,
                slowest_ms: r.slowest.as_secs_f64() * 1e3,
                first_crash: r.first_crash.as_deref(),
                first_crash_file: r.first_crash_file.as_ref().map(|f| f.display().to_string()),
            })
            .collect(),
    };
    serde_json::to_string_pretty(&record).context("encoding the figures as JSON")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> FuzzOptions {
        FuzzOptions {
            targets: Vec::new(),
            seconds_per_target: 1.0,
            seed: 1,
            crashes: PathBuf::from("fuzz-crashes"),
            hang_seconds: 1.0,
            json: None,
        }
    }

    #[test]
    fn the_defaults_are_valid_and_run_every_target() {
        options().validate().unwrap();
        assert_eq!(options().selected().unwrap().len(), TARGETS.len());
    }

    #[test]
    fn an_unknown_target_is_refused_listing_the_known_ones() {
        let bad = FuzzOptions {
            targets: vec!["map-yaml".into(), "wire-nope".into()],
            ..options()
        };
        let error = bad.validate().unwrap_err();
        assert_eq!(error.flag, "--targets");
        assert!(error.message.contains("\"wire-nope\""), "{}", error.message);
        assert!(error.message.contains("tile-cells"), "{}", error.message);
    }

    #[test]
    fn targets_are_chosen_once_in_the_order_given() {
        let some = FuzzOptions {
            targets: vec!["map-pgm".into(), "tile-cells".into(), "map-pgm".into()],
            ..options()
        };
        let names: Vec<_> = some.selected().unwrap().iter().map(|t| t.name).collect();
        assert_eq!(names, ["map-pgm", "tile-cells"]);
    }

    #[test]
    fn budgets_must_be_positive_and_finite() {
        for seconds in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let bad = FuzzOptions {
                seconds_per_target: seconds,
                ..options()
            };
            assert_eq!(bad.validate().unwrap_err().flag, "--seconds-per-target");
            let bad = FuzzOptions {
                hang_seconds: seconds,
                ..options()
            };
            assert_eq!(bad.validate().unwrap_err().flag, "--hang-seconds");
        }
    }

    #[test]
    fn a_crashes_folder_that_is_a_file_is_refused() {
        let file = tempfile::NamedTempFile::new().unwrap();
        let bad = FuzzOptions {
            crashes: file.path().to_path_buf(),
            ..options()
        };
        assert_eq!(bad.validate().unwrap_err().flag, "--crashes");
        let bad = FuzzOptions {
            json: Some(PathBuf::from("/no/such/folder/fuzz.json")),
            ..options()
        };
        assert_eq!(bad.validate().unwrap_err().flag, "--json");
    }

    #[test]
    fn the_table_names_each_target_and_its_first_crash() {
        let run = TargetRun {
            target: "map-yaml",
            execs: 1000,
            elapsed: Duration::from_secs(2),
            crashes: 3,
            hangs: 0,
            first_crash: Some("panicked at yaml.rs:1:1: boom".into()),
            first_crash_file: Some(PathBuf::from("fuzz-crashes/map-yaml-00")),
            slowest: Duration::from_millis(4),
        };
        let table = table(&[run]);
        assert!(table.contains("map-yaml"), "{table}");
        assert!(table.contains("500"), "{table}");
        assert!(table.contains("boom"), "{table}");
    }
}
