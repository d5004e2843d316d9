//! Everything `deog bench real` measured: the table it prints and the JSON
//! `--json` writes (its keys are listed in the [module docs](super)).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use deog_evaluation::tracking::Tracking;
use deog_grid::Pose2;
use serde::Serialize;

use super::judge::{WindowVerdict, params};
use super::{MAP, Recipe};

/// Tracking's target: RMS position error over the whole log, metres.
const TARGET_RMS_M: f64 = 0.05;
/// Tracking's target: mean |heading error| over the whole log, degrees.
const TARGET_HEADING_DEG: f64 = 1.0;
/// Global localization's target: the share of starts that converged.
const TARGET_CONVERGED: f64 = 0.9;

/// The reference map.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MapFigures {
    /// Metres per cell.
    pub resolution_m: f64,
    /// The ray model's belief in an echo's cell.
    pub hit_probability: f64,
    /// The ray model's belief in a crossed cell.
    pub miss_probability: f64,
    /// Stored tiles.
    pub tiles: u64,
    /// Cells ever observed.
    pub observed_cells: u64,
    /// Cells above the localizer's occupied threshold.
    pub occupied_cells: u64,
    /// The cartographer's wall-clock time, seconds.
    pub seconds: f64,
}

/// The tracking run.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct TrackingFigures {
    /// Where it started: the first scan's reference pose.
    pub initial_pose: Pose2,
    /// Scans the localizer was given.
    pub frames: u64,
    /// Its estimates judged.
    pub tracking: Tracking,
    /// The localizer's wall-clock time, seconds.
    pub seconds: f64,
}

impl TrackingFigures {
    /// The localizer's wall-clock seconds per scan given.
    pub fn seconds_per_frame(&self) -> f64 {
        per(self.seconds, self.frames)
    }

    /// The share of the estimates within the bounds.
    fn within_fraction(&self) -> Option<f64> {
        (self.tracking.paired > 0)
            .then(|| self.tracking.within as f64 / self.tracking.paired as f64)
    }
}

/// One global start.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct StartFigures {
    /// Its first scan.
    pub scan: u64,
    /// Its last scan.
    pub to: u64,
    /// The localizer's seed.
    pub seed: u64,
    /// How it did.
    pub verdict: WindowVerdict,
    /// The localizer's wall-clock time, seconds.
    pub seconds: f64,
}

impl StartFigures {
    /// One line on how the start did.
    pub fn summary(&self) -> String {
        let v = &self.verdict;
        let outcome = match (v.converged, v.settled_after_scans) {
            (true, Some(after)) => format!("converged after {after} scans"),
            (false, Some(after)) => format!("settled only after {after} scans: not converged"),
            (_, None) => "not converged".to_owned(),
        };
        let error = match (v.final_position_error_m, v.final_abs_error_rad) {
            (Some(m), Some(rad)) => format!("final error {m:.3} m, {:.2}°", rad.to_degrees()),
            _ => "no final estimate".to_owned(),
        };
        format!(
            "{outcome} ({error}; {} estimates, {:.1} s)",
            v.estimates, self.seconds
        )
    }
}

/// Everything measured in one run.
#[derive(Debug, Clone)]
pub(super) struct RealFigures {
    /// The log, as given.
    pub log: String,
    /// The robot's name on the server.
    pub robot: String,
    /// Scans localized (the log's, or its prefix's).
    pub scans: u64,
    /// The log's scans.
    pub log_scans: u64,
    /// The bench's seed.
    pub seed: u64,
    /// `--settle-scans`.
    pub settle_scans: u64,
    /// Scans in a global window after its first.
    pub window: u64,
    /// The localizer's flags.
    pub recipe: Recipe,
    /// The reference map.
    pub map: MapFigures,
    /// The tracking run.
    pub tracking: TrackingFigures,
    /// The global starts, in order of their scans.
    pub starts: Vec<StartFigures>,
    /// The whole run's wall-clock time, seconds.
    pub wall_s: f64,
    /// Each process's command line.
    pub commands: Vec<String>,
}

impl RealFigures {
    /// Starts that converged.
    fn converged(&self) -> usize {
        self.starts.iter().filter(|s| s.verdict.converged).count()
    }

    /// The share of starts that converged; `None` without starts.
    fn converged_fraction(&self) -> Option<f64> {
        (!self.starts.is_empty()).then(|| self.converged() as f64 / self.starts.len() as f64)
    }

