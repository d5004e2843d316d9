//! The simulator's one error type.

use thiserror::Error;

/// What can go wrong building or running a simulation.
#[derive(Debug, Error)]
pub enum SimError {
    /// A world with neither a boundary nor an obstacle has no extent.
    #[error("world {0:?} has neither a boundary nor obstacles")]
    EmptyWorld(String),
    /// A value given to the simulator is out of range or malformed.
    #[error("{field}: {reason}")]
    Invalid {
        /// The offending field, as the caller named it.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl SimError {
    /// An [`SimError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}
