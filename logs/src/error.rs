//! The one error type of log reading.

use thiserror::Error;

use deog_rig::RigError;

use crate::geometry::LaserSource;

/// Why a log, or a rig built from or checked against it, was refused.
/// Every variant names the log (its origin: a path or whatever the caller
/// passed), and a line when one is to blame.
#[derive(Debug, Error)]
pub enum LogError {
    /// The log could not be read (opening, reading, or a broken gzip
    /// stream).
    #[error("reading {origin}: {source}")]
    Read {
        /// The path or origin given.
        origin: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A line that is not what its first word says it is: a wrong number
    /// of fields, a number that does not parse, a reading count that does
    /// not match the readings.
    #[error("{origin}:{line}: {reason}")]
    Malformed {
        /// The path or origin given.
        origin: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong, naming the field.
        reason: String,
    },
    /// A log without a single laser scan.
    #[error("{origin}: no laser scans (no FLASER, RLASER or ROBOTLASER1 line)")]
    NoScans {
        /// The path or origin given.
        origin: String,
    },
    /// A rig was asked for a laser the log does not have.
    #[error("{origin}: the log has no {laser} scans")]
    NoSuchSource {
        /// The path or origin given.
        origin: String,
        /// The laser asked for.
        laser: LaserSource,
    },
    /// The log's laser geometry does not make a valid rig.
    #[error("{origin}: the {laser} laser does not make a rig: {error}")]
    Rig {
        /// The path or origin given.
        origin: String,
        /// The laser.
        laser: LaserSource,
        /// Why the rig refused it.
        error: RigError,
    },
    /// A scan that does not fit the rig it was checked against.
    #[error("{origin}:{line}: {error}")]
    RigMismatch {
        /// The path or origin given.
        origin: String,
        /// 1-based line number of the scan.
        line: usize,
        /// What the rig refused.
        error: RigError,
    },
}

impl LogError {
    pub(crate) fn malformed(origin: &str, line: usize, reason: impl Into<String>) -> Self {
        Self::Malformed {
            origin: origin.to_owned(),
            line,
            reason: reason.into(),
        }
    }
}