    /// The median of the converged starts' scans to converge (the mean of
    /// the middle two for an even count).
    fn median_scans_to_converge(&self) -> Option<f64> {
        let mut scans: Vec<u64> = self
            .starts
            .iter()
            .filter_map(|s| s.verdict.scans_to_converge())
            .collect();
        scans.sort_unstable();
        let n = scans.len();
        match n {
            0 => None,
            _ if n % 2 == 1 => Some(scans[n / 2] as f64),
            _ => Some((scans[n / 2 - 1] + scans[n / 2]) as f64 / 2.0),
        }
    }

    /// The global localizers' wall-clock seconds per scan given.
    fn global_seconds_per_frame(&self) -> Option<f64> {
        let frames: u64 = self.starts.iter().map(|s| s.to - s.scan + 1).sum();
        let seconds: f64 = self.starts.iter().map(|s| s.seconds).sum();
        (frames > 0).then(|| per(seconds, frames))
    }

    fn targets(&self) -> TargetsRecord {
        let t = &self.tracking.tracking;
        TargetsRecord {
            rms_position_m: TARGET_RMS_M,
            mean_abs_error_deg: TARGET_HEADING_DEG,
            converged_fraction: TARGET_CONVERGED,
            met: MetRecord {
                rms_position_m: t.paired > 0 && t.rms_m <= TARGET_RMS_M,
                mean_abs_error_deg: t.paired > 0
                    && t.mean_abs_heading_rad.to_degrees() <= TARGET_HEADING_DEG,
                converged_fraction: self
                    .converged_fraction()
                    .is_some_and(|f| f >= TARGET_CONVERGED),
            },
        }
    }

