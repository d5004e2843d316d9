//! Errors of the localizer core.

use thiserror::Error;

/// What can go wrong in the localizer core. Every variant names the
/// offending parameter or input.
#[derive(Debug, Error)]
pub enum LocalizerError {
    /// A parameter outside its allowed range.
    #[error("{name} must be in [{min}, {max}], got {value}")]
    OutOfRange {
        /// The parameter's name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
    },
    /// An input that cannot be used, with the reason.
    #[error("{0}")]
    Invalid(String),
    /// The map has no known-free cell to put particles on.
    #[error("the map has no known-free cell to spread particles over")]
    NoFreeSpace,
    /// Global localization would need more range tables than the cache
    /// holds.
    #[error(
        "global localization needs range tables for the {tiles} tiles with free cells, \
         but the cache budget holds {capacity}: give an initial pose or a larger cache"
    )]
    MapLargerThanCache {
        /// Held tiles with a known-free cell.
        tiles: usize,
        /// Range tables the budget holds.
        capacity: usize,
    },
    /// The map's tiles could not be fetched.
    #[error("fetching tiles")]
    Fetch(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// A grid operation failed.
    #[error(transparent)]
    Grid(#[from] deog_grid::GridError),
}

/// `Ok(value)` if it is finite and within `[min, max]`.
pub(crate) fn within(
    name: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<f64, LocalizerError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(LocalizerError::OutOfRange {
            name,
            value,
            min,
            max,
        })
    }
}
