//! Fixed-point log-odds, the one arithmetic of occupancy in deog.
//!
//! A cell's belief is stored as `round(1000 · ln(p / (1 - p)))` in an `i16`:
//! one unit is a thousandth of a nat, so a probability near 0.5 is kept to
//! within 0.000125, and the Bayes update of the thesis's Fig. 7.1 (eq. 3.13
//! with a 0.5 prior) becomes an integer addition. The value `i16::MIN` is
//! reserved for a cell never observed, so an observed cell whose evidence
//! cancelled out (log-odds 0) stays distinguishable from an unknown one.
//!
//! Beliefs are clamped after each update, by default to the probabilities
//! 0.12 and 0.97 as OctoMap does: a cell can then change its mind after a few
//! contrary readings (a door opens, a person walks off) instead of after as
//! many as it ever received.

use crate::error::{GridError, within};

/// Fixed-point units per nat of log-odds.
pub const LOG_ODDS_SCALE: f64 = 1000.0;

/// A log-odds belief in thousandths of a nat.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct LogOdds(i16);

impl LogOdds {
    /// Probability 0.5: no evidence either way.
    pub const EVEN: LogOdds = LogOdds(0);
    /// The raw value marking a cell never observed.
    pub const UNKNOWN_RAW: i16 = i16::MIN;
    /// Largest representable belief, about 32.8 nats (p ≈ 1 - 6e-15).
    pub const MAX: LogOdds = LogOdds(i16::MAX);
    /// Smallest representable belief; `i16::MIN` is the unknown marker.
    pub const MIN: LogOdds = LogOdds(-i16::MAX);

    /// From raw fixed-point units; `None` for the unknown marker.
    pub fn from_raw(raw: i16) -> Option<Self> {
        (raw != Self::UNKNOWN_RAW).then_some(Self(raw))
    }

    /// The raw fixed-point value.
    pub fn raw(self) -> i16 {
        self.0
    }

    /// From a value in nats, rounded to the nearest unit and saturated at
    /// [`Self::MIN`] and [`Self::MAX`].
    pub fn from_nats(nats: f64) -> Result<Self, GridError> {
        let nats = within("log_odds", nats, f64::MIN, f64::MAX)?;
        Ok(Self(
            (nats * LOG_ODDS_SCALE)
                .round()
                .clamp(f64::from(Self::MIN.0), f64::from(Self::MAX.0)) as i16,
        ))
    }

    /// From a probability strictly between 0 and 1.
    pub fn from_probability(p: f64) -> Result<Self, GridError> {
        within("probability", p, 0.0, 1.0)?;
        if p == 0.0 || p == 1.0 {
            return Err(GridError::OutOfRange {
                field: "probability",
                value: p,
                min: f64::MIN_POSITIVE,
                max: 1.0 - f64::EPSILON,
            });
        }
        Self::from_nats(logit(p))
    }

    /// The belief in nats.
    pub fn nats(self) -> f64 {
        f64::from(self.0) / LOG_ODDS_SCALE
    }

    /// The belief as a probability of being occupied.
    pub fn probability(self) -> f64 {
        sigmoid(self.nats())
    }
}

/// `ln(p / (1 - p))`.
pub fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// The inverse of [`logit`]: `1 / (1 + e^-l)`.
pub fn sigmoid(nats: f64) -> f64 {
    1.0 / (1.0 + (-nats).exp())
}

/// Lower and upper bounds a cell's belief is clamped to after each update.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClampLimits {
    min: LogOdds,
    max: LogOdds,
}

impl ClampLimits {
    /// OctoMap's figures: probabilities 0.12 and 0.97.
    pub const DEFAULT_PROBABILITIES: (f64, f64) = (0.12, 0.97);
    /// No clamping beyond what the i16 holds: updates add exactly (until
    /// they saturate at ±32.7 nats).
    pub const NONE: ClampLimits = ClampLimits {
        min: LogOdds::MIN,
        max: LogOdds::MAX,
    };

    /// Limits from probabilities, `0 < min_p < 0.5 < max_p < 1`.
    pub fn from_probabilities(min_p: f64, max_p: f64) -> Result<Self, GridError> {
        within("clamp_min_probability", min_p, 1e-9, 0.5 - 1e-9)?;
        within("clamp_max_probability", max_p, 0.5 + 1e-9, 1.0 - 1e-9)?;
        Ok(Self {
            min: LogOdds::from_probability(min_p)?,
            max: LogOdds::from_probability(max_p)?,
        })
    }

    /// The lower bound.
    pub fn min(self) -> LogOdds {
        self.min
    }

    /// The upper bound.
    pub fn max(self) -> LogOdds {
        self.max
    }

