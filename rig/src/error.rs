//! The one error type of rigs.

use thiserror::Error;

/// Why a rig, or a reading judged against it, was refused. Every variant
/// names what it refuses, so a service can pass the message on unchanged.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RigError {
    /// A rig description that does not hold together.
    #[error("rig {rig}: {field}: {reason}")]
    Invalid {
        /// The rig's name (or the file it came from).
        rig: String,
        /// The field, `sensor[3].max_range_m` style.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A rig file that is not TOML of the rig format.
    #[error("{origin}: {reason}")]
    Parse {
        /// The file or built-in name.
        origin: String,
        /// The TOML error, with its line.
        reason: String,
    },
    /// A rig file that could not be read.
    #[error("reading rig file {file}: {reason}")]
    Read {
        /// The path.
        file: String,
        /// The I/O error.
        reason: String,
    },
    /// Neither a file nor a built-in name.
    #[error("no rig file or built-in rig called {spec:?} (built in: {})", known.join(", "))]
    Unknown {
        /// What was asked for.
        spec: String,
        /// The built-in names.
        known: Vec<String>,
    },
    /// A frame whose number of readings is not the rig's.
    #[error("rig {rig} reads {expected} ranges per frame, the frame has {got}")]
    WrongReadingCount {
        /// The rig's name.
        rig: String,
        /// The rig's readings per frame.
        expected: usize,
        /// The frame's.
        got: usize,
    },
    /// A reading that is not a range.
    #[error("rig {rig}: ranges[{index}] is {value}, not a range")]
    BadReading {
        /// The rig's name.
        rig: String,
        /// The reading's index in the frame.
        index: usize,
        /// The value.
        value: f64,
    },
}

impl RigError {
    pub(crate) fn invalid(
        rig: impl Into<String>,
        field: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            rig: rig.into(),
            field: field.into(),
            reason: reason.into(),
        }
    }
}
