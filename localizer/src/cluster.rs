//! The pose estimate: particles binned on a grid of poses, adjacent
//! occupied bins joined into clusters, and the weighted mean and covariance
//! of the heaviest cluster. The same bins count `k` for KLD-sampling.

use deog_grid::{Pose2, normalize_angle};

use crate::numeric::floor_i64;

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

/// The hasher of bins: the grid's hasher for small integer keys (every
/// frame hashes each particle's bin once or twice, and the standard
/// library's hasher took a tenth of a tracking update).
pub type BinHasher = deog_grid::KeyHasher;

/// A map keyed by bins (or other small integers) with [`BinHasher`].
pub type BinMap<K, V> = deog_grid::KeyMap<K, V>;

/// A set of bins (or other small integers) with [`BinHasher`].
pub type BinSet<K = Bin> = deog_grid::KeySet<K>;

impl BinSize {
    fn headings(&self) -> i64 {
        ((std::f64::consts::TAU / self.theta).round() as i64).max(1)
    }

    /// The bin holding pose `p`.
    pub fn bin_of(&self, p: &Pose2) -> (i64, i64, i64) {
        let h = self.headings();
        let t = (normalize_angle(p.theta) + std::f64::consts::PI) / std::f64::consts::TAU;
        (
            floor_i64(p.x / self.xy),
            floor_i64(p.y / self.xy),
            floor_i64(t * h as f64).rem_euclid(h),
        )
    }

    /// Bins holding at least one of `particles`.
    pub fn occupied_bins<'a>(&self, particles: impl IntoIterator<Item = &'a Pose2>) -> usize {
        let mut bins = BinSet::default();
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

/// Where a cluster lies and how far it spreads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterShape {
    /// Weighted mean pose (circular mean of headings).
    pub mean: Pose2,
    /// `√(σx² + σy²)`, metres.
    pub spread_m: f64,
    /// The headings' spread about the mean, radians.
    pub spread_rad: f64,
}

/// Clusters of at least this many particles are judged at their mean pose
/// ([`Clusters::evidence`]): over 120 seeds of map1, kidnap recovery rose
/// from 81 % to 88 % against judging every cluster by its best particle
/// (BENCHMARKS.md).
pub const MEAN_POSE_MIN_PARTICLES: usize = 50;

/// Particles grouped into clusters: occupied bins joined when they touch
/// (including diagonally, and across the heading wrap).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Clusters {
    /// Each particle's cluster, an index into [`Self::weights`].
    pub of: Vec<u32>,
    /// Each cluster's share of the total weight; they sum to 1.
    pub weights: Vec<f64>,
    /// Each cluster's number of particles.
    pub counts: Vec<usize>,
}

impl Clusters {
    /// The heaviest cluster (the first of equals).
    pub fn heaviest(&self) -> Option<usize> {
        let mut best: Option<usize> = None;
        for (c, w) in self.weights.iter().enumerate() {
            if best.is_none_or(|b| *w > self.weights[b]) {
                best = Some(c);
            }
        }
        best
    }

    /// The effective sample size within the clusters, summed:
    /// `Σ_c (Σ_{i∈c} wᵢ)² / Σ_{i∈c} wᵢ²`. It equals the particle count when
    /// the weights are equal within each cluster, whatever the clusters'
    /// weights, so it measures how far the likelihoods have spread the
    /// weights since the last resampling, not how unequal the clusters are.
    pub fn effective_sample_size(&self, weights: &[f64]) -> f64 {
        let mut sums = vec![(0.0, 0.0); self.weights.len()];
        for (&c, &w) in self.of.iter().zip(weights) {
            let s = &mut sums[c as usize];
            s.0 += w;
            s.1 += w * w;
        }
        sums.iter()
            .filter(|s| s.1 > 0.0)
            .map(|s| s.0 * s.0 / s.1)
            .sum()
    }

