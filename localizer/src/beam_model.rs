//! The sonar beam model (Probabilistic Robotics, section 6.3): the
//! likelihood of a measured range `z` given the range `z*` the map predicts
//! for the beam's cone, as a mixture of four causes.
//!
//! - **hit**: the echo of the predicted obstacle, `N(z; z*, σ(z*)²)` with
//!   `σ(z*) = σ₀ + σ₁·z*` (map blur plus the sonar's relative error);
//! - **short**: an unmapped obstacle (another robot, a person) in front of
//!   it, `λ·e^(−λz) / (1 − e^(−λz*))` for `z < z*`;
//! - **max**: no echo (a specular reflection lost the sound), a point mass
//!   at the maximum range;
//! - **random**: anything else, uniform `1 / z_max`, which also covers the
//!   long ranges of multiple reflections.
//!
//! When the cone holds no obstacle within range (`z*` = no echo), a
//! no-echo reading is the expected one and gets the hit weight as well;
//! when the sensor sits inside an obstacle (`z*` = 0), only the random and
//! max causes remain. Masses (max) and densities (per metre) mix only
//! across particles that share the same measurement, so comparing them is
//! sound.
//!
//! **Combining beams.** A particle's log-likelihood is
//! `τ · Σₖ ln p(zₖ | z*ₖ)`. The beams are not independent: the Scout's
//! 30° cones overlap by 7.5° on each side, and errors of a sonar-built map
//! repeat from beam to beam. Counting 16 beams as 16 independent
//! observations makes the posterior far too sharp, and then a few unlucky
//! frames wipe out the right particles before the evidence that tells two
//! look-alike places apart arrives. The tempering `τ` counts the frame as
//! `16 · τ` independent observations; it is the exponent of the product of
//! beam likelihoods, applied once in log space. The default, 1/20 (a frame
//! weighs as much as one independent beam), was measured best for global
//! localization in the nearly symmetric `map1` and costs nothing in
//! tracking accuracy (BENCHMARKS.md, localization).
//!
//! Per frame, each beam's log-likelihood is tabulated over `z*` in
//! centimetres ([`BeamModel::tabulate`]), so that scoring a particle costs
//! one table read per beam and an integer sum.

use crate::error::{LocalizerError, within};

/// Units of a tabulated log-likelihood per nat.
pub const TABLE_SCALE: f64 = 1000.0;

/// Table slots per beam: predicted ranges 0 to `z_max` in whole centimetres,
/// and one more for no echo.
pub fn table_len(max_range: f64) -> usize {
    (max_range * 100.0).ceil() as usize + 2
}

/// τ for a specular sonar ([`BeamModelParams::for_sonar`]): a frame of
/// one counts as 16 · 0.08 ≈ 1.3 independent beams. Its walls met past
/// the critical angle send nothing back, so fewer of a frame's beams carry
/// an echo, and the map built from such readings disagrees with more of
/// them; the default τ then weighs a frame too lightly to single out a
/// place. Measured best for
/// `--sonar realistic` in `map2` (converged within 60 s in 56 of 60 seeds
/// against 47 at the default; 0.07 to 0.10 all better than 0.05, 0.12
/// worse), no worse in `map1`, and still best once the weights of
/// [`BeamModelParams::for_sonar`] were fitted (BENCHMARKS.md,
/// localization).
pub const SPECULAR_TEMPERING: f64 = 0.08;

/// σ₀ for a specular sonar ([`BeamModelParams::for_sonar`]), metres. The
/// echoes a specular sonar keeps come from walls met within the critical
/// angle of their normal, so nearly square on: their ranges spread less
/// about the map's than a sonar's that hears walls at any slant. With
/// the specular surface depth of [`crate::range_table::ConeGeometry::for_sonar`],
/// σ₀ 0.03 and σ₁ 0.005 against 0.05 and 0.02 took the mean error after
/// convergence in `map2` from 3.5 cm and 1.05° to 2.8 cm and 0.86°, and
/// converged more often in `map1` (BENCHMARKS.md, localization).
pub const SPECULAR_HIT_SIGMA_M: f64 = 0.03;

/// σ₁ for a specular sonar: the hit spread's growth per metre (see
/// [`SPECULAR_HIT_SIGMA_M`]).
pub const SPECULAR_HIT_SIGMA_PER_M: f64 = 0.005;

