//! The mapping crate's one error type.

use thiserror::Error;

/// What can go wrong building, exporting or judging a map.
#[derive(Debug, Error)]
pub enum MappingError {
    /// A grid computation refused its input.
    #[error(transparent)]
    Grid(#[from] deog_grid::GridError),
    /// A value is out of range or malformed.
    #[error("{field}: {reason}")]
    Invalid {
        /// The offending field.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A frame's own values cannot be mapped (a pose beyond the grid's
    /// reach, say): the frame is to be skipped, the mapping goes on.
    #[error("frame {sequence}: {reason}")]
    UnusableFrame {
        /// The frame's sequence.
        sequence: u64,
        /// What in it cannot be used.
        reason: String,
    },
}

impl MappingError {
    /// An [`MappingError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}
