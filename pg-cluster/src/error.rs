//! The crate's one error type.

use std::io;

/// What can go wrong starting, driving or stopping a [`crate::LocalCluster`].
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// No PostgreSQL server binaries (`initdb` and `postgres`) were found.
    #[error(
        "no PostgreSQL server binaries found (looked in {searched}); \
         install the PostgreSQL server (Debian: apt-get install postgresql)"
    )]
    NotInstalled {
        /// The places that were searched.
        searched: String,
    },
    /// An operating-system call failed.
    #[error("{doing}: {source}")]
    Io {
        /// What was being done, e.g. "creating a temporary folder".
        doing: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// A binary ran but exited unsuccessfully.
    #[error("`{command}` failed ({status}): {stderr}")]
    Command {
        /// The command line, for reading.
        command: String,
        /// How it exited.
        status: String,
        /// The last lines of its standard error.
        stderr: String,
    },
    /// The server did not come up (it exited, or was not accepting
    /// connections within the time allowed).
    #[error("PostgreSQL did not become ready: {reason}; last lines of its log:\n{log_tail}")]
    NotReady {
        /// Why it is considered failed.
        reason: String,
        /// The last lines the server logged during this start.
        log_tail: String,
    },
}

impl ClusterError {
    /// An [`ClusterError::Io`] saying what was being done.
    pub(crate) fn io(doing: impl Into<String>, source: io::Error) -> Self {
        Self::Io {
            doing: doing.into(),
            source,
        }
    }
}

/// The last `lines` lines of `text`.
pub(crate) fn tail(text: &str, lines: usize) -> String {
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}
