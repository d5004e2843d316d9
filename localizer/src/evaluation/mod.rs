//! Localization accuracy from true poses and estimates: a robot's true
//! poses (the simulator's, the thesis's `gs()`) against a localizer's
//! estimates, frame by frame, as in the thesis's section 7.4 and its
//! Tables 7.3 to 7.7, with convergence and kidnap recovery added.
//!
//! # Layout
//! - this file: the inputs, the definitions below, [`evaluate`] and the
//!   [`LocalizationReport`] it returns;
//! - `report`: the report as a markdown table ([`LocalizationReport::table`])
//!   and as JSON ([`LocalizationReport::to_json`], [`reports_to_json`]);
//! - [`plot`]: the true path against the estimated one, as a PNG.
//!
//! # Inputs
//! - **Truth** ([`TruthSample`]): the frames that carry a true pose,
//!   sequence strictly increasing, time never decreasing.
//! - **Estimates** ([`EstimateSample`]): the localizer's poses, sequence
//!   (of the frame each follows) strictly increasing.
//!
//! An estimate is **paired** with the truth sample of the same sequence;
//! an estimate without one is counted and otherwise ignored. Truth samples
//! after the last paired estimate's frame are dropped: the localizer had
//! stopped, and a kidnap there could not be recovered from. Those before
//! the first estimate stay, so the localizer's start-up counts toward its
//! convergence time (pass a later first frame to leave it out).
//!
//! # Definitions
//! - **Error** of a paired estimate: estimate minus truth, signed: `x` and
//!   `y` in metres (world frame), `theta` in radians normalised to
//!   (-π, π], so 179° against -179° is an error of -2°. The **position
//!   error** is `hypot(x, y)`.
//! - **Within the bounds**: position error ≤ `converge_m` and
//!   |theta error| ≤ `converge_rad` (defaults 0.25 m and 0.25 rad).
//! - **Kidnap**: a jump between consecutive truth samples `a`, `b` that
//!   driving cannot explain. With `dt = b.time - a.time`: the distance is
//!   more than `kidnap_jump_m + max_speed_mps · dt`, or the heading change
//!   (normalised) is more than `kidnap_turn_rad + max_turn_rate_rad_s · dt`
//!   (defaults 0.5 m, 45°, and the simulated Scout's limits, 1 m/s and
//!   π/2 rad/s). The kidnap happens at `b`: its sequence and time are
//!   `b`'s.
//! - **Segments**: the kidnaps cut the run in segments: the first from the
//!   first truth sample, each further one from a kidnap's `b` up to the
//!   next kidnap or the end. An estimate belongs to its frame's segment.
//! - **Settling** of a segment: its first paired estimate from which every
//!   paired estimate of the segment is within the bounds (the start of the
//!   segment's trailing run of estimates within the bounds). A segment
//!   whose last estimate is outside the bounds, or that has none, does not
//!   settle.
//! - **Convergence**: the earliest settling of any segment (normally the
//!   first segment's; a later one's when the robot was kidnapped before
//!   the filter ever settled). `converge_s` is its frame's time minus the
//!   first truth sample's time; `converge_distance_m` the path the robot
//!   drove from the first truth sample to that frame: the sum of the
//!   straight steps between consecutive truth samples, kidnap jumps left
//!   out. Not converged when no segment settles.
//! - **Recovery** of a kidnap: the settling of the segment the kidnap
//!   starts. `recover_s` is its time minus the kidnap's time,
//!   `recover_distance_m` the path driven in between. A kidnap whose
//!   segment does not settle is not recovered.
//! - **Used estimates**: each settled segment's estimates from its
//!   settling on. So everything before the convergence, and the time from
//!   each kidnap to its recovery (the whole segment if it never
//!   recovers), are left out. Every used estimate is within the bounds by
//!   construction: the figures describe tracking once localized, which is
//!   what the thesis's tables report.
//! - **Figures** ([`ErrorStats`]) over the `n` used estimates, for `x`,
//!   `y` and `theta`: the mean absolute error `Σ|e| / n` (the thesis's
//!   "mean error"), the standard deviation of the signed error (population
//!   form, `sqrt(Σ(e - ē)² / n)`, 0 for one estimate) and the mean signed
//!   error `ē` (the bias); in metres and inches (0.0254 m), radians and
//!   degrees. `rms_position_m = sqrt(Σ(x² + y²) / n)`; `max_position_m`
//!   the largest position error. Used theta errors lie within
//!   ±`converge_rad` ≤ π, so their plain mean is meaningful. No used
//!   estimate: no figures.
//! - **Per robot**: `kidnapped` when there is at least one kidnap;
//!   `recovered` when every kidnap was recovered from (undefined without a
//!   kidnap); `recover_s` the longest recovery (undefined without a kidnap
//!   or when one was not recovered from).
//! - **Filter claims**: of the paired estimates, those the filter flagged
//!   as converged, and how many of them were within the bounds: whether
//!   its own confidence can be trusted.
//!
//! Figures that do not exist are `None`, `null` in JSON, never NaN.
//!
//! # Errors
//! Bad parameters, non-finite poses, sequences out of order, no truth, no
//! estimate, or no estimate for a frame with a true pose: each an
//! [`EvaluationError`] naming the field or the robot.
//!
//! # Example
//! A robot driving along x, an estimate 0.1 m ahead of it at every frame:
//! ```
//! use deog_grid::Pose2;
//! use deog_localizer::evaluation::{EstimateSample, EvalInput, TruthSample, evaluate};
//!
//! let truth: Vec<TruthSample> = (1..=10)
//!     .map(|s| TruthSample::new(s, s as f64 * 0.1, Pose2::new(s as f64 * 0.05, 0.0, 0.0)))
//!     .collect();
//! let estimates: Vec<EstimateSample> = truth
//!     .iter()
//!     .map(|t| EstimateSample::new(t.sequence, Pose2::new(t.pose.x + 0.1, 0.0, 0.0)))
//!     .collect();
//! let report = evaluate(&EvalInput::new("scout", &truth, &estimates))?;
//! assert_eq!(report.converge_s(), Some(0.0));
//! let stats = report.stats.expect("figures");
//! assert!((stats.x_m.mean_abs - 0.1).abs() < 1e-12 && stats.x_m.std_dev < 1e-12);
//! # Ok::<(), deog_localizer::evaluation::EvaluationError>(())
//! ```

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use deog_grid::{Pose2, normalize_angle};
use thiserror::Error;

