//! Normal samples (`rand_distr`'s ziggurat) and the normal quantile.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// One sample of N(0, 1) (the ziggurat method: most draws cost one random
/// number and a table lookup, where a polar or Box-Muller draw needs a
/// logarithm and a square root; the motion model draws three per particle).
pub fn standard_normal(rng: &mut impl Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// One sample of N(0, std²); `std` of 0 gives 0.
pub fn normal(rng: &mut impl Rng, std: f64) -> f64 {
    if std > 0.0 {
        std * standard_normal(rng)
    } else {
        0.0
    }
}

/// The quantile function of the standard normal distribution: the `z` with
/// Φ(z) = `p`, for `p` in (0, 1); infinite at 0 and 1. Acklam's rational
/// approximation, relative error below 1.2e-9.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    if p.is_nan() || p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let low = 0.02425;
    if p < low {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - low {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn quantiles_match_the_tables() {
        assert_abs_diff_eq!(normal_quantile(0.5), 0.0, epsilon = 1e-9);
        assert_abs_diff_eq!(normal_quantile(0.99), 2.326_347_874, epsilon = 1e-6);
        assert_abs_diff_eq!(normal_quantile(0.95), 1.644_853_627, epsilon = 1e-6);
        assert_abs_diff_eq!(normal_quantile(0.01), -2.326_347_874, epsilon = 1e-6);
        assert_abs_diff_eq!(normal_quantile(0.001), -3.090_232_306, epsilon = 1e-6);
        assert!(normal_quantile(0.0).is_infinite());
        assert!(normal_quantile(1.0).is_infinite());
    }

    #[test]
    fn samples_have_the_asked_spread() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 100_000;
        let samples: Vec<f64> = (0..n).map(|_| normal(&mut rng, 2.0)).collect();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / n as f64;
        assert_abs_diff_eq!(mean, 0.0, epsilon = 0.03);
        assert_abs_diff_eq!(var.sqrt(), 2.0, epsilon = 0.03);
        assert_eq!(normal(&mut rng, 0.0), 0.0);
    }
}
