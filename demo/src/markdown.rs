//! The demo's results for people: report.md (the thesis-style tables, the
//! pictures, the commands each process ran with) and the short summary
//! printed at the end.

use std::fmt::Write as _;

use deog_evaluation::localization::LocalizationReport;

use deog_evaluation::map_quality::MapQuality;

use crate::commands::REFIT_MAP;
use crate::judge::{REFIT_VERDICT_PNG, VERDICT_PNG};
use crate::report::DemoOutcome;

// Writing to a String cannot fail: the `let _ =` on every `writeln!` below
// drops an error that never comes.

/// The short table printed at the end.
pub(crate) fn summary(outcome: &DemoOutcome<'_>) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "\n{}", map_line("map", &outcome.judgement.quality));
    if let Some(refit) = &outcome.judgement.refit {
        let label = format!("refitted map ({REFIT_MAP})");
        let _ = writeln!(out, "{}", map_line(&label, &refit.quality));
    }
    for robot in &outcome.judgement.robots {
        let lag = outcome.max_lag_s(&robot.report.robot);
        let _ = writeln!(out, "{}", robot_line(&robot.report, lag));
    }
    let maps = match &outcome.judgement.refit {
        Some(refit) => format!("{}, {}", outcome.judgement.map_yaml, refit.map_yaml),
        None => outcome.judgement.map_yaml.clone(),
    };
    let _ = writeln!(
        out,
        "{:.0} s in all; wrote {} (report.md, report.json, {maps}, the plots, logs/)",
        outcome.wall_s,
        outcome.plan.out.display(),
    );
    out
}

/// report.md: the thesis-style tables and the figures of the run.
pub(crate) fn report(outcome: &DemoOutcome<'_>) -> String {
    let mut md = String::new();
    let plan = outcome.plan;
    let judgement = outcome.judgement;
    let _ = writeln!(md, "# deog demo: {}\n", plan.world.name());
    let driver = if plan.explore { "explorer" } else { "wanderer" };
    let drove = if plan.explore {
        format!(
            "explored for {:.0} simulated seconds (at most {})",
            outcome.driven.simulated_s, plan.schedule.duration_s
        )
    } else {
        format!("drove {} simulated seconds", plan.schedule.duration_s)
    };
    let _ = write!(
        md,
        "{} robots {drove} at {}x (seed {}), in {:.0} s of wall-clock time. ",
        plan.robots.len(),
        plan.schedule.speed,
        plan.seed,
        outcome.wall_s,
    );
    if !plan.localize {
        let _ = writeln!(
            md,
            "Each robot had its own {driver} and cartographer process; no localizer ran."
        );
    } else {
        let _ = writeln!(
            md,
            "Each robot had its own {driver}, cartographer and localizer process; the \
             localizers started from {:.0} s, one after another {:.0} s apart, with no idea \
             where their robots were.",
            plan.schedule.localize_at_s,
            plan.schedule.localizer_start_s(1, plan.robots.len()) - plan.schedule.localize_at_s,
        );
        match outcome.kidnap {
            Some(k) => {
                let _ = writeln!(
                    md,
                    "At {:.1} s {} was kidnapped: carried from ({:.2}, {:.2}) to ({:.2}, {:.2}) \
                     without its odometry noticing.",
                    k.time_s, k.robot, k.from.x, k.from.y, k.to.x, k.to.y
                );
            }
            None => {
                let _ = writeln!(md, "No robot was kidnapped.");
            }
        }
        let _ = writeln!(md, "\n## Localization\n");
        let _ = writeln!(
            md,
            "| robot | converged after | mean abs. error x | y | heading | RMS position | kidnapped | recovered after |"
        );
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---|---:|");
        for robot in &judgement.robots {
            let r = &robot.report;
            let stats = r.stats.as_ref();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} |",
                r.robot,
                seconds(r.converge_s()),
                metres(stats.map(|s| s.x_m.mean_abs)),
                metres(stats.map(|s| s.y_m.mean_abs)),
                stats.map_or("-".to_string(), |s| format!(
                    "{:.2}°",
                    s.theta_rad.mean_abs.to_degrees()
                )),
                metres(stats.map(|s| s.rms_position_m)),
                if r.kidnapped() { "yes" } else { "no" },
                match r.recovered() {
                    None => "-".to_string(),
                    Some(false) => "not recovered".to_string(),
                    Some(true) => seconds(r.recover_s()),
                },
            );
        }
        for robot in &judgement.robots {
            let _ = writeln!(md, "\n### {}\n", robot.report.robot);
            let _ = writeln!(
                md,
                "True path red, estimate green; a kidnap is marked.\n\n![{}]({})\n",
                robot.report.robot, robot.plot
            );
            let _ = writeln!(md, "```\n{}```", robot.report.table());
        }
    }
    let _ = writeln!(md, "\n## Map\n");
    let _ = writeln!(
        md,
        "![map]({})\n\nExported as ROS map_server files: `{}` with its `.pgm`. \
         Judged against the world's ground truth:\n",
        judgement.map_png, judgement.map_yaml
    );
    let _ = writeln!(md, "{}", judgement.quality.table());
    let _ = writeln!(
        md,
        "Where it is right and wrong (white free and black occupied: right; yellow free \
         but uncertain, red free but occupied, blue occupied but free, purple occupied \
         but uncertain; light grey never observed, dark grey the world's walls):\n\n\
         ![where the map is right]({VERDICT_PNG})\n"
    );
    if let Some(refit) = &judgement.refit {
        let _ = writeln!(md, "## The map refitted to every frame\n");
        let _ = writeln!(
            md,
            "Once the robots stopped, `deog refit` fitted the map to every frame at once, \
             through the specular sonar's forward model, and `deog import` loaded it as map \
             `{REFIT_MAP}` (the live map above is unchanged).\n\n![refitted map]({})\n\n\
             As ROS map_server files: `{}` with its `.pgm`. Judged against the world's \
             ground truth:\n",
            refit.map_png, refit.map_yaml
        );
        let _ = writeln!(md, "{}", refit.quality.table());
        let _ = writeln!(
            md,
            "Where it is right and wrong, coloured as above:\n\n\
             ![where the refitted map is right]({REFIT_VERDICT_PNG})\n"
        );
    }
    let _ = writeln!(md, "## The processes\n");
    let _ = writeln!(
        md,
        "Each ran as its own process; the logs are in `logs/`. By hand, the same \
         commands (with the addresses of your server and simulator):\n"
    );
    let _ = writeln!(md, "```");
    for (name, line) in &outcome.commands {
        let _ = writeln!(md, "# {name}\n{line}");
    }
    let _ = writeln!(md, "```");
    md
}

