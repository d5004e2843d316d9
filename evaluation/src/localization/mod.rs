//! Localization accuracy from true poses and estimates: a robot's true
//! poses (the simulator's, the thesis's `gs()`) against a localizer's
//! estimates, frame by frame, as in the thesis's section 7.4 and its
//! Tables 7.3 to 7.7, with convergence and kidnap recovery added.
//!
//! # Layout
//! - this file: the definitions below, the defaults and [`EvaluationError`];
//! - `input`: what is judged: [`TruthSample`], [`EstimateSample`],
//!   [`EvalParams`], [`EvalInput`], and their checks;
//! - `evaluate`: [`evaluate`] and the [`LocalizationReport`] it returns;
//! - `report`: the report as a markdown table ([`LocalizationReport::table`])
//!   and as JSON ([`LocalizationRecord`], [`LocalizationReport::to_json`],
//!   [`reports_to_json`]);
//! - [`plot`]: the true path against the estimated one, as a PNG;
//!   `plot_path` (which estimates are joined), `plot_legend` (the legend).
//!
//! # Inputs
//! - **Truth** ([`TruthSample`]): the frames that carry a true pose,
//!   sequence strictly increasing, time never decreasing.
//! - **Estimates** ([`EstimateSample`]): the localizer's poses, sequence
//!   (of the frame each follows) strictly increasing. An estimate's time
//!   is its frame's.
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
//!   driving cannot explain. When both carry the frame's odometry pose, a
//!   step of the true pose that the odometry does not make: the true
//!   pose's move expressed in `a`'s frame, against the odometry's, differs
//!   by more than `kidnap_jump_m` plus a fifth of the odometry's distance,
//!   or turns by more than `kidnap_turn_rad` plus a fifth of the
//!   odometry's turn (a corrected log's scans a metre apart are driving;
//!   its reference pose jumping where the wheels did not is a kidnap).
//!   Without odometry, with `dt = b.time - a.time`: the distance is
//!   more than `kidnap_jump_m + max_speed_mps · dt`, or the heading change
//!   (normalised) is more than `kidnap_turn_rad + max_turn_rate_rad_s · dt`
//!   (defaults 0.5 m, 45°, and the simulated Scout's limits, 1 m/s and
//!   π/2 rad/s). Either way, a kidnap the caller knows of
//!   ([`EvalInput::known_kidnaps`]) falls after `a` and by `b`. The kidnap
//!   happens at `b`: its sequence and time are `b`'s.
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
//!   degrees. `mean_position_m = Σ hypot(x, y) / n`,
//!   `rms_position_m = sqrt(Σ(x² + y²) / n)`; `max_position_m` the
//!   largest position error. Used theta errors lie within
//!   ±`converge_rad` ≤ π, so their plain mean is meaningful. No used
//!   estimate: no figures.
//! - **Per robot**: `kidnapped` when there is at least one kidnap;
//!   `recovered` when every kidnap was recovered from (undefined without a
//!   kidnap); `recover_s` the longest recovery (undefined without a kidnap
//!   or when one was not recovered from).
//! - **Filter claims**: of the paired estimates, those the filter flagged
//!   as converged, and how many of them were within the bounds: whether
//!   its own confidence can be trusted; and **false convergence**: the
//!   flagged estimates more than [`FALSE_CONVERGED_M`] (0.5 m) or
//!   [`FALSE_CONVERGED_RAD`] (0.25 rad) from the truth, a filter wrong and
//!   sure of it. A filter may take long to converge; it may never claim a
//!   pose it is not at.
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
//! use deog_evaluation::localization::{EstimateSample, EvalInput, TruthSample, evaluate};
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
//! # Ok::<(), deog_evaluation::localization::EvaluationError>(())
//! ```

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

mod evaluate;
mod input;
pub mod plot;
mod plot_legend;
mod plot_path;
mod report;
pub(crate) use report::pretty;

pub use crate::error::EvaluationError;
pub use evaluate::{AxisStats, ErrorStats, Kidnap, LocalizationReport, Settling, evaluate};
pub use input::{EstimateSample, EvalInput, EvalParams, TruthSample};
pub use plot::{PlotInput, Raster, RobotPath, render_plot};
pub use plot_path::JUMP_BREAK_M;
pub use report::{
    BoundsRecord, KidnapRecord, LocalizationRecord, PoseRecord, XyRecord, reports_to_json,
};

/// Metres in an inch, for the thesis's units.
pub const METRES_PER_INCH: f64 = 0.0254;
/// Default largest position error of a settled estimate, metres.
pub const DEFAULT_CONVERGE_M: f64 = 0.25;
/// Default largest heading error of a settled estimate, radians.
pub const DEFAULT_CONVERGE_RAD: f64 = 0.25;
/// Position error past which an estimate flagged converged is a false
/// convergence, metres.
pub const FALSE_CONVERGED_M: f64 = 0.5;
/// Heading error past which an estimate flagged converged is a false
/// convergence, radians.
pub const FALSE_CONVERGED_RAD: f64 = 0.25;
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

#[cfg(test)]
mod plot_tests;
#[cfg(test)]
mod tests;
