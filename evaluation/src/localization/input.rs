//! What is judged: true poses, estimates, the bounds, and the checks
//! that make bad input an error rather than a wrong figure.

use std::f64::consts::PI;

use deog_grid::Pose2;

use super::{
    DEFAULT_CONVERGE_M, DEFAULT_CONVERGE_RAD, DEFAULT_KIDNAP_JUMP_M, DEFAULT_KIDNAP_TURN_RAD,
    DEFAULT_MAX_SPEED_MPS, DEFAULT_MAX_TURN_RATE_RAD_S, EvaluationError,
};

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
    /// The frame's odometry pose, when it has one: a jump of the true
    /// pose that the odometry does not make is a kidnap, however short
    /// the time between the frames.
    pub odometry: Option<Pose2>,
}

impl TruthSample {
    /// A sample from its parts, without odometry.
    pub const fn new(sequence: u64, time_s: f64, pose: Pose2) -> Self {
        Self {
            sequence,
            time_s,
            pose,
            odometry: None,
        }
    }

    /// The sample with the frame's odometry pose.
    pub const fn with_odometry(mut self, odometry: Option<Pose2>) -> Self {
        self.odometry = odometry;
        self
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

/// The bounds and limits of the definitions in the [module docs](super).
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
    /// Kidnaps the caller made and so knows of, each as the sequence of
    /// the first frame after it: they start segments even when the jump
    /// is too short to tell from driving.
    pub known_kidnaps: &'a [u64],
}

impl<'a> EvalInput<'a> {
    /// `estimates` against `truth` for `robot`, on no named map, with the
    /// default parameters.
    pub fn new(robot: &'a str, truth: &'a [TruthSample], estimates: &'a [EstimateSample]) -> Self {
        Self {
            robot,
            map: None,
            truth,
            estimates,
            params: EvalParams::default(),
            known_kidnaps: &[],
        }
    }
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

pub(super) fn check_truth(truth: &[TruthSample]) -> Result<(), EvaluationError> {
    for (i, t) in truth.iter().enumerate() {
        check_pose(format!("truth[{i}].pose"), &t.pose)?;
        if let Some(odometry) = &t.odometry {
            check_pose(format!("truth[{i}].odometry"), odometry)?;
        }
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

pub(super) fn check_estimates(estimates: &[EstimateSample]) -> Result<(), EvaluationError> {
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
