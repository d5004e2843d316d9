//! The demo's reports: report.json for tools, from the serde record
//! [`DemoReport`], and report.md for people (`markdown`). The keys of
//! report.json are an interface: README.md documents them and the
//! end-to-end test reads them.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use deog_evaluation::localization::{LocalizationRecord, PoseRecord};
use deog_evaluation::map_quality::MapQualityRecord;
use serde::Serialize;

use crate::coverage::{CoverageSample, time_to};
use crate::judge::Judgement;
use crate::kidnap::KidnapDone;
use crate::markdown;
use crate::plan::DemoPlan;

/// Everything the reports say about one run.
#[derive(Debug)]
pub(crate) struct DemoOutcome<'a> {
    /// What was run.
    pub plan: &'a DemoPlan,
    /// What the judging found.
    pub judgement: &'a Judgement,
    /// The kidnap, if one happened.
    pub kidnap: Option<&'a KidnapDone>,
    /// Wall-clock seconds from start to the end of the judging.
    pub wall_s: f64,
    /// Each robot's largest localizer lag, simulated seconds (`None`: its
    /// localizer never published an estimate while the robots drove).
    pub max_lags_s: Vec<(String, Option<f64>)>,
    /// The map's coverage of the reachable free space as the robots drove.
    pub coverage: Vec<CoverageSample>,
    /// Each process's name and command line, in the order they started.
    pub commands: Vec<(String, String)>,
    /// How the robots drove.
    pub driven: Driven,
}

/// How the robots drove, as the simulator saw it when the last one
/// stopped.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Driven {
    /// Simulated seconds until the last robot's driver ended.
    pub simulated_s: f64,
    /// Each robot's bumps into obstacles, in the plan's order.
    pub bumps: Vec<(String, u64)>,
}

impl DemoOutcome<'_> {
    /// `robot`'s largest localizer lag, simulated seconds.
    pub fn max_lag_s(&self, robot: &str) -> Option<f64> {
        self.max_lags_s
            .iter()
            .find(|(name, _)| name == robot)
            .and_then(|(_, lag)| *lag)
    }
}

/// report.json: the robots' and the map's figures, with the run's
/// settings. Figures that do not exist are `null`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DemoReport {
    /// Each robot's localization figures, in order from `scout-1`.
    pub robots: Vec<DemoRobotRecord>,
    /// The map against the world's ground truth.
    pub map: MapQualityRecord,
    /// The map refitted to every frame once the robots stopped (`deog
    /// refit`, loaded as map `demo-refit`), against the same truth; `null`
    /// when the demo did not refit (a sonar whose every wall echoes, or
    /// `--no-refit`).
    pub refit_map: Option<MapQualityRecord>,
    /// Wall-clock seconds the demo took, up to the end of the judging.
    pub duration_s: f64,
    /// Simulated seconds the robots drove (`--duration`).
    pub simulated_s: f64,
    /// Simulated seconds per wall-clock second (`--speed`).
    pub speed: f64,
    /// The world's name.
    pub world: String,
    /// The demo's seed (`--seed`).
    pub seed: u64,
    /// The simulated sonar's preset (`--sonar`): `default`, `realistic`
    /// or `specular60`.
    pub sonar: String,
    /// Simulated second the first localizer started (the others a few
    /// seconds apart after it).
    pub localize_at_s: f64,
    /// The kidnap; `null` when nobody was kidnapped.
    pub kidnap: Option<DemoKidnapRecord>,
    /// Whether explorers drove the robots (`--explore`) rather than
    /// wanderers.
    pub explore: bool,
    /// The pose the explorers drove from (`--explore-pose`): `true` or
    /// `estimate`.
    pub explore_pose: String,
    /// The map's coverage of the world's reachable free space, every 10
    /// simulated seconds and once the robots stopped.
    pub coverage: Vec<CoverageSample>,
    /// Simulated seconds until the coverage reached 95%; `null` if never.
    pub coverage_95_s: Option<f64>,
    /// The same for 99%.
    pub coverage_99_s: Option<f64>,
    /// Whether localizers ran (not with `--no-localize`).
    pub localize: bool,
    /// Simulated seconds until the last robot's driver ended: `simulated_s`
    /// for wanderers, less for explorers that found nothing left to explore.
    pub driven_s: f64,
    /// Each robot's bumps into obstacles, as the simulator counted them (a
    /// press of the bumper counts once).
    pub bumps: BTreeMap<String, u64>,
}

