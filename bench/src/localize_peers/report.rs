//! The figures of `deog bench localize-peers`: per run, deog's and amcl's
//! side by side with their ratio, printed as a table and written as JSON
//! for `--json`.

use std::fmt::Write as _;

use anyhow::{Context, Result};
use serde::Serialize;

use super::amcl_side::{AmclSettings, Versions};
use super::deog_side::{FilterRun, Prior};
use super::judge::Accuracy;

/// One side's figures for one run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(super) struct SideFigures {
    /// Filter updates (sensor corrections) made.
    pub updates: u64,
    /// Mean particles scored per update (null: the side does not say).
    pub mean_particles: Option<f64>,
    /// Thread CPU time per update, milliseconds.
    pub cpu_per_update_ms: Option<f64>,
    /// Thread CPU seconds of all updates.
    pub update_cpu_s: f64,
    /// Particles × beams scored per CPU second of the updates: one core's
    /// rate (null: particle count unknown).
    pub particle_beams_per_s: Option<f64>,
    /// Accuracy against the true poses.
    #[serde(flatten)]
    pub accuracy: Accuracy,
}

impl SideFigures {
    /// The figures of `run` with `beams` beams a frame, judged as
    /// `accuracy`.
    pub fn new(run: &FilterRun, beams: usize, accuracy: Accuracy) -> Self {
        let updates = run.updates;
        let per_update = |v: f64| (updates > 0).then(|| v / updates as f64);
        Self {
            updates,
            mean_particles: run.particles_scored.and_then(|p| per_update(p as f64)),
            cpu_per_update_ms: per_update(run.update_cpu_s * 1e3),
            update_cpu_s: run.update_cpu_s,
            particle_beams_per_s: run.particles_scored.and_then(|p| {
                (run.update_cpu_s > 0.0).then(|| (p * beams as u64) as f64 / run.update_cpu_s)
            }),
            accuracy,
        }
    }
}

/// One run on both sides.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct RunRow {
    /// "tracking-500", "global".
    pub name: String,
    /// Fewest and most particles.
    pub min_particles: usize,
    pub max_particles: usize,
    /// deog's prior.
    pub deog_prior: Prior,
    /// amcl's prior, when amcl ran (null: it cannot start from deog's).
    pub amcl_prior: Option<Prior>,
    pub deog: SideFigures,
    pub amcl: Option<SideFigures>,
}

/// One world's runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct WorldFigures {
    pub world: String,
    /// Frames both sides read.
    pub frames: usize,
    /// Simulated seconds the frames span.
    pub seconds: f64,
    /// The occupancy grid amcl read: cells wide and high.
    pub grid_width: u32,
    pub grid_height: u32,
    /// Its cells by class.
    pub grid_occupied: u64,
    pub grid_free: u64,
    pub grid_unknown: u64,
    /// deog's CPU seconds to build the range tables of every tile (and
    /// score two frames from the uniform prior), before and apart from
    /// the runs; null without a uniform run.
    pub table_cpu_s: Option<f64>,
    pub runs: Vec<RunRow>,
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct PeersReport {
    /// What the CPU figures count.
    pub cpu_clock: String,
    /// Beams a frame: the Scout's sonars.
    pub beams: usize,
    /// Minutes of wandering that built each map.
    pub map_minutes: f64,
    /// The bounds of settling: metres and radians.
    pub settle_position_m: f64,
    pub settle_heading_rad: f64,
    /// The versions amcl ran with (null: amcl skipped).
    pub amcl_versions: Option<Versions>,
    /// amcl's settings (null: amcl skipped).
    pub amcl_settings: Option<AmclSettings>,
    pub worlds: Vec<WorldFigures>,
}

impl PeersReport {
    /// The report as pretty JSON.
    pub fn json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(self).context("assembling the JSON")
    }
}

/// `v` with `digits` decimals, or a dash.
fn cell(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".into(), |v| format!("{v:.digits$}"))
}

/// `amcl / deog`, when both are there and deog's is not 0.
fn ratio(deog: Option<f64>, amcl: Option<f64>) -> Option<f64> {
    match (deog, amcl) {
        (Some(d), Some(a)) if d != 0.0 => Some(a / d),
        _ => None,
    }
}

/// A table line: label, deog's figure, amcl's, decimals, the scale the
/// figures are printed in.
type Line<'a> = (&'a str, Option<f64>, Option<f64>, usize, f64);

