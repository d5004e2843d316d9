//! The one error type of the robot client.

use thiserror::Error;

/// Why a robot-client operation failed.
#[derive(Debug, Error)]
pub enum ClientError {
    /// The configuration cannot work (a bad address, a bad certificate).
    #[error("invalid client configuration: {0}")]
    Config(String),
    /// The server could not be reached within the retry policy.
    #[error("cannot reach {endpoint} after {attempts} attempts: {last_error}")]
    Unreachable {
        /// The address tried.
        endpoint: String,
        /// Attempts made.
        attempts: u32,
        /// The last failure.
        last_error: String,
    },
    /// The server refused a call.
    #[error("the server refused the call: {0}")]
    Status(#[from] tonic::Status),
    /// A tile from the server could not be decoded.
    #[error("bad tile from the server: {0}")]
    Grid(#[from] deog_grid::GridError),
    /// A wire message lacks a field or holds a value the client cannot
    /// use; `field` names it as the proto does.
    #[error("{field}: {reason}")]
    Wire {
        /// Path of the offending field, e.g. `bounds_cells`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The update stream stopped for good (a refused batch, or the sender
    /// task ended).
    #[error("update stream failed: {0}")]
    Updates(String),
}

impl ClientError {
    /// A [`ClientError::Wire`] naming `field`.
    pub fn wire(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Wire {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// Whether retrying the same call later may succeed.
    pub fn is_transient(&self) -> bool {
        match self {
            ClientError::Status(status) => is_transient(status),
            ClientError::Unreachable { .. } => true,
            _ => false,
        }
    }
}

/// Whether a status means "try again": the server was down or restarting,
/// not that the request was wrong.
pub fn is_transient(status: &tonic::Status) -> bool {
    use tonic::Code;
    matches!(
        status.code(),
        Code::Unavailable
            | Code::Unknown
            | Code::Cancelled
            | Code::DeadlineExceeded
            | Code::Aborted
    )
}