/// One robot in report.json: the localization library's record, and how
/// far its localizer fell behind while the robots drove.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DemoRobotRecord {
    /// The localization figures, their keys unchanged.
    #[serde(flatten)]
    pub localization: LocalizationRecord,
    /// The largest lag seen, simulated seconds between the robot's clock
    /// and the frame of its localizer's latest estimate, sampled at every
    /// status line; `null` when no estimate came while the robots drove.
    pub max_lag_s: Option<f64>,
}

/// The kidnap the demo made, in report.json.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DemoKidnapRecord {
    /// The robot carried off.
    pub robot: String,
    /// Simulated second it was carried off.
    pub time_s: f64,
    /// Its true pose before.
    pub from: PoseRecord,
    /// Its true pose after.
    pub to: PoseRecord,
}

impl DemoReport {
    /// The record of `outcome`.
    pub(crate) fn new(outcome: &DemoOutcome<'_>) -> Self {
        let plan = outcome.plan;
        Self {
            robots: outcome
                .judgement
                .robots
                .iter()
                .map(|r| DemoRobotRecord {
                    localization: r.report.record(),
                    max_lag_s: outcome.max_lag_s(&r.report.robot),
                })
                .collect(),
            map: outcome.judgement.quality.record(),
            refit_map: outcome.judgement.refit.as_ref().map(|r| r.quality.record()),
            duration_s: outcome.wall_s,
            simulated_s: plan.schedule.duration_s,
            speed: plan.schedule.speed,
            world: plan.world.name().to_string(),
            seed: plan.seed,
            sonar: plan.sonar.name().to_string(),
            localize_at_s: plan.schedule.localize_at_s,
            kidnap: outcome.kidnap.map(|k| DemoKidnapRecord {
                robot: k.robot.clone(),
                time_s: k.time_s,
                from: k.from.into(),
                to: k.to.into(),
            }),
            explore: plan.explore,
            explore_pose: plan.explore_pose.name().to_string(),
            coverage: outcome.coverage.clone(),
            coverage_95_s: time_to(&outcome.coverage, 0.95),
            coverage_99_s: time_to(&outcome.coverage, 0.99),
            localize: plan.localize,
            driven_s: outcome.driven.simulated_s,
            bumps: outcome.driven.bumps.iter().cloned().collect(),
        }
    }

    /// Pretty JSON with a closing newline.
    pub(crate) fn to_json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(self).context("assembling report.json")
    }
}