pub mod plot;
mod report;

pub use plot::{PlotInput, Raster, RobotPath, render_plot};
pub use report::reports_to_json;

/// Metres in an inch, for the thesis's units.
pub const METRES_PER_INCH: f64 = 0.0254;
/// Default largest position error of a settled estimate, metres.
pub const DEFAULT_CONVERGE_M: f64 = 0.25;
/// Default largest heading error of a settled estimate, radians.
pub const DEFAULT_CONVERGE_RAD: f64 = 0.25;
/// Default jump between consecutive frames, beyond what driving explains,
/// that counts as a kidnap, metres.
pub const DEFAULT_KIDNAP_JUMP_M: f64 = 0.5;
/// Default heading change between consecutive frames, beyond what turning
/// explains, that counts as a kidnap, radians (45°).
pub const DEFAULT_KIDNAP_TURN_RAD: f64 = FRAC_PI_4;
/// Default top speed of the robot, metres per second: the simulated
/// Scout's limit.
pub const DEFAULT_MAX_SPEED_MPS: f64 = 1.0;
/// Default top turn rate of the robot, radians per second: the simulated
/// Scout's limit.
pub const DEFAULT_MAX_TURN_RATE_RAD_S: f64 = FRAC_PI_2;

/// Why an evaluation could not be made. Each variant names the offending
/// field or robot.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EvaluationError {
    /// A parameter or an input sample is unusable.
    #[error("{field}: {reason}")]
    Invalid {
        /// The parameter or sample, e.g. `converge_m`, `truth[3].pose`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// There is nothing to evaluate.
    #[error("robot {robot}: {reason}")]
    NoData {
        /// The robot evaluated.
        robot: String,
        /// What is missing.
        reason: String,
    },
    /// The plot could not be drawn or encoded.
    #[error("plot: {0}")]
    Plot(String),
}

impl EvaluationError {
    fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }

    fn no_data(robot: &str, reason: impl Into<String>) -> Self {
        Self::NoData {
            robot: robot.to_string(),
            reason: reason.into(),
        }
    }
}

/// A frame's true pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSample {
    /// The frame's sequence number.
    pub sequence: u64,
    /// The frame's time, seconds.
    pub time_s: f64,
    /// The true pose: metres, world frame; radians, counter-clockwise
    /// from +x.
    pub pose: Pose2,
}