    /// The figures as a Markdown table: a line on the run first, then
    /// tracking and global localization beside their targets, then each
    /// global start.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let r = &self.recipe;
        let t = &self.tracking.tracking;
        let targets = self.targets();
        let verdict = |met: bool| if met { "met" } else { "not met" };
        let bounds = params();
        let _ = writeln!(
            out,
            "\nreal log: {}, {} of {} scans, robot {}; recipe --field-tempering {} --field-search-tempering {}{}{}{} --field-beams {} --motion-noise-scale {} --min-particles {} --max-particles {} (tracking: --initial-std-xy {} --initial-std-theta {}); bounds {} m, {} rad",
            self.log,
            self.scans,
            self.log_scans,
            self.robot,
            r.field_tempering,
            r.field_search_tempering,
            if r.no_refine { " --no-refine" } else { "" },
            if r.no_realign { " --no-realign" } else { "" },
            if r.no_ambiguity_check {
                " --no-ambiguity-check"
            } else {
                ""
            },
            r.field_beams,
            r.motion_noise_scale,
            r.min_particles,
            r.max_particles,
            r.initial_std_xy,
            r.initial_std_theta,
            bounds.converge_m,
            bounds.converge_rad
        );
        let _ = writeln!(
            out,
            "map {MAP} (reference poses, echoes {} and crossings {} likely occupied): {} tiles, {} cells observed, {} occupied, {} m cells",
            self.map.hit_probability,
            self.map.miss_probability,
            self.map.tiles,
            self.map.observed_cells,
            self.map.occupied_cells,
            self.map.resolution_m
        );
        let _ = writeln!(out, "\n| figure | value | target |");
        let _ = writeln!(out, "|---|---|---|");
        let _ = writeln!(
            out,
            "| tracking: RMS position error, every estimate | {:.4} m | ≤ {TARGET_RMS_M} m: {} |",
            t.rms_m,
            verdict(targets.met.rms_position_m)
        );
        let _ = writeln!(
            out,
            "| tracking: mean \\|heading error\\| | {:.3}° | ≤ {TARGET_HEADING_DEG}°: {} |",
            t.mean_abs_heading_rad.to_degrees(),
            verdict(targets.met.mean_abs_error_deg)
        );
        let _ = writeln!(
            out,
            "| tracking: mean position error | {:.4} m | |",
            t.mean_m
        );
        let _ = writeln!(
            out,
            "| tracking: within the bounds | {} of {} ({:.1} %) | |",
            t.within,
            t.paired,
            self.tracking.within_fraction().unwrap_or(0.0) * 100.0
        );
        let _ = writeln!(
            out,
            "| tracking: largest error | {:.3} m, {:.2}° | |",
            t.max_m,
            t.max_abs_heading_rad.to_degrees()
        );
        let _ = writeln!(
            out,
            "| tracking: false convergence (flagged converged, over 0.5 m or 0.25 rad off) | {} | 0 |",
            t.false_converged
        );
        let _ = writeln!(
            out,
            "| tracking: localizer time | {:.1} s, {:.3} s a frame | |",
            self.tracking.seconds,
            self.tracking.seconds_per_frame()
        );
        match self.converged_fraction() {
            Some(fraction) => {
                let _ = writeln!(
                    out,
                    "| global: converged within {} scans, staying to scan +{} | {} of {} ({:.0} %) | ≥ {:.0} %: {} |",
                    self.settle_scans,
                    self.window,
                    self.converged(),
                    self.starts.len(),
                    fraction * 100.0,
                    TARGET_CONVERGED * 100.0,
                    verdict(targets.met.converged_fraction)
                );
                let _ = writeln!(
                    out,
                    "| global: median scans to converge | {} | |",
                    self.median_scans_to_converge()
                        .map_or("-".to_owned(), |m| format!("{m}"))
                );
                let _ = writeln!(
                    out,
                    "| global: false convergence | {} | 0 |",
                    self.starts
                        .iter()
                        .map(|s| s.verdict.false_converged)
                        .sum::<u64>()
                );
                let _ = writeln!(
                    out,
                    "| global: localizer time | {:.3} s a frame | |",
                    self.global_seconds_per_frame().unwrap_or(0.0)
                );
            }
            None => {
                let _ = writeln!(out, "| global | not run (--starts 0) | |");
            }
        }
        if !self.starts.is_empty() {
            let _ = writeln!(
                out,
                "\n| start scan | to | seed | converged | scans to converge | final error | seconds |"
            );
            let _ = writeln!(out, "|---|---|---|---|---|---|---|");
            for s in &self.starts {
                let v = &s.verdict;
                let error = match (v.final_position_error_m, v.final_abs_error_rad) {
                    (Some(m), Some(rad)) => format!("{m:.3} m, {:.2}°", rad.to_degrees()),
                    _ => "-".to_owned(),
                };
                let settled = match v.settled_after_scans {
                    Some(after) if v.converged => after.to_string(),
                    Some(after) => format!("({after})"),
                    None => "-".to_owned(),
                };
                let _ = writeln!(
                    out,
                    "| {} | {} | {} | {} | {settled} | {error} | {:.1} |",
                    s.scan,
                    s.to,
                    s.seed,
                    if v.converged { "yes" } else { "no" },
                    s.seconds
                );
            }
        }
        let _ = writeln!(out, "\nwall-clock: {:.0} s", self.wall_s);
        out
    }

    /// The JSON record.
    fn record(&self) -> RealRecord<'_> {
        let t = &self.tracking.tracking;
        let bounds = params();
        RealRecord {
            log: &self.log,
            robot: &self.robot,
            scans: self.scans,
            log_scans: self.log_scans,
            seed: self.seed,
            settle_scans: self.settle_scans,
            window_scans: self.window,
            recipe: &self.recipe,
            bounds: BoundsRecord {
                position_m: bounds.converge_m,
                heading_rad: bounds.converge_rad,
            },
            map: MapRecord {
                name: MAP,
                resolution_m: self.map.resolution_m,
                hit_probability: self.map.hit_probability,
                miss_probability: self.map.miss_probability,
                tiles: self.map.tiles,
                observed_cells: self.map.observed_cells,
                occupied_cells: self.map.occupied_cells,
                seconds: self.map.seconds,
            },
            tracking: TrackingRecord {
                initial_pose: PoseRecord {
                    x: self.tracking.initial_pose.x,
                    y: self.tracking.initial_pose.y,
                    theta: self.tracking.initial_pose.theta,
                },
                frames: self.tracking.frames,
                estimates: t.paired,
                rms_position_m: t.rms_m,
                mean_position_m: t.mean_m,
                max_position_error_m: t.max_m,
                mean_abs_error_deg: t.mean_abs_heading_rad.to_degrees(),
                max_abs_error_deg: t.max_abs_heading_rad.to_degrees(),
                within_bounds_fraction: self.tracking.within_fraction(),
                stretches_outside_bounds: t.lost_stretches,
                last_estimate_within_bounds: t.last_within,
                false_converged: t.false_converged,
                seconds: self.tracking.seconds,
                seconds_per_frame: self.tracking.seconds_per_frame(),
            },
            global: GlobalRecord {
                starts: self
                    .starts
                    .iter()
                    .map(|s| StartRecord {
                        scan: s.scan,
                        to: s.to,
                        seed: s.seed,
                        estimates: s.verdict.estimates,
                        converged: s.verdict.converged,
                        scans_to_converge: s.verdict.scans_to_converge(),
                        settled_after_scans: s.verdict.settled_after_scans,
                        final_position_error_m: s.verdict.final_position_error_m,
                        final_abs_error_deg: s.verdict.final_abs_error_rad.map(f64::to_degrees),
                        false_converged: s.verdict.false_converged,
                        seconds: s.seconds,
                    })
                    .collect(),
                converged: self.converged(),
                converged_fraction: self.converged_fraction(),
                median_scans_to_converge: self.median_scans_to_converge(),
                false_converged: self.starts.iter().map(|s| s.verdict.false_converged).sum(),
                seconds_per_frame: self.global_seconds_per_frame(),
            },
            targets: self.targets(),
            wall_s: self.wall_s,
            commands: &self.commands,
        }
    }

    /// The figures as the JSON `--json` writes.
    pub fn json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(&self.record()).context("assembling the JSON")
    }
}