/// The mixture's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamModelParams {
    /// The sonar's maximum range, metres; readings at or past it are no echo.
    pub max_range: f64,
    /// σ₀: the hit spread at zero range, metres.
    pub hit_sigma_m: f64,
    /// σ₁: the hit spread's growth per metre of range.
    pub hit_sigma_per_m: f64,
    /// Weight of hits.
    pub weight_hit: f64,
    /// Weight of short readings.
    pub weight_short: f64,
    /// Weight of no echo.
    pub weight_max: f64,
    /// Weight of random readings.
    pub weight_random: f64,
    /// λ of short readings, per metre.
    pub short_rate: f64,
    /// τ: the exponent applied to the product of the beams' likelihoods.
    pub tempering: f64,
}

impl Default for BeamModelParams {
    fn default() -> Self {
        Self {
            max_range: 10.668,
            hit_sigma_m: 0.05,
            hit_sigma_per_m: 0.02,
            weight_hit: 0.75,
            weight_short: 0.05,
            weight_max: 0.05,
            weight_random: 0.15,
            short_rate: 0.5,
            tempering: 0.05,
        }
    }
}

impl BeamModelParams {
    /// The defaults, or for a specular sonar (its walls past the critical
    /// angle send no echo) [`SPECULAR_TEMPERING`] and the causes' weights
    /// as such a sonar's readings show them: fitted by expectation–
    /// maximization (Probabilistic Robotics, 6.3.2) to the 28,800 beams of
    /// 180 s of `--sonar realistic` frames at the true pose, on the map
    /// built from such frames, they came out as hit 0.55, short 0.03, max
    /// 0.10 and random 0.32 in `map2` (0.60, 0.00, 0.11 and 0.29 in
    /// `map1`), against the defaults' 0.75, 0.05, 0.05 and 0.15. More
    /// echoes lost (max) and more that no prediction explains (random):
    /// a miss costs a particle less. The hit spread is narrower
    /// ([`SPECULAR_HIT_SIGMA_M`], [`SPECULAR_HIT_SIGMA_PER_M`]).
    pub fn for_sonar(specular: bool) -> Self {
        let defaults = Self::default();
        if !specular {
            return defaults;
        }
        Self {
            tempering: SPECULAR_TEMPERING,
            weight_hit: 0.57,
            weight_short: 0.03,
            weight_max: 0.10,
            weight_random: 0.30,
            hit_sigma_m: SPECULAR_HIT_SIGMA_M,
            hit_sigma_per_m: SPECULAR_HIT_SIGMA_PER_M,
            ..defaults
        }
    }

    /// The parameters if each is in range and the weights are not all zero.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("max_range", self.max_range, 0.1, 60.0)?;
        within("hit_sigma_m", self.hit_sigma_m, 0.001, 5.0)?;
        within("hit_sigma_per_m", self.hit_sigma_per_m, 0.0, 1.0)?;
        within("weight_hit", self.weight_hit, 0.0, 1.0)?;
        within("weight_short", self.weight_short, 0.0, 1.0)?;
        within("weight_max", self.weight_max, 0.0, 1.0)?;
        within("weight_random", self.weight_random, 1e-6, 1.0)?;
        within("short_rate", self.short_rate, 1e-3, 100.0)?;
        within("tempering", self.tempering, 1e-3, 1.0)?;
        Ok(self)
    }
}

/// The beam model with its constants worked out, and the tables of the
/// measured ranges met so far.
#[derive(Debug, Clone)]
pub struct BeamModel {
    params: BeamModelParams,
    no_echo_slot: usize,
    /// Per predicted range slot: `1 / (1 − e^(−λz*))`, the short term's
    /// normaliser.
    short_norms: Vec<f64>,
    /// Per measured range in whole centimetres (and no echo, last): its
    /// table, built the first time a frame holds that range. Ranges repeat
    /// from frame to frame, so after a few frames tabulating costs nothing.
    cache: Vec<Option<Box<[i16]>>>,
}

impl BeamModel {
    /// A model from validated parameters.
    pub fn new(params: BeamModelParams) -> Result<Self, LocalizerError> {
        let params = params.validate()?;
        let len = table_len(params.max_range);
        let short_norms = (0..len - 1)
            .map(|slot| {
                let expected = slot as f64 / 100.0;
                1.0 / (1.0 - (-params.short_rate * expected).exp()).max(1e-12)
            })
            .collect();
        Ok(Self {
            no_echo_slot: len - 1,
            short_norms,
            cache: vec![None; len],
            params,
        })
    }

