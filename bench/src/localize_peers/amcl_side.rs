//! amcl's side: `bench/localize_peers_amcl.py` (built into this crate, so
//! the bench runs from any directory) as a child process of the chosen
//! interpreter, reading the frames, grid and run files and printing its
//! report as one JSON object.

use std::ffi::OsString;
use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, bail, ensure};

use crate::python_script::{PythonScript, failure};
use deog_grid::Pose2;
use serde::{Deserialize, Serialize};

use super::deog_side::{FilterRun, Prior, RunSpec};

/// The script, as kept in the repository.
const SCRIPT: &str = include_str!("../../localize_peers_amcl.py");

/// How to install what the script needs.
pub(super) const INSTALL_HINT: &str = "pip install amcl numpy";

/// The versions the script reports.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
pub(super) struct Versions {
    /// The interpreter's.
    pub python: String,
    /// numpy's.
    pub numpy: String,
    /// The `amcl` distribution's (it bundles nav2's amcl core).
    pub amcl: String,
}

/// nav2 amcl's odometry noise (its `alpha1`..`alpha5`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(super) struct MotionParams {
    pub alpha1: f64,
    pub alpha2: f64,
    pub alpha3: f64,
    pub alpha4: f64,
    pub alpha5: f64,
}

/// nav2 amcl's beam model (the only laser model the package binds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(super) struct LaserParams {
    pub z_hit: f64,
    pub z_short: f64,
    pub z_max: f64,
    pub z_rand: f64,
    /// Metres.
    pub sigma_hit: f64,
    pub lambda_short: f64,
    pub chi_outlier: f64,
    /// Beams used per scan.
    pub max_beams: u32,
}

/// One amcl run in the run file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct AmclRun {
    pub name: String,
    pub min_particles: usize,
    pub max_particles: usize,
    /// Rates of the slow and fast likelihood averages (random particles
    /// are injected when the fast falls below the slow; 0 and 0: never).
    pub alpha_slow: f64,
    pub alpha_fast: f64,
    /// The initial pose: x, y (metres), theta (radians).
    pub initial_pose: [f64; 3],
    /// Its standard deviations: x, y (metres), theta (radians).
    pub initial_std: [f64; 3],
}

/// The run file: amcl's settings and its runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct AmclSettings {
    pub motion: MotionParams,
    pub laser: LaserParams,
    /// "differential".
    pub robot_model: String,
    /// Metres driven, or radians turned, before the next filter update
    /// (nav2's `update_min_d`, `update_min_a`).
    pub update_min_d: f64,
    pub update_min_a: f64,
    pub runs: Vec<AmclRun>,
}

impl AmclSettings {
    /// nav2's defaults for a scan of `beams` beams (every beam used: its
    /// default of 60 is more than a sonar ring has, and the package's beam
    /// step would then be 0), updates after `update` (metres, radians),
    /// and no runs yet.
    pub fn nav2_defaults(beams: u32, update: (f64, f64)) -> Self {
        Self {
            motion: MotionParams {
                alpha1: 0.2,
                alpha2: 0.2,
                alpha3: 0.2,
                alpha4: 0.2,
                alpha5: 0.2,
            },
            laser: LaserParams {
                z_hit: 0.5,
                z_short: 0.05,
                z_max: 0.05,
                z_rand: 0.5,
                sigma_hit: 0.2,
                lambda_short: 0.1,
                chi_outlier: 0.0,
                max_beams: beams,
            },
            robot_model: "differential".into(),
            update_min_d: update.0,
            update_min_a: update.1,
            runs: Vec::new(),
        }
    }