impl TruthSample {
    /// A sample from its parts.
    pub const fn new(sequence: u64, time_s: f64, pose: Pose2) -> Self {
        Self {
            sequence,
            time_s,
            pose,
        }
    }
}

/// A localizer's estimate for a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateSample {
    /// Sequence number of the frame the estimate follows.
    pub sequence: u64,
    /// The estimated pose: metres, world frame; radians, counter-clockwise
    /// from +x.
    pub pose: Pose2,
    /// Whether the filter said it had converged.
    pub filter_converged: bool,
}

impl EstimateSample {
    /// An estimate the filter did not flag as converged.
    pub const fn new(sequence: u64, pose: Pose2) -> Self {
        Self {
            sequence,
            pose,
            filter_converged: false,
        }
    }
}

/// The bounds and limits of the definitions in the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalParams {
    /// Largest position error within the bounds, metres, > 0.
    pub converge_m: f64,
    /// Largest heading error within the bounds, radians, in (0, π].
    pub converge_rad: f64,
    /// Unexplained jump that makes a kidnap, metres, > 0.
    pub kidnap_jump_m: f64,
    /// Unexplained heading change that makes a kidnap, radians, in (0, π].
    pub kidnap_turn_rad: f64,
    /// The robot's top speed, metres per second, ≥ 0: how far driving
    /// explains a jump.
    pub max_speed_mps: f64,
    /// The robot's top turn rate, radians per second, ≥ 0.
    pub max_turn_rate_rad_s: f64,
}

impl Default for EvalParams {
    fn default() -> Self {
        Self {
            converge_m: DEFAULT_CONVERGE_M,
            converge_rad: DEFAULT_CONVERGE_RAD,
            kidnap_jump_m: DEFAULT_KIDNAP_JUMP_M,
            kidnap_turn_rad: DEFAULT_KIDNAP_TURN_RAD,
            max_speed_mps: DEFAULT_MAX_SPEED_MPS,
            max_turn_rate_rad_s: DEFAULT_MAX_TURN_RATE_RAD_S,
        }
    }
}

/// Largest accepted distance parameter, metres (and speed, m/s).
const MAX_DISTANCE_M: f64 = 1.0e6;

impl EvalParams {
    /// Checks every parameter is finite and within its range.
    pub fn validate(&self) -> Result<(), EvaluationError> {
        let positive = [
            ("converge_m", self.converge_m, MAX_DISTANCE_M),
            ("converge_rad", self.converge_rad, PI),
            ("kidnap_jump_m", self.kidnap_jump_m, MAX_DISTANCE_M),
            ("kidnap_turn_rad", self.kidnap_turn_rad, PI),
        ];
        for (field, value, max) in positive {
            if !(value.is_finite() && value > 0.0 && value <= max) {
                return Err(EvaluationError::invalid(
                    field,
                    format!("must be above 0 and at most {max}, got {value}"),
                ));
            }
        }
        let limits = [
            ("max_speed_mps", self.max_speed_mps),
            ("max_turn_rate_rad_s", self.max_turn_rate_rad_s),
        ];
        for (field, value) in limits {
            if !(value.is_finite() && (0.0..=MAX_DISTANCE_M).contains(&value)) {
                return Err(EvaluationError::invalid(
                    field,
                    format!("must be within 0 to {MAX_DISTANCE_M}, got {value}"),
                ));
            }
        }
        Ok(())
    }
}

/// What to evaluate.
#[derive(Debug, Clone, Copy)]
pub struct EvalInput<'a> {
    /// The robot's name, for the report and errors.
    pub robot: &'a str,
    /// The map the estimates are on, when the caller chose one (reported
    /// only).
    pub map: Option<&'a str>,
    /// The frames with a true pose.
    pub truth: &'a [TruthSample],
    /// The localizer's estimates.
    pub estimates: &'a [EstimateSample],
    /// Bounds and limits.
    pub params: EvalParams,
}

impl<'a> EvalInput<'a> {
    /// `estimates` against `truth` for `robot`, on no named map, with the
    /// default parameters.
    pub fn new(
        robot: &'a str,
        truth: &'a [TruthSample],
        estimates: &'a [EstimateSample],
    ) -> Self {
        Self {
            robot,
            map: None,
            truth,
            estimates,
            params: EvalParams::default(),
        }
    }
}

