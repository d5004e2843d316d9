//! The figures `deog bench localize` prints, as JSON for `--json`.

use anyhow::{Context, Result};
use deog_evaluation::runs::{RunFigures, RunsSummary};
use serde::Serialize;

/// The whole file: the options that matter to the figures and one entry per
/// world.
#[derive(Debug, Clone, Serialize)]
pub(super) struct LocalizeReport {
    /// The rig's name.
    pub rig: String,
    /// The filter's sensor model.
    pub sensor: String,
    /// The sonar preset of the runs (`default`, `realistic`, `specular60`).
    pub sonar: String,
    /// Whether the map came from the default sonar whatever the runs'.
    pub clean_map: bool,
    /// Whether the map was refitted to its frames through the forward
    /// model (`--forward-fit`).
    pub forward_fit: bool,
    /// Whether the map was drawn from the world itself (`--true-map`).
    pub true_map: bool,
    /// Simulated minutes of mapping before the filter starts.
    pub map_minutes: f64,
    /// With `--growing-map`: the robots that built the map during each
    /// run and the simulated seconds between the filter's map refreshes;
    /// `None` for a map built before the runs.
    pub growing_map: Option<GrowingMapFigures>,
    /// The beam model's tempering τ; `None` for the likelihood field.
    pub beam_tempering: Option<f64>,
    /// The beam model's hit spread at zero range and its growth per
    /// metre, metres; `None` for the likelihood field.
    pub beam_hit_sigma_m: Option<f64>,
    pub beam_hit_sigma_per_m: Option<f64>,
    /// How far past the first occupied cell echoes were expected, metres;
    /// `None` for the likelihood field.
    pub surface_depth_m: Option<f64>,
    /// The probability above which the localizer took a map's cell for
    /// a wall (`--occupied-threshold`).
    pub occupied_threshold: f64,
    /// Seconds of a run, and its kidnap (0: none).
    pub seconds: f64,
    pub kidnap_at_s: f64,
    /// Convergence and recovery count when within this many seconds.
    pub converge_limit_s: f64,
    /// One entry per world, in the order run.
    pub worlds: Vec<WorldFigures>,
}

/// How a growing map was built and taken in.
#[derive(Debug, Clone, Copy, Serialize)]
pub(super) struct GrowingMapFigures {
    pub mappers: u64,
    pub refresh_s: f64,
}

/// One world's summary line and its runs.
#[derive(Debug, Clone, Serialize)]
pub(super) struct WorldFigures {
    pub world: String,
    /// Runs made.
    pub runs: usize,
    /// Runs whose filter converged within the limit.
    pub converged: usize,
    /// Runs whose filter found the robot again within the limit of the
    /// kidnap.
    pub recovered: usize,
    /// Mean position error after convergence, metres (null: none
    /// converged).
    pub mean_abs_error_m: Option<f64>,
    /// Mean heading error after convergence, degrees.
    pub mean_abs_error_deg: Option<f64>,
    /// Estimates flagged converged while more than 0.5 m or 0.25 rad off,
    /// over every run: a filter wrong and sure of it.
    pub false_converged: u64,
    /// Runs with at least one such estimate.
    pub runs_false_converged: usize,
    /// Every run, by seed.
    pub per_run: Vec<RunRow>,
}

/// One seeded run.
#[derive(Debug, Clone, Serialize)]
pub(super) struct RunRow {
    pub seed: u64,
    /// Seconds to convergence (null: never).
    pub converge_s: Option<f64>,
    /// Seconds from the kidnap to recovery (null: never).
    pub recover_s: Option<f64>,
    pub mean_abs_error_m: Option<f64>,
    pub mean_abs_error_deg: Option<f64>,
    /// Estimates flagged converged while more than 0.5 m or 0.25 rad off.
    pub false_converged: u64,
    /// Frames judged after convergence.
    pub samples: u64,
    /// The most particles the filter held from 10 s after it settled to
    /// the kidnap (null: it never settled that long before).
    pub most_particles_settled: Option<usize>,
}

