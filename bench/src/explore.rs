//! `deog bench explore`: wanderers and explorers on the same world, seeds
//! and robot counts, side by side. Each run is a whole `deog demo` (a child
//! process of this binary, with `--no-localize --no-view`, and `--explore`
//! for the explorers) in a folder of its own under `--out`; its report.json
//! gives the coverage curve, the map's quality, the bumps and when the
//! robots stopped.
//!
//! Printed and written (`--json`): per run, the simulated seconds to 95%
//! and 99% of the reachable free space, the last coverage, the share of
//! observed cells the map has right, bumps, and whether the drivers ended
//! by themselves before `--duration`; per driver and robot count, their
//! means over the seeds; and per robot count, the explorers' time to 99%
//! over the wanderers' time to 95%.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use deog_harness::progress::Progress;
use deog_harness::{Role, Supervisor};
use serde::Serialize;
use serde_json::Value;

use crate::option_error::{OptionError, require, require_folder_of};

/// Options of `deog bench explore`.
#[derive(Debug, Clone, Args)]
pub struct ExploreBenchOptions {
    /// The world: a built-in name or a file, as `deog demo --world` takes it.
    #[arg(long, default_value = "office")]
    pub world: String,
    /// Robot counts to run, comma-separated (each 1 to 8).
    #[arg(long, value_delimiter = ',', default_value = "3")]
    pub robots: Vec<u32>,
    /// Seeded runs per driver and robot count.
    #[arg(long, default_value_t = 1)]
    pub seeds: u64,
    /// The first seed; runs use this one and those after it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds a run may last: the wanderers drive this long,
    /// the explorers at most this long.
    #[arg(long, default_value_t = 1200.0)]
    pub duration: f64,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 4.0)]
    pub speed: f64,
    /// The drivers compared, comma-separated: wander, explore.
    #[arg(long, value_delimiter = ',', default_value = "wander,explore")]
    pub drivers: Vec<Driver>,
    /// Folder for each run's demo output.
    #[arg(long, default_value = "bench-explore-out")]
    pub out: PathBuf,
    /// Also write the figures here as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What drives the robots in a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Driver {
    /// The thesis's wanderer: at random, turning away from walls.
    Wander,
    /// `deog explore`: to the shared map's frontiers.
    Explore,
}

impl Driver {
    fn name(self) -> &'static str {
        match self {
            Driver::Wander => "wander",
            Driver::Explore => "explore",
        }
    }
}

/// One run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct ExploreRun {
    /// What drove the robots.
    pub driver: Driver,
    /// How many robots.
    pub robots: u32,
    /// The demo's seed.
    pub seed: u64,
    /// Simulated seconds to 95% of the reachable free space; `None` if
    /// never.
    pub coverage_95_s: Option<f64>,
    /// The same for 99%.
    pub coverage_99_s: Option<f64>,
    /// The coverage when the robots stopped.
    pub final_coverage: f64,
    /// Observed cells the map has right.
    pub map_correct: f64,
    /// Bumps into obstacles, all robots together.
    pub bumps: u64,
    /// Simulated seconds until the last robot stopped.
    pub driven_s: f64,
    /// Whether the drivers ended by themselves before `--duration`.
    pub ended_by_itself: bool,
    /// Wall-clock seconds of the whole demo.
    pub wall_s: f64,
    /// The demo's output folder.
    pub out: PathBuf,
}

/// One driver and robot count over the seeds.
#[derive(Debug, Clone, Serialize)]
pub struct ExploreSummary {
    /// What drove the robots.
    pub driver: Driver,
    /// How many robots.
    pub robots: u32,
    /// Runs (seeds).
    pub runs: usize,
    /// Runs that reached 95%.
    pub reached_95: usize,
    /// Runs that reached 99%.
    pub reached_99: usize,
    /// Mean simulated seconds to 95% over the runs that reached it.
    pub mean_coverage_95_s: Option<f64>,
    /// The same for 99%.
    pub mean_coverage_99_s: Option<f64>,
    /// Mean coverage when the robots stopped.
    pub mean_final_coverage: f64,
    /// The worst run's share of observed cells right.
    pub min_map_correct: f64,
    /// Bumps, all runs together.
    pub bumps: u64,
    /// Runs whose drivers ended by themselves.
    pub ended_by_itself: usize,
}