    /// The slot of a measured range: whole centimetres (below the no-echo
    /// slot), or the no-echo slot at or past the maximum range.
    pub fn measured_slot(&self, measured: f64) -> usize {
        // NaN counts as no echo too.
        if measured.is_nan() || measured >= self.params.max_range {
            return self.no_echo_slot;
        }
        ((measured.max(0.0) * 100.0).round() as usize).min(self.no_echo_slot - 1)
    }

    /// The table ([`Self::tabulate`]) of the measured range of `slot`
    /// ([`Self::measured_slot`]), built once and kept.
    pub fn cached_table(&mut self, slot: usize) -> &[i16] {
        let slot = slot.min(self.no_echo_slot);
        if self.cache[slot].is_none() {
            let measured = if slot == self.no_echo_slot {
                self.params.max_range
            } else {
                // The last slot rounds up past the maximum; keep it an echo.
                (slot as f64 / 100.0).min(self.params.max_range - 1e-6)
            };
            let mut table = Vec::new();
            self.tabulate(measured, &mut table);
            self.cache[slot] = Some(table.into_boxed_slice());
        }
        self.cache[slot].as_deref().unwrap_or_default()
    }

    /// A table [`Self::cached_table`] has built.
    pub fn built_table(&self, slot: usize) -> Option<&[i16]> {
        self.cache.get(slot)?.as_deref()
    }

    /// The parameters.
    pub fn params(&self) -> &BeamModelParams {
        &self.params
    }

    /// The table slot of the no-echo prediction.
    pub fn no_echo_slot(&self) -> usize {
        self.no_echo_slot
    }

    /// `p(z | z*)`; `None` for either means no echo.
    pub fn likelihood(&self, measured: Option<f64>, predicted: Option<f64>) -> f64 {
        let p = &self.params;
        let z_max = p.max_range;
        let random = p.weight_random / z_max;
        match (measured, predicted) {
            (None, None) => p.weight_hit + p.weight_max,
            (None, Some(expected)) => {
                let sigma = p.hit_sigma_m + p.hit_sigma_per_m * expected;
                p.weight_max + p.weight_hit * upper_tail((z_max - expected) / sigma)
            }
            (Some(z), predicted) => {
                let expected = predicted.unwrap_or(z_max);
                let sigma = p.hit_sigma_m + p.hit_sigma_per_m * expected;
                let hit = p.weight_hit * gaussian_density(z - expected, sigma);
                let short = if z < expected {
                    let norm = 1.0 - (-p.short_rate * expected).exp();
                    p.weight_short * p.short_rate * (-p.short_rate * z).exp() / norm.max(1e-12)
                } else {
                    0.0
                };
                hit + short + random
            }
        }
    }

    /// `ln p(z | z*)` for every predicted range slot (centimetres, then no
    /// echo), for one measured range, into `out`, in thousandths of a nat
    /// ([`TABLE_SCALE`]; the tempering is applied to the sum): 16 beams'
    /// tables then fit the first-level cache. A measured range at or past
    /// the maximum is no echo; one below zero counts as zero.
    pub fn tabulate(&self, measured: f64, out: &mut Vec<i16>) {
        out.clear();
        if measured.is_nan() || measured >= self.params.max_range {
            for slot in 0..self.no_echo_slot {
                out.push(fixed(self.likelihood(None, Some(slot as f64 / 100.0))));
            }
            out.push(fixed(self.likelihood(None, None)));
            return;
        }
        // As `likelihood` term by term, with what repeats worked out once: a
        // hit more than `HIT_REACH` spreads off adds less than the table's
        // resolution, and below the measured range there is no short term,
        // so most slots are the random share alone and need no logarithm.
        const HIT_REACH: f64 = 8.0;
        let p = &self.params;
        let z = measured.max(0.0);
        let random = p.weight_random / p.max_range;
        let random_only = fixed(random);
        let short_scale = p.weight_short * p.short_rate * (-p.short_rate * z).exp();
        for slot in 0..self.no_echo_slot {
            let expected = slot as f64 / 100.0;
            let sigma = p.hit_sigma_m + p.hit_sigma_per_m * expected;
            let offset = z - expected;
            let near = offset.abs() < HIT_REACH * sigma;
            let short = z < expected && p.weight_short > 0.0;
            if !near && !short {
                out.push(random_only);
                continue;
            }
            let mut likelihood = random;
            if near {
                likelihood += p.weight_hit * gaussian_density(offset, sigma);
            }
            if short {
                likelihood += short_scale * self.short_norms[slot];
            }
            out.push(fixed(likelihood));
        }
        out.push(fixed(self.likelihood(Some(z), None)));
    }
}

