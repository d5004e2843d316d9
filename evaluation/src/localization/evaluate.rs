//! [`evaluate`]: pairing, kidnaps, segments, settling, and the figures,
//! as the [definitions](super) say.

use deog_grid::{Pose2, normalize_angle};

use super::input::{check_estimates, check_truth};
use super::{EstimateSample, EvalInput, EvalParams, EvaluationError, TruthSample};

/// The moment a segment settled (see the [module docs](super)).
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
    /// The first estimate back within the bounds, which may leave them
    /// again before the settling; `None` if none came back.
    pub first_within: Option<Settling>,
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
    /// Mean position error (`hypot(x, y)`), metres.
    pub mean_position_m: f64,
    /// Root mean square of the position error, metres.
    pub rms_position_m: f64,
    /// Largest position error, metres.
    pub max_position_m: f64,
}

/// How well a localizer followed one robot; definitions in the
/// [module docs](super).
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
    /// Of the flagged ones, those more than [`super::FALSE_CONVERGED_M`]
    /// or [`super::FALSE_CONVERGED_RAD`] off: false convergence.
    pub false_converged: u64,
    /// Time of the first truth sample, seconds.
    pub start_time_s: f64,
    /// Time of the last truth sample judged, seconds.
    pub end_time_s: f64,
    /// The first settling; `None` if the estimate never settled.
    pub convergence: Option<Settling>,
    /// The first estimate within the bounds before any kidnap, which may
    /// leave them again before the settling; `None` if none was within.
    pub first_within: Option<Settling>,
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

    /// Seconds from the first frame to the first estimate within the
    /// bounds, before any kidnap; `None` if none was.
    pub fn first_within_s(&self) -> Option<f64> {
        self.first_within.map(|c| c.after_s)
    }

    /// The longest time from a kidnap to the first estimate back within
    /// the bounds; `None` without a kidnap or when one never came back.
    pub fn first_back_s(&self) -> Option<f64> {
        if !self.kidnapped() {
            return None;
        }
        self.kidnaps
            .iter()
            .map(|k| k.first_within.map(|r| r.after_s))
            .collect::<Option<Vec<_>>>()?
            .into_iter()
            .reduce(f64::max)
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

    fn falsely_converged(&self) -> bool {
        self.filter_converged
            && (self.position() > super::FALSE_CONVERGED_M
                || self.theta.abs() > super::FALSE_CONVERGED_RAD)
    }

    fn within(&self, params: &EvalParams) -> bool {
        self.position() <= params.converge_m && self.theta.abs() <= params.converge_rad
    }
}

/// Judges `input.estimates` against `input.truth`; every definition is in
/// the [module docs](super).
pub fn evaluate(input: &EvalInput<'_>) -> Result<LocalizationReport, EvaluationError> {
    let params = input.params;
    params.validate()?;
    let robot = input.robot;
    let on_map = input
        .map
        .map_or_else(String::new, |m| format!(" on map {m}"));
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
        let jump = (b.pose.x - a.pose.x).hypot(b.pose.y - a.pose.y);
        let teleported = unexplained(a, b, &params);
        let known = input
            .known_kidnaps
            .iter()
            .any(|&k| a.sequence < k && k <= b.sequence);
        if teleported || known {
            kidnap_starts.push(i + 1);
        }
        driven.push(driven[i] + if teleported || known { 0.0 } else { jump });
    }

    // Each segment's paired estimates (contiguous: both lists are sorted by
    // sequence) and its settling, as an index into `paired`.
    let mut segment_starts = vec![0];
    segment_starts.extend_from_slice(&kidnap_starts);
    let mut settlings: Vec<Option<usize>> = Vec::with_capacity(segment_starts.len());
    let mut firsts: Vec<Option<usize>> = Vec::with_capacity(segment_starts.len());
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
        firsts.push(
            paired[lo..hi]
                .iter()
                .position(|p| p.within(&params))
                .map(|first| lo + first),
        );
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
    // Of the segment before any kidnap, as the convergence (which is the
    // first segment that settled) mostly is.
    let first_within = firsts[0].map(|index| settling_from(0, index));
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
                first_within: firsts[k + 1].map(|index| settling_from(start, index)),
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
        false_converged: paired.iter().filter(|p| p.falsely_converged()).count() as u64,
        start_time_s: truth[0].time_s,
        end_time_s: truth[truth.len() - 1].time_s,
        convergence,
        first_within,
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
        mean_position_m: used.iter().map(|p| p.position()).sum::<f64>() / n,
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

/// Share of the odometry's step its slip may add to the jump and the turn
/// that driving explains.
const ODOMETRY_SLIP: f64 = 0.2;

/// Whether the true pose's step from `a` to `b` is more than driving
/// explains: with both frames' odometry, a step the odometry does not
/// make (the true pose's move in `a`'s frame against the odometry's,
/// beyond `kidnap_jump_m` and `kidnap_turn_rad` plus a fifth of the
/// odometry's own move for slip); without it, more than the robot's top
/// speed and turn rate make in the time between them.
fn unexplained(a: &TruthSample, b: &TruthSample, params: &EvalParams) -> bool {
    if let (Some(from), Some(to)) = (a.odometry, b.odometry) {
        let truth = relative(&a.pose, &b.pose);
        let odometry = relative(&from, &to);
        let jump = (truth.x - odometry.x).hypot(truth.y - odometry.y);
        let turn = normalize_angle(truth.theta - odometry.theta).abs();
        let moved = odometry.x.hypot(odometry.y);
        return jump > params.kidnap_jump_m + ODOMETRY_SLIP * moved
            || turn > params.kidnap_turn_rad + ODOMETRY_SLIP * odometry.theta.abs();
    }
    let dt = b.time_s - a.time_s;
    let jump = (b.pose.x - a.pose.x).hypot(b.pose.y - a.pose.y);
    let turn = normalize_angle(b.pose.theta - a.pose.theta).abs();
    jump > params.kidnap_jump_m + params.max_speed_mps * dt
        || turn > params.kidnap_turn_rad + params.max_turn_rate_rad_s * dt
}

/// `to` in the frame of `from`.
fn relative(from: &Pose2, to: &Pose2) -> Pose2 {
    let (s, c) = from.theta.sin_cos();
    let (dx, dy) = (to.x - from.x, to.y - from.y);
    Pose2::new(
        c * dx + s * dy,
        -s * dx + c * dy,
        normalize_angle(to.theta - from.theta),
    )
}