    /// Adds `spec` as an amcl run with the recovery rates `alpha` (slow,
    /// fast); false, adding nothing, for a prior amcl cannot start from.
    pub fn add_run(&mut self, spec: &RunSpec, alpha: (f64, f64)) -> bool {
        let Prior::Gaussian {
            centre,
            std_xy,
            std_theta,
        } = spec.prior
        else {
            return false;
        };
        self.runs.push(AmclRun {
            name: spec.name.clone(),
            min_particles: spec.min_particles,
            max_particles: spec.max_particles,
            alpha_slow: alpha.0,
            alpha_fast: alpha.1,
            initial_pose: centre,
            initial_std: [std_xy, std_xy, std_theta],
        });
        true
    }
}

/// One run as the script reports it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub(super) struct ScriptRun {
    pub name: String,
    /// Filter updates made.
    pub updates: u64,
    /// Thread CPU seconds inside `AMCL.update`.
    pub update_cpu_s: f64,
    /// The estimate at every frame: x, y, theta.
    pub poses: Vec<[f64; 3]>,
}

/// The script's report.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub(super) struct ScriptReport {
    #[serde(flatten)]
    pub versions: Versions,
    /// Frames read.
    pub frames: usize,
    pub runs: Vec<ScriptRun>,
}

impl ScriptReport {
    /// Parses the script's stdout, checking it holds `frames` poses per
    /// run.
    pub fn parse(stdout: &[u8], frames: usize) -> Result<Self> {
        let report: Self = serde_json::from_slice(stdout).with_context(|| {
            let text = String::from_utf8_lossy(stdout);
            let head: String = text.chars().take(200).collect();
            format!("reading the script's report: {}", head.trim())
        })?;
        ensure!(
            report.frames == frames,
            "the script read {} frames of {frames}",
            report.frames
        );
        for run in &report.runs {
            ensure!(
                run.poses.len() == frames,
                "run {} reported {} poses for {frames} frames",
                run.name,
                run.poses.len()
            );
        }
        Ok(report)
    }

    /// Run `name` as a filter run, its particles scored known only for a
    /// fixed count (the package does not expose its sample count).
    pub fn filter_run(&self, spec: &AmclRun) -> Option<FilterRun> {
        let run = self.runs.iter().find(|r| r.name == spec.name)?;
        let fixed = spec.min_particles == spec.max_particles;
        Some(FilterRun {
            updates: run.updates,
            update_cpu_s: run.update_cpu_s,
            step_cpu_s: run.update_cpu_s,
            particles_scored: fixed.then(|| run.updates * spec.max_particles as u64),
            estimates: run
                .poses
                .iter()
                .map(|p| Some(Pose2::new(p[0], p[1], p[2])))
                .collect(),
        })
    }
}

/// The interpreter `python` with the script written into `work`.
pub(super) struct AmclScript(PythonScript);

impl AmclScript {
    /// Writes the script into `work` (a temporary directory) for `python`.
    pub fn new(python: impl Into<OsString>, work: &Path) -> Result<Self> {
        PythonScript::new(
            python,
            work,
            "localize_peers_amcl.py",
            SCRIPT,
            "amcl's side",
            INSTALL_HINT,
        )
        .map(Self)
    }

    /// The versions, or why the script cannot run: no such interpreter, or
    /// a module it needs missing (the reason then says how to install it).
    pub fn probe(&self) -> Result<Versions, String> {
        self.0.probe()
    }

    /// Runs amcl over the frames of `frames_file` on the grid of
    /// `grid_file` as `runs_file` says.
    pub fn run(
        &self,
        frames_file: &Path,
        grid_file: &Path,
        runs_file: &Path,
        frames: usize,
    ) -> Result<ScriptReport> {
        let output = self
            .command()
            .arg(frames_file)
            .arg(grid_file)
            .arg(runs_file)
            .output()
            .with_context(|| format!("running {}", self.0.python()))?;
        if !output.status.success() {
            bail!("{}", failure("amcl's runs", &output));
        }
        ScriptReport::parse(&output.stdout, frames)
    }