/// `ln(likelihood)` in thousandths of a nat ([`TABLE_SCALE`]), rounded half
/// away from zero and held within `i16`.
fn fixed(likelihood: f64) -> i16 {
    let scaled = likelihood.ln() * TABLE_SCALE;
    let limit = f64::from(i16::MAX);
    // A conversion truncates; with a half added away from zero it rounds
    // (no call to the library's `round`).
    let rounded = (scaled + 0.5f64.copysign(scaled)).clamp(-limit, limit);
    rounded as i16
}

fn gaussian_density(x: f64, sigma: f64) -> f64 {
    const INV_SQRT_TAU: f64 = 0.398_942_280_401_432_7;
    INV_SQRT_TAU / sigma * (-0.5 * (x / sigma).powi(2)).exp()
}

/// P(N(0, 1) > x), from the complementary error function (Abramowitz and
/// Stegun 7.1.26, absolute error below 1.5e-7).
fn upper_tail(x: f64) -> f64 {
    let t = x / std::f64::consts::SQRT_2;
    let z = t.abs();
    let k = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = k
        * (0.254_829_592
            + k * (-0.284_496_736
                + k * (1.421_413_741 + k * (-1.453_152_027 + k * 1.061_405_429))));
    let erfc = poly * (-z * z).exp();
    let erfc = if t >= 0.0 { erfc } else { 2.0 - erfc };
    0.5 * erfc
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    fn model() -> BeamModel {
        BeamModel::new(BeamModelParams::default()).unwrap()
    }

    #[test]
    fn a_specular_sonar_weighs_its_frames_more_and_its_misses_less() {
        let plain = BeamModelParams::for_sonar(false);
        let specular = BeamModelParams::for_sonar(true).validate().unwrap();
        assert_eq!(plain, BeamModelParams::default());
        assert!(specular.tempering > plain.tempering);
        let weights =
            |p: &BeamModelParams| p.weight_hit + p.weight_short + p.weight_max + p.weight_random;
        assert_abs_diff_eq!(weights(&specular), weights(&plain), epsilon = 1e-12);
        // The same range; the causes' shares differ, and the echoes kept
        // (walls met nearly square on) spread less.
        assert!(specular.hit_sigma_m < plain.hit_sigma_m);
        assert!(specular.hit_sigma_per_m < plain.hit_sigma_per_m);
        assert_eq!(specular.max_range, plain.max_range);
        let (plain, specular) = (
            BeamModel::new(plain).unwrap(),
            BeamModel::new(specular).unwrap(),
        );
        // A reading far longer than predicted (a grazed wall the map
        // expected to answer) and a lost echo cost less; a match still
        // beats either.
        let far = |m: &BeamModel| m.likelihood(Some(6.0), Some(2.0));
        let lost = |m: &BeamModel| m.likelihood(None, Some(2.0));
        assert!(far(&specular) > far(&plain));
        assert!(lost(&specular) > lost(&plain));
        let matched = specular.likelihood(Some(2.0), Some(2.0));
        assert!(matched > far(&specular) && matched > lost(&specular));
    }

    #[test]
    fn a_matching_reading_beats_a_mismatch() {
        let m = model();
        let right = m.likelihood(Some(2.0), Some(2.0));
        let near = m.likelihood(Some(2.0), Some(2.1));
        let far = m.likelihood(Some(2.0), Some(4.0));
        let beyond = m.likelihood(Some(4.0), Some(2.0));
        assert!(
            right > near && near > far && near > beyond,
            "{right} {near} {far} {beyond}"
        );
        // A short reading (something in front) is likelier than one past the wall.
        assert!(far > beyond);
        // No echo is expected when nothing is in range.
        assert!(m.likelihood(None, None) > m.likelihood(None, Some(2.0)));
        // Inside a wall, a reading gets only the random share.
        let inside = m.likelihood(Some(2.0), Some(0.0));
        assert_abs_diff_eq!(inside, 0.15 / 10.668, epsilon = 1e-6);
    }

    #[test]
    fn hit_term_is_the_gaussian() {
        let params = BeamModelParams {
            weight_hit: 1.0,
            weight_short: 0.0,
            weight_max: 0.0,
            weight_random: 1e-6,
            ..BeamModelParams::default()
        };
        let m = BeamModel::new(params).unwrap();
        // σ(3 m) = 0.05 + 0.06 = 0.11 m; one σ off the density falls by e^(−1/2).
        let at = m.likelihood(Some(3.0), Some(3.0));
        let off = m.likelihood(Some(3.11), Some(3.0));
        assert_abs_diff_eq!(off / at, (-0.5f64).exp(), epsilon = 1e-4);
        assert_abs_diff_eq!(
            at,
            1.0 / (0.11 * std::f64::consts::TAU.sqrt()),
            epsilon = 1e-3
        );
    }

    #[test]
    fn tail_function_matches_known_values() {
        assert_abs_diff_eq!(upper_tail(0.0), 0.5, epsilon = 1e-7);
        assert_abs_diff_eq!(upper_tail(1.0), 0.158_655_25, epsilon = 1e-6);
        assert_abs_diff_eq!(upper_tail(-1.96), 0.975_002_1, epsilon = 1e-6);
    }

    #[test]
    fn table_holds_tempered_logs() {
        let m = model();
        let mut table = Vec::new();
        m.tabulate(2.0, &mut table);
        assert_eq!(table.len(), table_len(10.668));
        assert_eq!(table.len() - 1, m.no_echo_slot());
        let expected = m.likelihood(Some(2.0), Some(2.0)).ln();
        assert_abs_diff_eq!(
            f64::from(table[200]) / TABLE_SCALE,
            expected,
            epsilon = 1e-3
        );
        let best = (0..table.len())
            .max_by_key(|&a| (table[a], std::cmp::Reverse(a.abs_diff(200))))
            .unwrap();
        assert_eq!(best, 200);
        m.tabulate(20.0, &mut table);
        let best = (0..table.len()).max_by_key(|&a| table[a]).unwrap();
        assert_eq!(best, m.no_echo_slot());
    }

    #[test]
    fn tables_match_the_likelihood_slot_by_slot() {
        for params in [
            BeamModelParams::default(),
            BeamModelParams {
                weight_short: 0.0,
                hit_sigma_per_m: 0.0,
                ..BeamModelParams::default()
            },
        ] {
            let m = BeamModel::new(params).unwrap();
            let mut table = Vec::new();
            for measured in [
                0.0, 0.004, 0.37, 1.0, 2.345, 5.5, 10.0, 10.667, 10.668, 30.0,
            ] {
                m.tabulate(measured, &mut table);
                let z = (measured < params.max_range).then_some(measured);
                for (slot, &value) in table.iter().enumerate() {
                    let predicted = (slot < m.no_echo_slot()).then(|| slot as f64 / 100.0);
                    let exact = m.likelihood(z, predicted).ln() * TABLE_SCALE;
                    assert!(
                        (f64::from(value) - exact).abs() <= 0.5 + 1e-6,
                        "measured {measured}, slot {slot}: {value} against {exact}"
                    );
                }
            }
        }
    }

    #[test]
    fn cached_tables_are_the_tables_of_whole_centimetres() {
        let mut m = model();
        let mut table = Vec::new();
        m.tabulate(2.34, &mut table);
        let slot = m.measured_slot(2.3449);
        assert_eq!(slot, 234);
        assert_eq!(m.cached_table(slot), &table[..]);
        assert_eq!(m.measured_slot(10.668), m.no_echo_slot());
        assert_eq!(m.measured_slot(f64::INFINITY), m.no_echo_slot());
        assert_eq!(m.measured_slot(10.6675), m.no_echo_slot() - 1);
        m.tabulate(20.0, &mut table);
        let no_echo = m.no_echo_slot();
        assert_eq!(m.cached_table(no_echo), &table[..]);
        assert!(m.built_table(no_echo).is_some());
        assert!(m.built_table(5).is_none());
    }

    #[test]
    fn bad_parameters_are_named() {
        let err = BeamModel::new(BeamModelParams {
            tempering: 0.0,
            ..BeamModelParams::default()
        })
        .unwrap_err();
        assert!(err.to_string().contains("tempering"), "{err}");
    }
}
