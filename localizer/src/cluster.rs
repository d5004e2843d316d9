//! The pose estimate: particles binned on a grid of poses, adjacent
//! occupied bins joined into clusters, and the weighted mean and covariance
//! of the heaviest cluster. The same bins count `k` for KLD-sampling.

use std::collections::HashMap;

use deog_grid::{Pose2, normalize_angle};

/// The size of a histogram bin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BinSize {
    /// Metres along x and y.
    pub xy: f64,
    /// Radians of heading.
    pub theta: f64,
}

impl Default for BinSize {
    /// Fox's KLD-sampling bins: 50 cm × 50 cm × 10°.
    fn default() -> Self {
        Self {
            xy: 0.5,
            theta: 10f64.to_radians(),
        }
    }
}

type Bin = (i64, i64, i64);

impl BinSize {
    fn headings(&self) -> i64 {
        ((std::f64::consts::TAU / self.theta).round() as i64).max(1)
    }

    /// The bin holding pose `p`.
    pub fn bin_of(&self, p: &Pose2) -> (i64, i64, i64) {
        let h = self.headings();
        let t = (normalize_angle(p.theta) + std::f64::consts::PI) / std::f64::consts::TAU;
        (
            (p.x / self.xy).floor() as i64,
            (p.y / self.xy).floor() as i64,
            ((t * h as f64).floor() as i64).rem_euclid(h),
        )
    }

    /// Bins holding at least one of `particles`.
    pub fn occupied_bins<'a>(&self, particles: impl IntoIterator<Item = &'a Pose2>) -> usize {
        let mut bins = std::collections::HashSet::new();
        for p in particles {
            bins.insert(self.bin_of(p));
        }
        bins.len()
    }
}

/// The heaviest cluster's summary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterEstimate {
    /// Weighted mean pose (circular mean of headings).
    pub pose: Pose2,
    /// Covariance of (x, y, θ), row-major.
    pub covariance: [f64; 9],
    /// The cluster's share of the total weight.
    pub weight: f64,
    /// How many clusters the particles form.
    pub clusters: usize,
}

/// Clusters `particles` (with `weights`, not necessarily normalised) by
/// joining occupied bins that touch (including diagonally, and across the
/// heading wrap), and summarises the heaviest. `None` if there are no
/// particles or no weight.
pub fn heaviest_cluster(
    particles: &[Pose2],
    weights: &[f64],
    bins: BinSize,
) -> Option<ClusterEstimate> {
    let total: f64 = weights.iter().sum();
    if particles.is_empty() || particles.len() != weights.len() || total.is_nan() || total <= 0.0 {
        return None;
    }
    let mut bin_ids: HashMap<Bin, usize> = HashMap::new();
    let mut particle_bin = Vec::with_capacity(particles.len());
    let mut bin_list: Vec<Bin> = Vec::new();
    for p in particles {
        let b = bins.bin_of(p);
        let id = *bin_ids.entry(b).or_insert_with(|| {
            bin_list.push(b);
            bin_list.len() - 1
        });
        particle_bin.push(id);
    }
    // Union-find over bins.
    let mut parent: Vec<usize> = (0..bin_list.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let h = bins.headings();
    for (id, &(bx, by, bt)) in bin_list.iter().enumerate() {
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dt in -1..=1 {
                    let n = (bx + dx, by + dy, (bt + dt).rem_euclid(h));
                    if let Some(&other) = bin_ids.get(&n) {
                        let (a, b) = (root(&mut parent, id), root(&mut parent, other));
                        if a != b {
                            parent[a.max(b)] = a.min(b);
                        }
                    }
                }
            }
        }
    }
    let mut cluster_weight: HashMap<usize, f64> = HashMap::new();
    let mut cluster_of = Vec::with_capacity(particles.len());
    for (i, w) in weights.iter().enumerate() {
        let c = root(&mut parent, particle_bin[i]);
        *cluster_weight.entry(c).or_insert(0.0) += w;
        cluster_of.push(c);
    }
    let (&best, &best_weight) = cluster_weight
        .iter()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0)))?;
    // Weighted means; the heading by its unit vectors.
    let (mut sx, mut sy, mut sc, mut ss) = (0.0, 0.0, 0.0, 0.0);
    for ((p, w), c) in particles.iter().zip(weights).zip(&cluster_of) {
        if *c == best {
            sx += w * p.x;
            sy += w * p.y;
            sc += w * p.theta.cos();
            ss += w * p.theta.sin();
        }
    }
    let mean = Pose2::new(sx / best_weight, sy / best_weight, ss.atan2(sc));
    let mut cov = [0.0; 9];
    for ((p, w), c) in particles.iter().zip(weights).zip(&cluster_of) {
        if *c == best {
            let d = [
                p.x - mean.x,
                p.y - mean.y,
                normalize_angle(p.theta - mean.theta),
            ];
            for r in 0..3 {
                for k in 0..3 {
                    cov[r * 3 + k] += w * d[r] * d[k];
                }
            }
        }
    }
    for v in &mut cov {
        *v /= best_weight;
    }
    Some(ClusterEstimate {
        pose: mean,
        covariance: cov,
        weight: best_weight / total,
        clusters: cluster_weight.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn heaviest_of_two_clouds_is_found_with_its_spread() {
        let mut particles = Vec::new();
        let mut weights = Vec::new();
        // Cloud A near (1, 1, 0) with weight 3 each; cloud B far away, weight 1.
        for i in 0..10 {
            let d = (i as f64 - 4.5) * 0.02;
            particles.push(Pose2::new(1.0 + d, 1.0 - d, d));
            weights.push(3.0);
            particles.push(Pose2::new(8.0 + d, -4.0, 2.0));
            weights.push(1.0);
        }
        let e = heaviest_cluster(&particles, &weights, BinSize::default()).unwrap();
        assert_eq!(e.clusters, 2);
        assert_abs_diff_eq!(e.weight, 0.75, epsilon = 1e-12);
        assert_abs_diff_eq!(e.pose.x, 1.0, epsilon = 1e-9);
        assert_abs_diff_eq!(e.pose.y, 1.0, epsilon = 1e-9);
        assert_abs_diff_eq!(e.pose.theta, 0.0, epsilon = 1e-9);
        // Var of d: spacing 0.02, 10 values → 0.02² · (100 − 1)/12.
        let var = 0.0004 * 99.0 / 12.0;
        assert_abs_diff_eq!(e.covariance[0], var, epsilon = 1e-12);
        assert_abs_diff_eq!(e.covariance[1], -var, epsilon = 1e-12);
        assert_abs_diff_eq!(e.covariance[8], var, epsilon = 1e-12);
    }

    #[test]
    fn headings_wrap_round() {
        let particles = vec![Pose2::new(0.0, 0.0, 3.1), Pose2::new(0.0, 0.0, -3.1)];
        let e = heaviest_cluster(&particles, &[1.0, 1.0], BinSize::default()).unwrap();
        assert_eq!(e.clusters, 1);
        assert_abs_diff_eq!(e.pose.theta.abs(), std::f64::consts::PI, epsilon = 1e-9);
        assert!(e.covariance[8] < 0.01);
    }

    #[test]
    fn empty_or_weightless_gives_none() {
        assert!(heaviest_cluster(&[], &[], BinSize::default()).is_none());
        assert!(heaviest_cluster(&[Pose2::default()], &[0.0], BinSize::default()).is_none());
    }
}
