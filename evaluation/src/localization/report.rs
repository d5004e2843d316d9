//! A [`LocalizationReport`] as a markdown table for people and as JSON for
//! tools ([`LocalizationRecord`], serialised with serde). The JSON names
//! are an interface: other tools read them.

use std::fmt::Write as _;

use deog_grid::Pose2;
use serde::Serialize;

use crate::json::pretty_json;

use super::{AxisStats, ErrorStats, Kidnap, LocalizationReport, METRES_PER_INCH};

/// Inches per metre.
const INCHES_PER_METRE: f64 = 1.0 / METRES_PER_INCH;

/// Every report in one JSON document: `{"robots": [<report>, ...]}`, each
/// report as [`LocalizationReport::to_json`] writes it.
pub fn reports_to_json(reports: &[LocalizationReport]) -> String {
    #[derive(Serialize)]
    struct Robots {
        robots: Vec<LocalizationRecord>,
    }
    let all = Robots {
        robots: reports.iter().map(LocalizationReport::record).collect(),
    };
    pretty(&all)
}

/// A pose in JSON.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseRecord {
    /// Metres, world frame.
    pub x: f64,
    /// Metres, world frame.
    pub y: f64,
    /// Radians, counter-clockwise from +x.
    pub theta: f64,
}

impl From<Pose2> for PoseRecord {
    fn from(p: Pose2) -> Self {
        Self {
            x: p.x,
            y: p.y,
            theta: p.theta,
        }
    }
}

/// An x and a y figure; `null` where undefined.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct XyRecord {
    /// Along x.
    pub x: Option<f64>,
    /// Along y.
    pub y: Option<f64>,
}

/// One kidnap in JSON.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KidnapRecord {
    /// The last frame before the jump.
    pub sequence_before: u64,
    /// The first frame after it.
    pub sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// True pose before the jump.
    pub from: PoseRecord,
    /// True pose after it.
    pub to: PoseRecord,
    /// Distance jumped, metres.
    pub jump_m: f64,
    /// Heading change, degrees.
    pub turn_deg: f64,
    /// Whether the estimate settled again.
    pub recovered: bool,
    /// Seconds from the kidnap to the settling.
    pub recover_s: Option<f64>,
    /// Metres driven from the kidnap to the settling.
    pub recover_distance_m: Option<f64>,
    /// The settling estimate's frame.
    pub recover_sequence: Option<u64>,
    /// Seconds from the kidnap to the first estimate back within the
    /// bounds (it may leave them again before the settling).
    pub first_within_s: Option<f64>,
}

/// The bounds and limits of the judging, in JSON.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoundsRecord {
    /// See [`super::EvalParams::converge_m`].
    pub converge_m: f64,
    /// See [`super::EvalParams::converge_rad`].
    pub converge_rad: f64,
    /// See [`super::EvalParams::kidnap_jump_m`].
    pub kidnap_jump_m: f64,
    /// See [`super::EvalParams::kidnap_turn_rad`].
    pub kidnap_turn_rad: f64,
    /// See [`super::EvalParams::max_speed_mps`].
    pub max_speed_mps: f64,
    /// See [`super::EvalParams::max_turn_rate_rad_s`].
    pub max_turn_rate_rad_s: f64,
}

/// A [`LocalizationReport`] as JSON shows it. The keys `name`,
/// `converged`, `converge_s`, `mean_abs_error_m` (`x`, `y`),
/// `mean_abs_error_deg`, `rms_position_m`, `kidnapped`, `recovered` and
/// `recover_s` are an interface; the others add the rest of the report.
/// Figures that do not exist are `null`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[allow(missing_docs)] // Each field is the report's figure of that name.
pub struct LocalizationRecord {
    pub name: String,
    pub map: Option<String>,
    pub converged: bool,
    pub converge_s: Option<f64>,
    pub converge_sequence: Option<u64>,
    pub converge_distance_m: Option<f64>,
    pub first_within_s: Option<f64>,
    pub mean_abs_error_m: XyRecord,
    pub mean_abs_error_in: XyRecord,
    pub std_error_m: XyRecord,
    pub std_error_in: XyRecord,
    pub mean_error_m: XyRecord,
    pub mean_abs_error_rad: Option<f64>,
    pub mean_abs_error_deg: Option<f64>,
    pub std_error_rad: Option<f64>,
    pub std_error_deg: Option<f64>,
    pub mean_error_rad: Option<f64>,
    pub mean_error_deg: Option<f64>,
    pub mean_position_m: Option<f64>,
    pub rms_position_m: Option<f64>,
    pub max_position_m: Option<f64>,
    pub estimates_used: u64,
    pub kidnapped: bool,
    pub recovered: Option<bool>,
    pub recover_s: Option<f64>,
    pub first_back_s: Option<f64>,
    pub kidnap_count: usize,
    pub kidnaps: Vec<KidnapRecord>,
    pub frames: u64,
    pub frames_after_last_estimate: u64,
    pub estimates: u64,
    pub estimates_paired: u64,
    pub estimates_within_bounds: u64,
    pub filter_converged: u64,
    pub filter_converged_within_bounds: u64,
    pub false_converged: u64,
    pub start_time_s: f64,
    pub end_time_s: f64,
    pub bounds: BoundsRecord,
}

