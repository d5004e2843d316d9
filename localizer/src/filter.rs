//! The particle filter: augmented MCL (Probabilistic Robotics, table 8.3)
//! with KLD-sampling (table 8.4), selective, low-variance resampling, and
//! clusters that keep their weight through resampling (in the spirit of
//! Milstein et al.'s Cluster-MCL).
//!
//! Each frame: [`Mcl::predict`] moves the particles by the odometry since
//! the last correction once the robot has moved far enough to be worth a
//! sensor update (turning or driving a little between frames would
//! otherwise count the same scene many times over). Then the caller makes
//! sure the map holds the tiles [`Mcl::tiles_for_frame`] names, and
//! [`Mcl::correct`] weighs every particle by its sonar frame:
//! - weights multiply by the tempered beam likelihood (see
//!   [`crate::beam_model`]), and each cluster's weight by the likelihood
//!   at its mean pose, or a small cluster's by its best particle's
//!   ([`Clusters::evidence`]): modes are weighed by a pose that stands for
//!   each, not by how well its particles happen to cover it;
//! - the mean per-beam likelihood feeds a slow and a fast average; when the
//!   fast falls below the slow (the scene no longer fits the map where the
//!   particles are: kidnapping, or a wrong early convergence), a share
//!   `max(0, 1 − w_fast / w_slow)` of the particles drawn at the next
//!   resampling, once it passes `recovery_threshold` (smaller drops are
//!   the noise of a filter tracking well), come from the known-free cells
//!   of the map instead (of the tiles nearest the estimate when the map
//!   is larger than the cache can hold range tables for). A settled
//!   filter injecting less than `search_share` trickles (the injected
//!   particles come on top and do not grow the set); a larger drop, or a
//!   filter not settled, searches (the set grows towards the most
//!   allowed);
//! - the particles are clustered (bins that touch, [`crate::cluster`]) and
//!   the estimate is the heaviest cluster by weight;
//! - for a few metres after a global start or the start of a search, the
//!   filter keeps the frames it weighed, and its tight modes share their
//!   weight by the likelihood of all of them, each mode's mean carried
//!   back by the odometry (`Mcl::weigh_by_history`): a mode's weight
//!   when it forms is the luck of the first draws, which frame-by-frame
//!   weighing can only multiply;
//! - resampling happens only when the effective sample size, counted
//!   within each cluster and summed, falls below a fraction of the
//!   particle count, or when particles are to be injected. The new count
//!   comes from the KLD bound on the number of bins the drawn particles
//!   occupy (leaving room, up to half the set, for the clusters kept);
//!   then every cluster holding at least `cluster_keep_weight` of
//!   the weight is topped up to `cluster_min_particles`, and each cluster
//!   keeps its weight, shared evenly among its new particles. A nearly
//!   symmetric room gives two modes whose weights swing for a long while
//!   before the map tells them apart; with weights equal after each
//!   resampling, the lighter mode's particle count would random-walk to
//!   nothing once KLD-sampling shrank the set, however the frames went on
//!   to favour it. A cluster is now lost only when its weight is
//!   negligible (below `cluster_keep_weight`, where what it draws is left
//!   to chance as before).
//!
//! Deterministic for a given seed: one ChaCha stream drives every draw.

use deog_grid::{CellIndex, FrameMotion, Pose2, RingFiring, SensorRing, TileKey, normalize_angle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::ambiguity::{AmbiguitySettings, Ring, rival_in_ring};
use crate::beam_model::BeamModelParams;
use crate::cluster::{
    BinMap, BinSet, BinSize, ClusterEstimate, Clusters, MEAN_POSE_MIN_PARTICLES, cluster_particles,
    heaviest_cluster,
};
use crate::error::{LocalizerError, within};
use crate::local_map::LocalMap;
use crate::motion::{MotionNoise, OdometryMove};
use crate::numeric::floor_i64;
use crate::realign::{RealignSettings, best_in_window, move_rigidly};
use crate::sampling::{KldSettings, systematic_resample};
use crate::sensors::{SensorModel, SonarCone};

/// Every setting of the filter.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterSettings {
    /// The odometry motion model's noise.
    pub motion: MotionNoise,
    /// The sonar beam model ([`Mcl::new`]'s sensor).
    pub beam: BeamModelParams,
    /// KLD-sampling bounds and limits.
    pub kld: KldSettings,
    /// Histogram bins for KLD-sampling and clustering.
    pub bins: BinSize,
    /// The sonars' mounts on the robot ([`Mcl::new`]'s sensor).
    pub ring: SensorRing,
    /// Metres driven before the next sensor update.
    pub update_min_distance: f64,
    /// Radians turned before the next sensor update.
    pub update_min_rotation: f64,
    /// Resample when the effective sample size falls below this share of
    /// the particles.
    pub resample_below: f64,
    /// Smoothing rate of the long-term likelihood average.
    pub alpha_slow: f64,
    /// Smoothing rate of the short-term likelihood average.
    pub alpha_fast: f64,
    /// Particles are injected only when their share, `1 − w_fast /
    /// w_slow`, is above this: the frames fitting a few tens of percent
    /// worse for a while is noise a settled filter sees all the time. A
    /// real kidnap drops the fit far further. 0 injects at any drop, as
    /// amcl does.
    pub recovery_threshold: f64,
    /// A settled filter injecting a share below this trickles: the
    /// injected particles come on top of the draws and do not grow the
    /// set. At or above it, or while not settled, it searches: injected
    /// particles open bins as drawn ones do, and the set grows towards
    /// the most particles allowed.
    pub search_share: f64,
    /// The heaviest cluster must hold this share of the weight to count as
    /// converged…
    pub converged_weight: f64,
    /// … with a position spread (√(σx² + σy²)) at most this, metres …
    pub converged_spread_m: f64,
    /// … and a heading spread at most this, radians.
    pub converged_spread_rad: f64,
    /// A cluster holding at least this share of the weight keeps at least
    /// [`Self::cluster_min_particles`] particles through a resampling;
    /// lighter ones get what their weight draws and may die out.
    pub cluster_keep_weight: f64,
    /// The fewest particles a cluster that is kept gets at a resampling.
    pub cluster_min_particles: usize,
    /// How a tracked pose whose frame stops fitting is realigned
    /// ([`Mcl::realign`]); `None` never realigns.
    pub realign: Option<RealignSettings>,
    /// How a laser filter's estimate is checked for a rival pose nearby
    /// that its frame fits nearly as well ([`Mcl::rival_nearby`]);
    /// `None` never checks.
    pub ambiguity: Option<AmbiguitySettings>,
    /// Seed of every random draw.
    pub seed: u64,
}

impl Default for FilterSettings {
    fn default() -> Self {
        Self {
            motion: MotionNoise::default(),
            beam: BeamModelParams::default(),
            kld: KldSettings::default(),
            bins: BinSize::default(),
            ring: SensorRing::scout(),
            update_min_distance: 0.05,
            update_min_rotation: 0.05,
            resample_below: 0.5,
            alpha_slow: 0.01,
            alpha_fast: 0.1,
            recovery_threshold: 0.2,
            search_share: 0.5,
            converged_weight: 0.6,
            converged_spread_m: 0.2,
            converged_spread_rad: 0.2,
            cluster_keep_weight: 1e-6,
            cluster_min_particles: 300,
            realign: Some(RealignSettings::default()),
            ambiguity: Some(AmbiguitySettings::default()),
            seed: 1,
        }
    }
}

impl FilterSettings {
    /// The settings if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        self.motion.validate()?;
        self.beam.validate()?;
        self.kld.validate()?;
        within("bin_xy", self.bins.xy, 0.01, 10.0)?;
        within("bin_theta", self.bins.theta, 0.01, std::f64::consts::PI)?;
        within("update_min_distance", self.update_min_distance, 0.0, 10.0)?;
        within("update_min_rotation", self.update_min_rotation, 0.0, 7.0)?;
        within("resample_below", self.resample_below, 0.0, 1.0)?;
        within("alpha_slow", self.alpha_slow, 0.0, 1.0)?;
        within("alpha_fast", self.alpha_fast, 0.0, 1.0)?;
        within("recovery_threshold", self.recovery_threshold, 0.0, 1.0)?;
        within("search_share", self.search_share, 0.0, 1.0)?;
        if self.alpha_fast < self.alpha_slow {
            return Err(LocalizerError::Invalid(format!(
                "alpha_fast ({}) must be at least alpha_slow ({})",
                self.alpha_fast, self.alpha_slow
            )));
        }
        within("converged_weight", self.converged_weight, 0.0, 1.0)?;
        within("converged_spread_m", self.converged_spread_m, 0.0, 100.0)?;
        within("converged_spread_rad", self.converged_spread_rad, 0.0, 7.0)?;
        within("cluster_keep_weight", self.cluster_keep_weight, 0.0, 1.0)?;
        if self.cluster_min_particles > self.kld.max_particles {
            return Err(LocalizerError::Invalid(format!(
                "cluster_min_particles ({}) must be at most max_particles ({})",
                self.cluster_min_particles, self.kld.max_particles
            )));
        }
        if self.ring.is_empty() {
            return Err(LocalizerError::Invalid(
                "the sensor ring has no sonar".into(),
            ));
        }
        if let Some(realign) = self.realign {
            realign.validate()?;
        }
        if let Some(ambiguity) = self.ambiguity {
            ambiguity.validate()?;
        }
        Ok(self)
    }
}

/// What the filter believes after a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Mean of the heaviest cluster, moved by the odometry since the last
    /// correction.
    pub pose: Pose2,
    /// Covariance of (x, y, θ), row-major.
    pub covariance: [f64; 9],
    /// Particles in the filter.
    pub particle_count: usize,
    /// The heaviest cluster's share of the weight.
    pub cluster_weight: f64,
    /// Whether the filter has settled on one pose.
    pub converged: bool,
    /// 0 when frames fit the map as well as they have lately, towards 1
    /// when they fit far worse (`1 − w_fast / w_slow`).
    pub lost_score: f64,
}

/// The filter's estimate at its last correction, with the odometry pose
/// it was made at: enough to give the estimate for any later odometry
/// without the filter (as amcl's pose follows odometry between updates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarriedEstimate {
    estimate: Estimate,
    /// Odometry at the last correction; `None` before the first frame.
    odometry: Option<Pose2>,
}

impl CarriedEstimate {
    /// The same estimate, not called converged: the filter's pose awaits
    /// a check ([`crate::searcher`]).
    pub fn unconfirmed(self) -> Self {
        Self {
            estimate: Estimate {
                converged: false,
                ..self.estimate
            },
            ..self
        }
    }

    /// The estimate for a frame with odometry pose `odometry`: the pose
    /// moved by the odometry since the correction.
    pub fn at(&self, odometry: &Pose2) -> Estimate {
        let pose = match self.odometry {
            Some(last) => OdometryMove::between(&last, odometry).apply(&self.estimate.pose),
            None => self.estimate.pose,
        };
        Estimate {
            pose,
            ..self.estimate
        }
    }
}