    /// Each cluster's evidence from one frame, as a log-likelihood: when
    /// `at_mean`, for a cluster of [`MEAN_POSE_MIN_PARTICLES`] or more,
    /// `score_at` its weighted mean pose; for a smaller one, or for every
    /// cluster when not `at_mean`, its best particle's entry of
    /// `log_likelihoods` (the frame's, one per particle).
    ///
    /// A mode is judged by a pose that stands for it, not by how well its
    /// particles cover it: their mean likelihood favours a tight cluster
    /// over a spread one, and their best favours the cluster with more
    /// particles (more draws, a luckier best). The mean of a large cluster
    /// sits on its peak whatever its size; a handful of particles has no
    /// mean to trust, and its best stands for it.
    pub fn evidence<E>(
        &self,
        particles: &[Pose2],
        weights: &[f64],
        log_likelihoods: &[f64],
        at_mean: bool,
        mut score_at: impl FnMut(&Pose2) -> Result<f64, E>,
    ) -> Result<Vec<f64>, E> {
        let n = self.weights.len();
        let mut evidence = vec![f64::NEG_INFINITY; n];
        for (&c, &l) in self.of.iter().zip(log_likelihoods) {
            evidence[c as usize] = evidence[c as usize].max(l);
        }
        if !at_mean {
            return Ok(evidence);
        }
        let means = self.means(particles, weights);
        for ((e, mean), &count) in evidence.iter_mut().zip(&means).zip(&self.counts) {
            if count >= MEAN_POSE_MIN_PARTICLES
                && let Some(mean) = mean
            {
                *e = score_at(mean)?;
            }
        }
        Ok(evidence)
    }

    /// Each cluster's weighted mean pose (the heading by its unit
    /// vectors), in one pass; `None` for a cluster without weight.
    fn means(&self, particles: &[Pose2], weights: &[f64]) -> Vec<Option<Pose2>> {
        let mut sums = vec![[0.0f64; 5]; self.weights.len()];
        for ((p, w), &c) in particles.iter().zip(weights).zip(&self.of) {
            let (sin, cos) = p.theta.sin_cos();
            let s = &mut sums[c as usize];
            s[0] += w;
            s[1] += w * p.x;
            s[2] += w * p.y;
            s[3] += w * cos;
            s[4] += w * sin;
        }
        sums.iter()
            .map(|s| (s[0] > 0.0).then(|| Pose2::new(s[1] / s[0], s[2] / s[0], s[4].atan2(s[3]))))
            .collect()
    }

    /// Each cluster's weighted mean pose and spread, `None` for a cluster
    /// without weight.
    pub fn shapes(&self, particles: &[Pose2], weights: &[f64]) -> Vec<Option<ClusterShape>> {
        let means = self.means(particles, weights);
        let mut sums = vec![[0.0f64; 3]; self.weights.len()];
        for ((p, w), &c) in particles.iter().zip(weights).zip(&self.of) {
            if let Some(mean) = means[c as usize] {
                let s = &mut sums[c as usize];
                let (dx, dy) = (p.x - mean.x, p.y - mean.y);
                let dtheta = normalize_angle(p.theta - mean.theta);
                s[0] += w;
                s[1] += w * (dx * dx + dy * dy);
                s[2] += w * dtheta * dtheta;
            }
        }
        means
            .iter()
            .zip(&sums)
            .map(|(mean, s)| {
                mean.map(|mean| ClusterShape {
                    mean,
                    spread_m: (s[1] / s[0]).sqrt(),
                    spread_rad: (s[2] / s[0]).sqrt(),
                })
            })
            .collect()
    }