/// Everything `deog bench explore` measured.
#[derive(Debug, Clone, Serialize)]
pub struct ExploreBenchReport {
    /// The world.
    pub world: String,
    /// The most simulated seconds a run could last.
    pub duration_s: f64,
    /// Simulated seconds per wall-clock second.
    pub speed: f64,
    /// Every run, in the order run.
    pub runs: Vec<ExploreRun>,
    /// Per driver and robot count.
    pub summary: Vec<ExploreSummary>,
}

impl ExploreBenchOptions {
    /// Checks the options; the error names the flag.
    pub fn validate(&self) -> Result<(), OptionError> {
        require(!self.robots.is_empty(), "--robots", || {
            "--robots needs at least one count".to_string()
        })?;
        for &robots in &self.robots {
            require((1..=8).contains(&robots), "--robots", || {
                format!("--robots takes counts from 1 to 8, got {robots}")
            })?;
        }
        require((1..=100).contains(&self.seeds), "--seeds", || {
            format!("--seeds must be 1 to 100, got {}", self.seeds)
        })?;
        require(
            self.duration.is_finite() && self.duration >= 10.0,
            "--duration",
            || format!("--duration must be at least 10 s, got {}", self.duration),
        )?;
        require(
            self.speed.is_finite() && self.speed > 0.0 && self.speed <= 100.0,
            "--speed",
            || {
                format!(
                    "--speed must be above 0 and at most 100, got {}",
                    self.speed
                )
            },
        )?;
        require(!self.drivers.is_empty(), "--drivers", || {
            "--drivers needs wander, explore or both".to_string()
        })?;
        require_folder_of(self.json.as_deref(), "--json")
    }

    /// The runs, robot count by robot count, each driver on each seed.
    fn runs(&self) -> Vec<(Driver, u32, u64)> {
        let mut runs = Vec::new();
        for &robots in &self.robots {
            for &driver in &self.drivers {
                for seed in self.seed..self.seed + self.seeds {
                    runs.push((driver, robots, seed));
                }
            }
        }
        runs
    }
}

