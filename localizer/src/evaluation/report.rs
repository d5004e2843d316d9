//! A [`LocalizationReport`] as a markdown table for people and as JSON for
//! tools. The JSON names are an interface: other tools read them.

use std::fmt::Write as _;

use deog_grid::Pose2;

use super::{AxisStats, Kidnap, LocalizationReport, METRES_PER_INCH, Settling};

/// Inches per metre.
const INCHES_PER_METRE: f64 = 1.0 / METRES_PER_INCH;

/// Every report in one JSON document: `{"robots": [<report>, ...]}`, each
/// report as [`LocalizationReport::to_json`] writes it.
pub fn reports_to_json(reports: &[LocalizationReport]) -> String {
    let robots: Vec<String> = reports.iter().map(|r| r.json_object("    ")).collect();
    if robots.is_empty() {
        return "{\n  \"robots\": []\n}\n".to_string();
    }
    format!("{{\n  \"robots\": [\n{}\n  ]\n}}\n", robots.join(",\n"))
}

impl LocalizationReport {
    /// One JSON object. The keys `name`, `converged`, `converge_s`,
    /// `mean_abs_error_m` (`x`, `y`), `mean_abs_error_deg`,
    /// `rms_position_m`, `kidnapped`, `recovered` and `recover_s` are an
    /// interface; the others add the rest of the report. Figures that do
    /// not exist are `null`.
    pub fn to_json(&self) -> String {
        format!("{}\n", self.json_object(""))
    }

    /// The object, each line after the first indented by `indent`.
    fn json_object(&self, indent: &str) -> String {
        let stats = self.stats.as_ref();
        let axis = |pick: fn(&super::ErrorStats) -> AxisStats| stats.map(pick);
        let (x, y, theta) = (axis(|s| s.x_m), axis(|s| s.y_m), axis(|s| s.theta_rad));
        let xy = |factor: f64, field: fn(&AxisStats) -> f64| {
            format!(
                "{{\"x\": {}, \"y\": {}}}",
                number(x.map(|a| field(&a) * factor)),
                number(y.map(|a| field(&a) * factor))
            )
        };
        let angle =
            |factor: f64, field: fn(&AxisStats) -> f64| number(theta.map(|a| field(&a) * factor));
        let degrees = 180.0 / std::f64::consts::PI;
        let p = &self.params;
        let fields: Vec<(&str, String)> = vec![
            ("name", string(&self.robot)),
            ("map", self.map.as_deref().map_or("null".into(), string)),
            ("converged", self.converged().to_string()),
            ("converge_s", number(self.converge_s())),
            (
                "converge_sequence",
                integer(self.convergence.map(|c| c.sequence)),
            ),
            (
                "converge_distance_m",
                number(self.convergence.map(|c| c.distance_m)),
            ),
            ("mean_abs_error_m", xy(1.0, |a| a.mean_abs)),
            ("mean_abs_error_in", xy(INCHES_PER_METRE, |a| a.mean_abs)),
            ("std_error_m", xy(1.0, |a| a.std_dev)),
            ("std_error_in", xy(INCHES_PER_METRE, |a| a.std_dev)),
            ("mean_error_m", xy(1.0, |a| a.mean)),
            ("mean_abs_error_rad", angle(1.0, |a| a.mean_abs)),
            ("mean_abs_error_deg", angle(degrees, |a| a.mean_abs)),
            ("std_error_rad", angle(1.0, |a| a.std_dev)),
            ("std_error_deg", angle(degrees, |a| a.std_dev)),
            ("mean_error_rad", angle(1.0, |a| a.mean)),
            ("mean_error_deg", angle(degrees, |a| a.mean)),
            ("rms_position_m", number(stats.map(|s| s.rms_position_m))),
            ("max_position_m", number(stats.map(|s| s.max_position_m))),
            ("estimates_used", stats.map_or(0, |s| s.count).to_string()),
            ("kidnapped", self.kidnapped().to_string()),
            (
                "recovered",
                self.recovered().map_or("null".into(), |r| r.to_string()),
            ),
            ("recover_s", number(self.recover_s())),
            ("kidnap_count", self.kidnaps.len().to_string()),
            ("kidnaps", self.kidnaps_json(indent)),
            ("frames", self.frames.to_string()),
            (
                "frames_after_last_estimate",
                self.frames_after_last_estimate.to_string(),
            ),
            ("estimates", self.estimates.to_string()),
            ("estimates_paired", self.estimates_paired.to_string()),
            (
                "estimates_within_bounds",
                self.estimates_within_bounds.to_string(),
            ),
            ("filter_converged", self.filter_converged.to_string()),
            (
                "filter_converged_within_bounds",
                self.filter_converged_within_bounds.to_string(),
            ),
            ("start_time_s", number(Some(self.start_time_s))),
            ("end_time_s", number(Some(self.end_time_s))),
            (
                "bounds",
                format!(
                    "{{\"converge_m\": {}, \"converge_rad\": {}, \"kidnap_jump_m\": {}, \
                     \"kidnap_turn_rad\": {}, \"max_speed_mps\": {}, \"max_turn_rate_rad_s\": {}}}",
                    number(Some(p.converge_m)),
                    number(Some(p.converge_rad)),
                    number(Some(p.kidnap_jump_m)),
                    number(Some(p.kidnap_turn_rad)),
                    number(Some(p.max_speed_mps)),
                    number(Some(p.max_turn_rate_rad_s)),
                ),
            ),
        ];
        let body: Vec<String> = fields
            .iter()
            .map(|(name, value)| format!("{indent}  \"{name}\": {value}"))
            .collect();
        format!("{indent}{{\n{}\n{indent}}}", body.join(",\n"))
    }