impl LocalizationReport {
    /// The report as one JSON object (see [`LocalizationRecord`]).
    pub fn to_json(&self) -> String {
        pretty(&self.record())
    }

    /// The report's JSON form, to be put in a larger document.
    pub fn record(&self) -> LocalizationRecord {
        let stats = self.stats.as_ref();
        let axis = |pick: fn(&ErrorStats) -> AxisStats| stats.map(pick);
        let (x, y, theta) = (axis(|s| s.x_m), axis(|s| s.y_m), axis(|s| s.theta_rad));
        let xy = |factor: f64, field: fn(&AxisStats) -> f64| XyRecord {
            x: x.map(|a| field(&a) * factor),
            y: y.map(|a| field(&a) * factor),
        };
        let degrees = 180.0 / std::f64::consts::PI;
        let angle = |factor: f64, field: fn(&AxisStats) -> f64| theta.map(|a| field(&a) * factor);
        let p = &self.params;
        LocalizationRecord {
            name: self.robot.clone(),
            map: self.map.clone(),
            converged: self.converged(),
            converge_s: self.converge_s(),
            converge_sequence: self.convergence.map(|c| c.sequence),
            converge_distance_m: self.convergence.map(|c| c.distance_m),
            first_within_s: self.first_within_s(),
            mean_abs_error_m: xy(1.0, |a| a.mean_abs),
            mean_abs_error_in: xy(INCHES_PER_METRE, |a| a.mean_abs),
            std_error_m: xy(1.0, |a| a.std_dev),
            std_error_in: xy(INCHES_PER_METRE, |a| a.std_dev),
            mean_error_m: xy(1.0, |a| a.mean),
            mean_abs_error_rad: angle(1.0, |a| a.mean_abs),
            mean_abs_error_deg: angle(degrees, |a| a.mean_abs),
            std_error_rad: angle(1.0, |a| a.std_dev),
            std_error_deg: angle(degrees, |a| a.std_dev),
            mean_error_rad: angle(1.0, |a| a.mean),
            mean_error_deg: angle(degrees, |a| a.mean),
            mean_position_m: stats.map(|s| s.mean_position_m),
            rms_position_m: stats.map(|s| s.rms_position_m),
            max_position_m: stats.map(|s| s.max_position_m),
            estimates_used: stats.map_or(0, |s| s.count),
            kidnapped: self.kidnapped(),
            recovered: self.recovered(),
            recover_s: self.recover_s(),
            first_back_s: self.first_back_s(),
            kidnap_count: self.kidnaps.len(),
            kidnaps: self.kidnaps.iter().map(kidnap_record).collect(),
            frames: self.frames,
            frames_after_last_estimate: self.frames_after_last_estimate,
            estimates: self.estimates,
            estimates_paired: self.estimates_paired,
            estimates_within_bounds: self.estimates_within_bounds,
            filter_converged: self.filter_converged,
            filter_converged_within_bounds: self.filter_converged_within_bounds,
            false_converged: self.false_converged,
            start_time_s: self.start_time_s,
            end_time_s: self.end_time_s,
            bounds: BoundsRecord {
                converge_m: p.converge_m,
                converge_rad: p.converge_rad,
                kidnap_jump_m: p.kidnap_jump_m,
                kidnap_turn_rad: p.kidnap_turn_rad,
                max_speed_mps: p.max_speed_mps,
                max_turn_rate_rad_s: p.max_turn_rate_rad_s,
            },
        }
    }