/// The moment a segment settled (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settling {
    /// Sequence of the settling estimate's frame.
    pub sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// Seconds from the start (first frame, or the kidnap) to it.
    pub after_s: f64,
    /// Metres driven from the start to it, kidnap jumps left out.
    pub distance_m: f64,
}

/// A kidnap found in the true poses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kidnap {
    /// Sequence of the last frame before the jump.
    pub sequence_before: u64,
    /// Sequence of the first frame after it: where the kidnap happens.
    pub sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// True pose before the jump.
    pub from: Pose2,
    /// True pose after it.
    pub to: Pose2,
    /// Distance jumped, metres.
    pub jump_m: f64,
    /// Heading change, radians, in (-π, π].
    pub turn_rad: f64,
    /// When the estimate settled again; `None` if it never did.
    pub recovery: Option<Settling>,
}

/// Mean absolute error, mean signed error and the standard deviation of
/// the signed error along one axis, in the axis's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisStats {
    /// Mean of |error|.
    pub mean_abs: f64,
    /// Mean of the signed error (the bias).
    pub mean: f64,
    /// Population standard deviation of the signed error.
    pub std_dev: f64,
}

impl AxisStats {
    /// The figures of a non-empty set of errors; `None` for an empty one.
    fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let mean_abs = values.iter().map(|v| v.abs()).sum::<f64>() / n;
        let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        Some(Self {
            mean_abs,
            mean,
            std_dev: variance.sqrt(),
        })
    }

    /// The same figures multiplied by `factor` (> 0): a change of unit.
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            mean_abs: self.mean_abs * factor,
            mean: self.mean * factor,
            std_dev: self.std_dev * factor,
        }
    }
}

/// The thesis's table, over the used estimates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// Used estimates.
    pub count: u64,
    /// x error, metres.
    pub x_m: AxisStats,
    /// y error, metres.
    pub y_m: AxisStats,
    /// Heading error, radians.
    pub theta_rad: AxisStats,
    /// Root mean square of the position error, metres.
    pub rms_position_m: f64,
    /// Largest position error, metres.
    pub max_position_m: f64,
}

/// How well a localizer followed one robot; definitions in the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizationReport {
    /// The robot.
    pub robot: String,
    /// The map the estimates were taken from, if one was chosen.
    pub map: Option<String>,
    /// The bounds and limits used.
    pub params: EvalParams,
    /// Truth samples judged (up to the last paired estimate's frame).
    pub frames: u64,
    /// Truth samples dropped because they come after the last paired
    /// estimate.
    pub frames_after_last_estimate: u64,
    /// Estimates given.
    pub estimates: u64,
    /// Of those, the ones paired with a truth sample.
    pub estimates_paired: u64,
    /// Of those, the ones within the bounds.
    pub estimates_within_bounds: u64,
    /// Paired estimates the filter flagged as converged.
    pub filter_converged: u64,
    /// Of those, the ones within the bounds.
    pub filter_converged_within_bounds: u64,
    /// Time of the first truth sample, seconds.
    pub start_time_s: f64,
    /// Time of the last truth sample judged, seconds.
    pub end_time_s: f64,
    /// The first settling; `None` if the estimate never settled.
    pub convergence: Option<Settling>,
    /// The kidnaps, in order.
    pub kidnaps: Vec<Kidnap>,
    /// The figures over the used estimates; `None` when none was used.
    pub stats: Option<ErrorStats>,
}

impl LocalizationReport {
    /// Whether the estimate ever settled.
    pub fn converged(&self) -> bool {
        self.convergence.is_some()
    }

    /// Seconds from the first frame to the convergence.
    pub fn converge_s(&self) -> Option<f64> {
        self.convergence.map(|c| c.after_s)
    }

    /// Whether the robot was kidnapped at least once.
    pub fn kidnapped(&self) -> bool {
        !self.kidnaps.is_empty()
    }

    /// Whether every kidnap was recovered from; `None` without a kidnap.
    pub fn recovered(&self) -> Option<bool> {
        self.kidnapped()
            .then(|| self.kidnaps.iter().all(|k| k.recovery.is_some()))
    }

    /// The longest recovery, seconds; `None` without a kidnap or when one
    /// was not recovered from.
    pub fn recover_s(&self) -> Option<f64> {
        if !self.recovered()? {
            return None;
        }
        self.kidnaps
            .iter()
            .filter_map(|k| k.recovery.map(|r| r.after_s))
            .reduce(f64::max)
    }
}