/// Runs the benchmark and prints (and writes) its figures.
pub fn run(options: ExploreBenchOptions) -> Result<()> {
    options.validate()?;
    std::fs::create_dir_all(&options.out)
        .with_context(|| format!("creating {}", options.out.display()))?;
    let plan = options.runs();
    println!(
        "deog bench explore: {} runs of {} in {} (up to {} simulated s at {}x each)",
        plan.len(),
        options
            .drivers
            .iter()
            .map(|d| d.name())
            .collect::<Vec<_>>()
            .join(" and "),
        options.world,
        options.duration,
        options.speed
    );
    let progress = Progress::new("exploring runs", "runs", plan.len() as u64);
    let mut runs = Vec::with_capacity(plan.len());
    for (driver, robots, seed) in plan {
        let run = run_one(&options, driver, robots, seed)?;
        progress.suspend(|| println!("{}", run_line(&run)));
        runs.push(run);
        progress.inc(1);
    }
    progress.finish();
    let report = ExploreBenchReport {
        world: options.world.clone(),
        duration_s: options.duration,
        speed: options.speed,
        summary: summarize(&runs),
        runs,
    };
    print!("{}", table(&report));
    if let Some(path) = &options.json {
        let text = serde_json::to_string_pretty(&report).context("assembling the JSON")?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// One demo, run to its end and read back.
fn run_one(
    options: &ExploreBenchOptions,
    driver: Driver,
    robots: u32,
    seed: u64,
) -> Result<ExploreRun> {
    let name = format!("{}-{robots}-seed{seed}", driver.name());
    let out = options.out.join(&name);
    let mut args: Vec<OsString> = vec![
        "demo".into(),
        "--no-localize".into(),
        "--no-view".into(),
        "--world".into(),
        options.world.clone().into(),
        "--robots".into(),
        robots.to_string().into(),
        "--seed".into(),
        seed.to_string().into(),
        "--duration".into(),
        options.duration.to_string().into(),
        "--speed".into(),
        options.speed.to_string().into(),
        "--out".into(),
        out.clone().into(),
    ];
    if driver == Driver::Explore {
        args.push("--explore".into());
    }
    let mut children = Supervisor::new(&options.out.join("logs"))?;
    let began = Instant::now();
    children.start(&name, Role::Task, &args)?;
    while !children.all_done(&name) {
        std::thread::sleep(Duration::from_millis(500));
        children.check()?;
    }
    children.check()?;
    let wall_s = began.elapsed().as_secs_f64();
    read_run(&out, driver, robots, seed, options.duration, wall_s)
}

/// The figures of one run from its report.json.
fn read_run(
    out: &Path,
    driver: Driver,
    robots: u32,
    seed: u64,
    duration_s: f64,
    wall_s: f64,
) -> Result<ExploreRun> {
    let path = out.join("report.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let json: Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let number = |key: &str| json[key].as_f64();
    let final_coverage = json["coverage"]
        .as_array()
        .and_then(|samples| samples.last())
        .and_then(|s| s["fraction"].as_f64())
        .unwrap_or(0.0);
    let driven_s = number("driven_s").context("report.json has no driven_s")?;
    Ok(ExploreRun {
        driver,
        robots,
        seed,
        coverage_95_s: number("coverage_95_s"),
        coverage_99_s: number("coverage_99_s"),
        final_coverage,
        map_correct: json["map"]["fraction_correct"].as_f64().unwrap_or(0.0),
        bumps: json["bumps"]
            .as_object()
            .map_or(0, |b| b.values().filter_map(Value::as_u64).sum()),
        driven_s,
        // The demo's clock is sampled a quarter-second apart: a run that
        // ran its course ends at or just past the duration.
        ended_by_itself: driven_s < duration_s - 2.0,
        wall_s,
        out: out.to_path_buf(),
    })
}

/// Means per driver and robot count, in the order first run.
fn summarize(runs: &[ExploreRun]) -> Vec<ExploreSummary> {
    let mut keys: Vec<(Driver, u32)> = Vec::new();
    for run in runs {
        if !keys.contains(&(run.driver, run.robots)) {
            keys.push((run.driver, run.robots));
        }
    }
    keys.into_iter()
        .map(|(driver, robots)| {
            let group: Vec<&ExploreRun> = runs
                .iter()
                .filter(|r| r.driver == driver && r.robots == robots)
                .collect();
            let times_95: Vec<f64> = group.iter().filter_map(|r| r.coverage_95_s).collect();
            let times_99: Vec<f64> = group.iter().filter_map(|r| r.coverage_99_s).collect();
            ExploreSummary {
                driver,
                robots,
                runs: group.len(),
                reached_95: times_95.len(),
                reached_99: times_99.len(),
                mean_coverage_95_s: mean(&times_95),
                mean_coverage_99_s: mean(&times_99),
                mean_final_coverage: mean(
                    &group.iter().map(|r| r.final_coverage).collect::<Vec<_>>(),
                )
                .unwrap_or(0.0),
                min_map_correct: group
                    .iter()
                    .map(|r| r.map_correct)
                    .fold(f64::INFINITY, f64::min),
                bumps: group.iter().map(|r| r.bumps).sum(),
                ended_by_itself: group.iter().filter(|r| r.ended_by_itself).count(),
            }
        })
        .collect()
}

fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

fn seconds(value: Option<f64>) -> String {
    value.map_or("never".to_string(), |s| format!("{s:.0} s"))
}

/// One run, as printed when it ends.
fn run_line(run: &ExploreRun) -> String {
    format!(
        "{} x{} seed {}: 95% at {}, 99% at {}, {:.1}% covered, {:.1}% right, {} bumps, stopped at {:.0} s{} ({:.0} s wall)",
        run.driver.name(),
        run.robots,
        run.seed,
        seconds(run.coverage_95_s),
        seconds(run.coverage_99_s),
        100.0 * run.final_coverage,
        100.0 * run.map_correct,
        run.bumps,
        run.driven_s,
        if run.ended_by_itself {
            " by itself"
        } else {
            ""
        },
        run.wall_s
    )
}

/// The summary table, and each robot count's ratio when both drivers ran.
fn table(report: &ExploreBenchReport) -> String {
    let mut out = String::from(
        "\n| driver | robots | runs | 95% reached | mean to 95% | 99% reached | mean to 99% | final coverage | worst map right | bumps | ended by itself |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for s in &report.summary {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.1}% | {:.1}% | {} | {} |\n",
            s.driver.name(),
            s.robots,
            s.runs,
            s.reached_95,
            seconds(s.mean_coverage_95_s),
            s.reached_99,
            seconds(s.mean_coverage_99_s),
            100.0 * s.mean_final_coverage,
            100.0 * s.min_map_correct,
            s.bumps,
            s.ended_by_itself
        ));
    }
    for explore in report
        .summary
        .iter()
        .filter(|s| s.driver == Driver::Explore)
    {
        let wander = report
            .summary
            .iter()
            .find(|s| s.driver == Driver::Wander && s.robots == explore.robots);
        if let (Some(e99), Some(w95)) = (
            explore.mean_coverage_99_s,
            wander.and_then(|w| w.mean_coverage_95_s),
        ) {
            out.push_str(&format!(
                "{} robots: explorers' time to 99% over the wanderers' to 95%: {:.2}\n",
                explore.robots,
                e99 / w95
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(driver: Driver, robots: u32, t95: Option<f64>, t99: Option<f64>) -> ExploreRun {
        ExploreRun {
            driver,
            robots,
            seed: 1,
            coverage_95_s: t95,
            coverage_99_s: t99,
            final_coverage: 0.99,
            map_correct: 0.98,
            bumps: 1,
            driven_s: 300.0,
            ended_by_itself: driver == Driver::Explore,
            wall_s: 80.0,
            out: PathBuf::from("x"),
        }
    }

    #[test]
    fn summaries_average_the_runs_that_reached_a_coverage() {
        let runs = [
            run(Driver::Wander, 3, Some(600.0), None),
            run(Driver::Wander, 3, None, None),
            run(Driver::Explore, 3, Some(200.0), Some(250.0)),
            run(Driver::Explore, 3, Some(220.0), Some(290.0)),
        ];
        let summary = summarize(&runs);
        assert_eq!(summary.len(), 2);
        let wander = &summary[0];
        assert_eq!(
            (wander.runs, wander.reached_95, wander.reached_99),
            (2, 1, 0)
        );
        assert_eq!(wander.mean_coverage_95_s, Some(600.0));
        assert_eq!(wander.mean_coverage_99_s, None);
        assert_eq!(wander.bumps, 2);
        let explore = &summary[1];
        assert_eq!(explore.mean_coverage_99_s, Some(270.0));
        assert_eq!(explore.ended_by_itself, 2);
        let report = ExploreBenchReport {
            world: "office".into(),
            duration_s: 1200.0,
            speed: 4.0,
            runs: runs.to_vec(),
            summary,
        };
        assert!(
            table(&report)
                .contains("3 robots: explorers' time to 99% over the wanderers' to 95%: 0.45")
        );
    }

    #[test]
    fn bad_options_name_their_flag() {
        let mut options = ExploreBenchOptions {
            world: "office".into(),
            robots: vec![1, 9],
            seeds: 1,
            seed: 1,
            duration: 600.0,
            speed: 4.0,
            drivers: vec![Driver::Wander],
            out: PathBuf::from("out"),
            json: None,
        };
        assert_eq!(options.validate().expect_err("9 robots").flag, "--robots");
        options.robots = vec![2];
        options.duration = 1.0;
        assert_eq!(options.validate().expect_err("short").flag, "--duration");
        options.duration = 600.0;
        assert!(options.validate().is_ok());
        assert_eq!(options.runs(), [(Driver::Wander, 2, 1)]);
    }

    #[test]
    fn a_report_is_read_back_from_the_demos_json() {
        let dir = std::env::temp_dir().join(format!("deog-bench-explore-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a folder");
        std::fs::write(
            dir.join("report.json"),
            r#"{"coverage": [{"simulated_s": 10.0, "fraction": 0.5}, {"simulated_s": 412.5, "fraction": 0.995}],
                "coverage_95_s": 300.0, "coverage_99_s": 400.0, "map": {"fraction_correct": 0.98},
                "bumps": {"scout-1": 0, "scout-2": 1}, "driven_s": 412.5}"#,
        )
        .expect("written");
        let run = read_run(&dir, Driver::Explore, 2, 1, 1200.0, 100.0).expect("read");
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(run.coverage_99_s, Some(400.0));
        assert_eq!(run.final_coverage, 0.995);
        assert_eq!(run.bumps, 1);
        assert!(run.ended_by_itself);
    }
}