    /// Weighs the modes by their evidence: each cluster's share of
    /// `weights` (the particles' weights just after a frame) is set to its
    /// share of `old` (their weights before the frame) times
    /// `exp(evidence[c])` ([`Self::evidence`]), rather than times its
    /// particles' mean likelihood, which `weights` carry. Each cluster's
    /// particles keep their weights relative to one another. One cluster,
    /// or slices of the wrong lengths: nothing changes.
    pub fn weigh_by(&mut self, old: &[f64], evidence: &[f64], weights: &mut [f64]) {
        let n = self.weights.len();
        let particles = self.of.len();
        if n < 2 || evidence.len() != n || old.len() != particles || weights.len() != particles {
            return;
        }
        let mut before = vec![0.0; n];
        for (&c, &w) in self.of.iter().zip(old) {
            before[c as usize] += w;
        }
        let best = evidence.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !best.is_finite() {
            return;
        }
        let target: Vec<f64> = before
            .iter()
            .zip(evidence)
            .map(|(&b, &e)| b * (e - best).exp())
            .collect();
        let total: f64 = target.iter().sum();
        if total <= 0.0 || !total.is_finite() {
            return;
        }
        let scale: Vec<f64> = target
            .iter()
            .zip(&self.weights)
            .map(|(&t, &w)| if w > 0.0 { t / total / w } else { 0.0 })
            .collect();
        for (w, &c) in weights.iter_mut().zip(&self.of) {
            *w *= scale[c as usize];
        }
        let sum: f64 = weights.iter().sum();
        if sum > 0.0 {
            for w in weights.iter_mut() {
                *w /= sum;
            }
        }
        // The clusters' shares, as the weights now hold them.
        self.weights.iter_mut().for_each(|w| *w = 0.0);
        for (&c, &w) in self.of.iter().zip(weights.iter()) {
            self.weights[c as usize] += w;
        }
    }