/// Writes report.md and report.json to `out`.
pub(crate) fn write_reports(outcome: &DemoOutcome<'_>, out: &Path) -> Result<()> {
    let md = out.join("report.md");
    std::fs::write(&md, markdown::report(outcome))
        .with_context(|| format!("writing {}", md.display()))?;
    let json = out.join("report.json");
    std::fs::write(&json, DemoReport::new(outcome).to_json()?)
        .with_context(|| format!("writing {}", json.display()))
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use serde_json::Value;

    use super::*;
    use crate::fixtures::{judgement, kidnap, quiet_outcome, two_robots};

    fn keys(value: &Value) -> BTreeSet<&str> {
        value
            .as_object()
            .expect("an object")
            .keys()
            .map(String::as_str)
            .collect()
    }

    #[test]
    fn report_json_keeps_its_keys_and_nesting() {
        let (plan, judgement, kidnap) = (two_robots(), judgement(), kidnap());
        let outcome = DemoOutcome {
            plan: &plan,
            judgement: &judgement,
            kidnap: Some(&kidnap),
            wall_s: 80.5,
            max_lags_s: vec![("scout-1".to_string(), Some(0.75))],
            coverage: vec![
                crate::coverage::CoverageSample {
                    simulated_s: 10.0,
                    fraction: 0.5,
                },
                crate::coverage::CoverageSample {
                    simulated_s: 20.0,
                    fraction: 0.97,
                },
            ],
            commands: Vec::new(),
            driven: Driven {
                simulated_s: 100.0,
                bumps: vec![("scout-1".to_string(), 0), ("scout-2".to_string(), 2)],
            },
        };
        let text = DemoReport::new(&outcome).to_json().expect("serialises");
        assert!(text.ends_with("}\n"));
        let json: Value = serde_json::from_str(&text).expect("JSON");
        assert_eq!(
            keys(&json),
            BTreeSet::from([
                "robots",
                "map",
                "refit_map",
                "duration_s",
                "simulated_s",
                "speed",
                "world",
                "seed",
                "sonar",
                "localize_at_s",
                "kidnap",
                "explore",
                "explore_pose",
                "coverage",
                "coverage_95_s",
                "coverage_99_s",
                "localize",
                "driven_s",
                "bumps"
            ])
        );
        assert_eq!(json["explore"], false);
        assert_eq!(json["explore_pose"], "true");
        assert_eq!(
            json["coverage"][1],
            serde_json::json!({"simulated_s": 20.0, "fraction": 0.97})
        );
        assert_eq!(json["coverage_95_s"], 20.0);
        assert_eq!(json["coverage_99_s"], Value::Null);
        assert_eq!(json["localize"], true);
        assert_eq!(json["driven_s"], 100.0);
        assert_eq!(
            json["bumps"],
            serde_json::json!({"scout-1": 0, "scout-2": 2})
        );
        assert_eq!(json["sonar"], "default");
        assert_eq!(json["duration_s"], 80.5);
        assert_eq!(json["simulated_s"], 100.0);
        assert_eq!(json["speed"], 4.0);
        assert_eq!(json["world"], "map2");
        assert_eq!(json["seed"], 1);
        assert_eq!(json["localize_at_s"], 25.0);
        let k = &json["kidnap"];
        assert_eq!(keys(k), BTreeSet::from(["robot", "time_s", "from", "to"]));
        assert_eq!(k["robot"], "scout-1");
        assert_eq!(k["time_s"], 50.25);
        assert_eq!(keys(&k["from"]), BTreeSet::from(["x", "y", "theta"]));
        assert_eq!(k["to"]["x"], 4.0);
        assert_eq!(k["to"]["theta"], -1.0);

        // The libraries' own JSON, its keys unchanged, and the lag.
        let robots = json["robots"].as_array().expect("robots");
        for (robot, judged) in robots.iter().zip(&judgement.robots) {
            let alone: Value = serde_json::from_str(&judged.report.to_json()).expect("JSON");
            let mut robot = robot.clone();
            robot
                .as_object_mut()
                .and_then(|o| o.remove("max_lag_s"))
                .expect("max_lag_s");
            assert_eq!(robot, alone);
        }
        assert_eq!(robots[0]["max_lag_s"], 0.75);
        assert_eq!(robots[1]["max_lag_s"], Value::Null);
        assert_eq!(robots[0]["kidnapped"], true);
        assert_eq!(robots[1]["recovered"], Value::Null);
        let map: Value = serde_json::from_str(&judgement.quality.to_json()).expect("JSON");
        assert_eq!(json["map"], map);
        assert_eq!(json["refit_map"], Value::Null);
    }

    #[test]
    fn a_refitted_map_is_judged_beside_the_live_one() {
        let plan = two_robots();
        let mut judgement = judgement();
        let mut refitted = judgement.quality.clone();
        refitted.confusion.free_as_uncertain = 0;
        refitted.confusion.free_as_free = 81;
        judgement.refit = Some(crate::judge::RefitJudgement {
            quality: refitted.clone(),
            map_png: "map-refit.png".to_string(),
            map_yaml: "map-refit.yaml".to_string(),
        });
        let outcome = quiet_outcome(&plan, &judgement);
        let json: Value = serde_json::from_str(&DemoReport::new(&outcome).to_json().expect("JSON"))
            .expect("JSON");
        let alone: Value = serde_json::from_str(&refitted.to_json()).expect("JSON");
        assert_eq!(json["refit_map"], alone);
        assert_ne!(json["refit_map"], json["map"]);
        let md = markdown::report(&outcome);
        assert!(md.contains("![refitted map](map-refit.png)"), "{md}");
        assert!(md.contains("(map-refit-verdict.png)"), "{md}");
        let summary = markdown::summary(&outcome);
        assert!(
            summary
                .contains("refitted map (demo-refit): 90 cells observed, 100.0% classified right"),
            "{summary}"
        );
        assert!(
            summary.contains("wrote demo-out (report.md, report.json, map.yaml, map-refit.yaml,"),
            "{summary}"
        );
    }

    #[test]
    fn no_kidnap_is_null() {
        let (plan, judgement) = (two_robots(), judgement());
        let outcome = quiet_outcome(&plan, &judgement);
        let json: Value = serde_json::from_str(&DemoReport::new(&outcome).to_json().expect("JSON"))
            .expect("JSON");
        assert_eq!(json["kidnap"], Value::Null);
    }
}