    /// The raw value of a cell holding `current` (raw, possibly unknown)
    /// after adding `delta`. A zero delta leaves even an unknown cell
    /// unknown: no evidence was received.
    #[inline]
    pub fn apply(self, current: i16, delta: i16) -> i16 {
        if delta == 0 {
            return current;
        }
        let base = if current == LogOdds::UNKNOWN_RAW {
            0
        } else {
            i32::from(current)
        };
        (base + i32::from(delta)).clamp(i32::from(self.min.0), i32::from(self.max.0)) as i16
    }
}

impl Default for ClampLimits {
    fn default() -> Self {
        let (min, max) = Self::DEFAULT_PROBABILITIES;
        // The figures are constants inside the accepted range.
        Self::from_probabilities(min, max).expect("default clamp limits are valid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;

    /// The update of the thesis's Fig. 7.1 (eq. 3.13 in its probability form).
    fn fig_7_1_update(old: f64, reading: f64) -> f64 {
        let ps_e_pe = reading * old;
        ps_e_pe / ((1.0 - reading) * (1.0 - old) + ps_e_pe)
    }

    /// Largest probability error of one quantised log-odds step: half a unit,
    /// times the slope of the sigmoid, at most 1/4.
    const STEP_ERROR: f64 = 0.5 / LOG_ODDS_SCALE * 0.25;

    #[test]
    fn defaults_are_octomaps_figures() {
        let limits = ClampLimits::default();
        assert_abs_diff_eq!(limits.min().probability(), 0.12, epsilon = 1e-3);
        assert_abs_diff_eq!(limits.max().probability(), 0.97, epsilon = 1e-3);
    }

    #[test]
    fn probability_round_trip_is_within_half_a_unit() {
        for p in [0.001, 0.12, 0.3, 0.5, 0.7, 0.97, 0.999] {
            let l = LogOdds::from_probability(p).unwrap();
            assert_abs_diff_eq!(l.probability(), p, epsilon = STEP_ERROR);
        }
    }

    #[test]
    fn impossible_probabilities_are_errors() {
        for p in [0.0, 1.0, -0.1, 1.5, f64::NAN, f64::INFINITY] {
            assert!(LogOdds::from_probability(p).is_err(), "{p}");
        }
        assert!(ClampLimits::from_probabilities(0.6, 0.9).is_err());
        assert!(ClampLimits::from_probabilities(0.1, 0.4).is_err());
    }

    #[test]
    fn zero_delta_keeps_unknown_and_others_start_from_even() {
        let limits = ClampLimits::default();
        assert_eq!(limits.apply(LogOdds::UNKNOWN_RAW, 0), LogOdds::UNKNOWN_RAW);
        assert_eq!(limits.apply(LogOdds::UNKNOWN_RAW, 100), 100);
        assert_eq!(limits.apply(LogOdds::UNKNOWN_RAW, -100), -100);
        assert_eq!(limits.apply(0, 30_000), limits.max().raw());
        assert_eq!(limits.apply(0, -30_000), limits.min().raw());
        assert_eq!(ClampLimits::NONE.apply(i16::MAX, i16::MAX), i16::MAX);
        assert_ne!(
            ClampLimits::NONE.apply(-i16::MAX, -i16::MAX),
            LogOdds::UNKNOWN_RAW
        );
    }

    proptest! {
        /// A run of readings summed in log-odds gives what Fig. 7.1's formula
        /// gives applied in turn, within the quantisation of each step.
        #[test]
        fn summed_log_odds_agree_with_fig_7_1(readings in proptest::collection::vec(0.2f64..0.8, 1..40)) {
            let mut thesis = 0.5;
            let mut cell = LogOdds::UNKNOWN_RAW;
            for &p in &readings {
                thesis = fig_7_1_update(thesis, p);
                let delta = LogOdds::from_probability(p).unwrap().raw();
                cell = ClampLimits::NONE.apply(cell, delta);
            }
            let ours = LogOdds::from_raw(cell).unwrap().probability();
            prop_assert!((ours - thesis).abs() <= STEP_ERROR * readings.len() as f64,
                "{ours} vs {thesis}");
        }

        /// With clamping, the same holds against Fig. 7.1 with its result
        /// clamped to the limits after each step.
        #[test]
        fn clamped_log_odds_agree_with_clamped_fig_7_1(readings in proptest::collection::vec(0.05f64..0.95, 1..40)) {
            let limits = ClampLimits::default();
            let (lo, hi) = (limits.min().probability(), limits.max().probability());
            let mut thesis = 0.5;
            let mut cell = LogOdds::UNKNOWN_RAW;
            for &p in &readings {
                thesis = fig_7_1_update(thesis, p).clamp(lo, hi);
                cell = limits.apply(cell, LogOdds::from_probability(p).unwrap().raw());
            }
            let ours = LogOdds::from_raw(cell).unwrap().probability();
            prop_assert!((ours - thesis).abs() <= STEP_ERROR * readings.len() as f64,
                "{ours} vs {thesis}");
        }
    }
}