impl WorldFigures {
    /// A world's figures from its runs (seeds from `first_seed`) and their
    /// summary.
    pub fn new(
        world: &str,
        first_seed: u64,
        runs: &[RunFigures],
        particles: &[Option<usize>],
        summary: &RunsSummary,
    ) -> Self {
        Self {
            world: world.to_string(),
            runs: summary.runs,
            converged: summary.converged,
            recovered: summary.recovered,
            mean_abs_error_m: summary.mean_position_m,
            mean_abs_error_deg: summary.mean_heading_deg,
            false_converged: summary.false_converged,
            runs_false_converged: summary.runs_false_converged,
            per_run: runs
                .iter()
                .zip(first_seed..)
                .zip(particles.iter().chain(std::iter::repeat(&None)))
                .map(|((run, seed), &most_particles_settled)| RunRow {
                    seed,
                    converge_s: run.converge_s,
                    recover_s: run.recover_s,
                    mean_abs_error_m: run.mean_position_m,
                    mean_abs_error_deg: run.mean_heading_deg,
                    false_converged: run.false_converged,
                    samples: run.samples,
                    most_particles_settled,
                })
                .collect(),
        }
    }
}

impl LocalizeReport {
    /// The report as pretty JSON.
    pub fn json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(self).context("assembling the JSON")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_evaluation::runs::summarize;

    #[test]
    fn the_json_has_the_summary_keys_per_world() {
        let runs = [
            RunFigures {
                converge_s: Some(12.0),
                recover_s: None,
                mean_position_m: Some(0.2),
                mean_heading_deg: Some(3.0),
                samples: 40,
                false_converged: 3,
            },
            RunFigures {
                converge_s: None,
                recover_s: None,
                mean_position_m: None,
                mean_heading_deg: None,
                samples: 0,
                false_converged: 0,
            },
        ];
        let summary = summarize(&runs, 60.0);
        let report = LocalizeReport {
            rig: "scout".into(),
            sensor: "beam".into(),
            sonar: "realistic".into(),
            clean_map: false,
            forward_fit: false,
            true_map: false,
            map_minutes: 1.0,
            growing_map: Some(GrowingMapFigures {
                mappers: 3,
                refresh_s: 20.0,
            }),
            beam_tempering: Some(0.08),
            beam_hit_sigma_m: Some(0.03),
            beam_hit_sigma_per_m: Some(0.005),
            surface_depth_m: Some(0.1),
            occupied_threshold: 0.65,
            seconds: 180.0,
            kidnap_at_s: 90.0,
            converge_limit_s: 60.0,
            worlds: vec![WorldFigures::new(
                "map1",
                7,
                &runs,
                &[Some(812), None],
                &summary,
            )],
        };
        let json: serde_json::Value =
            serde_json::from_str(&report.json().expect("serializes")).expect("valid JSON");
        let world = &json["worlds"][0];
        assert_eq!(world["world"], "map1");
        assert_eq!(world["runs"], 2);
        assert_eq!(world["converged"], 1);
        assert_eq!(world["recovered"], 0);
        assert_eq!(world["false_converged"], 3);
        assert_eq!(world["runs_false_converged"], 1);
        assert_eq!(world["per_run"][0]["false_converged"], 3);
        assert!(world["mean_abs_error_m"].is_number());
        assert!(world["mean_abs_error_deg"].is_number());
        assert_eq!(world["per_run"][1]["seed"], 8);
        assert_eq!(world["per_run"][1]["converge_s"], serde_json::Value::Null);
        assert_eq!(world["per_run"][0]["most_particles_settled"], 812);
        assert_eq!(
            world["per_run"][1]["most_particles_settled"],
            serde_json::Value::Null
        );
        assert_eq!(json["sonar"], "realistic");
        assert_eq!(json["beam_tempering"], 0.08);
        assert_eq!(json["beam_hit_sigma_m"], 0.03);
        assert_eq!(json["beam_hit_sigma_per_m"], 0.005);
        assert_eq!(json["surface_depth_m"], 0.1);
        assert_eq!(json["occupied_threshold"], 0.65);
        assert_eq!(json["map_minutes"], 1.0);
        assert_eq!(json["growing_map"]["mappers"], 3);
        assert_eq!(json["growing_map"]["refresh_s"], 20.0);
    }
}
