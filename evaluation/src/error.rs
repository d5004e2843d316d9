//! The crate's one error type.

use thiserror::Error;

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
    /// A picture could not be drawn or encoded.
    #[error("plot: {0}")]
    Plot(String),
    /// A grid computation refused its input.
    #[error(transparent)]
    Grid(#[from] deog_grid::GridError),
}

impl EvaluationError {
    pub(crate) fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn no_data(robot: &str, reason: impl Into<String>) -> Self {
        Self::NoData {
            robot: robot.to_string(),
            reason: reason.into(),
        }
    }
}
