//! What the unit tests share: options as the command line gives them, a
//! plan, a judged run and a kidnap, made without any process.

use clap::Parser;
use deog_evaluation::localization::{EstimateSample, EvalInput, TruthSample, evaluate};
use deog_evaluation::map_quality::{Confusion, MapQuality};
use deog_grid::Pose2;

use crate::judge::{Judgement, RobotJudgement};
use crate::kidnap::KidnapDone;
use crate::options::DemoOptions;
use crate::plan::DemoPlan;
use crate::report::{DemoOutcome, Driven};

/// `deog demo` alone, to parse its flags as the binary does.
#[derive(Debug, Parser)]
struct Cli {
    #[command(flatten)]
    options: DemoOptions,
}

/// The options of `deog demo <args>`, or clap's refusal.
pub(crate) fn options(args: &[&str]) -> Result<DemoOptions, clap::Error> {
    Cli::try_parse_from(std::iter::once("demo").chain(args.iter().copied())).map(|cli| cli.options)
}

/// The plan of `deog demo <args>`.
pub(crate) fn plan(args: &[&str]) -> anyhow::Result<DemoPlan> {
    DemoPlan::new(&options(args)?)
}

/// A plan of two robots in map2 for 100 simulated seconds.
pub(crate) fn two_robots() -> DemoPlan {
    plan(&["--robots", "2", "--duration", "100"]).expect("valid options")
}

/// Robot `name` driving along x, estimated 5 cm ahead, and carried 3 m
/// half-way when `kidnapped`.
fn robot(name: &str, kidnapped: bool) -> RobotJudgement {
    let truth: Vec<TruthSample> = (1..=40)
        .map(|s| {
            let jump = if kidnapped && s > 20 { 3.0 } else { 0.0 };
            TruthSample::new(
                s,
                s as f64 * 0.1,
                Pose2::new(s as f64 * 0.05 + jump, 0.0, 0.0),
            )
        })
        .collect();
    let estimates: Vec<EstimateSample> = truth
        .iter()
        .map(|t| EstimateSample::new(t.sequence, Pose2::new(t.pose.x + 0.05, 0.0, 0.0)))
        .collect();
    RobotJudgement {
        report: evaluate(&EvalInput::new(name, &truth, &estimates)).expect("valid samples"),
        plot: format!("{name}.png"),
    }
}

/// A judgement of two robots, the first kidnapped; the map has 90 observed
/// cells, 89 of them right.
pub(crate) fn judgement() -> Judgement {
    Judgement {
        robots: vec![robot("scout-1", true), robot("scout-2", false)],
        quality: MapQuality {
            resolution_m: 0.05,
            robot_radius_m: 0.2,
            seeds_given: 2,
            seeds_used: 2,
            confusion: Confusion {
                free_as_free: 80,
                occupied_as_occupied: 9,
                free_as_uncertain: 1,
                ..Confusion::default()
            },
            map_occupied: 10,
            map_occupied_near_truth: 9,
            surface_cells: 20,
            surface_cells_found: 15,
            surface_cells_observed: 18,
            surface_cells_observed_found: 15,
            reachable_cells: 100,
            reachable_cells_free: 80,
        },
        map_png: "map.png".to_string(),
        map_yaml: "map.yaml".to_string(),
        refit: None,
    }
}

/// scout-1 carried from (1, 2) to (4, 3) at 50.25 s.
pub(crate) fn kidnap() -> KidnapDone {
    KidnapDone {
        robot: "scout-1".to_string(),
        time_s: 50.25,
        from: Pose2::new(1.0, 2.0, 0.5),
        to: Pose2::new(4.0, 3.0, -1.0),
    }
}

/// A run of `plan` judged as `judgement` in a second of wall-clock time,
/// with no kidnap, no lag, no coverage and no command lines.
pub(crate) fn quiet_outcome<'a>(plan: &'a DemoPlan, judgement: &'a Judgement) -> DemoOutcome<'a> {
    DemoOutcome {
        plan,
        judgement,
        kidnap: None,
        wall_s: 1.0,
        max_lags_s: Vec::new(),
        coverage: Vec::new(),
        commands: Vec::new(),
        driven: Driven::default(),
    }
}
