//! The one error type of the robot client.

use thiserror::Error;

/// Why a robot-client operation failed.
#[derive(Debug, Error)]
pub enum ClientError {
    /// The configuration cannot work (a bad address, a bad certificate).
    #[error("invalid client configuration: {0}")]
    Config(String),
    /// The server could not be reached within the retry policy or the
    /// connect timeout.
    #[error(
        "cannot reach the {peer} at {endpoint} ({last_error}; {attempts} attempts in {waited_s:.1} s): \
         is `{command}` running there? start one with `{command} --listen {listen}`",
        peer = peer.name(),
        command = peer.command(),
        listen = endpoint.split_once("://").map_or(endpoint.as_str(), |(_, rest)| rest)
    )]
    Unreachable {
        /// What was being reached.
        peer: Peer,
        /// The address tried.
        endpoint: String,
        /// Attempts made.
        attempts: u32,
        /// Seconds spent trying.
        waited_s: f64,
        /// The last failure, its innermost cause.
        last_error: String,
    },
    /// The server refused a call: its message, then the code in words.
    #[error("{}", status_line(.0))]
    Status(tonic::Status),
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

impl From<tonic::Status> for ClientError {
    fn from(status: tonic::Status) -> Self {
        Self::Status(status)
    }
}

/// What a client reaches, for its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Peer {
    /// `deog server`.
    #[default]
    MapServer,
    /// `deog sim`.
    Simulator,
}

impl Peer {
    /// Its name in a sentence.
    pub fn name(self) -> &'static str {
        match self {
            Peer::MapServer => "map server",
            Peer::Simulator => "simulator",
        }
    }

    /// The command that starts one.
    pub fn command(self) -> &'static str {
        match self {
            Peer::MapServer => "deog server",
            Peer::Simulator => "deog sim",
        }
    }
}

/// A refusal as one line: the server's message, then its code in words
/// (`map "x" does not exist (not found)`).
pub fn status_line(status: &tonic::Status) -> String {
    let words = code_words(status.code());
    let message = status.message().trim();
    if message.is_empty() {
        words.to_string()
    } else {
        format!("{message} ({words})")
    }
}

/// A gRPC code as words a person reads.
pub fn code_words(code: tonic::Code) -> &'static str {
    use tonic::Code;
    match code {
        Code::Ok => "ok",
        Code::Cancelled => "cancelled",
        Code::Unknown => "unknown error",
        Code::InvalidArgument => "invalid argument",
        Code::DeadlineExceeded => "deadline exceeded",
        Code::NotFound => "not found",
        Code::AlreadyExists => "already exists",
        Code::PermissionDenied => "permission denied",
        Code::ResourceExhausted => "resource exhausted",
        Code::FailedPrecondition => "failed precondition",
        Code::Aborted => "aborted",
        Code::OutOfRange => "out of range",
        Code::Unimplemented => "not implemented by the server",
        Code::Internal => "internal server error",
        Code::Unavailable => "unavailable",
        Code::DataLoss => "data loss",
        Code::Unauthenticated => "unauthenticated",
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_reads_as_one_line_without_repeating_itself() {
        let error = ClientError::from(tonic::Status::not_found("map \"nosuch\" does not exist"));
        assert_eq!(
            error.to_string(),
            "map \"nosuch\" does not exist (not found)"
        );
        // No source: a cause chain would print the status again.
        assert!(std::error::Error::source(&error).is_none());
        assert_eq!(
            ClientError::from(tonic::Status::unavailable("")).to_string(),
            "unavailable"
        );
    }

    #[test]
    fn an_unreachable_server_comes_with_a_hint() {
        let error = ClientError::Unreachable {
            peer: Peer::MapServer,
            endpoint: "127.0.0.1:50051".into(),
            attempts: 3,
            waited_s: 5.0,
            last_error: "Connection refused (os error 111)".into(),
        };
        let text = error.to_string();
        assert!(
            text.starts_with("cannot reach the map server at 127.0.0.1:50051"),
            "{text}"
        );
        assert!(
            text.contains("start one with `deog server --listen 127.0.0.1:50051`"),
            "{text}"
        );
        assert!(!text.contains('\n'), "{text}");
    }
}
