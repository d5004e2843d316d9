//! What exploration refuses.

/// An exploration step's error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExploreError {
    /// The map's window would be too large to hold.
    #[error("a window of {cells} cells is past the limit of {limit}")]
    WindowTooLarge {
        /// Cells asked for.
        cells: u64,
        /// The most allowed.
        limit: u64,
    },
    /// A parameter out of its range.
    #[error("{name} {reason}")]
    Invalid {
        /// The parameter.
        name: &'static str,
        /// What is wrong with it.
        reason: String,
    },
}