/// What one correction did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CorrectionReport {
    /// Effective sample size after weighting.
    pub effective_sample_size: f64,
    /// Whether the particles were resampled.
    pub resampled: bool,
    /// Particles drawn from free space instead of the old set.
    pub injected: usize,
    /// Range tables built for this correction.
    pub tables_built: usize,
}

/// A tracked pose moved onto where the frame fits ([`Mcl::realign`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Realignment {
    /// The tracked pose, moved by odometry.
    pub from: Pose2,
    /// Where the frame fits: the particles were moved rigidly onto it.
    pub to: Pose2,
    /// The frame's fit at `from`, as a share of the recent frames'.
    pub fit_before: f64,
    /// Its fit at `to`, the same way.
    pub fit_after: f64,
}

/// A settled filter whose newest frame fits less than this share as well
/// as its frames have lately is not called converged: a robot carried off
/// keeps its filter's tight cluster for the few frames the averages take
/// to fall, and those estimates are wrong. One frame's fit varies far less
/// than this while tracking.
const CONVERGED_FRAME_FIT: f64 = 0.3;

/// The most particles a set may hold for [`Mcl::move_uphill`] to move
/// its modes: a filter's few modes, not a global search. A set of 9,000
/// that has just settled on two modes is still above 5,000, and there a
/// mode of a hundred particles copied off its peak lost to its image in
/// two seconds; with 20,000, `map1` on the world's own map converged in
/// 74 of 80 seeds against 70 (BENCHMARKS.md).
const UPHILL_MOST: usize = 20_000;

/// The widest a cluster may spread, metres (the root of its position
/// variances' sum) and radians, and still be a pose the filter tracks:
/// wider than settled, so that a filter started at a pose given to
/// within 0.25 m tracks it from its first frame.
const TRACKED_SPREAD_M: f64 = 1.0;
const TRACKED_SPREAD_RAD: f64 = 0.5;

/// The most weighed frames a filter keeps after a global start or the
/// start of a search to weigh its modes by ([`Mcl::weigh_by_history`]):
/// a few metres of driving. Past it, the modes' weights carry on frame by
/// frame. A mode's mean is a few centimetres and tenths of a degree off,
/// and carried back further its path leaves the robot's: 30 frames and 50
/// settled map1's global runs better than the weights alone, 100 and 300
/// worse (BENCHMARKS.md).
const HISTORY_FRAMES: usize = 50;

/// The most modes weighed by the frames kept, heaviest first.
const HISTORY_MODES: usize = 8;

/// A weighed frame, kept to judge modes found after it.
#[derive(Debug, Clone)]
struct WeighedFrame {
    /// The odometry pose the frame was weighed at.
    odometry: Pose2,
    ranges: Vec<f64>,
    /// The pose the sensor model judged the frame at
    /// ([`SensorModel::set_reference`]).
    reference: Option<Pose2>,
    /// Where the robot stood at each reading ([`Mcl::note_frame`]).
    reading_poses: Option<Vec<Pose2>>,
}

/// Monte Carlo Localization of one robot.
#[derive(Debug)]
pub struct Mcl {
    settings: FilterSettings,
    sensor: Box<dyn SensorModel>,
    rng: ChaCha8Rng,
    particles: Vec<Pose2>,
    weights: Vec<f64>,
    /// The odometry pose the particles were last moved to.
    odometry: Option<Pose2>,
    w_slow: f64,
    w_fast: f64,
    /// The last frame's fit over the slow average's before it: how the
    /// newest frame alone fits, beside how frames have fitted lately.
    frame_fit: f64,
    cluster: Option<ClusterEstimate>,
    /// The tracked cluster's mean ([`Mcl::tracked_pose`]), moved by the
    /// odometry since it was found: the pose the sensor model judges a
    /// frame's readings at ([`SensorModel::set_reference`]). `None` while
    /// searching.
    reference: Option<Pose2>,
    /// Sensor updates left in which the odometry is suspect after a
    /// realignment ([`Mcl::realign`]).
    odometry_suspect: usize,
    scratch_log: Vec<f64>,
    /// The new weights as [`Self::correct`] works them out.
    scratch_weights: Vec<f64>,
    /// Indices, in the set the last resampling drew, of the particles
    /// [`Mcl::move_uphill`] moves: every one drawn from the old set when
    /// it held two modes or more and the new set is small.
    uphill: Vec<usize>,
    scratch_indices: Vec<usize>,
    /// The frames weighed since a global start or the start of a search,
    /// while fewer than [`HISTORY_FRAMES`]; `None` otherwise (and after a
    /// start at a given pose, whose modes are not equal a priori).
    history: Option<Vec<WeighedFrame>>,
    /// When the sensors fire within a frame ([`Self::set_firing`]).
    firing: RingFiring,
    /// The robot's pace between the frames noted ([`Self::note_frame`]).
    frame_motion: FrameMotion,
    /// Where the robot stood at each reading of the frame noted last, in
    /// its pose's frame; `None` when they were all taken with the frame.
    reading_poses: Option<Vec<Pose2>>,
    /// Where injected particles are drawn around instead of over every
    /// free cell: the global search's hypotheses
    /// ([`Mcl::set_injection_poses`]).
    injection_poses: Option<InjectionPoses>,
    /// The most particles the set may hold now: the settings' most, or
    /// fewer where a CPU budget says so ([`Mcl::set_most_particles`]).
    most: usize,
}

/// Poses injected particles are drawn around, and how widely.
#[derive(Debug, Clone)]
struct InjectionPoses {
    poses: Vec<Pose2>,
    std_xy: f64,
    std_theta: f64,
}

impl Mcl {
    /// A filter with no particles yet: start it with [`Self::start_global`]
    /// or [`Self::start_at`].
    pub fn new(settings: FilterSettings) -> Result<Self, LocalizerError> {
        let settings = settings.validate()?;
        let sonar = SonarCone::new(settings.ring.clone(), settings.beam)?;
        Self::with_sensor(settings, Box::new(sonar))
    }