/// A map's figures on one line, after `label`.
fn map_line(label: &str, q: &MapQuality) -> String {
    format!(
        "{label}: {} cells observed, {:.1}% classified right, occupied precision {}, recall {} \
         ({} of the walls it observed)",
        q.cells_observed(),
        100.0 * q.fraction_correct(),
        percent(q.occupied_precision()),
        percent(q.occupied_recall()),
        percent(q.observed_occupied_recall()),
    )
}

/// One robot's figures on one line.
fn robot_line(r: &LocalizationReport, max_lag_s: Option<f64>) -> String {
    let mut line = format!("{}: ", r.robot);
    match r.converge_s() {
        Some(s) => {
            let _ = write!(line, "converged after {s:.1} s");
        }
        None => line.push_str("never converged"),
    }
    // The judge's convergence is the last time an estimate left the
    // bounds: say when it first came within them, if that was earlier.
    if let Some(first) = r.first_within_s().filter(|&f| r.converge_s() != Some(f)) {
        let _ = write!(line, " (first within the bounds after {first:.1} s)");
    }
    if let Some(s) = &r.stats {
        let _ = write!(
            line,
            ", mean error {:.1} cm x, {:.1} cm y, {:.2}°",
            100.0 * s.x_m.mean_abs,
            100.0 * s.y_m.mean_abs,
            s.theta_rad.mean_abs.to_degrees()
        );
    }
    match r.recovered() {
        Some(true) => {
            let _ = write!(
                line,
                "; kidnapped, found again after {}",
                seconds(r.recover_s())
            );
            if let Some(first) = r.first_back_s().filter(|&f| r.recover_s() != Some(f)) {
                let _ = write!(line, " (first back within the bounds after {first:.1} s)");
            }
        }
        Some(false) => line.push_str("; kidnapped, not found again"),
        None => {}
    }
    if let Some(lag) = max_lag_s {
        let _ = write!(line, "; at most {lag:.1} s behind its robot");
    }
    line
}

fn seconds(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |s| format!("{s:.1} s"))
}

fn metres(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |m| format!("{:.1} cm", 100.0 * m))
}