    fn command(&self) -> Command {
        self.0.command()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tracking(n: usize) -> RunSpec {
        RunSpec {
            name: format!("tracking-{n}"),
            min_particles: n,
            max_particles: n,
            prior: Prior::Gaussian {
                centre: [1.0, 2.0, 0.5],
                std_xy: 0.1,
                std_theta: 0.05,
            },
        }
    }

    #[test]
    fn the_run_file_has_the_keys_the_script_reads() {
        let mut settings = AmclSettings::nav2_defaults(16, (0.25, 0.2));
        assert!(settings.add_run(&tracking(500), (0.001, 0.1)));
        let uniform = RunSpec {
            prior: Prior::Uniform,
            ..tracking(500)
        };
        assert!(
            !settings.add_run(&uniform, (0.0, 0.0)),
            "amcl has no uniform start"
        );
        let json: serde_json::Value = serde_json::to_value(&settings).expect("serializes");
        for key in ["alpha1", "alpha2", "alpha3", "alpha4", "alpha5"] {
            assert!(json["motion"][key].is_number(), "{key}");
        }
        for key in [
            "z_hit",
            "z_short",
            "z_max",
            "z_rand",
            "sigma_hit",
            "lambda_short",
            "chi_outlier",
        ] {
            assert!(json["laser"][key].is_number(), "{key}");
        }
        assert_eq!(json["laser"]["max_beams"], 16);
        assert_eq!(json["robot_model"], "differential");
        assert_eq!(json["update_min_d"], 0.25);
        let run = &json["runs"][0];
        assert_eq!(run["name"], "tracking-500");
        assert_eq!(
            (run["min_particles"].as_u64(), run["max_particles"].as_u64()),
            (Some(500), Some(500))
        );
        assert_eq!(run["alpha_fast"], 0.1);
        assert_eq!(run["initial_pose"], serde_json::json!([1.0, 2.0, 0.5]));
        assert_eq!(run["initial_std"], serde_json::json!([0.1, 0.1, 0.05]));
        assert_eq!(json["runs"].as_array().map(Vec::len), Some(1));
    }

    #[test]
    fn the_report_is_parsed_and_checked_against_the_frames() {
        let text = br#"{"python": "3.11.7", "numpy": "2.4.6", "amcl": "0.1.2", "frames": 2,
            "width": 10, "height": 8,
            "runs": [{"name": "tracking-500", "updates": 1, "update_cpu_s": 0.004,
                      "poses": [[1.0, 2.0, 0.5], [1.1, 2.0, 0.5]]},
                     {"name": "global", "updates": 2, "update_cpu_s": 0.5,
                      "poses": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]}]}"#;
        let report = ScriptReport::parse(text, 2).expect("parses");
        assert_eq!(report.versions.amcl, "0.1.2");
        let mut settings = AmclSettings::nav2_defaults(16, (0.25, 0.2));
        settings.add_run(&tracking(500), (0.0, 0.0));
        let fixed = report.filter_run(&settings.runs[0]).expect("reported");
        assert_eq!((fixed.updates, fixed.particles_scored), (1, Some(500)));
        assert_eq!(fixed.estimates[1], Some(Pose2::new(1.1, 2.0, 0.5)));
        let adaptive = AmclRun {
            name: "global".into(),
            min_particles: 500,
            max_particles: 2000,
            ..settings.runs[0].clone()
        };
        let global = report.filter_run(&adaptive).expect("reported");
        assert_eq!(
            global.particles_scored, None,
            "adaptive counts are not exposed"
        );
        let missing = AmclRun {
            name: "nothing".into(),
            ..adaptive
        };
        assert!(report.filter_run(&missing).is_none());
        let err = ScriptReport::parse(text, 3).expect_err("3 frames expected");
        assert!(err.to_string().contains("2 frames of 3"), "{err}");
        let err = ScriptReport::parse(b"Traceback", 2).expect_err("not JSON");
        assert!(err.to_string().contains("Traceback"), "{err}");
    }
}