    /// A filter that scores its particles with `sensor` rather than the
    /// sonar ring and beam model the settings name: any rig's model as
    /// [`crate::sensors::SensorChoice::build`] makes it, or one of its own.
    pub fn with_sensor(
        settings: FilterSettings,
        sensor: Box<dyn SensorModel>,
    ) -> Result<Self, LocalizerError> {
        let settings = settings.validate()?;
        Ok(Self {
            most: settings.kld.max_particles,
            sensor,
            rng: ChaCha8Rng::seed_from_u64(settings.seed),
            settings,
            particles: Vec::new(),
            weights: Vec::new(),
            odometry: None,
            w_slow: 0.0,
            w_fast: 0.0,
            frame_fit: 1.0,
            cluster: None,
            reference: None,
            odometry_suspect: 0,
            scratch_log: Vec::new(),
            scratch_weights: Vec::new(),
            uphill: Vec::new(),
            scratch_indices: Vec::new(),
            history: None,
            firing: RingFiring::Together,
            frame_motion: FrameMotion::default(),
            reading_poses: None,
            injection_poses: None,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &FilterSettings {
        &self.settings
    }

    /// Holds the set to at most `most` particles from the next start or
    /// resampling on (within the settings' fewest and most): what a CPU
    /// budget per update affords. KLD-sampling still decides below it.
    pub fn set_most_particles(&mut self, most: usize) {
        let kld = self.settings.kld;
        self.most = most.clamp(kld.min_particles, kld.max_particles);
    }

    /// The most particles the set may hold now.
    pub fn most_particles(&self) -> usize {
        self.most
    }

    /// The particles.
    pub fn particles(&self) -> &[Pose2] {
        &self.particles
    }

    /// The particles' normalised weights.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Global localization: the most particles the settings allow, spread
    /// uniformly over the known-free cells the map holds, all headings.
    ///
    /// Every particle must be scored against the sensor's tables (range
    /// tables, distance fields) each frame, so the tiles with free cells
    /// must fit in the cache's budget ([`SensorModel::tile_capacity`]): a
    /// map larger than that is refused rather than rebuilt tile by tile
    /// every frame.
    pub fn start_global(&mut self, map: &LocalMap) -> Result<(), LocalizerError> {
        let (tiles, capacity) = (map.free_tile_count(), self.sensor.tile_capacity(map));
        if tiles > capacity {
            return Err(LocalizerError::MapLargerThanCache { tiles, capacity });
        }
        let free = map.free_cells();
        if free.is_empty() {
            return Err(LocalizerError::NoFreeSpace);
        }
        let n = self.most;
        let res = map.settings().resolution;
        self.particles.clear();
        self.weights.clear();
        for _ in 0..n {
            let cell = free[self.rng.random_range(0..free.len())];
            self.particles
                .push(random_pose_in(cell, res, &mut self.rng));
        }
        self.sort_particles(res);
        self.reset_weights();
        self.history = Some(Vec::new());
        Ok(())
    }

    /// Global localization from a search's hypotheses: `per_pose`
    /// particles around each of `poses` (within the settings' fewest and
    /// most), with standard deviations `std_xy` (metres) and `std_theta`
    /// (radians). The modes are then weighed by every frame from here on,
    /// as after a uniform start: the search ranks them by one cloud of
    /// echoes, the filter by the whole way the robot drives.
    pub fn start_hypotheses(
        &mut self,
        poses: &[Pose2],
        per_pose: usize,
        std_xy: f64,
        std_theta: f64,
    ) -> Result<(), LocalizerError> {
        if poses.is_empty() {
            return Err(LocalizerError::Invalid(
                "a start from hypotheses needs at least one".into(),
            ));
        }
        within("hypothesis std_xy", std_xy, 0.0, 1000.0)?;
        within("hypothesis std_theta", std_theta, 0.0, 10.0)?;
        let kld = self.settings.kld;
        let n = poses
            .len()
            .saturating_mul(per_pose.max(1))
            .clamp(kld.min_particles, self.most);
        self.particles.clear();
        self.weights.clear();
        for i in 0..n {
            let pose = poses[i % poses.len()].validate("hypothesis")?;
            let p = self.around(&pose, std_xy, std_theta);
            self.particles.push(p);
        }
        self.sort_particles(deog_grid::Resolution::DEFAULT);
        self.reset_weights();
        self.history = Some(Vec::new());
        Ok(())
    }

    /// Adds `per_pose` particles around each of `poses`, each mode with
    /// the weight of the heaviest cluster: a rival the search found for
    /// the filter's pose is weighed against it from here on, frame by
    /// frame and over the frames to come, rather than left out.
    pub fn add_rivals(
        &mut self,
        poses: &[Pose2],
        per_pose: usize,
        std_xy: f64,
        std_theta: f64,
    ) -> Result<(), LocalizerError> {
        if poses.is_empty() || self.particles.is_empty() {
            return Ok(());
        }
        let room = self.most.saturating_sub(self.particles.len());
        let per_pose = per_pose.min(room / poses.len());
        if per_pose == 0 {
            return Ok(());
        }
        let mode_weight = self.cluster.map_or(0.5, |c| c.weight.max(0.05));
        let total_before: f64 = self.weights.iter().sum();
        for pose in poses {
            let pose = pose.validate("rival")?;
            for _ in 0..per_pose {
                let p = self.around(&pose, std_xy, std_theta);
                self.particles.push(p);
                self.weights
                    .push(total_before * mode_weight / per_pose as f64);
            }
        }
        let total: f64 = self.weights.iter().sum();
        for w in &mut self.weights {
            *w /= total;
        }
        self.sort_particles(deog_grid::Resolution::DEFAULT);
        self.cluster = heaviest_cluster(&self.particles, &self.weights, self.settings.bins);
        self.reference = self.tracked_pose();
        self.history = Some(Vec::new());
        Ok(())
    }

    /// Draws injected particles around `poses` (with these spreads) from
    /// now on, instead of over every free cell; `None` goes back to free
    /// space.
    pub fn set_injection_poses(&mut self, poses: Option<Vec<Pose2>>, std_xy: f64, std_theta: f64) {
        self.injection_poses = poses.filter(|p| !p.is_empty()).map(|poses| InjectionPoses {
            poses,
            std_xy,
            std_theta,
        });
    }

    /// A pose drawn around `pose`.
    fn around(&mut self, pose: &Pose2, std_xy: f64, std_theta: f64) -> Pose2 {
        Pose2::new(
            pose.x + crate::gaussian::normal(&mut self.rng, std_xy),
            pose.y + crate::gaussian::normal(&mut self.rng, std_xy),
            normalize_angle(pose.theta + crate::gaussian::normal(&mut self.rng, std_theta)),
        )
    }

    /// Tracking: the most particles the settings allow, drawn around `pose`
    /// with standard deviations `std_xy` (metres) and `std_theta` (radians);
    /// KLD-sampling cuts their number at the first resampling if the pose
    /// is as certain as that.
    pub fn start_at(
        &mut self,
        pose: Pose2,
        std_xy: f64,
        std_theta: f64,
    ) -> Result<(), LocalizerError> {
        let pose = pose.validate("initial pose")?;
        within("initial std_xy", std_xy, 0.0, 1000.0)?;
        within("initial std_theta", std_theta, 0.0, 10.0)?;
        let n = self.most;
        self.particles.clear();
        self.weights.clear();
        for _ in 0..n {
            let p = Pose2::new(
                pose.x + crate::gaussian::normal(&mut self.rng, std_xy),
                pose.y + crate::gaussian::normal(&mut self.rng, std_xy),
                normalize_angle(pose.theta + crate::gaussian::normal(&mut self.rng, std_theta)),
            );
            self.particles.push(p);
        }
        // Any grid gives the order its locality; the map's is not at hand.
        self.sort_particles(deog_grid::Resolution::DEFAULT);
        self.reset_weights();
        self.history = None;
        Ok(())
    }

    /// Puts the particles in row-major order of squares of 4 × 4 cells,
    /// and by heading in sixteenths of a turn within each square, so that
    /// particles scored one after another read the same lines of the range
    /// tables rather than jumping about: with 100,000 particles spread over
    /// a room, half the first-level cache misses of plain row-major cells
    /// (BENCHMARKS.md). The weights go with their particles when there is
    /// one per particle (a new set's weights are set afterwards).
    fn sort_particles(&mut self, res: deog_grid::Resolution) {
        let inv = 1.0 / res.metres();
        // Each particle's key worked out once, not at every comparison.
        let key = |p: &Pose2| {
            (
                floor_i64(p.y * inv) >> 2,
                floor_i64(p.x * inv) >> 2,
                floor_i64(p.theta * (8.0 / std::f64::consts::PI)),
            )
        };
        let paired = self.weights.len() == self.particles.len();
        let mut keyed: Vec<((i64, i64, i64), Pose2, f64)> = self
            .particles
            .iter()
            .enumerate()
            .map(|(i, p)| (key(p), *p, if paired { self.weights[i] } else { 0.0 }))
            .collect();
        keyed.sort_unstable_by_key(|e| e.0);
        for (i, (_, p, w)) in keyed.into_iter().enumerate() {
            self.particles[i] = p;
            if paired {
                self.weights[i] = w;
            }
        }
    }

    fn reset_weights(&mut self) {
        let n = self.particles.len();
        self.weights = vec![1.0 / n as f64; n];
        self.odometry = None;
        self.w_slow = 0.0;
        self.w_fast = 0.0;
        self.frame_fit = 1.0;
        self.odometry_suspect = 0;
        self.cluster = heaviest_cluster(&self.particles, &self.weights, self.settings.bins);
        self.reference = self.tracked_pose();
    }

    /// The heaviest cluster's mean, when the filter holds mostly that one
    /// mode: settled, or gathered about a pose it was started at.
    fn tracked_pose(&self) -> Option<Pose2> {
        self.cluster
            .filter(|cluster| {
                let c = cluster.covariance;
                cluster.weight >= self.settings.converged_weight
                    && (c[0] + c[4]).sqrt() <= TRACKED_SPREAD_M
                    && c[8].sqrt() <= TRACKED_SPREAD_RAD
            })
            .map(|cluster| cluster.pose)
    }

    /// When the sensors fire within a frame: a ring that fires in turn
    /// has its readings scored where the robot stood at each
    /// ([`Self::note_frame`]). By default, together.
    pub fn set_firing(&mut self, firing: RingFiring) {
        self.firing = firing;
        self.reading_poses = None;
    }

    /// Notes the next frame's `odometry` and time, before it is predicted
    /// and corrected: with a ring that fires in turn
    /// ([`Self::set_firing`]), its readings are then scored where the robot
    /// stood when each was taken, at the pace odometry shows since the
    /// frame noted before. The placement holds until the next frame is
    /// noted: note every frame stepped (frames skipped between two noted
    /// ones only widen the step the pace is taken over).
    pub fn note_frame(&mut self, odometry: &Pose2, time_s: f64) {
        let back = self.frame_motion.observe(odometry, time_s);
        self.reading_poses = self
            .firing
            .robot_at_readings(self.sensor.readings(), back.as_ref());
    }

    /// Takes the frame's odometry pose. Returns true when a sensor update
    /// is due: on the first frame, and once the robot has moved far enough
    /// since the last one (the particles are then moved by that motion).
    pub fn predict(&mut self, odometry: &Pose2) -> Result<bool, LocalizerError> {
        let odometry = odometry.validate("odometry")?;
        let Some(last) = self.odometry else {
            self.odometry = Some(odometry);
            return Ok(true);
        };
        let step = OdometryMove::between(&last, &odometry);
        if step.translation() < self.settings.update_min_distance
            && step.rotation() < self.settings.update_min_rotation
        {
            return Ok(false);
        }
        for p in &mut self.particles {
            *p = step.sample(p, &self.settings.motion, &mut self.rng);
        }
        self.reference = self.reference.map(|pose| step.apply(&pose));
        self.odometry = Some(odometry);
        Ok(true)
    }

    /// The tiles [`Self::realign`] reads for a frame of `readings`: those
    /// its echoes fall in from the tracked pose's window (its centre and
    /// corners at the window's extreme headings). Empty when the filter
    /// would not realign.
    pub fn tiles_for_realign(&self, map: &LocalMap, readings: &[f64]) -> Vec<TileKey> {
        let (Some(settings), Some(at)) = (self.realign_settings(), self.reference) else {
            return Vec::new();
        };
        let (l, a) = (settings.linear_m, settings.angular_rad);
        let mut poses = vec![at];
        for (dx, dy, dt) in [(l, l, a), (l, -l, -a), (-l, l, -a), (-l, -l, a)] {
            poses.push(Pose2::new(at.x + dx, at.y + dy, at.theta + dt));
        }
        self.sensor.tiles_needed(map, &poses, readings)
    }

    /// The realignment's settings when this filter realigns now: it has
    /// them, its sensor is sharp (it judges modes by their best particle,
    /// as a laser does), it tracks one tight pose, and it has a recent fit
    /// to compare the frame with.
    fn realign_settings(&self) -> Option<RealignSettings> {
        let settings = self.settings.realign?;
        (!self.sensor.judges_modes_at_mean()
            && self.reference.is_some()
            && self.settled()
            && self.w_slow > 0.0)
            .then_some(settings)
    }

    /// Before a correction, once [`Self::predict`] has moved the
    /// particles: when the filter tracks one pose and the frame of
    /// `readings` fits it far worse than frames have lately, the poses of
    /// a window around it are scored with the sensor model, and if one
    /// fits as frames usually do, the particles are moved rigidly onto it
    /// ([`crate::realign`]). `tiles` are [`Self::tiles_for_realign`]'s,
    /// fetched. Returns the move made, if any.
    pub fn realign(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        readings: &[f64],
    ) -> Result<Option<Realignment>, LocalizerError> {
        let (Some(settings), Some(at)) = (self.realign_settings(), self.reference) else {
            return Ok(None);
        };
        self.sensor.check_frame(readings)?;
        self.sensor.set_searching(false);
        self.sensor.set_reference(self.reference);
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        // Fits as shares of the recent frames', in logarithms.
        let (observations, recent) = (self.sensor.observations(), self.w_slow.ln());
        let mut centre = Vec::with_capacity(1);
        self.sensor
            .score_poses(map, tiles, std::slice::from_ref(&at), readings, &mut centre)?;
        let Some(&centre) = centre.first() else {
            return Ok(None);
        };
        let before = centre / observations - recent;
        let poor = if self.odometry_suspect > 0 {
            self.odometry_suspect -= 1;
            settings.suspect_fit
        } else {
            settings.poor_fit
        };
        if before >= poor.ln() {
            return Ok(None);
        }
        let sensor = &mut self.sensor;
        let window = best_in_window(&at, &settings, |poses, out| {
            let from = out.len();
            sensor.score_poses(map, tiles, poses, readings, out)?;
            for fit in &mut out[from..] {
                *fit = *fit / observations - recent;
            }
            Ok(())
        })?;
        if window.best_log_fit < settings.good_fit.ln()
            || window.best_rank - window.centre_log_fit < settings.min_gain.ln()
        {
            return Ok(None);
        }
        move_rigidly(&mut self.particles, &at, &window.best);
        self.odometry_suspect = settings.suspect_updates;
        self.reference = Some(window.best);
        Ok(Some(Realignment {
            from: at,
            to: window.best,
            fit_before: window.centre_log_fit.exp(),
            fit_after: window.best_log_fit.exp(),
        }))
    }

    /// The ring check's settings when this filter checks its estimate
    /// for a rival nearby: it has them and its sensor is sharp (a laser's).
    fn ambiguity_settings(&self) -> Option<AmbiguitySettings> {
        let settings = self.settings.ambiguity?;
        (!self.sensor.judges_modes_at_mean()).then_some(settings)
    }

    /// The tiles [`Self::rival_nearby`] reads for a frame of `readings`
    /// around `pose`: those its echoes fall in from the ring's corners at
    /// its extreme headings. Empty when the filter does not check.
    pub fn tiles_for_ring(&self, map: &LocalMap, pose: &Pose2, readings: &[f64]) -> Vec<TileKey> {
        let Some(settings) = self.ambiguity_settings() else {
            return Vec::new();
        };
        let (l, a) = (settings.far_m, settings.half_rad);
        let mut poses = vec![*pose];
        for (dx, dy, dt) in [(l, l, a), (l, -l, -a), (-l, l, -a), (-l, -l, a)] {
            poses.push(Pose2::new(pose.x + dx, pose.y + dy, pose.theta + dt));
        }
        self.sensor.tiles_needed(map, &poses, readings)
    }

    /// The best pose of a ring around the estimate `pose` (0.4 to 0.8 m
    /// off by default) and how its frame fits there beside `pose`
    /// ([`crate::ambiguity`]): where one fits nearly as well, the frame
    /// does not pin the robot and the estimate is not converged. `tiles`
    /// are [`Self::tiles_for_ring`]'s, fetched. `None` when the filter
    /// does not check.
    pub fn rival_nearby(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<Option<(Ring, bool)>, LocalizerError> {
        let Some(settings) = self.ambiguity_settings() else {
            return Ok(None);
        };
        self.sensor.check_frame(readings)?;
        self.sensor.set_searching(false);
        self.sensor.set_reference(self.reference);
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        let observations = self.sensor.observations();
        let sensor = &mut self.sensor;
        let ring = rival_in_ring(pose, &settings, |poses, out| {
            let from = out.len();
            sensor.score_poses(map, tiles, poses, readings, out)?;
            for fit in &mut out[from..] {
                *fit /= observations;
            }
            Ok(())
        })?;
        Ok(ring.map(|ring| (ring, ring.ambiguous(settings.rival_fit))))
    }

    /// The tiles under the particles' sensors: those within the sensor's
    /// reach of every particle, or the [`SensorModel::tile_capacity`] of
    /// them under the most ([`crate::sensors::tiles_within_reach`]). What
    /// the sonar reads whatever its frame; a sensor whose tiles depend on
    /// the frame is asked through [`Self::tiles_for_frame`].
    pub fn tiles_needed(&self, map: &LocalMap) -> Vec<TileKey> {
        crate::sensors::tiles_within_reach(
            map,
            &self.particles,
            self.sensor.reach(),
            self.sensor.tile_capacity(map),
        )
    }

    /// The tiles the next correction reads for a frame of `readings`, as
    /// the sensor model says ([`SensorModel::tiles_needed`]): for the sonar,
    /// [`Self::tiles_needed`]; for the likelihood field, the tiles its
    /// echoes' endpoints fall in.
    pub fn tiles_for_frame(&self, map: &LocalMap, readings: &[f64]) -> Vec<TileKey> {
        self.sensor.tiles_needed(map, &self.particles, readings)
    }

    /// The tiles, sorted, the map must fetch before the tiles `needed`
    /// ([`Self::tiles_for_frame`]) can be scored
    /// ([`SensorModel::missing_tiles`]).
    pub fn missing_tiles(&self, map: &LocalMap, needed: &[TileKey]) -> Vec<TileKey> {
        self.sensor.missing_tiles(map, needed)
    }

    /// The sensor model's half of [`Self::correct`]: every particle's
    /// tempered log-likelihood of `ranges`, kept for the weighting (and
    /// returned by [`Self::scores`]). Returns how many range tables it
    /// built. Public so that benchmarks can time it alone.
    pub fn score(&mut self, map: &mut LocalMap, ranges: &[f64]) -> Result<usize, LocalizerError> {
        self.sensor.check_frame(ranges)?;
        if self.particles.is_empty() {
            return Err(LocalizerError::Invalid(
                "the filter has no particles: start it first".into(),
            ));
        }
        let keys = self.tiles_for_frame(map, ranges);
        self.sensor.set_searching(!self.settled());
        self.sensor.set_reference(self.reference);
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        self.scratch_log.clear();
        self.sensor
            .score_particles(map, &keys, &self.particles, ranges, &mut self.scratch_log)
    }

    /// The log-likelihoods [`Self::score`] last computed, one per particle.
    pub fn scores(&self) -> &[f64] {
        &self.scratch_log
    }

    /// Weighs the particles by one sonar frame (`ranges` in the ring's
    /// order, metres; at or past the maximum means no echo), updates the
    /// likelihood averages and resamples if due. Builds the range tables
    /// it lacks from the tiles `map` holds.
    pub fn correct(
        &mut self,
        map: &mut LocalMap,
        ranges: &[f64],
    ) -> Result<CorrectionReport, LocalizerError> {
        let tables_built = self.score(map, ranges)?;
        self.keep_frame(ranges);
        // New weights ∝ old · likelihood, the likelihoods scaled by the
        // best of them so that the exponentials stay in range: one
        // exponential per particle and no logarithm.
        let mut best = self
            .scratch_log
            .iter()
            .fold(f64::NEG_INFINITY, |a, &l| a.max(l));
        let mut total = 0.0;
        self.scratch_weights.clear();
        for (l, w) in self.scratch_log.iter().zip(&self.weights) {
            let product = w * (l - best).exp();
            total += product;
            self.scratch_weights.push(product);
        }
        if total <= f64::MIN_POSITIVE {
            // Every product underflowed (the best fits sat on particles of
            // next to no weight): again, wholly in log space.
            best = f64::NEG_INFINITY;
            for ((l, w), p) in self
                .scratch_log
                .iter()
                .zip(&self.weights)
                .zip(self.scratch_weights.iter_mut())
            {
                *p = l + w.ln();
                best = best.max(*p);
            }
            total = 0.0;
            for p in &mut self.scratch_weights {
                *p = (*p - best).exp();
                total += *p;
            }
        }
        // The weights before the frame stay in the scratch vector, for the
        // clusters to be weighed peak against peak.
        std::mem::swap(&mut self.weights, &mut self.scratch_weights);
        for w in &mut self.weights {
            *w /= total;
        }
        // Σ old·likelihood = e^best · total: the average likelihood, taken
        // per observation (the tempering undone, then the geometric mean
        // over readings) so that its scale does not depend on the sensor.
        let average = ((best + total.ln()) / self.sensor.observations()).exp();
        self.frame_fit = if self.w_slow > 0.0 {
            average / self.w_slow
        } else {
            1.0
        };
        if self.w_slow == 0.0 {
            self.w_slow = average;
            self.w_fast = average;
        } else {
            self.w_slow += self.settings.alpha_slow * (average - self.w_slow);
            self.w_fast += self.settings.alpha_fast * (average - self.w_fast);
        }
        let mut clusters = cluster_particles(&self.particles, &self.weights, self.settings.bins)
            .ok_or_else(|| LocalizerError::Invalid("the particles have no weight".into()))?;
        if clusters.weights.len() > 1 {
            let sensor = &mut self.sensor;
            let at_mean = sensor.judges_modes_at_mean();
            let evidence = clusters.evidence(
                &self.particles,
                &self.weights,
                &self.scratch_log,
                at_mean,
                |pose| sensor.score_pose(map, pose, ranges),
            )?;
            clusters.weigh_by(&self.scratch_weights, &evidence, &mut self.weights);
            self.weigh_by_history(map, &mut clusters)?;
        }
        let ess = clusters.effective_sample_size(&self.weights);
        let inject = self.injection_share();
        let mut report = CorrectionReport {
            effective_sample_size: ess,
            tables_built,
            ..CorrectionReport::default()
        };
        // The estimate comes from the weighted set, before resampling: a
        // crowd of freshly injected particles would otherwise count for
        // the weight they are about to earn, not the weight they have.
        self.cluster = clusters
            .heaviest()
            .map(|best| clusters.summarize(&self.particles, &self.weights, best));
        self.reference = self.tracked_pose();
        if ess < self.settings.resample_below * self.particles.len() as f64 || inject > 0.0 {
            report.injected = self.resample(map, inject, &clusters)?;
            self.move_uphill(map, ranges)?;
            self.sort_particles(map.settings().resolution);
            report.resampled = true;
        }
        Ok(report)
    }

    /// The tempered log-likelihood `τ · Σ ln p(zₖ | z*ₖ)` of one frame at
    /// `pose`, as a particle there would get it: for diagnostics and tests.
    pub fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        ranges: &[f64],
    ) -> Result<f64, LocalizerError> {
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        self.sensor.score_pose(map, pose, ranges)
    }

    /// The tempered log-likelihood of a stretch of `frames` (each its
    /// odometry pose and readings) for a robot now at `pose`, with
    /// odometry `now`: each frame scored where the odometry carries `pose`
    /// back to, as [`Self::score_pose`] scores one (all readings taken
    /// with their frame). How well a pose explains the way the robot came,
    /// to weigh it against another.
    pub fn path_score<'a>(
        &mut self,
        map: &mut LocalMap,
        now: &Pose2,
        pose: &Pose2,
        frames: impl IntoIterator<Item = (&'a Pose2, &'a [f64])>,
    ) -> Result<f64, LocalizerError> {
        self.sensor.set_reading_poses(None);
        self.sensor.set_reference(None);
        let mut total = 0.0;
        let mut failed = None;
        for (odometry, readings) in frames {
            let at = OdometryMove::between(now, odometry).apply(pose);
            match self.sensor.score_pose(map, &at, readings) {
                Ok(score) => total += score,
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        self.sensor.set_reference(self.reference);
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        match failed {
            Some(e) => Err(e),
            None => Ok(total),
        }
    }

    /// Whether a frame of `readings` the filter does not correct with (the
    /// robot has not moved enough since the last) still fits at `pose` at
    /// least 0.3 as well as frames have lately: a
    /// robot carried off moves no odometry, and its filter would stay sure
    /// of the old pose until the robot drove on.
    pub fn still_fits(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<bool, LocalizerError> {
        if self.w_slow <= 0.0 {
            return Ok(true);
        }
        let score = self.score_pose(map, pose, readings)?;
        let fit = (score / self.sensor.observations()).exp() / self.w_slow;
        Ok(fit >= CONVERGED_FRAME_FIT)
    }

    /// The tiles a frame of `readings` needs scored at `pose` alone: what
    /// [`Self::refine`] reads.
    pub fn tiles_for_pose(&self, map: &LocalMap, pose: &Pose2, readings: &[f64]) -> Vec<TileKey> {
        self.sensor
            .tiles_needed(map, std::slice::from_ref(pose), readings)
    }

    /// Whether [`Self::refine`] may change an estimate.
    pub fn refines(&self) -> bool {
        self.sensor.refines()
    }

    /// `estimate` with its pose refined by matching `readings` against the
    /// map over `tiles` ([`Self::tiles_for_pose`], fetched), when the
    /// sensor model refines and trusts the result
    /// ([`SensorModel::refine_pose`]); as it is otherwise. The particles
    /// are not touched.
    pub fn refine(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        estimate: Estimate,
        readings: &[f64],
    ) -> Result<Estimate, LocalizerError> {
        Ok(
            match self
                .sensor
                .refine_pose(map, tiles, &estimate.pose, readings)?
            {
                Some(pose) => Estimate { pose, ..estimate },
                None => estimate,
            },
        )
    }

    /// The share of particles the next resampling draws from free space.
    pub fn injection_share(&self) -> f64 {
        if self.w_slow > 0.0 {
            let share = (1.0 - self.w_fast / self.w_slow).clamp(0.0, 1.0);
            if share > self.settings.recovery_threshold {
                share
            } else {
                0.0
            }
        } else {
            0.0
        }
    }

    /// KLD-sampling as Fox describes it, cluster by cluster in its
    /// weights: particles are drawn one at a time (from the old set, or
    /// from free space with probability `inject`) until their number
    /// reaches the bound for the bins they fill. Draws from the old set
    /// take a random order through a low-variance (systematic) sample of
    /// the most particles allowed. Injected particles open new bins, so a
    /// lost filter grows back towards the maximum.
    ///
    /// Then every cluster of `clusters` holding at least
    /// `cluster_keep_weight` of the weight is topped up to
    /// `cluster_min_particles` from its own particles, and the new weights
    /// keep each cluster's weight (shared evenly among the particles drawn
    /// from it): the particle counts no longer carry the clusters'
    /// weights, so a mode the frames have favoured all along does not
    /// random-walk to nothing when KLD-sampling shrinks the set, and the
    /// estimate stays the cluster the frames favour, not the one that
    /// happened to draw more particles (Milstein et al.'s Cluster-MCL).
    /// Injected particles share the weight of the draws they took, as
    /// every particle did when weights were reset to equal.
    fn resample(
        &mut self,
        map: &LocalMap,
        inject: f64,
        clusters: &Clusters,
    ) -> Result<usize, LocalizerError> {
        const INJECTED: u32 = u32::MAX;
        let kld = self.settings.kld;
        let pool = self.most;
        systematic_resample(
            &self.weights,
            pool,
            &mut self.rng,
            &mut self.scratch_indices,
        )?;
        let res = map.settings().resolution;
        let around_hypotheses = self.injection_poses.clone().filter(|_| inject > 0.0);
        let free = if inject > 0.0 && around_hypotheses.is_none() {
            // Recovery searches as far as the cache can hold range tables
            // for, half of it (the particles' sonars reach into the tiles
            // around): on a map larger than that, the tiles nearest the
            // estimate; on a smaller one, all free space.
            let around = self
                .cluster
                .map(|c| c.pose)
                .or_else(|| self.particles.first().copied());
            let max_tiles = (self.sensor.tile_capacity(map) / 2).max(1);
            match around.map(|p| res.cell_of(p.x, p.y)) {
                Some(Ok(cell)) => map.free_cells_near(cell, max_tiles),
                _ => Vec::new(),
            }
        } else {
            Vec::new()
        };
        let mut bins = BinSet::default();
        let mut next = Vec::with_capacity(self.particles.len());
        // Where each new particle came from: its cluster, or INJECTED.
        let mut source: Vec<u32> = Vec::with_capacity(self.particles.len());
        let mut drawn = vec![0usize; clusters.weights.len()];
        let mut bound = kld.particles_for(0);
        let mut injected = 0;
        let mut taken = 0;
        // Room kept for the clusters the top-up keeps: a recovery that
        // draws the most particles allowed would otherwise leave none for
        // them, and a light cluster on the true pose would be lost.
        let reserved: usize = clusters
            .weights
            .iter()
            .filter(|&&w| w >= self.settings.cluster_keep_weight && w > 0.0)
            .count()
            .saturating_mul(self.settings.cluster_min_particles);
        // At most half the set, so a spread filter's many small clusters
        // still leave the draw its share.
        let most = pool - reserved.min(pool / 2);
        // A settled filter whose frames fit a little worse injects a
        // trickle: its particles come on top of the draws KLD-sampling
        // calls for and open no bins (each would call for the particles a
        // new bin asks for, and the set would grow to the most allowed at
        // every dip of the fit). A large drop, or a filter not settled,
        // searches: injected particles count, and the set grows.
        let search = !self.settled() || inject >= self.settings.search_share;
        let counted = |next: &Vec<Pose2>, injected: usize| {
            if search {
                next.len()
            } else {
                next.len() - injected
            }
        };
        while counted(&next, injected) < bound && next.len() < most && taken < pool {
            let can_inject = !free.is_empty() || around_hypotheses.is_some();
            let pose = if can_inject && self.rng.random_bool(inject) {
                injected += 1;
                source.push(INJECTED);
                let pose = match &around_hypotheses {
                    Some(h) => {
                        let centre = h.poses[self.rng.random_range(0..h.poses.len())];
                        self.around(&centre, h.std_xy, h.std_theta)
                    }
                    None => {
                        let cell = free[self.rng.random_range(0..free.len())];
                        random_pose_in(cell, res, &mut self.rng)
                    }
                };
                if !search {
                    next.push(pose);
                    continue;
                }
                pose
            } else {
                let i = self.next_draw(&mut taken, pool);
                let c = clusters.of[i];
                drawn[c as usize] += 1;
                source.push(c);
                self.particles[i]
            };
            if bins.insert(self.settings.bins.bin_of(&pose)) {
                bound = kld.particles_for(bins.len());
            }
            next.push(pose);
        }
        let mut draws = next.len();
        self.top_up_clusters(clusters, &mut drawn, &mut next, &mut source)?;
        // The room kept for top-ups they did not need goes back to the
        // draw, so that the set never holds fewer than the fewest allowed
        // (with fewest = most, a fixed count is that count).
        while next.len() < kld.min_particles && taken < pool {
            let i = self.next_draw(&mut taken, pool);
            let c = clusters.of[i];
            drawn[c as usize] += 1;
            source.push(c);
            next.push(self.particles[i]);
            draws += 1;
        }
        // A set of a few modes has every mode's particles moved to its peak,
        // so that the modes are weighed peak against peak.
        self.uphill.clear();
        let modes = drawn.iter().filter(|&&n| n > 0).count();
        if modes >= 2 && next.len() <= UPHILL_MOST {
            self.uphill
                .extend((0..next.len()).filter(|&i| source[i] != INJECTED));
        }
        // Each cluster drawn from keeps its share of the old set's weight,
        // over the clusters drawn from; injected particles get the share
        // of the draws they took.
        let injected_share = injected as f64 / draws as f64;
        let drawn_weight: f64 = drawn
            .iter()
            .zip(&clusters.weights)
            .filter(|(n, _)| **n > 0)
            .map(|(_, w)| w)
            .sum();
        self.weights = source
            .iter()
            .map(|&c| {
                if c == INJECTED {
                    injected_share / injected as f64
                } else {
                    let c = c as usize;
                    (1.0 - injected_share) * clusters.weights[c] / drawn_weight / drawn[c] as f64
                }
            })
            .collect();
        let total: f64 = self.weights.iter().sum();
        for w in &mut self.weights {
            *w /= total;
        }
        self.particles = next;
        if injected > 0 {
            // The injected particles answer the drop; start the averages anew
            // so that one bad stretch does not keep injecting.
            self.w_fast = self.w_slow;
            if inject >= self.settings.search_share {
                // A search: the modes it finds are judged by the frames
                // from here on, not by those from before the robot was
                // lost (or carried off).
                self.history = Some(Vec::new());
            }
        }
        Ok(injected)
    }

    /// Keeps the frame just scored in the history, while there is one;
    /// past [`HISTORY_FRAMES`] the history ends.
    fn keep_frame(&mut self, ranges: &[f64]) {
        let (Some(history), Some(odometry)) = (&mut self.history, self.odometry) else {
            return;
        };
        if history.len() >= HISTORY_FRAMES {
            self.history = None;
            return;
        }
        history.push(WeighedFrame {
            odometry,
            ranges: ranges.to_vec(),
            reference: self.reference,
            reading_poses: self.reading_poses.clone(),
        });
    }

    /// Weighs the filter's modes by every frame since the global start or
    /// the search that found them, while the history lasts: each mode's
    /// mean pose is carried back by the odometry to each frame kept and
    /// scored there, and the modes share the weight they hold by the
    /// likelihood of that whole stretch. Weighing frame by frame
    /// ([`Clusters::weigh_by`]) can only multiply the weight a mode already
    /// has, and a mode's weight when it forms is the luck of the first
    /// draws: in a symmetric room the true pose could lead its mirror image
    /// by several nats over the first half-minute and still hold a
    /// minority of the weight. Modes are those of at least
    /// [`MEAN_POSE_MIN_PARTICLES`], no wider than a tracked pose, the
    /// [`HISTORY_MODES`] heaviest of them; the rest keep their weights.
    /// Once the history ends the weights this left carry on frame by
    /// frame.
    fn weigh_by_history(
        &mut self,
        map: &mut LocalMap,
        clusters: &mut Clusters,
    ) -> Result<(), LocalizerError> {
        let (Some(history), Some(now)) = (&self.history, self.odometry) else {
            return Ok(());
        };
        let shapes = clusters.shapes(&self.particles, &self.weights);
        let mut modes: Vec<usize> = (0..clusters.weights.len())
            .filter(|&c| {
                clusters.counts[c] >= MEAN_POSE_MIN_PARTICLES
                    && clusters.weights[c] >= self.settings.cluster_keep_weight
                    && clusters.weights[c] > 0.0
                    && shapes[c].is_some_and(|s| {
                        s.spread_m <= TRACKED_SPREAD_M && s.spread_rad <= TRACKED_SPREAD_RAD
                    })
            })
            .collect();
        if modes.len() < 2 {
            return Ok(());
        }
        modes.sort_by(|a, b| {
            clusters.weights[*b]
                .total_cmp(&clusters.weights[*a])
                .then(a.cmp(b))
        });
        modes.truncate(HISTORY_MODES);
        let means: Vec<Pose2> = modes
            .iter()
            .filter_map(|&c| shapes[c].map(|s| s.mean))
            .collect();
        let mut evidence = vec![0.0; means.len()];
        let mut poses = Vec::with_capacity(means.len());
        let mut scores = Vec::with_capacity(means.len());
        for frame in history {
            let back = OdometryMove::between(&now, &frame.odometry);
            poses.clear();
            poses.extend(means.iter().map(|m| back.apply(m)));
            self.sensor.set_reference(frame.reference);
            self.sensor
                .set_reading_poses(frame.reading_poses.as_deref());
            let keys = self.sensor.tiles_needed(map, &poses, &frame.ranges);
            scores.clear();
            self.sensor
                .score_particles(map, &keys, &poses, &frame.ranges, &mut scores)?;
            for (e, s) in evidence.iter_mut().zip(&scores) {
                *e += s;
            }
        }
        self.sensor.set_reference(self.reference);
        self.sensor.set_reading_poses(self.reading_poses.as_deref());
        let best = evidence.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let shares: Vec<f64> = evidence.iter().map(|e| (e - best).exp()).collect();
        let total: f64 = shares.iter().sum();
        let mass: f64 = modes.iter().map(|&c| clusters.weights[c]).sum();
        if !best.is_finite() || total <= 0.0 {
            return Ok(());
        }
        let mut scale = vec![1.0; clusters.weights.len()];
        for (&c, share) in modes.iter().zip(&shares) {
            let target = mass * share / total;
            scale[c] = target / clusters.weights[c];
            clusters.weights[c] = target;
        }
        for (w, &c) in self.weights.iter_mut().zip(&clusters.of) {
            *w *= scale[c as usize];
        }
        Ok(())
    }

    /// The old particle of the next draw: a random one of the systematic
    /// sample's `pool` indices not yet taken (`taken` of them are).
    fn next_draw(&mut self, taken: &mut usize, pool: usize) -> usize {
        let j = self.rng.random_range(*taken..pool);
        self.scratch_indices.swap(*taken, j);
        *taken += 1;
        self.scratch_indices[*taken - 1]
    }

    /// Draws more particles for each cluster of the old set that holds at
    /// least `cluster_keep_weight` of the weight but got fewer than
    /// `cluster_min_particles`, heaviest first while the set is below the
    /// most particles allowed (twice the draws, once settled): a
    /// systematic sample of the cluster's own particles by their weights.
    fn top_up_clusters(
        &mut self,
        clusters: &Clusters,
        drawn: &mut [usize],
        next: &mut Vec<Pose2>,
        source: &mut Vec<u32>,
    ) -> Result<(), LocalizerError> {
        let (keep, least) = (
            self.settings.cluster_keep_weight,
            self.settings.cluster_min_particles,
        );
        let mut short: Vec<usize> = (0..drawn.len())
            .filter(|&c| {
                clusters.weights[c] >= keep && clusters.weights[c] > 0.0 && drawn[c] < least
            })
            .collect();
        if short.is_empty() {
            return Ok(());
        }
        short.sort_by(|a, b| {
            clusters.weights[*b]
                .total_cmp(&clusters.weights[*a])
                .then(a.cmp(b))
        });
        let heaviest = clusters.heaviest().unwrap_or(0) as u32;
        let mut members: BinMap<u32, Vec<usize>> = short
            .iter()
            .map(|&c| (c as u32, Vec::new()))
            .chain([(heaviest, Vec::new())])
            .collect();
        for (i, c) in clusters.of.iter().enumerate() {
            if let Some(m) = members.get_mut(c) {
                m.push(i);
            }
        }
        // Once settled, light clusters are moved by a kernel the size of
        // the heaviest one's spread: the shape a mode of this filter takes,
        // which the few copies of a light mode cannot show. (A filter still
        // searching keeps its modes as they are: its heaviest cluster may
        // be spread over metres.)
        let spread = if self.settled() {
            kernel_spread(&self.particles, &self.weights, &members[&heaviest], least)
        } else {
            [0.0; 3]
        };
        let mut weights = Vec::new();
        let mut picks = Vec::new();
        // A settled filter's top-ups at most double the draws: particles
        // it injected a frame ago are clusters of one with a share of the
        // weight, and topping each up to the floor would grow it many
        // times over whenever it injects a few. The heaviest clusters,
        // modes the frames have favoured, come first. A filter searching
        // (after a kidnap, say) keeps every mode it can.
        let most = if self.settled() {
            (2 * next.len()).min(self.most)
        } else {
            self.most
        };
        for c in short {
            let room = most.saturating_sub(next.len());
            let need = (least - drawn[c]).min(room);
            if need == 0 {
                break;
            }
            let m = &members[&(c as u32)];
            weights.clear();
            weights.extend(m.iter().map(|&i| self.weights[i]));
            systematic_resample(&weights, need, &mut self.rng, &mut picks)?;
            for &j in &picks {
                let p = self.particles[m[j]];
                if spread == [0.0; 3] {
                    next.push(p);
                    source.push(c as u32);
                    continue;
                }
                next.push(Pose2::new(
                    p.x + crate::gaussian::normal(&mut self.rng, spread[0]),
                    p.y + crate::gaussian::normal(&mut self.rng, spread[1]),
                    normalize_angle(p.theta + crate::gaussian::normal(&mut self.rng, spread[2])),
                ));
                source.push(c as u32);
            }
            drawn[c] += need;
        }
        Ok(())
    }

    /// Moves the particles the last resampling marked (a set of two modes
    /// or more, at most [`UPHILL_MOST`]) towards their mode's peak: a few
    /// Metropolis steps of a small Gaussian walk, each accepted with the
    /// frame's likelihood ratio (resample-move, Gilks and Berzuini, 2001).
    /// The particles' weights follow their likelihoods: a light mode, a
    /// few particles copied many times, sits off its peak by as much as
    /// their spread, and its particles lose weight to one another even
    /// where the frames favour its mode (the clusters' own weights are
    /// weighed by a pose standing for each, [`Clusters::evidence`]). Only the light
    /// modes were moved at first; that favoured them against a heavy mode
    /// off its own peak.
    fn move_uphill(&mut self, map: &mut LocalMap, ranges: &[f64]) -> Result<(), LocalizerError> {
        if self.uphill.is_empty() {
            return Ok(());
        }
        let mut at: Vec<Pose2> = self.uphill.iter().map(|&i| self.particles[i]).collect();
        let sensor = &mut self.sensor;
        metropolis_walk(&mut self.rng, &mut at, |poses, out| {
            let keys = sensor.tiles_needed(map, poses, ranges);
            sensor.score_particles(map, &keys, poses, ranges, out)?;
            Ok(())
        })?;
        for (k, &i) in self.uphill.iter().enumerate() {
            self.particles[i] = at[k];
        }
        self.uphill.clear();
        Ok(())
    }

    /// Whether the heaviest cluster holds enough of the weight, tightly
    /// enough, to call the robot found ([`Estimate::converged`]).
    pub fn settled(&self) -> bool {
        self.cluster.is_some_and(|cluster| {
            let c = cluster.covariance;
            cluster.weight >= self.settings.converged_weight
                && (c[0] + c[4]).sqrt() <= self.settings.converged_spread_m
                && c[8].sqrt() <= self.settings.converged_spread_rad
        })
    }

    /// The estimate for a frame with odometry pose `odometry`: the heaviest
    /// cluster's mean moved by the odometry since the last correction.
    pub fn estimate(&self, odometry: &Pose2) -> Option<Estimate> {
        Some(self.carried()?.at(odometry))
    }

    /// What [`Mcl::estimate`] needs, apart from the filter: a process can
    /// carry it by odometry to frames that come while the filter is busy.
    pub fn carried(&self) -> Option<CarriedEstimate> {
        let cluster = self.cluster?;
        Some(CarriedEstimate {
            estimate: Estimate {
                pose: cluster.pose,
                covariance: cluster.covariance,
                particle_count: self.particles.len(),
                cluster_weight: cluster.weight,
                // Just after a realignment the pose rests on a scan's match
                // alone: not converged while the odometry is suspect.
                converged: self.settled()
                    && self.frame_fit >= CONVERGED_FRAME_FIT
                    && self.odometry_suspect == 0,
                lost_score: self.injection_share(),
            },
            odometry: self.odometry,
        })
    }

    /// At most `count` particles drawn by weight (systematic resampling,
    /// no random draw: the same filter gives the same sample), each moved
    /// by the odometry since the last correction as [`Mcl::estimate`]
    /// moves the mean. For viewers: a picture of the belief, not a filter.
    pub fn sample(&self, count: usize, odometry: &Pose2) -> Vec<Pose2> {
        let n = self.particles.len();
        if count == 0 || n == 0 {
            return Vec::new();
        }
        let moved = |p: &Pose2| match self.odometry {
            Some(last) => OdometryMove::between(&last, odometry).apply(p),
            None => *p,
        };
        if count >= n {
            return self.particles.iter().map(moved).collect();
        }
        let total: f64 = self.weights.iter().sum();
        if total.is_nan() || total <= 0.0 {
            // Weights not yet normalised (or all zero): an even stride.
            return (0..count)
                .map(|i| moved(&self.particles[i * n / count]))
                .collect();
        }
        let step = total / count as f64;
        let mut sample = Vec::with_capacity(count);
        let mut next = step / 2.0;
        let mut reached = 0.0;
        for (particle, weight) in self.particles.iter().zip(&self.weights) {
            reached += weight;
            while next < reached && sample.len() < count {
                sample.push(moved(particle));
                next += step;
            }
        }
        sample
    }
}

/// The spread of the kernel a topped-up cluster's draws are moved by: the
/// weighted spread per axis (x, y, heading) of the particles `members`
/// times the bandwidth of a regularized particle filter for `draws`
/// particles in three dimensions (Musso, Oudjane and Le Gland, 2001). A
/// light cluster is drawn from a few of its own particles at every
/// resampling, and without it those few copies would stay where they first
/// landed: a mode a few centimetres off its peak scores below one on it,
/// and the true mode of a symmetric room loses to its image.
fn kernel_spread(
    particles: &[Pose2],
    weights: &[f64],
    members: &[usize],
    draws: usize,
) -> [f64; 3] {
    const DIMENSIONS: f64 = 3.0;
    let bandwidth =
        (4.0 / (draws.max(1) as f64 * (DIMENSIONS + 2.0))).powf(1.0 / (DIMENSIONS + 4.0));
    let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
    let (mut sc, mut ss) = (0.0, 0.0);
    for &i in members {
        let (p, w) = (particles[i], weights[i]);
        sw += w;
        sx += w * p.x;
        sy += w * p.y;
        sc += w * p.theta.cos();
        ss += w * p.theta.sin();
    }
    if sw.is_nan() || sw <= 0.0 {
        return [0.0; 3];
    }
    let (mx, my, mt) = (sx / sw, sy / sw, ss.atan2(sc));
    let mut var = [0.0; 3];
    for &i in members {
        let (p, w) = (particles[i], weights[i]);
        var[0] += w * (p.x - mx).powi(2);
        var[1] += w * (p.y - my).powi(2);
        var[2] += w * normalize_angle(p.theta - mt).powi(2);
    }
    var.map(|v| bandwidth * (v / sw).sqrt())
}

/// A pose uniformly inside `cell`, any heading.
fn random_pose_in(cell: CellIndex, res: deog_grid::Resolution, rng: &mut impl Rng) -> Pose2 {
    let (x0, y0) = res.cell_corner(cell);
    let m = res.metres();
    Pose2::new(
        x0 + rng.random_range(0.0..m),
        y0 + rng.random_range(0.0..m),
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
    )
}

/// Steps of the Metropolis walk [`Mcl::move_uphill`] takes, and their
/// spread: a fraction of the cloud a tracking filter keeps (3 to 5 cm).
const WALK_STEPS: usize = 4;
const WALK_STEP_XY: f64 = 0.02;
const WALK_STEP_THETA: f64 = 0.02;

/// [`WALK_STEPS`] Metropolis steps for each pose of `at`: a Gaussian move,
/// kept with the probability `min(1, e^(l' - l))` of the log-likelihoods
/// `score` gives (one per pose, pushed onto its second argument).
fn metropolis_walk(
    rng: &mut ChaCha8Rng,
    at: &mut [Pose2],
    mut score: impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError>,
) -> Result<(), LocalizerError> {
    let mut current = Vec::with_capacity(at.len());
    score(at, &mut current)?;
    let (mut proposed, mut scores) = (Vec::with_capacity(at.len()), Vec::new());
    for _ in 0..WALK_STEPS {
        proposed.clear();
        for p in at.iter() {
            proposed.push(Pose2::new(
                p.x + crate::gaussian::normal(rng, WALK_STEP_XY),
                p.y + crate::gaussian::normal(rng, WALK_STEP_XY),
                normalize_angle(p.theta + crate::gaussian::normal(rng, WALK_STEP_THETA)),
            ));
        }
        scores.clear();
        score(&proposed, &mut scores)?;
        for (k, p) in at.iter_mut().enumerate() {
            let gain = scores[k] - current[k];
            if gain >= 0.0 || rng.random::<f64>() < gain.exp() {
                *p = proposed[k];
                current[k] = scores[k];
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use deog_grid::TileSize;

    fn empty_map() -> LocalMap {
        LocalMap::empty_for_tests(1 << 20)
    }

    #[test]
    fn a_sample_follows_the_weight_and_its_size() {
        let mcl = two_modes(200, 0.25);
        let sample = mcl.sample(100, &Pose2::new(0.0, 0.0, 0.0));
        assert_eq!(sample.len(), 100);
        let light = sample.iter().filter(|p| (p.x - 2.0).abs() < 1.0).count();
        assert!(
            (20..=30).contains(&light),
            "{light} of 100 in the light mode"
        );
        assert_eq!(mcl.sample(0, &Pose2::new(0.0, 0.0, 0.0)).len(), 0);
        let all = mcl.sample(1_000_000, &Pose2::new(0.0, 0.0, 0.0));
        assert_eq!(all.len(), mcl.particles().len());
    }

    #[test]
    fn a_carried_estimate_moves_as_the_filters_own_does() {
        let mut mcl = Mcl::new(FilterSettings {
            seed: 5,
            ..FilterSettings::default()
        })
        .unwrap();
        mcl.start_at(Pose2::new(3.0, 4.0, 0.5), 0.01, 0.01).unwrap();
        let before = mcl.carried().unwrap();
        // Before any frame there is no odometry to carry by.
        let far = Pose2::new(10.0, -2.0, 1.0);
        assert_eq!(before.at(&far), mcl.estimate(&far).unwrap());
        assert_eq!(
            before.at(&far).pose,
            before.at(&Pose2::new(0.0, 0.0, 0.0)).pose
        );
        mcl.predict(&Pose2::new(1.0, 1.0, 0.0)).unwrap();
        let carried = mcl.carried().unwrap();
        let later = Pose2::new(1.5, 1.0, 0.2);
        let estimate = mcl.estimate(&later).unwrap();
        assert_eq!(carried.at(&later), estimate);
        // Half a metre ahead along the heading it was corrected at.
        let start = carried.at(&Pose2::new(1.0, 1.0, 0.0)).pose;
        assert_abs_diff_eq!(
            estimate.pose.x - start.x,
            0.5 * start.theta.cos(),
            epsilon = 1e-9
        );
        assert_abs_diff_eq!(
            estimate.pose.y - start.y,
            0.5 * start.theta.sin(),
            epsilon = 1e-9
        );
        assert_abs_diff_eq!(estimate.pose.theta - start.theta, 0.2, epsilon = 1e-9);
    }

    /// A sensor whose frame names the true position, heading 0 (`[x, y,
    /// lead]`): a pose scores by its squared distance from the truth or
    /// from the truth's image about (5, 3), turned half a turn, the image
    /// `lead` nats worse.
    #[derive(Debug)]
    struct MirrorSensor;

    impl MirrorSensor {
        fn score(pose: &Pose2, readings: &[f64]) -> f64 {
            let (x, y, lead) = (readings[0], readings[1], readings[2]);
            let near = |px: f64, py: f64, theta: f64| {
                -((pose.x - px).powi(2) + (pose.y - py).powi(2)) / 0.01
                    - normalize_angle(pose.theta - theta).powi(2) / 0.01
            };
            near(x, y, 0.0).max(near(10.0 - x, 6.0 - y, std::f64::consts::PI) - lead)
        }
    }

    impl SensorModel for MirrorSensor {
        fn readings(&self) -> usize {
            3
        }
        fn reach(&self) -> f64 {
            0.0
        }
        fn observations(&self) -> f64 {
            3.0
        }
        fn score_particles(
            &mut self,
            _: &mut LocalMap,
            _: &[TileKey],
            particles: &[Pose2],
            readings: &[f64],
            out: &mut Vec<f64>,
        ) -> Result<usize, LocalizerError> {
            out.extend(particles.iter().map(|p| Self::score(p, readings)));
            Ok(0)
        }
        fn score_pose(
            &mut self,
            _: &mut LocalMap,
            pose: &Pose2,
            readings: &[f64],
        ) -> Result<f64, LocalizerError> {
            Ok(Self::score(pose, readings))
        }
    }

    /// A robot driving along x from (1, 1), 10 cm a frame, whose first 10
    /// frames told its pose from the image by a nat each, and whose filter
    /// then formed two modes, the truth's with a tenth of the weight; the
    /// next frame tells them apart not at all.
    fn mirrored_modes(history: bool) -> (Mcl, Pose2) {
        let settings = FilterSettings {
            seed: 3,
            ..FilterSettings::default()
        };
        let mut mcl = Mcl::with_sensor(settings, Box::new(MirrorSensor)).unwrap();
        let truth_at = |k: usize| Pose2::new(1.0 + 0.1 * k as f64, 1.0, 0.0);
        let odometry_at = |k: usize| Pose2::new(0.1 * k as f64, 0.0, 0.0);
        mcl.history = history.then(|| {
            (0..10)
                .map(|k| WeighedFrame {
                    odometry: odometry_at(k),
                    ranges: vec![truth_at(k).x, truth_at(k).y, 1.0],
                    reference: None,
                    reading_poses: None,
                })
                .collect()
        });
        mcl.odometry = Some(odometry_at(10));
        let truth = truth_at(10);
        let image = Pose2::new(10.0 - truth.x, 6.0 - truth.y, std::f64::consts::PI);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for (centre, weight) in [(truth, 0.1), (image, 0.9)] {
            for _ in 0..200 {
                mcl.particles.push(Pose2::new(
                    centre.x + rng.random_range(-0.02..0.02),
                    centre.y + rng.random_range(-0.02..0.02),
                    normalize_angle(centre.theta + rng.random_range(-0.02..0.02)),
                ));
                mcl.weights.push(weight / 200.0);
            }
        }
        (mcl, truth)
    }

    #[test]
    fn modes_are_weighed_by_the_frames_since_the_start() {
        let mut map = empty_map();
        for history in [true, false] {
            let (mut mcl, truth) = mirrored_modes(history);
            mcl.correct(&mut map, &[truth.x, truth.y, 0.0]).unwrap();
            let best = mcl.cluster.unwrap();
            let on_truth = (best.pose.x - truth.x).hypot(best.pose.y - truth.y) < 0.1;
            // With the history the truth leads by 10 nats; without it, the
            // weight the modes formed with stands.
            assert_eq!(on_truth, history, "{best:?}");
            if history {
                assert!(best.weight > 0.99, "{best:?}");
            }
        }
    }

    #[test]
    fn the_history_ends_after_its_frames_and_at_a_start_at_a_pose() {
        let (mut mcl, truth) = mirrored_modes(true);
        let mut map = empty_map();
        for k in 0..HISTORY_FRAMES {
            mcl.odometry = Some(Pose2::new(1.0 + 0.1 * k as f64, 0.0, 0.0));
            mcl.correct(&mut map, &[truth.x, truth.y, 0.0]).unwrap();
        }
        assert!(mcl.history.is_none());
        let (mut mcl, _) = mirrored_modes(true);
        mcl.start_at(truth, 0.1, 0.1).unwrap();
        assert!(mcl.history.is_none());
        mcl.start_global(&map_with_free_tile()).unwrap();
        assert_eq!(mcl.history.as_ref().map(Vec::len), Some(0));
    }

    /// A filter holding two tight modes: `light` particles about (2, 2, 0)
    /// sharing `light_weight` of the weight, 2,000 about (7, 5, π) sharing
    /// the rest.
    fn two_modes(light: usize, light_weight: f64) -> Mcl {
        let mut settings = FilterSettings {
            seed: 7,
            ..FilterSettings::default()
        };
        settings.kld.max_particles = 20_000;
        let mut mcl = Mcl::new(settings).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut jitter = |scale: f64| rng.random_range(-scale..scale);
        for _ in 0..light {
            mcl.particles.push(Pose2::new(
                2.0 + jitter(0.05),
                2.0 + jitter(0.05),
                jitter(0.03),
            ));
            mcl.weights.push(light_weight / light as f64);
        }
        for _ in 0..2_000 {
            mcl.particles.push(Pose2::new(
                7.0 + jitter(0.05),
                5.0 + jitter(0.05),
                std::f64::consts::PI - 0.05 + jitter(0.03),
            ));
            mcl.weights.push((1.0 - light_weight) / 2_000.0);
        }
        mcl
    }

    fn resample_once(mcl: &mut Mcl, map: &LocalMap) {
        let clusters = cluster_particles(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
        mcl.resample(map, 0.0, &clusters).unwrap();
    }

    /// The weight and particle count of the mode about (2, 2).
    fn light_mode(mcl: &Mcl) -> (f64, usize) {
        mcl.particles
            .iter()
            .zip(&mcl.weights)
            .filter(|(p, _)| p.x < 4.5)
            .fold((0.0, 0), |(w, n), (_, pw)| (w + pw, n + 1))
    }

    #[test]
    fn a_light_mode_keeps_its_weight_and_particles_through_resampling() {
        let map = empty_map();
        let mut mcl = two_modes(40, 0.002);
        for _ in 0..30 {
            resample_once(&mut mcl, &map);
            let (weight, count) = light_mode(&mcl);
            assert_abs_diff_eq!(weight, 0.002, epsilon = 1e-9);
            assert!(
                count >= mcl.settings.cluster_min_particles,
                "the light mode has {count} particles"
            );
        }
        // KLD-sampling still shrinks the set to what two tight modes need.
        assert!(mcl.particles.len() < 5_000, "{}", mcl.particles.len());
        // The frames then favour the light mode (a likelihood ratio of
        // 10⁴, about what seeing the one box that breaks a room's symmetry
        // gives): it becomes the estimate.
        for (p, w) in mcl.particles.iter().zip(&mut mcl.weights) {
            if p.x < 4.5 {
                *w *= 1e4;
            }
        }
        let best = heaviest_cluster(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
        assert_abs_diff_eq!(best.pose.x, 2.0, epsilon = 0.05);
        assert!(best.weight > 0.9, "{best:?}");
    }

    #[test]
    fn a_budget_holds_the_set_below_the_settings_most() {
        let map = empty_map();
        // Spread wide, the set fills many bins: KLD-sampling asks for more
        // than the budget allows.
        let spread = |most: Option<usize>| {
            let mut mcl = two_modes(0, 0.0);
            if let Some(most) = most {
                mcl.set_most_particles(most);
            }
            mcl.start_at(Pose2::new(5.0, 4.0, 0.0), 2.0, 3.0)
                .expect("starts");
            mcl
        };
        let mut free = spread(None);
        assert_eq!(free.particles.len(), 20_000);
        resample_once(&mut free, &map);
        assert!(free.particles.len() > 1_200, "{}", free.particles.len());
        let mut held = spread(Some(1_200));
        assert_eq!(held.most_particles(), 1_200);
        assert_eq!(held.particles.len(), 1_200);
        for _ in 0..3 {
            resample_once(&mut held, &map);
            assert!(held.particles.len() <= 1_200, "{}", held.particles.len());
        }
        // Never below the fewest, never above the most.
        held.set_most_particles(1);
        assert_eq!(held.most_particles(), held.settings.kld.min_particles);
        held.set_most_particles(usize::MAX);
        assert_eq!(held.most_particles(), held.settings.kld.max_particles);
    }

    #[test]
    fn a_fixed_count_is_that_count_after_resampling() {
        let map = empty_map();
        // One tight mode: the room kept for its top-up is what went missing.
        let mut mcl = two_modes(0, 0.0);
        mcl.settings.kld.min_particles = 500;
        mcl.settings.kld.max_particles = 500;
        mcl.set_most_particles(500);
        for _ in 0..5 {
            resample_once(&mut mcl, &map);
            assert_eq!(mcl.particles.len(), 500);
        }
    }

    #[test]
    fn a_settled_filters_light_mode_is_spread_like_the_heavy_one() {
        let map = empty_map();
        // Forty copies of one pose: a light mode drawn from a single
        // particle, as a mode that lost most of its particles is.
        let mut mcl = two_modes(40, 0.002);
        for p in mcl.particles.iter_mut().take(40) {
            *p = Pose2::new(2.0, 2.0, 0.0);
        }
        let clusters = cluster_particles(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
        mcl.cluster = clusters
            .heaviest()
            .map(|c| clusters.summarize(&mcl.particles, &mcl.weights, c));
        assert!(mcl.settled());
        mcl.resample(&map, 0.0, &clusters).unwrap();
        let light: Vec<&Pose2> = mcl.particles.iter().filter(|p| p.x < 4.5).collect();
        let distinct = light.iter().filter(|p| p.x != 2.0 || p.y != 2.0).count();
        assert!(
            distinct > light.len() / 2,
            "{distinct} of {} moved",
            light.len()
        );
        // The heavy mode spreads ±5 cm (σ ≈ 2.9 cm); the kernel is that
        // times the bandwidth for 300 draws (0.43): about 1.2 cm.
        let std_x =
            (light.iter().map(|p| (p.x - 2.0).powi(2)).sum::<f64>() / light.len() as f64).sqrt();
        assert!((0.006..0.025).contains(&std_x), "σx {std_x}");
    }

    /// A log-likelihood peaked at (2, 2, 0), `width` metres and radians
    /// wide.
    fn peaked(width: f64) -> impl FnMut(&[Pose2], &mut Vec<f64>) -> Result<(), LocalizerError> {
        move |poses, out| {
            out.extend(poses.iter().map(|p| {
                -((p.x - 2.0).powi(2) + (p.y - 2.0).powi(2) + p.theta.powi(2))
                    / (2.0 * width.powi(2))
            }));
            Ok(())
        }
    }

    /// A log-likelihood the same everywhere.
    fn flat(poses: &[Pose2], out: &mut Vec<f64>) -> Result<(), LocalizerError> {
        out.extend(std::iter::repeat_n(0.0, poses.len()));
        Ok(())
    }

    fn mean_distance(poses: &[Pose2]) -> f64 {
        poses
            .iter()
            .map(|p| (p.x - 2.0).hypot(p.y - 2.0))
            .sum::<f64>()
            / poses.len() as f64
    }

    #[test]
    fn the_walk_climbs_towards_the_peak() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // Copies of one pose 10 cm and 0.1 rad off a peak 3 cm wide (the
        // tempered sonar likelihood's, about).
        let mut at = vec![Pose2::new(2.1, 2.0, 0.1); 1_000];
        metropolis_walk(&mut rng, &mut at, peaked(0.03)).unwrap();
        let distance = mean_distance(&at);
        let heading = at.iter().map(|p| p.theta.abs()).sum::<f64>() / at.len() as f64;
        // Four steps of 2 cm climb a little: a plain random walk from there
        // ends farther off, not nearer.
        assert!(distance < 0.09, "mean distance {distance:.3} m");
        assert!(heading < 0.09, "mean heading {heading:.3} rad");
        let mut plain = vec![Pose2::new(2.1, 2.0, 0.1); 1_000];
        metropolis_walk(&mut rng, &mut plain, flat).unwrap();
        assert!(mean_distance(&plain) > 0.1, "{:.3}", mean_distance(&plain));
        // The copies are copies no longer.
        let distinct = at.iter().filter(|p| p.x != 2.1).count();
        assert!(distinct > 900, "{distinct} moved");
    }

    #[test]
    fn the_walk_does_not_leave_a_peak_it_is_on() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut at = vec![Pose2::new(2.0, 2.0, 0.0); 1_000];
        metropolis_walk(&mut rng, &mut at, peaked(0.01)).unwrap();
        // The walk samples the peak's own spread (1 cm), not its steps' (2 cm
        // a step, 4 cm after four).
        let distance = mean_distance(&at);
        assert!(distance < 0.015, "mean distance {distance:.3} m");
        // A flat likelihood accepts every step: a plain random walk.
        let mut wandered = vec![Pose2::new(2.0, 2.0, 0.0); 1_000];
        metropolis_walk(&mut rng, &mut wandered, flat).unwrap();
        let spread = mean_distance(&wandered);
        assert!(
            (0.04..0.06).contains(&spread),
            "mean distance {spread:.3} m"
        );
    }

    #[test]
    fn the_kernel_is_the_members_spread_times_the_bandwidth() {
        let particles: Vec<Pose2> = [-0.1, 0.1]
            .iter()
            .map(|&d| Pose2::new(1.0 + d, 2.0 - d, d))
            .collect();
        let spread = kernel_spread(&particles, &[0.5, 0.5], &[0, 1], 300);
        let bandwidth = (4.0f64 / 1500.0).powf(1.0 / 7.0);
        assert_abs_diff_eq!(bandwidth, 0.429, epsilon = 1e-3);
        for s in spread {
            assert_abs_diff_eq!(s, 0.1 * bandwidth, epsilon = 1e-12);
        }
        assert_eq!(
            kernel_spread(&particles, &[0.0, 0.0], &[0, 1], 300),
            [0.0; 3]
        );
    }

    /// An empty map but for one tile of free space to inject into.
    fn map_with_free_tile() -> LocalMap {
        let mut map = empty_map();
        let size = TileSize::new(64).unwrap();
        let key = TileKey::new(-1, -1);
        let free = deog_grid::TileDelta::from_raw(key, size, vec![-2000; size.area()]).unwrap();
        let mut tile = deog_grid::Tile::unknown(size);
        tile.apply(&free, deog_grid::ClampLimits::default())
            .unwrap();
        map.insert_tile(key, 1, Some(&tile)).unwrap();
        map
    }

    #[test]
    fn a_settled_filter_trickles_and_a_large_drop_searches() {
        let map = map_with_free_tile();
        let settled = || {
            let mut mcl = two_modes(0, 0.0);
            mcl.cluster = heaviest_cluster(&mcl.particles, &mcl.weights, mcl.settings.bins);
            assert!(mcl.settled());
            mcl
        };
        // A dip of the fit: the injected share comes on top of the draws.
        let mut mcl = settled();
        let clusters = cluster_particles(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
        let injected = mcl.resample(&map, 0.3, &clusters).unwrap();
        let drawn = mcl.particles.len() - injected;
        let share = injected as f64 / mcl.particles.len() as f64;
        assert!(
            (0.2..0.4).contains(&share),
            "{injected} of {}",
            mcl.particles.len()
        );
        assert!(drawn < 2_000, "{drawn} drawn");
        assert!(mcl.history.is_none(), "a trickle is no search");
        // A large drop searches: the injected particles' bins call for
        // the most particles allowed, and the modes it finds are weighed
        // by the frames from here on.
        let mut mcl = settled();
        let injected = mcl.resample(&map, 0.6, &clusters).unwrap();
        assert!(injected > 5_000, "{injected} injected");
        assert_eq!(mcl.history.as_ref().map(Vec::len), Some(0));
    }

    #[test]
    fn only_a_drop_past_the_threshold_injects() {
        let mut mcl = Mcl::new(FilterSettings::default()).unwrap();
        mcl.w_slow = 1.0;
        for (fast, share) in [(1.1, 0.0), (0.9, 0.0), (0.8, 0.0), (0.5, 0.5), (0.1, 0.9)] {
            mcl.w_fast = fast;
            assert_abs_diff_eq!(mcl.injection_share(), share, epsilon = 1e-12);
        }
        mcl.settings.recovery_threshold = 0.0;
        mcl.w_fast = 0.9;
        assert_abs_diff_eq!(mcl.injection_share(), 0.1, epsilon = 1e-12);
    }

    #[test]
    fn a_mode_with_more_weight_than_particles_stays_the_estimate() {
        // 50 particles holding 70 % of the weight against 2,000 holding
        // 30 %: resampling must not hand the estimate to the crowd.
        let map = empty_map();
        let mut mcl = two_modes(50, 0.7);
        for _ in 0..5 {
            resample_once(&mut mcl, &map);
            let best = heaviest_cluster(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
            assert_abs_diff_eq!(best.pose.x, 2.0, epsilon = 0.05);
            assert_abs_diff_eq!(best.weight, 0.7, epsilon = 1e-9);
        }
    }

    #[test]
    fn a_light_mode_keeps_its_floor_when_recovery_fills_the_set() {
        // Free space to inject into, away from both modes: half of each
        // resampling comes from it, and KLD-sampling's bound for all the
        // bins injected particles open is the most particles allowed.
        let map = map_with_free_tile();
        let mut mcl = two_modes(40, 0.002);
        let clusters = cluster_particles(&mcl.particles, &mcl.weights, mcl.settings.bins).unwrap();
        let injected = mcl.resample(&map, 0.5, &clusters).unwrap();
        assert!(injected > 5_000, "{injected} injected");
        let light = mcl
            .particles
            .iter()
            .filter(|p| (p.x - 2.0).abs() < 0.5 && (p.y - 2.0).abs() < 0.5)
            .count();
        assert!(
            light >= mcl.settings.cluster_min_particles,
            "the light mode has {light} particles"
        );
        assert!(mcl.particles.len() <= mcl.settings.kld.max_particles);
    }

    #[test]
    fn a_mode_below_the_keep_weight_gets_no_floor() {
        let map = empty_map();
        let mut mcl = two_modes(40, 1e-8);
        resample_once(&mut mcl, &map);
        let (_, count) = light_mode(&mcl);
        assert!(count < 10, "the negligible mode kept {count} particles");
    }
}