/// One paired estimate: its truth sample's index, its error, and the
/// filter's flag.
#[derive(Debug, Clone, Copy)]
struct Paired {
    truth: usize,
    x: f64,
    y: f64,
    theta: f64,
    filter_converged: bool,
}

impl Paired {
    fn position(&self) -> f64 {
        self.x.hypot(self.y)
    }

    fn within(&self, params: &EvalParams) -> bool {
        self.position() <= params.converge_m && self.theta.abs() <= params.converge_rad
    }
}

/// Judges `input.estimates` against `input.truth`; every definition is in
/// the [module docs](self).
pub fn evaluate(input: &EvalInput<'_>) -> Result<LocalizationReport, EvaluationError> {
    let params = input.params;
    params.validate()?;
    let robot = input.robot;
    let on_map = input.map.map_or_else(String::new, |m| format!(" on map {m}"));
    if input.truth.is_empty() {
        return Err(EvaluationError::no_data(
            robot,
            "no frame with a true pose to judge the estimates against",
        ));
    }
    if input.estimates.is_empty() {
        return Err(EvaluationError::no_data(
            robot,
            format!("no pose estimate{on_map} to judge"),
        ));
    }
    check_truth(input.truth)?;
    check_estimates(input.estimates)?;

    let paired = pair(input.truth, input.estimates);
    let Some(last) = paired.last() else {
        return Err(EvaluationError::no_data(
            robot,
            format!(
                "none of the {} estimates{on_map} (frames {} to {}) is for one of the {} \
                 frames with a true pose (frames {} to {})",
                input.estimates.len(),
                input.estimates[0].sequence,
                input.estimates[input.estimates.len() - 1].sequence,
                input.truth.len(),
                input.truth[0].sequence,
                input.truth[input.truth.len() - 1].sequence,
            ),
        ));
    };
    let truth = &input.truth[..=last.truth];

    // Path driven up to each sample, and where the kidnaps start segments.
    let mut driven = Vec::with_capacity(truth.len());
    driven.push(0.0);
    let mut kidnap_starts = Vec::new();
    for (i, pair) in truth.windows(2).enumerate() {
        let (a, b) = (&pair[0], &pair[1]);
        let dt = b.time_s - a.time_s;
        let jump = (b.pose.x - a.pose.x).hypot(b.pose.y - a.pose.y);
        let turn = normalize_angle(b.pose.theta - a.pose.theta).abs();
        let teleported = jump > params.kidnap_jump_m + params.max_speed_mps * dt
            || turn > params.kidnap_turn_rad + params.max_turn_rate_rad_s * dt;
        if teleported {
            kidnap_starts.push(i + 1);
        }
        driven.push(driven[i] + if teleported { 0.0 } else { jump });
    }

    // Each segment's paired estimates (contiguous: both lists are sorted by
    // sequence) and its settling, as an index into `paired`.
    let mut segment_starts = vec![0];
    segment_starts.extend_from_slice(&kidnap_starts);
    let mut settlings: Vec<Option<usize>> = Vec::with_capacity(segment_starts.len());
    let mut used: Vec<&Paired> = Vec::new();
    for (s, &start) in segment_starts.iter().enumerate() {
        let end = segment_starts.get(s + 1).copied().unwrap_or(truth.len());
        let lo = paired.partition_point(|p| p.truth < start);
        let hi = paired.partition_point(|p| p.truth < end);
        let settle = paired[lo..hi]
            .iter()
            .rposition(|p| !p.within(&params))
            .map_or(lo, |bad| lo + bad + 1);
        let settle = (settle < hi).then_some(settle);
        if let Some(first) = settle {
            used.extend(&paired[first..hi]);
        }
        settlings.push(settle);
    }

    let settling_from = |start: usize, index: usize| {
        let sample = &truth[paired[index].truth];
        Settling {
            sequence: sample.sequence,
            time_s: sample.time_s,
            after_s: sample.time_s - truth[start].time_s,
            distance_m: driven[paired[index].truth] - driven[start],
        }
    };
    let convergence = settlings
        .iter()
        .flatten()
        .next()
        .map(|&index| settling_from(0, index));
    let kidnaps = kidnap_starts
        .iter()
        .enumerate()
        .map(|(k, &start)| {
            let (a, b) = (&truth[start - 1], &truth[start]);
            Kidnap {
                sequence_before: a.sequence,
                sequence: b.sequence,
                time_s: b.time_s,
                from: a.pose,
                to: b.pose,
                jump_m: (b.pose.x - a.pose.x).hypot(b.pose.y - a.pose.y),
                turn_rad: normalize_angle(b.pose.theta - a.pose.theta),
                recovery: settlings[k + 1].map(|index| settling_from(start, index)),
            }
        })
        .collect();

    let within = paired.iter().filter(|p| p.within(&params)).count();
    let claimed = paired.iter().filter(|p| p.filter_converged);
    Ok(LocalizationReport {
        robot: robot.to_string(),
        map: input.map.map(str::to_string),
        params,
        frames: truth.len() as u64,
        frames_after_last_estimate: (input.truth.len() - truth.len()) as u64,
        estimates: input.estimates.len() as u64,
        estimates_paired: paired.len() as u64,
        estimates_within_bounds: within as u64,
        filter_converged: claimed.clone().count() as u64,
        filter_converged_within_bounds: claimed.filter(|p| p.within(&params)).count() as u64,
        start_time_s: truth[0].time_s,
        end_time_s: truth[truth.len() - 1].time_s,
        convergence,
        kidnaps,
        stats: error_stats(&used),
    })
}

