//! Many seeded runs summed up, as `deog bench localize` reports them: how
//! many converged and how many recovered from their kidnap within a time
//! limit, and the mean errors once localized.

use serde::Serialize;

use crate::localization::LocalizationReport;

/// One run's figures, from its [`LocalizationReport`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RunFigures {
    /// Seconds from the first frame to the convergence.
    pub converge_s: Option<f64>,
    /// Seconds from the kidnap to the recovery (the longest, if several);
    /// `None` without a kidnap or when not recovered.
    pub recover_s: Option<f64>,
    /// Mean position error of the used estimates, metres.
    pub mean_position_m: Option<f64>,
    /// Mean absolute heading error of the used estimates, degrees.
    pub mean_heading_deg: Option<f64>,
    /// Estimates used for the mean errors.
    pub samples: u64,
    /// Estimates flagged converged while more than 0.5 m or 0.25 rad off.
    pub false_converged: u64,
}

impl From<&LocalizationReport> for RunFigures {
    fn from(r: &LocalizationReport) -> Self {
        let stats = r.stats.as_ref();
        Self {
            converge_s: r.converge_s(),
            recover_s: r.recover_s(),
            mean_position_m: stats.map(|s| s.mean_position_m),
            mean_heading_deg: stats.map(|s| s.theta_rad.mean_abs.to_degrees()),
            samples: stats.map_or(0, |s| s.count),
            false_converged: r.false_converged,
        }
    }
}

/// Runs summed up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RunsSummary {
    /// Runs.
    pub runs: usize,
    /// The time limit, seconds.
    pub limit_s: f64,
    /// Runs that converged within the limit.
    pub converged: usize,
    /// Runs that recovered from their kidnap within the limit.
    pub recovered: usize,
    /// Mean over the runs that have one of their mean position error, metres.
    pub mean_position_m: Option<f64>,
    /// The same for the heading, degrees.
    pub mean_heading_deg: Option<f64>,
    /// Estimates flagged converged while more than 0.5 m or 0.25 rad off,
    /// over every run.
    pub false_converged: u64,
    /// Runs with at least one such estimate.
    pub runs_false_converged: usize,
}

impl RunsSummary {
    /// The share of runs that converged within the limit, percent.
    pub fn converged_percent(&self) -> f64 {
        percent(self.converged, self.runs)
    }

    /// The share that recovered within the limit, percent.
    pub fn recovered_percent(&self) -> f64 {
        percent(self.recovered, self.runs)
    }
}

fn percent(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

/// Sums up `runs` against a time limit of `limit_s` seconds.
pub fn summarize(runs: &[RunFigures], limit_s: f64) -> RunsSummary {
    let within = |t: Option<f64>| t.is_some_and(|t| t <= limit_s);
    let with: Vec<&RunFigures> = runs.iter().filter(|f| f.samples > 0).collect();
    let mean = |pick: fn(&RunFigures) -> Option<f64>| {
        let values: Vec<f64> = with.iter().filter_map(|f| pick(f)).collect();
        (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
    };
    RunsSummary {
        runs: runs.len(),
        limit_s,
        converged: runs.iter().filter(|f| within(f.converge_s)).count(),
        recovered: runs.iter().filter(|f| within(f.recover_s)).count(),
        mean_position_m: mean(|f| f.mean_position_m),
        mean_heading_deg: mean(|f| f.mean_heading_deg),
        false_converged: runs.iter().map(|f| f.false_converged).sum(),
        runs_false_converged: runs.iter().filter(|f| f.false_converged > 0).count(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_past_the_limit_or_without_samples_do_not_count() {
        let runs = [
            RunFigures {
                converge_s: Some(10.0),
                recover_s: Some(61.0),
                mean_position_m: Some(0.02),
                mean_heading_deg: Some(0.5),
                samples: 100,
                false_converged: 0,
            },
            RunFigures {
                converge_s: Some(60.0),
                recover_s: Some(5.0),
                mean_position_m: Some(0.04),
                mean_heading_deg: Some(1.5),
                samples: 50,
                false_converged: 4,
            },
            RunFigures::default(),
        ];
        let s = summarize(&runs, 60.0);
        assert_eq!((s.runs, s.converged, s.recovered), (3, 2, 1));
        assert!((s.mean_position_m.unwrap() - 0.03).abs() < 1e-12);
        assert!((s.mean_heading_deg.unwrap() - 1.0).abs() < 1e-12);
        assert!((s.converged_percent() - 200.0 / 3.0).abs() < 1e-9);
        assert_eq!((s.false_converged, s.runs_false_converged), (4, 1));
        assert_eq!(summarize(&[], 60.0).mean_position_m, None);
    }
}
