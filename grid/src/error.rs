//! The one error type of the grid core.

use thiserror::Error;

/// Why a grid-core operation refused its input. Every variant names the
/// offending quantity so that a service can pass the message on unchanged.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GridError {
    /// A number that must be finite was NaN or infinite.
    #[error("{field} must be a finite number, got {value}")]
    NotFinite {
        /// Name of the quantity.
        field: &'static str,
        /// The value received.
        value: f64,
    },
    /// A number was outside the range it may take.
    #[error("{field} must be within [{min}, {max}], got {value}")]
    OutOfRange {
        /// Name of the quantity.
        field: &'static str,
        /// The value received.
        value: f64,
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
    },
    /// A tile size that is not a power of two in the accepted range.
    #[error("tile size must be a power of two from {min} to {max}, got {value}")]
    BadTileSize {
        /// The value received.
        value: u32,
        /// Smallest accepted size.
        min: u32,
        /// Largest accepted size.
        max: u32,
    },
    /// A tile key whose cells fall outside the i32 cell range.
    #[error("tile key ({x}, {y}) is outside the map's addressable range for tile size {tile_size}")]
    TileKeyOutOfRange {
        /// Tile x index.
        x: i32,
        /// Tile y index.
        y: i32,
        /// Cells per tile side.
        tile_size: u32,
    },
    /// A packed cell array of the wrong length or layout.
    #[error("{field}: {reason}")]
    BadCells {
        /// Name of the field holding the cells.
        field: &'static str,
        /// What is wrong with them.
        reason: String,
    },
    /// A frame whose number of ranges does not match the sensor ring.
    #[error("ranges: expected {expected} readings, got {got}")]
    WrongReadingCount {
        /// Number of sensors on the ring.
        expected: usize,
        /// Number of ranges received.
        got: usize,
    },
    /// A reading of a frame that is not a range (NaN, negative, or
    /// infinite where infinity does not mean no echo).
    #[error("ranges[{index}] is {value}, not a range")]
    BadReading {
        /// The reading's index in the frame.
        index: usize,
        /// The value received.
        value: f64,
    },
}

/// Checks that `value` is finite.
pub(crate) fn finite(field: &'static str, value: f64) -> Result<f64, GridError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(GridError::NotFinite { field, value })
    }
}

/// Checks that `value` is finite and within `[min, max]`.
pub(crate) fn within(
    field: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<f64, GridError> {
    finite(field, value)?;
    if (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(GridError::OutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}
