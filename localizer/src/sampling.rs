//! Resampling and the adaptive particle count.
//!
//! - [`systematic_resample`]: low-variance resampling (Probabilistic
//!   Robotics, table 4.4): one random offset, then `n` evenly spaced
//!   pointers through the cumulative weights; O(N + n), and a particle of
//!   weight `w` is drawn `⌊n·w⌋` or `⌈n·w⌉` times.
//! - [`kld_sample_count`]: the number of particles KLD-sampling asks for
//!   (Fox 2003): with `k` histogram bins holding particles, enough samples
//!   that the Kullback–Leibler distance between the sample-based and the
//!   true posterior stays below `ε` with probability `1 − δ`. The bound
//!   uses `z₁₋δ`, the upper `1 − δ` quantile of the standard normal
//!   distribution (2.326 for δ = 0.01), computed as a quantile.

use rand::Rng;

use crate::error::{LocalizerError, within};
use crate::gaussian::normal_quantile;

/// Indices of the particles drawn by systematic resampling of `weights`
/// into `n` particles, appended to `out` (cleared first). Weights need not
/// be normalised; they must be finite, non-negative and not all zero.
pub fn systematic_resample(
    weights: &[f64],
    n: usize,
    rng: &mut impl Rng,
    out: &mut Vec<usize>,
) -> Result<(), LocalizerError> {
    out.clear();
    let total: f64 = weights.iter().sum();
    let valid = |w: &f64| w.is_finite() && *w >= 0.0;
    if !total.is_finite() || total <= 0.0 || !weights.iter().all(valid) {
        return Err(LocalizerError::Invalid(format!(
            "weights must be finite, non-negative and not all zero (sum {total})"
        )));
    }
    if n == 0 {
        return Ok(());
    }
    out.reserve(n);
    let step = total / n as f64;
    let mut pointer = rng.random_range(0.0..step);
    let mut cumulative = weights[0];
    let mut i = 0;
    for _ in 0..n {
        while pointer > cumulative && i + 1 < weights.len() {
            i += 1;
            cumulative += weights[i];
        }
        out.push(i);
        pointer += step;
    }
    Ok(())
}

/// The settings of KLD-sampling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KldSettings {
    /// ε: the largest Kullback–Leibler distance allowed.
    pub epsilon: f64,
    /// δ: the probability of exceeding it.
    pub delta: f64,
    /// Fewest particles whatever the bound says.
    pub min_particles: usize,
    /// Most particles whatever the bound says.
    pub max_particles: usize,
}

impl Default for KldSettings {
    /// ROS amcl's defaults for ε and δ (0.01, 0.01); 500 to 100,000
    /// particles. Global localization in a nearly symmetric room needs the
    /// 100,000: with fewer, each half of the room holds only a handful of
    /// particles near the right pose, and whichever half happens to hold
    /// the better-placed one wins before the sonars can tell them apart
    /// (BENCHMARKS.md, localization).
    fn default() -> Self {
        Self {
            epsilon: 0.01,
            delta: 0.01,
            min_particles: 500,
            max_particles: 100_000,
        }
    }
}

impl KldSettings {
    /// The settings if each is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("kld_epsilon", self.epsilon, 1e-6, 1.0)?;
        within("kld_delta", self.delta, 1e-9, 0.5)?;
        if self.min_particles == 0 || self.min_particles > self.max_particles {
            return Err(LocalizerError::Invalid(format!(
                "min_particles must be at least 1 and at most max_particles ({} > {})",
                self.min_particles, self.max_particles
            )));
        }
        if self.max_particles > 10_000_000 {
            return Err(LocalizerError::Invalid(format!(
                "max_particles must be at most 10000000, got {}",
                self.max_particles
            )));
        }
        Ok(self)
    }

    /// The particle count for `bins` occupied histogram bins, within the
    /// minimum and maximum.
    pub fn particles_for(&self, bins: usize) -> usize {
        kld_sample_count(bins, self.epsilon, self.delta)
            .clamp(self.min_particles, self.max_particles)
    }
}

/// Fox's bound: `n = (k − 1)/(2ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1))) · z₁₋δ)³`
/// for `k` ≥ 2 occupied bins; 1 for fewer.
pub fn kld_sample_count(bins: usize, epsilon: f64, delta: f64) -> usize {
    if bins < 2 {
        return 1;
    }
    let k1 = (bins - 1) as f64;
    let z = normal_quantile(1.0 - delta);
    let a = 2.0 / (9.0 * k1);
    let n = k1 / (2.0 * epsilon) * (1.0 - a + a.sqrt() * z).powi(3);
    if n.is_finite() && n > 0.0 {
        n.ceil().min(usize::MAX as f64) as usize
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn kld_bound_uses_the_quantile() {
        // k = 100, ε = 0.05, δ = 0.01: z = 2.326 gives 99/0.1 · (1 − 0.002245
        // + 0.04738 · 2.326)³ = 990 · 1.10798³ ≈ 1346.6. Taking 0.99 itself as
        // z would give about 1,129 instead.
        assert_eq!(kld_sample_count(100, 0.05, 0.01), 1347);
        assert_eq!(kld_sample_count(1, 0.05, 0.01), 1);
        // More bins, more particles; tighter ε, more particles.
        assert!(kld_sample_count(200, 0.05, 0.01) > kld_sample_count(100, 0.05, 0.01));
        assert!(kld_sample_count(100, 0.01, 0.01) > kld_sample_count(100, 0.05, 0.01));
        let s = KldSettings::default();
        assert_eq!(s.particles_for(1), 500);
        assert_eq!(s.particles_for(1_000_000), 100_000);
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = KldSettings {
            min_particles: 10,
            max_particles: 5,
            ..KldSettings::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("min_particles")
        );
        let bad = KldSettings {
            epsilon: 0.0,
            ..KldSettings::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("kld_epsilon")
        );
    }

    #[test]
    fn bad_weights_are_errors() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut out = Vec::new();
        assert!(systematic_resample(&[0.0, 0.0], 4, &mut rng, &mut out).is_err());
        assert!(systematic_resample(&[1.0, f64::NAN], 4, &mut rng, &mut out).is_err());
        assert!(systematic_resample(&[1.0, -1.0, 3.0], 4, &mut rng, &mut out).is_err());
        assert!(systematic_resample(&[], 4, &mut rng, &mut out).is_err());
    }

    proptest! {
        /// Each particle is drawn ⌊n·w⌋ or ⌈n·w⌉ times (low variance), and
        /// the indices come out in order.
        #[test]
        fn draws_are_proportional(
            weights in prop::collection::vec(0.0..10.0f64, 1..50),
            n in 1usize..500,
            seed in any::<u64>(),
        ) {
            prop_assume!(weights.iter().sum::<f64>() > 1e-6);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut out = Vec::new();
            systematic_resample(&weights, n, &mut rng, &mut out).unwrap();
            prop_assert_eq!(out.len(), n);
            prop_assert!(out.windows(2).all(|w| w[0] <= w[1]));
            let total: f64 = weights.iter().sum();
            for (i, w) in weights.iter().enumerate() {
                let count = out.iter().filter(|&&j| j == i).count() as f64;
                let expected = n as f64 * w / total;
                prop_assert!(count >= expected.floor() - 1e-6 - 1e-9 * n as f64 && count <= expected.ceil() + 1e-6,
                    "particle {} drawn {} times, expected {}", i, count, expected);
            }
        }
    }
}
