//! The one error type of the map server, and its gRPC status.

use deog_grid::GridError;
use thiserror::Error;
use tonic::{Code, Status};

/// Why a map-server operation failed. Each variant maps to one gRPC code in
/// the single `From<StoreError> for Status` below.
#[derive(Debug, Error)]
pub enum StoreError {
    /// A request field was malformed; `field` names it as the proto does.
    #[error("{field}: {reason}")]
    InvalidArgument {
        /// Path of the offending field, e.g. `tiles[3].cells`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A request was larger than the server accepts.
    #[error("{field}: {reason}")]
    TooLarge {
        /// The field or message that is too large.
        field: String,
        /// The size and the limit.
        reason: String,
    },
    /// No map has this name.
    #[error("map {0:?} does not exist")]
    MapNotFound(String),
    /// A map with this name exists already.
    #[error("map {0:?} already exists")]
    MapExists(String),
    /// No rig has this name.
    #[error("rig {0:?} is not known to the server: store it with PutRig first (a --rig FILE does)")]
    RigNotFound(String),
    /// A different rig has this name.
    #[error("a different rig called {0:?} is known to the server: give yours another name")]
    RigExists(String),
    /// A frame names a rig the server does not know.
    #[error(
        "{field}: rig {rig:?} is not known to the server: store it with PutRig first (a --rig FILE does)"
    )]
    UnknownRig {
        /// Path of the field, e.g. `frames[3].rig`.
        field: String,
        /// The name.
        rig: String,
    },
    /// A batch's sequence is below its client's highest applied one and
    /// was never applied: the client's numbering went backwards.
    #[error(
        "batch sequence {sequence} of client {client:?} on map {map:?} is below the last applied \
         ({last}) and was never applied: sequences must increase"
    )]
    SequenceOutOfOrder {
        /// The map.
        map: String,
        /// The client id.
        client: String,
        /// The batch's sequence.
        sequence: u64,
        /// The client's highest applied sequence.
        last: u64,
    },
    /// The server is shutting down and takes no more writes.
    #[error("the map server is shutting down")]
    ShuttingDown,
    /// The embedded database failed.
    #[error("storage failure: {0}")]
    Backend(String),
    /// The device under the store is full: writes fail until it has room.
    #[error("the store cannot write: {0}")]
    OutOfSpace(String),
    /// The store cannot serve the call now (it is recovering from a failed
    /// write); the call may succeed later.
    #[error("the store is unavailable: {0}")]
    Unavailable(String),
    /// The write met a concurrent one through another server and was
    /// rolled back (a deadlock or serialization failure the database
    /// resolved); sending it again succeeds.
    #[error("the write met a concurrent one and was rolled back: {0}")]
    Conflict(String),
    /// A group of writes was not committed; `reason` is the error that
    /// stopped it, already worded (every write of the group gets it).
    #[error("{reason}")]
    NotCommitted {
        /// Why.
        reason: String,
        /// The cause passes (a full device, a lost database connection, a
        /// concurrent write): the write may succeed if sent again.
        transient: bool,
    },
    /// Stored bytes could not be decoded: the data directory is damaged or
    /// was written by an incompatible version.
    #[error("stored record {what} is corrupt: {reason}")]
    Corrupt {
        /// Which record.
        what: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl StoreError {
    /// Whether this is the store's own failure rather than a refusal of
    /// one request.
    pub fn is_backend(&self) -> bool {
        matches!(
            self,
            Self::Backend(_)
                | Self::OutOfSpace(_)
                | Self::Unavailable(_)
                | Self::Conflict(_)
                | Self::Corrupt { .. }
        )
    }

    /// The same failure again, for each later call that meets it.
    pub fn again(&self) -> Self {
        match self {
            Self::Backend(reason) => Self::Backend(reason.clone()),
            Self::OutOfSpace(reason) => Self::OutOfSpace(reason.clone()),
            Self::Unavailable(reason) => Self::Unavailable(reason.clone()),
            Self::Conflict(reason) => Self::Conflict(reason.clone()),
            Self::Corrupt { what, reason } => Self::Corrupt {
                what: what.clone(),
                reason: reason.clone(),
            },
            other => Self::Backend(other.to_string()),
        }
    }

    /// Whether the cause passes by itself, so the same write sent again
    /// may succeed.
    pub fn is_transient(&self) -> bool {
        matches!(
            self,
            Self::OutOfSpace(_) | Self::Unavailable(_) | Self::Conflict(_) | Self::ShuttingDown
        ) || matches!(
            self,
            Self::NotCommitted {
                transient: true,
                ..
            }
        )
    }

    /// An invalid-argument error naming `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::InvalidArgument {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// An invalid-argument error from a grid-core refusal, under `prefix`
    /// (the grid names its own field; the prefix says where it sits).
    pub fn grid(prefix: &str, error: GridError) -> Self {
        let reason = error.to_string();
        if prefix.is_empty() {
            Self::invalid("request", reason)
        } else {
            Self::invalid(prefix, reason)
        }
    }
}

impl From<sled::Error> for StoreError {
    fn from(error: sled::Error) -> Self {
        match &error {
            sled::Error::Io(io) if io.kind() == std::io::ErrorKind::StorageFull => {
                Self::OutOfSpace(io.to_string())
            }
            _ => Self::Backend(error.to_string()),
        }
    }
}

impl From<StoreError> for Status {
    fn from(error: StoreError) -> Self {
        let code = match &error {
            StoreError::InvalidArgument { .. } => Code::InvalidArgument,
            StoreError::TooLarge { .. } => Code::ResourceExhausted,
            StoreError::MapNotFound(_) => Code::NotFound,
            StoreError::MapExists(_) | StoreError::RigExists(_) => Code::AlreadyExists,
            StoreError::RigNotFound(_) => Code::NotFound,
            StoreError::UnknownRig { .. } | StoreError::SequenceOutOfOrder { .. } => {
                Code::FailedPrecondition
            }
            StoreError::ShuttingDown
            | StoreError::OutOfSpace(_)
            | StoreError::Unavailable(_)
            | StoreError::Conflict(_) => Code::Unavailable,
            StoreError::NotCommitted { transient, .. } => {
                if *transient {
                    Code::Unavailable
                } else {
                    Code::Internal
                }
            }
            StoreError::Backend(_) | StoreError::Corrupt { .. } => Code::Internal,
        };
        Status::new(code, error.to_string())
    }
}
