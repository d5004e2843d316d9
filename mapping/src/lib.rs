//! Maps from frames and back out: the cartographer's frame-to-deltas step,
//! map_server export and import of a map's tiles, and map quality against a
//! world's ground truth. Pure: the processes in `cli/` do the I/O.
//!
//! # Layout
//! - [`error`]: the crate's one error type, [`MappingError`].

pub mod error;

pub use error::MappingError;