/// A run's table: a line per figure, deog | amcl | amcl/deog.
pub(super) fn table(row: &RunRow) -> String {
    let mut out = String::new();
    let amcl = row.amcl.as_ref();
    let lines: [Line; 8] = [
        (
            "updates",
            Some(row.deog.updates as f64),
            amcl.map(|a| a.updates as f64),
            0,
            1.0,
        ),
        (
            "particles (mean)",
            row.deog.mean_particles,
            amcl.and_then(|a| a.mean_particles),
            0,
            1.0,
        ),
        (
            "CPU per update, ms",
            row.deog.cpu_per_update_ms,
            amcl.and_then(|a| a.cpu_per_update_ms),
            3,
            1.0,
        ),
        (
            "particle-beams/s/core, M",
            row.deog.particle_beams_per_s,
            amcl.and_then(|a| a.particle_beams_per_s),
            2,
            1e-6,
        ),
        (
            "RMS position after settling, m",
            row.deog.accuracy.rms_position_m,
            amcl.and_then(|a| a.accuracy.rms_position_m),
            3,
            1.0,
        ),
        (
            "mean heading error after, °",
            row.deog.accuracy.mean_heading_deg,
            amcl.and_then(|a| a.accuracy.mean_heading_deg),
            2,
            1.0,
        ),
        (
            "settled after, s",
            row.deog.accuracy.settle_s,
            amcl.and_then(|a| a.accuracy.settle_s),
            1,
            1.0,
        ),
        (
            "RMS position whole run, m",
            row.deog.accuracy.rms_position_whole_m,
            amcl.and_then(|a| a.accuracy.rms_position_whole_m),
            3,
            1.0,
        ),
    ];
    let _ = writeln!(
        out,
        "  {:<32} {:>12} {:>12} {:>10}",
        "", "deog", "amcl", "amcl/deog"
    );
    for (label, d, a, digits, scale) in lines {
        let (d, a) = (d.map(|v| v * scale), a.map(|v| v * scale));
        let _ = writeln!(
            out,
            "  {label:<32} {:>12} {:>12} {:>10}",
            cell(d, digits),
            cell(a, digits),
            cell(ratio(d, a), 2)
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accuracy(settle: Option<f64>) -> Accuracy {
        Accuracy {
            settle_s: settle,
            rms_position_m: settle.map(|_| 0.1),
            mean_heading_deg: settle.map(|_| 2.0),
            rms_position_whole_m: Some(0.5),
        }
    }

    fn run(particles: Option<u64>) -> FilterRun {
        FilterRun {
            updates: 4,
            update_cpu_s: 0.002,
            step_cpu_s: 0.003,
            particles_scored: particles,
            estimates: Vec::new(),
        }
    }

    #[test]
    fn side_figures_divide_by_updates_and_cpu() {
        let f = SideFigures::new(&run(Some(2000)), 16, accuracy(Some(1.0)));
        assert_eq!(f.mean_particles, Some(500.0));
        assert_eq!(f.cpu_per_update_ms, Some(0.5));
        assert_eq!(f.particle_beams_per_s, Some(2000.0 * 16.0 / 0.002));
        let unknown = SideFigures::new(&run(None), 16, accuracy(None));
        assert_eq!(
            (unknown.mean_particles, unknown.particle_beams_per_s),
            (None, None)
        );
        let idle = SideFigures::new(
            &FilterRun {
                updates: 0,
                update_cpu_s: 0.0,
                ..run(Some(0))
            },
            16,
            accuracy(None),
        );
        assert_eq!(
            (idle.cpu_per_update_ms, idle.particle_beams_per_s),
            (None, None)
        );
    }

    #[test]
    fn the_table_and_json_show_both_sides_and_their_ratio() {
        let prior = Prior::Gaussian {
            centre: [0.0, 0.0, 0.0],
            std_xy: 0.1,
            std_theta: 0.1,
        };
        let row = RunRow {
            name: "tracking-500".into(),
            min_particles: 500,
            max_particles: 500,
            deog_prior: prior,
            amcl_prior: Some(prior),
            deog: SideFigures::new(&run(Some(2000)), 16, accuracy(Some(0.0))),
            amcl: Some(SideFigures::new(
                &FilterRun {
                    update_cpu_s: 0.02,
                    ..run(Some(2000))
                },
                16,
                accuracy(None),
            )),
        };
        let text = table(&row);
        let cpu = text
            .lines()
            .find(|l| l.contains("CPU per update"))
            .expect("a CPU line");
        assert!(cpu.ends_with("10.00"), "{cpu}");
        let settled = text.lines().find(|l| l.contains("settled")).expect("line");
        assert!(settled.contains('—'), "{settled}");
        let uniform = RunRow {
            deog_prior: Prior::Uniform,
            amcl_prior: None,
            amcl: None,
            ..row.clone()
        };
        assert!(
            table(&uniform)
                .lines()
                .nth(3)
                .expect("a line")
                .contains('—')
        );

        let report = PeersReport {
            cpu_clock: "thread".into(),
            beams: 16,
            map_minutes: 10.0,
            settle_position_m: 0.25,
            settle_heading_rad: 0.25,
            amcl_versions: None,
            amcl_settings: Some(AmclSettings::nav2_defaults(16, (0.25, 0.2))),
            worlds: vec![WorldFigures {
                world: "map2".into(),
                frames: 1802,
                seconds: 180.2,
                grid_width: 10,
                grid_height: 20,
                grid_occupied: 1,
                grid_free: 2,
                grid_unknown: 197,
                table_cpu_s: Some(0.5),
                runs: vec![row, uniform],
            }],
        };
        let json: serde_json::Value =
            serde_json::from_str(&report.json().expect("serializes")).expect("valid JSON");
        let runs = &json["worlds"][0]["runs"];
        assert_eq!(runs[0]["deog"]["cpu_per_update_ms"], 0.5);
        assert_eq!(runs[0]["amcl"]["cpu_per_update_ms"], 5.0);
        assert_eq!(runs[0]["deog"]["settle_s"], 0.0);
        assert_eq!(runs[0]["amcl"]["settle_s"], serde_json::Value::Null);
        assert_eq!(runs[0]["deog_prior"]["kind"], "gaussian");
        assert_eq!(runs[1]["deog_prior"]["kind"], "uniform");
        assert_eq!(runs[1]["amcl"], serde_json::Value::Null);
        assert_eq!(json["amcl_settings"]["laser"]["max_beams"], 16);
    }
}