/// The figures over `used`; `None` when it is empty.
fn error_stats(used: &[&Paired]) -> Option<ErrorStats> {
    let xs: Vec<f64> = used.iter().map(|p| p.x).collect();
    let ys: Vec<f64> = used.iter().map(|p| p.y).collect();
    let thetas: Vec<f64> = used.iter().map(|p| p.theta).collect();
    let n = used.len() as f64;
    let square_sum: f64 = used.iter().map(|p| p.x * p.x + p.y * p.y).sum();
    Some(ErrorStats {
        count: used.len() as u64,
        x_m: AxisStats::of(&xs)?,
        y_m: AxisStats::of(&ys)?,
        theta_rad: AxisStats::of(&thetas)?,
        rms_position_m: (square_sum / n).sqrt(),
        max_position_m: used.iter().map(|p| p.position()).fold(0.0, f64::max),
    })
}

/// Each estimate with the truth sample of its frame, when there is one;
/// sorted by sequence as the estimates are.
fn pair(truth: &[TruthSample], estimates: &[EstimateSample]) -> Vec<Paired> {
    estimates
        .iter()
        .filter_map(|e| {
            let index = truth
                .binary_search_by_key(&e.sequence, |t| t.sequence)
                .ok()?;
            let t = &truth[index].pose;
            Some(Paired {
                truth: index,
                x: e.pose.x - t.x,
                y: e.pose.y - t.y,
                theta: normalize_angle(e.pose.theta - t.theta),
                filter_converged: e.filter_converged,
            })
        })
        .collect()
}

fn check_pose(field: String, pose: &Pose2) -> Result<(), EvaluationError> {
    if pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite() {
        Ok(())
    } else {
        Err(EvaluationError::invalid(
            field,
            format!(
                "must be finite, got ({}, {}, {})",
                pose.x, pose.y, pose.theta
            ),
        ))
    }
}

fn check_truth(truth: &[TruthSample]) -> Result<(), EvaluationError> {
    for (i, t) in truth.iter().enumerate() {
        check_pose(format!("truth[{i}].pose"), &t.pose)?;
        if !t.time_s.is_finite() {
            return Err(EvaluationError::invalid(
                format!("truth[{i}].time_s"),
                format!("must be finite, got {}", t.time_s),
            ));
        }
        if i > 0 {
            let before = &truth[i - 1];
            if t.sequence <= before.sequence {
                return Err(EvaluationError::invalid(
                    format!("truth[{i}].sequence"),
                    format!(
                        "must be after the one before, got {} after {}",
                        t.sequence, before.sequence
                    ),
                ));
            }
            if t.time_s < before.time_s {
                return Err(EvaluationError::invalid(
                    format!("truth[{i}].time_s"),
                    format!(
                        "must not go back, got {} after {} (frame {})",
                        t.time_s, before.time_s, t.sequence
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn check_estimates(estimates: &[EstimateSample]) -> Result<(), EvaluationError> {
    for (i, e) in estimates.iter().enumerate() {
        check_pose(format!("estimates[{i}].pose"), &e.pose)?;
        if i > 0 && e.sequence <= estimates[i - 1].sequence {
            return Err(EvaluationError::invalid(
                format!("estimates[{i}].sequence"),
                format!(
                    "must be after the one before, got {} after {}",
                    e.sequence,
                    estimates[i - 1].sequence
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