/// `seconds / frames`, 0 for no frame.
fn per(seconds: f64, frames: u64) -> f64 {
    if frames > 0 {
        seconds / frames as f64
    } else {
        0.0
    }
}

#[derive(Serialize)]
struct RealRecord<'a> {
    log: &'a str,
    robot: &'a str,
    scans: u64,
    log_scans: u64,
    seed: u64,
    settle_scans: u64,
    window_scans: u64,
    recipe: &'a Recipe,
    bounds: BoundsRecord,
    map: MapRecord,
    tracking: TrackingRecord,
    global: GlobalRecord,
    targets: TargetsRecord,
    wall_s: f64,
    commands: &'a [String],
}

#[derive(Serialize)]
struct BoundsRecord {
    position_m: f64,
    heading_rad: f64,
}

#[derive(Serialize)]
struct MapRecord {
    name: &'static str,
    resolution_m: f64,
    hit_probability: f64,
    miss_probability: f64,
    tiles: u64,
    observed_cells: u64,
    occupied_cells: u64,
    seconds: f64,
}

#[derive(Serialize)]
struct PoseRecord {
    x: f64,
    y: f64,
    theta: f64,
}

#[derive(Serialize)]
struct TrackingRecord {
    initial_pose: PoseRecord,
    frames: u64,
    estimates: u64,
    rms_position_m: f64,
    mean_position_m: f64,
    max_position_error_m: f64,
    mean_abs_error_deg: f64,
    max_abs_error_deg: f64,
    within_bounds_fraction: Option<f64>,
    stretches_outside_bounds: u64,
    last_estimate_within_bounds: bool,
    false_converged: u64,
    seconds: f64,
    seconds_per_frame: f64,
}

#[derive(Serialize)]
struct StartRecord {
    scan: u64,
    to: u64,
    seed: u64,
    estimates: u64,
    converged: bool,
    scans_to_converge: Option<u64>,
    settled_after_scans: Option<u64>,
    final_position_error_m: Option<f64>,
    final_abs_error_deg: Option<f64>,
    false_converged: u64,
    seconds: f64,
}

#[derive(Serialize)]
struct GlobalRecord {
    starts: Vec<StartRecord>,
    converged: usize,
    converged_fraction: Option<f64>,
    median_scans_to_converge: Option<f64>,
    false_converged: u64,
    seconds_per_frame: Option<f64>,
}

#[derive(Serialize)]
struct TargetsRecord {
    rms_position_m: f64,
    mean_abs_error_deg: f64,
    converged_fraction: f64,
    met: MetRecord,
}

