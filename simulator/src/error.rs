//! The simulator's one error type.

use thiserror::Error;

/// What can go wrong building or running a simulation.
#[derive(Debug, Error)]
pub enum SimError {
    /// No robot of that name is in the world.
    #[error("no robot named {0:?} in the world")]
    UnknownRobot(String),
    /// A robot of that name is already in the world.
    #[error("a robot named {0:?} is already in the world")]
    RobotExists(String),
    /// The request is valid but the world does not allow it (a pose inside
    /// an obstacle, no free place left).
    #[error("{0}")]
    Blocked(String),
    /// A line of a wanderer data file is malformed.
    #[error("{file}:{line}: {field}: {reason}")]
    DataFile {
        /// The file, as named to the parser.
        file: String,
        /// 1-based line number.
        line: usize,
        /// The column: `x`, `y`, `theta`, `s1` ... or `ranges`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The gRPC server failed.
    #[error("serving failed: {0}")]
    Serve(String),
    /// A request was larger than the simulator accepts.
    #[error("{field}: {reason}")]
    TooLarge {
        /// The message that is too large.
        field: String,
        /// Its size and the limit.
        reason: String,
    },
    /// The simulator already holds as many robots or watch streams as it
    /// was started to allow.
    #[error("{0}")]
    Limit(String),
    /// The TLS certificate or key cannot be served.
    #[error(transparent)]
    Tls(#[from] deog_proto::tls::TlsError),
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