    /// The kidnaps as a JSON array, one object a line.
    fn kidnaps_json(&self, indent: &str) -> String {
        if self.kidnaps.is_empty() {
            return "[]".to_string();
        }
        let items: Vec<String> = self
            .kidnaps
            .iter()
            .map(|k| format!("{indent}    {}", kidnap_json(k)))
            .collect();
        format!("[\n{}\n{indent}  ]", items.join(",\n"))
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
            "the filter said converged for {} estimates, {} of them within the bounds",
            self.filter_converged, self.filter_converged_within_bounds
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
                "\n| kidnap | frames | time s | jump m | turn deg | recovered | recover s | recover m |"
            );
            let _ = writeln!(out, "|---:|---|---:|---:|---:|---|---:|---:|");
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
                    "| {} | {} to {} | {:.3} | {:.3} | {:.1} | {recovered} | {seconds} | {metres} |",
                    i + 1,
                    k.sequence_before,
                    k.sequence,
                    k.time_s,
                    k.jump_m,
                    k.turn_rad.to_degrees(),
                );
            }
        }
        out
    }
}

fn kidnap_json(k: &Kidnap) -> String {
    let recovery = |pick: fn(&Settling) -> f64| number(k.recovery.as_ref().map(pick));
    format!(
        "{{\"sequence_before\": {}, \"sequence\": {}, \"time_s\": {}, \"from\": {}, \"to\": {}, \
         \"jump_m\": {}, \"turn_deg\": {}, \"recovered\": {}, \"recover_s\": {}, \
         \"recover_distance_m\": {}, \"recover_sequence\": {}}}",
        k.sequence_before,
        k.sequence,
        number(Some(k.time_s)),
        pose(&k.from),
        pose(&k.to),
        number(Some(k.jump_m)),
        number(Some(k.turn_rad.to_degrees())),
        k.recovery.is_some(),
        recovery(|r| r.after_s),
        recovery(|r| r.distance_m),
        integer(k.recovery.map(|r| r.sequence)),
    )
}

fn pose(p: &Pose2) -> String {
    format!(
        "{{\"x\": {}, \"y\": {}, \"theta\": {}}}",
        number(Some(p.x)),
        number(Some(p.y)),
        number(Some(p.theta))
    )
}

/// A JSON number, or `null` for an undefined or non-finite one (JSON has
/// no NaN). Rust's `Display` for `f64` never uses an exponent, so the text
/// is valid JSON as it stands.
fn number(value: Option<f64>) -> String {
    match value {
        Some(v) if v.is_finite() => format!("{v}"),
        _ => "null".to_string(),
    }
}

fn integer(value: Option<u64>) -> String {
    value.map_or_else(|| "null".to_string(), |v| v.to_string())
}

/// A JSON string literal.
fn string(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if u32::from(c) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
