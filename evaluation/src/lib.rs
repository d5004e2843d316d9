//! How well deog did, judged in one place for `deog eval`, `deog demo`
//! and every benchmark. Pure: callers read the true poses, the estimates
//! and the maps, and hand them in.
//!
//! # Layout
//! - [`localization`]: a localizer's estimates against the true poses, as
//!   the thesis's Tables 7.3 to 7.7, with convergence and kidnap recovery
//!   ([`localization::evaluate`]), as a table, as JSON, and the path plot.
//! - [`map_quality`]: a map against a world's ground truth: cells right,
//!   occupied precision and recall, coverage of reachable free space
//!   ([`map_quality::map_quality`]), and a picture of where it is right
//!   and wrong ([`map_quality::verdict_image`]).
//! - [`tracking`]: the same pairing over a whole run, lapses included
//!   ([`tracking::track`]): what a tracking benchmark reports.
//! - [`runs`]: many seeded runs summed up: how many converged and
//!   recovered within a time limit, and the mean errors.
//! - [`json`]: [`json::pretty_json`], how every record is written.
//! - [`error`]: [`EvaluationError`], the crate's one error type.

pub mod error;
pub mod json;
pub mod localization;
pub mod map_quality;
pub mod runs;
pub mod tracking;

pub use error::EvaluationError;