    /// The weighted mean and covariance of cluster `c`.
    pub fn summarize(&self, particles: &[Pose2], weights: &[f64], c: usize) -> ClusterEstimate {
        let c = c as u32;
        // Weighted means; the heading by its unit vectors.
        let (mut sw, mut sx, mut sy, mut sc, mut ss) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for ((p, w), k) in particles.iter().zip(weights).zip(&self.of) {
            if *k == c {
                sw += w;
                sx += w * p.x;
                sy += w * p.y;
                let (sin, cos) = p.theta.sin_cos();
                sc += w * cos;
                ss += w * sin;
            }
        }
        let mean = Pose2::new(sx / sw, sy / sw, ss.atan2(sc));
        let mut cov = [0.0; 9];
        for ((p, w), k) in particles.iter().zip(weights).zip(&self.of) {
            if *k == c {
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
            *v /= sw;
        }
        ClusterEstimate {
            pose: mean,
            covariance: cov,
            weight: self.weights[c as usize],
            clusters: self.weights.len(),
        }
    }
}

/// Clusters `particles` (with `weights`, not necessarily normalised) by
/// joining occupied bins that touch. `None` if there are no particles or
/// no weight.
pub fn cluster_particles(particles: &[Pose2], weights: &[f64], bins: BinSize) -> Option<Clusters> {
    let total: f64 = weights.iter().sum();
    if particles.is_empty() || particles.len() != weights.len() || total.is_nan() || total <= 0.0 {
        return None;
    }
    let mut bin_ids: BinMap<Bin, usize> = BinMap::default();
    let mut particle_bin = Vec::with_capacity(particles.len());
    let mut bin_list: Vec<Bin> = Vec::new();
    // Particles come sorted by place and heading, so neighbours often
    // share a bin.
    let mut last: Option<(Bin, usize)> = None;
    for p in particles {
        let b = bins.bin_of(p);
        let id = match last {
            Some((bin, id)) if bin == b => id,
            _ => *bin_ids.entry(b).or_insert_with(|| {
                bin_list.push(b);
                bin_list.len() - 1
            }),
        };
        last = Some((b, id));
        particle_bin.push(id);
    }
    // Union-find over bins; a root is the smallest bin id of its cluster.
    let mut parent: Vec<usize> = (0..bin_list.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let h = bins.headings();
    // Each pair of touching bins is joined from one side: the 13 offsets
    // after (0, 0, 0) in their order, whose opposites are the other 13.
    let forward = (-1..=1)
        .flat_map(|dx| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dt| (dx, dy, dt))))
        .filter(|&d| d > (0, 0, 0));
    let forward: Vec<(i64, i64, i64)> = forward.collect();
    for (id, &(bx, by, bt)) in bin_list.iter().enumerate() {
        for &(dx, dy, dt) in &forward {
            let n = (bx + dx, by + dy, (bt + dt).rem_euclid(h));
            if let Some(&other) = bin_ids.get(&n) {
                let (a, b) = (root(&mut parent, id), root(&mut parent, other));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    // Clusters numbered in the order of their roots (a root comes before
    // every other bin of its cluster).
    let mut bin_cluster = vec![u32::MAX; bin_list.len()];
    let mut clusters = 0u32;
    for id in 0..bin_list.len() {
        let r = root(&mut parent, id);
        if r == id {
            bin_cluster[id] = clusters;
            clusters += 1;
        } else {
            bin_cluster[id] = bin_cluster[r];
        }
    }
    let mut out = Clusters {
        of: Vec::with_capacity(particles.len()),
        weights: vec![0.0; clusters as usize],
        counts: vec![0; clusters as usize],
    };
    for (b, w) in particle_bin.iter().zip(weights) {
        let c = bin_cluster[*b];
        out.of.push(c);
        out.weights[c as usize] += w;
        out.counts[c as usize] += 1;
    }
    for w in &mut out.weights {
        *w /= total;
    }
    Some(out)
}

/// Clusters `particles` (with `weights`, not necessarily normalised) as
/// [`cluster_particles`] does and summarises the heaviest. `None` if there
/// are no particles or no weight.
pub fn heaviest_cluster(
    particles: &[Pose2],
    weights: &[f64],
    bins: BinSize,
) -> Option<ClusterEstimate> {
    let clusters = cluster_particles(particles, weights, bins)?;
    let best = clusters.heaviest()?;
    Some(clusters.summarize(particles, weights, best))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    /// Two clusters of 100 particles, half the weight each before a
    /// frame: A's particles all fit it a little (log-likelihood -1), B
    /// holds one particle on its peak (0) and 99 far off it (-10).
    fn two_modes() -> (Clusters, Vec<f64>, Vec<f64>, Vec<f64>) {
        let of: Vec<u32> = (0..200).map(|i| u32::from(i >= 100)).collect();
        let old = vec![0.005; 200];
        let log: Vec<f64> = (0..200)
            .map(|i| match i {
                0..100 => -1.0,
                100 => 0.0,
                _ => -10.0,
            })
            .collect();
        // The weights after the frame: old times likelihood, normalized.
        let mut weights: Vec<f64> = old.iter().zip(&log).map(|(w, l)| w * l.exp()).collect();
        let total: f64 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
        let mut shares = vec![0.0; 2];
        for (&c, &w) in of.iter().zip(&weights) {
            shares[c as usize] += w;
        }
        let clusters = Clusters {
            of,
            weights: shares,
            counts: vec![100, 100],
        };
        (clusters, old, log, weights)
    }

    /// The evidence of [`two_modes`] judged by each cluster's best
    /// particle: A's −1, B's 0.
    const BEST_OF_TWO_MODES: [f64; 2] = [-1.0, 0.0];

    #[test]
    fn modes_are_weighed_by_their_evidence_not_their_mean_likelihood() {
        let (mut clusters, old, _, mut weights) = two_modes();
        // By the mean likelihood, A holds nearly all the weight.
        assert!(clusters.weights[0] > 0.97, "{:?}", clusters.weights);
        let within_b = weights[101] / weights[100];
        clusters.weigh_by(&old, &BEST_OF_TWO_MODES, &mut weights);
        // By the evidence, B: e⁰ against e⁻¹.
        let expected_b = 1.0 / (1.0 + (-1.0f64).exp());
        assert_abs_diff_eq!(clusters.weights[1], expected_b, epsilon = 1e-12);
        assert_abs_diff_eq!(clusters.weights[0], 1.0 - expected_b, epsilon = 1e-12);
        assert_abs_diff_eq!(weights.iter().sum::<f64>(), 1.0, epsilon = 1e-12);
        let b: f64 = weights[100..].iter().sum();
        assert_abs_diff_eq!(b, expected_b, epsilon = 1e-12);
        // Within a cluster the particles keep their ratios.
        assert_abs_diff_eq!(weights[101] / weights[100], within_b, epsilon = 1e-12);
        assert_abs_diff_eq!(weights[0], weights[99], epsilon = 1e-15);
        assert_eq!(clusters.heaviest(), Some(1));
    }

    #[test]
    fn the_weight_before_the_frame_still_counts() {
        let (mut clusters, mut old, _, mut weights) = two_modes();
        // B held a hundredth of A's weight before the frame: one frame's
        // e¹ does not make up for it.
        for w in &mut old[100..] {
            *w /= 100.0;
        }
        clusters.weigh_by(&old, &BEST_OF_TWO_MODES, &mut weights);
        let ratio = clusters.weights[1] / clusters.weights[0];
        assert_abs_diff_eq!(ratio, std::f64::consts::E / 100.0, epsilon = 1e-12);
    }

    #[test]
    fn one_cluster_or_mismatched_slices_change_nothing() {
        let (mut clusters, old, _, mut weights) = two_modes();
        let before = (clusters.clone(), weights.clone());
        clusters.weigh_by(&old[1..], &BEST_OF_TWO_MODES, &mut weights);
        clusters.weigh_by(&old, &BEST_OF_TWO_MODES[1..], &mut weights);
        assert_eq!((clusters.clone(), weights.clone()), before);
        let mut one = Clusters {
            of: vec![0; 200],
            weights: vec![1.0],
            counts: vec![200],
        };
        let kept = weights.clone();
        one.weigh_by(&old, &[0.0], &mut weights);
        assert_eq!(weights, kept);
        assert_eq!(one.weights, vec![1.0]);
    }

    #[test]
    fn a_large_cluster_is_judged_at_its_mean_a_small_one_by_its_best() {
        // A: a ring of particles about (1, 0) facing east, none on the
        // peak there, each scored −2; B: a few particles, the best −0.5.
        let large = MEAN_POSE_MIN_PARTICLES;
        let small = MEAN_POSE_MIN_PARTICLES - 1;
        let mut particles = Vec::new();
        let mut log = Vec::new();
        for i in 0..large {
            let angle = std::f64::consts::TAU * i as f64 / large as f64;
            particles.push(Pose2::new(1.0 + 0.3 * angle.cos(), 0.3 * angle.sin(), 0.0));
            log.push(-2.0);
        }
        for i in 0..small {
            particles.push(Pose2::new(5.0, 5.0 + 0.01 * i as f64, 1.0));
            log.push(if i == 3 { -0.5 } else { -3.0 });
        }
        let n = particles.len();
        let clusters = Clusters {
            of: (0..n).map(|i| u32::from(i >= large)).collect(),
            weights: vec![0.5, 0.5],
            counts: vec![large, small],
        };
        let weights = vec![1.0 / n as f64; n];
        // The likelihood falls with the distance from (1, 0, 0).
        let mut asked = Vec::new();
        let score = |p: &Pose2| -> Result<f64, ()> {
            asked.push(*p);
            Ok(-((p.x - 1.0).powi(2) + p.y.powi(2) + p.theta.powi(2)))
        };
        let evidence = clusters
            .evidence(&particles, &weights, &log, true, score)
            .unwrap();
        assert_eq!(asked.len(), 1, "only the large cluster's mean is scored");
        assert_abs_diff_eq!(asked[0].x, 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(asked[0].y, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(evidence[0], 0.0, epsilon = 1e-12);
        assert_eq!(evidence[1], -0.5);
        // A scoring error ends the weighing with it.
        let failing = |_: &Pose2| -> Result<f64, &str> { Err("no table") };
        assert_eq!(
            clusters.evidence(&particles, &weights, &log, true, failing),
            Err("no table")
        );
        // Not at the mean: every cluster by its best particle, none scored.
        let never = |_: &Pose2| -> Result<f64, &str> { Err("not asked") };
        assert_eq!(
            clusters.evidence(&particles, &weights, &log, false, never),
            Ok(vec![-2.0, -0.5])
        );
    }

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

    proptest::proptest! {
        /// Two particles share a cluster exactly when a chain of touching
        /// bins (every axis within one, headings round the turn) joins
        /// theirs: checked against a search over every pair of bins.
        #[test]
        fn clusters_are_the_chains_of_touching_bins(
            poses in proptest::collection::vec(
                (-1.5f64..1.5, -1.5f64..1.5, -3.2f64..3.2), 1..40),
        ) {
            let bins = BinSize::default();
            let particles: Vec<Pose2> =
                poses.iter().map(|&(x, y, t)| Pose2::new(x, y, t)).collect();
            let weights = vec![1.0; particles.len()];
            let clusters = cluster_particles(&particles, &weights, bins).unwrap();
            let of: Vec<Bin> = particles.iter().map(|p| bins.bin_of(p)).collect();
            let h = bins.headings();
            let touch = |a: Bin, b: Bin| {
                let dt = (a.2 - b.2).rem_euclid(h);
                (a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1 && (dt <= 1 || dt == h - 1)
            };
            // Components by flooding from each particle's bin.
            let mut component = vec![usize::MAX; particles.len()];
            for start in 0..particles.len() {
                if component[start] != usize::MAX {
                    continue;
                }
                component[start] = start;
                let mut frontier = vec![start];
                while let Some(i) = frontier.pop() {
                    for j in 0..particles.len() {
                        if component[j] == usize::MAX && touch(of[i], of[j]) {
                            component[j] = start;
                            frontier.push(j);
                        }
                    }
                }
            }
            for i in 0..particles.len() {
                for j in 0..particles.len() {
                    proptest::prop_assert_eq!(
                        component[i] == component[j],
                        clusters.of[i] == clusters.of[j]
                    );
                }
            }
        }
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
    fn effective_sample_size_is_counted_within_clusters() {
        // Two clouds far apart, equal weights within each but 0.9 / 0.1
        // between them: every particle counts.
        let mut particles = Vec::new();
        let mut weights = Vec::new();
        for i in 0..10 {
            let d = f64::from(i) * 0.01;
            particles.push(Pose2::new(1.0 + d, 1.0, 0.0));
            weights.push(0.09);
            particles.push(Pose2::new(6.0 + d, 3.0, 1.0));
            weights.push(0.01);
        }
        let c = cluster_particles(&particles, &weights, BinSize::default()).unwrap();
        assert_eq!(c.weights.len(), 2);
        assert_eq!(c.counts, vec![10, 10]);
        assert_abs_diff_eq!(c.weights[0] + c.weights[1], 1.0, epsilon = 1e-12);
        assert_abs_diff_eq!(c.effective_sample_size(&weights), 20.0, epsilon = 1e-9);
        // The plain 1 / Σw² would count far fewer.
        let plain = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        assert!(plain < 13.0, "{plain}");
        // One particle of the first cloud holding all of its weight: that
        // cloud counts as one.
        let mut skewed = weights.clone();
        for (i, w) in skewed.iter_mut().enumerate() {
            if i % 2 == 0 {
                *w = if i == 0 { 0.9 } else { 0.0 };
            }
        }
        assert_abs_diff_eq!(c.effective_sample_size(&skewed), 11.0, epsilon = 1e-9);
        assert_eq!(c.heaviest(), Some(c.of[0] as usize));
    }

    #[test]
    fn empty_or_weightless_gives_none() {
        assert!(heaviest_cluster(&[], &[], BinSize::default()).is_none());
        assert!(heaviest_cluster(&[Pose2::default()], &[0.0], BinSize::default()).is_none());
    }
}