fn percent(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |p| format!("{:.1}%", 100.0 * p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{judgement, kidnap, quiet_outcome, two_robots};

    #[test]
    fn report_md_has_the_tables_the_kidnap_and_the_commands() {
        let (plan, judgement, kidnap) = (two_robots(), judgement(), kidnap());
        let outcome = DemoOutcome {
            plan: &plan,
            judgement: &judgement,
            kidnap: Some(&kidnap),
            wall_s: 80.4,
            max_lags_s: Vec::new(),
            coverage: Vec::new(),
            commands: vec![("server".to_string(), "deog server --data d".to_string())],
            driven: Default::default(),
        };
        let md = report(&outcome);
        assert!(md.starts_with(
            "# deog demo: map2\n\n2 robots drove 100 simulated seconds at 4x (seed 1), in 80 s"
        ));
        assert!(md.contains(
            "At 50.2 s scout-1 was kidnapped: carried from (1.00, 2.00) to (4.00, 3.00)"
        ));
        assert!(md.contains("| robot | converged after |"));
        assert!(
            md.contains("| scout-1 | 0.0 s | 5.0 cm | 0.0 cm | 0.00° | 5.0 cm | yes | 0.0 s |")
        );
        assert!(md.contains("| scout-2 | 0.0 s | 5.0 cm | 0.0 cm | 0.00° | 5.0 cm | no | - |"));
        assert!(md.contains("![scout-2](scout-2.png)"));
        assert!(md.contains("![where the map is right](map-verdict.png)"));
        assert!(md.ends_with("```\n# server\ndeog server --data d\n```\n"));
    }

    #[test]
    fn no_kidnap_is_said() {
        let (plan, judgement) = (two_robots(), judgement());
        let outcome = quiet_outcome(&plan, &judgement);
        assert!(report(&outcome).contains("No robot was kidnapped."));
    }

    #[test]
    fn the_summary_has_a_line_per_robot() {
        let (plan, judgement) = (two_robots(), judgement());
        let outcome = DemoOutcome {
            plan: &plan,
            judgement: &judgement,
            kidnap: None,
            wall_s: 80.4,
            max_lags_s: vec![("scout-1".to_string(), Some(0.4))],
            coverage: Vec::new(),
            commands: Vec::new(),
            driven: Default::default(),
        };
        let summary = summary(&outcome);
        let lines: Vec<&str> = summary.lines().collect();
        assert_eq!(lines.len(), 5, "{summary}");
        assert_eq!(
            lines[1],
            "map: 90 cells observed, 98.9% classified right, occupied precision 90.0%, \
             recall 75.0% (83.3% of the walls it observed)"
        );
        assert_eq!(
            lines[2],
            "scout-1: converged after 0.0 s, mean error 5.0 cm x, 0.0 cm y, 0.00°; \
             kidnapped, found again after 0.0 s; at most 0.4 s behind its robot"
        );
        assert_eq!(
            lines[4],
            "80 s in all; wrote demo-out (report.md, report.json, map.yaml, the plots, logs/)"
        );
    }

    #[test]
    fn a_robot_that_strayed_after_it_was_first_right_says_both_times() {
        use deog_evaluation::localization::{EstimateSample, EvalInput, TruthSample, evaluate};
        use deog_grid::Pose2;
        let truth: Vec<TruthSample> = (1..=40)
            .map(|s| TruthSample::new(s, s as f64 * 0.1, Pose2::new(s as f64 * 0.05, 0.0, 0.0)))
            .collect();
        // 5 cm ahead throughout, but 1 m off at frame 10.
        let estimates: Vec<EstimateSample> = truth
            .iter()
            .map(|t| {
                let off = if t.sequence == 10 { 1.0 } else { 0.05 };
                EstimateSample::new(t.sequence, Pose2::new(t.pose.x + off, 0.0, 0.0))
            })
            .collect();
        let report = evaluate(&EvalInput::new("scout-1", &truth, &estimates)).expect("judged");
        assert_eq!(
            robot_line(&report, None),
            "scout-1: converged after 1.0 s (first within the bounds after 0.0 s), \
             mean error 5.0 cm x, 0.0 cm y, 0.00°"
        );
    }

    #[test]
    fn missing_figures_are_dashes() {
        assert_eq!(seconds(None), "-");
        assert_eq!(metres(Some(0.0123)), "1.2 cm");
        assert_eq!(percent(Some(0.981)), "98.1%");
    }
}