#[derive(Serialize)]
struct MetRecord {
    rms_position_m: bool,
    mean_abs_error_deg: bool,
    converged_fraction: bool,
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        recipe: Recipe,
    }

    fn verdict(converged: bool, after: Option<u64>) -> WindowVerdict {
        WindowVerdict {
            estimates: 41,
            converged,
            settled_after_scans: after,
            final_position_error_m: Some(0.04),
            final_abs_error_rad: Some(0.01),
            false_converged: u64::from(!converged),
        }
    }

    fn figures(verdicts: &[WindowVerdict]) -> RealFigures {
        RealFigures {
            log: "data/carmen/aces-corrected.log.gz".into(),
            robot: "log".into(),
            scans: 440,
            log_scans: 440,
            seed: 1,
            settle_scans: 30,
            window: 40,
            recipe: Cli::parse_from(["real"]).recipe,
            map: MapFigures {
                resolution_m: 0.05,
                hit_probability: 0.85,
                miss_probability: 0.45,
                tiles: 120,
                observed_cells: 300_000,
                occupied_cells: 20_000,
                seconds: 3.0,
            },
            tracking: TrackingFigures {
                initial_pose: Pose2::new(1.0, -2.0, 0.5),
                frames: 440,
                tracking: Tracking {
                    paired: 440,
                    within: 438,
                    mean_m: 0.05,
                    rms_m: 0.06,
                    max_m: 0.4,
                    mean_abs_heading_rad: 0.01,
                    max_abs_heading_rad: 0.1,
                    false_converged: 2,
                    ..Tracking::default()
                },
                seconds: 44.0,
            },
            starts: verdicts
                .iter()
                .enumerate()
                .map(|(i, &verdict)| StartFigures {
                    scan: 10 * (i as u64 + 1),
                    to: 10 * (i as u64 + 1) + 40,
                    seed: 1 + i as u64,
                    verdict,
                    seconds: 4.1,
                })
                .collect(),
            wall_s: 100.0,
            commands: vec!["deog server".into()],
        }
    }

    #[test]
    fn the_json_has_its_stable_keys_and_figures() {
        let f = figures(&[
            verdict(true, Some(0)),
            verdict(true, Some(5)),
            verdict(false, Some(33)),
            verdict(false, None),
        ]);
        let json: serde_json::Value = serde_json::from_str(&f.json().unwrap()).unwrap();
        for key in [
            "log", "scans", "recipe", "map", "tracking", "global", "targets",
        ] {
            assert!(json.get(key).is_some(), "{key} in {json}");
        }
        assert_eq!(json["scans"], 440);
        assert_eq!(json["recipe"]["field_tempering"], 0.5);
        assert_eq!(json["recipe"]["min_particles"], 2000);
        assert_eq!(json["map"]["observed_cells"], 300_000);
        assert_eq!(json["map"]["occupied_cells"], 20_000);
        assert_eq!(json["map"]["hit_probability"], 0.85);
        assert_eq!(json["map"]["miss_probability"], 0.45);
        let t = &json["tracking"];
        assert_eq!(t["rms_position_m"], 0.06);
        assert_eq!(t["max_position_error_m"], 0.4);
        assert_eq!(t["seconds_per_frame"], 0.1);
        assert_eq!(t["false_converged"], 2);
        approx::assert_relative_eq!(
            t["mean_abs_error_deg"].as_f64().unwrap(),
            0.01f64.to_degrees()
        );
        approx::assert_relative_eq!(t["within_bounds_fraction"].as_f64().unwrap(), 438.0 / 440.0);
        let g = &json["global"];
        assert_eq!(g["converged_fraction"], 0.5);
        assert_eq!(g["median_scans_to_converge"], 2.5);
        assert_eq!(g["starts"].as_array().unwrap().len(), 4);
        assert_eq!(g["starts"][1]["scans_to_converge"], 5);
        assert_eq!(g["starts"][2]["scans_to_converge"], serde_json::Value::Null);
        assert_eq!(g["starts"][2]["settled_after_scans"], 33);
        assert_eq!(g["starts"][2]["false_converged"], 1);
        assert_eq!(g["false_converged"], 2);
        approx::assert_relative_eq!(g["seconds_per_frame"].as_f64().unwrap(), 0.1);
        assert_eq!(json["targets"]["met"]["rms_position_m"], false);
        assert_eq!(json["targets"]["met"]["mean_abs_error_deg"], true);
        assert_eq!(json["targets"]["met"]["converged_fraction"], false);
    }

    #[test]
    fn without_starts_the_global_figures_are_null() {
        let f = figures(&[]);
        let json: serde_json::Value = serde_json::from_str(&f.json().unwrap()).unwrap();
        assert_eq!(
            json["global"]["converged_fraction"],
            serde_json::Value::Null
        );
        assert_eq!(
            json["global"]["median_scans_to_converge"],
            serde_json::Value::Null
        );
        assert!(f.table().contains("not run (--starts 0)"));
    }

    #[test]
    fn the_table_shows_the_figures_beside_their_targets() {
        let f = figures(&[verdict(true, Some(1)), verdict(true, Some(3))]);
        let table = f.table();
        assert!(
            table.contains(
                "| tracking: RMS position error, every estimate | 0.0600 m | ≤ 0.05 m: not met |"
            ),
            "{table}"
        );
        assert!(table.contains("2 of 2 (100 %) | ≥ 90 %: met |"), "{table}");
        assert!(
            table.contains("| global: median scans to converge | 2 | |"),
            "{table}"
        );
        assert!(
            table.contains("| 10 | 50 | 1 | yes | 1 | 0.040 m, 0.57° | 4.1 |"),
            "{table}"
        );
    }
}
