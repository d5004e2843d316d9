//! The one error type of the crate.

use deog_rig::RigError;

/// What can go wrong writing or reading a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// CDR bytes that do not decode: too short, another encapsulation, a
    /// count larger than the message.
    #[error("bad CDR: {0}")]
    Cdr(String),
    /// A message on `topic` that does not decode as its schema says.
    #[error("message {index} on {topic} ({schema}): {reason}")]
    Message {
        /// The channel's topic.
        topic: String,
        /// The schema's name.
        schema: String,
        /// The message's place on its topic, from 1.
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// The MCAP container itself is unreadable or could not be written.
    #[error("MCAP")]
    Mcap(#[from] mcap::McapError),
    /// Bytes that are not an MCAP file at all.
    #[error("not an MCAP file (it does not begin with MCAP's magic bytes)")]
    NotMcap,
    /// No topic of the kind needed, or not the one asked for.
    #[error("{0}")]
    Topic(String),
    /// The recording has what is needed but not enough of it to make a
    /// frame (no scan within the odometry's time span, for one).
    #[error("{0}")]
    Empty(String),
    /// A value that cannot be recorded: a negative or non-finite time, a
    /// map too large for one message.
    #[error("{0}")]
    Unrecordable(String),
    /// The rig the scans describe is not one deog takes.
    #[error("the rig built from {topic}: {source}")]
    Rig {
        /// The topic whose messages gave the geometry.
        topic: String,
        /// Why the rig was refused.
        source: RigError,
    },
    /// A scan whose geometry differs from the first scan's on its topic.
    #[error("{0}")]
    Geometry(String),
}