    /// The thesis's table and the rest of the report, in markdown.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let on_map = self
            .map
            .as_deref()
            .map_or_else(String::new, |m| format!(" on map {m}"));
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "robot {}{on_map}: {} frames with a true pose ({:.3} s to {:.3} s), \
             {} estimates, {} of them for those frames, {} within {} m and {} rad",
            self.robot,
            self.frames,
            self.start_time_s,
            self.end_time_s,
            self.estimates,
            self.estimates_paired,
            self.estimates_within_bounds,
            self.params.converge_m,
            self.params.converge_rad,
        );
        let _ = match &self.convergence {
            Some(c) => writeln!(
                out,
                "converged after {:.3} s and {:.3} m driven (frame {})",
                c.after_s, c.distance_m, c.sequence
            ),
            None => writeln!(out, "never converged"),
        };
        if let Some(first) = self.first_within
            && self
                .convergence
                .is_none_or(|c| c.sequence != first.sequence)
        {
            let _ = writeln!(
                out,
                "first within the bounds after {:.3} s (frame {}), outside them again before settling",
                first.after_s, first.sequence
            );
        }
        let recovered = self.kidnaps.iter().filter(|k| k.recovery.is_some()).count();
        let _ = match (self.kidnaps.len(), self.recover_s()) {
            (0, _) => writeln!(out, "not kidnapped"),
            (1, Some(s)) => writeln!(out, "kidnapped once, recovered, in {s:.3} s"),
            (1, None) => writeln!(out, "kidnapped once, not recovered"),
            (n, Some(s)) => writeln!(
                out,
                "kidnapped {n} times, recovered every time, the longest in {s:.3} s"
            ),
            (n, None) => writeln!(out, "kidnapped {n} times, recovered {recovered} times"),
        };
        let _ = writeln!(
            out,
            "the filter said converged for {} estimates, {} of them within the bounds, {} of them falsely (over {} m or {} rad off)",
            self.filter_converged,
            self.filter_converged_within_bounds,
            self.false_converged,
            super::FALSE_CONVERGED_M,
            super::FALSE_CONVERGED_RAD
        );
        match &self.stats {
            Some(s) => {
                let _ = writeln!(
                    out,
                    "\nerror over {} estimates after convergence and recoveries\n",
                    s.count
                );
                let _ = writeln!(
                    out,
                    "| | mean error | standard deviation | mean error | standard deviation | bias |"
                );
                let _ = writeln!(out, "|---|---:|---:|---:|---:|---:|");
                for (name, a) in [("x", s.x_m), ("y", s.y_m)] {
                    let inches = a.scaled(INCHES_PER_METRE);
                    let _ = writeln!(
                        out,
                        "| {name} | {:.4} m | {:.4} m | {:.4} in | {:.4} in | {:+.4} m |",
                        a.mean_abs, a.std_dev, inches.mean_abs, inches.std_dev, a.mean
                    );
                }
                let t = s.theta_rad;
                let d = t.scaled(180.0 / std::f64::consts::PI);
                let _ = writeln!(
                    out,
                    "| theta | {:.4} rad | {:.4} rad | {:.4} deg | {:.4} deg | {:+.4} deg |",
                    t.mean_abs, t.std_dev, d.mean_abs, d.std_dev, d.mean
                );
                let _ = writeln!(
                    out,
                    "\n(mean error: of |estimate - truth|; standard deviation and bias: of the \
                     signed error)"
                );
                let _ = writeln!(
                    out,
                    "rms position error {:.4} m ({:.4} in), largest {:.4} m",
                    s.rms_position_m,
                    s.rms_position_m * INCHES_PER_METRE,
                    s.max_position_m
                );
            }
            None => {
                let _ = writeln!(out, "\nno estimate after convergence: no error figures");
            }
        }
        if !self.kidnaps.is_empty() {
            let _ = writeln!(
                out,
                "\n| kidnap | frames | time s | jump m | turn deg | recovered | recover s | recover m | first back s |"
            );
            let _ = writeln!(out, "|---:|---|---:|---:|---:|---|---:|---:|---:|");
            for (i, k) in self.kidnaps.iter().enumerate() {
                let (recovered, seconds, metres) = match k.recovery {
                    Some(r) => (
                        "yes",
                        format!("{:.3}", r.after_s),
                        format!("{:.3}", r.distance_m),
                    ),
                    None => ("no", "n/a".to_string(), "n/a".to_string()),
                };
                let _ = writeln!(
                    out,
                    "| {} | {} to {} | {:.3} | {:.3} | {:.1} | {recovered} | {seconds} | {metres} | {} |",
                    i + 1,
                    k.sequence_before,
                    k.sequence,
                    k.time_s,
                    k.jump_m,
                    k.turn_rad.to_degrees(),
                    k.first_within
                        .map_or("n/a".to_string(), |f| format!("{:.3}", f.after_s)),
                );
            }
        }
        out
    }
}

fn kidnap_record(k: &Kidnap) -> KidnapRecord {
    KidnapRecord {
        sequence_before: k.sequence_before,
        sequence: k.sequence,
        time_s: k.time_s,
        from: k.from.into(),
        to: k.to.into(),
        jump_m: k.jump_m,
        turn_deg: k.turn_rad.to_degrees(),
        recovered: k.recovery.is_some(),
        recover_s: k.recovery.map(|r| r.after_s),
        recover_distance_m: k.recovery.map(|r| r.distance_m),
        recover_sequence: k.recovery.map(|r| r.sequence),
        first_within_s: k.first_within.map(|r| r.after_s),
    }
}

/// [`pretty_json`] of a record of plain data (numbers, strings, options),
/// which cannot fail.
pub(crate) fn pretty(value: &impl Serialize) -> String {
    pretty_json(value).unwrap_or_default()
}
