//! Maps from frames and back out: the cartographer's frame-to-deltas step,
//! map_server export and import of a map's tiles, and map quality against a
//! world's ground truth. Pure: the processes in `cli/` do the I/O.
//!
//! # Layout
//! - [`cartographer`]: [`Cartographer`], one frame to per-tile deltas from
//!   the chosen pose ([`PoseChoice`]).
//! - [`sensors`]: the inverse sensor models behind
//!   [`sensors::InverseSensorModel`]; the sonar ring's cones
//!   ([`sensors::SonarCone`]) are one.
//! - [`map_export`]: [`export_map`], a map's tiles to a trinary map_server
//!   image covering its observed cells ([`MapExport`]).
//! - [`map_import`]: [`import_map`], a map_server image to tile deltas at
//!   the map's clamp limits ([`MapImport`]).
//! - [`quality`]: [`map_quality`], a map judged against a world's ground
//!   truth ([`QualityInput`] in, [`MapQuality`] out), and
//!   [`verdict_image`], a picture of where it is right and wrong.
//! - [`error`]: the crate's one error type, [`MappingError`].

pub mod cartographer;
pub mod error;
pub mod map_export;
pub mod map_import;
pub mod quality;
pub mod sensors;

pub use cartographer::{Cartographer, FrameInput, PoseChoice, mapping_sonar_model};
pub use error::MappingError;
pub use map_export::{ExportCounts, MapExport, export_map};
pub use map_import::{ImportTarget, MapImport, image_origin_cell, import_map};
pub use quality::{
    Confusion, MapQuality, QualityInput, Verdict, VerdictImage, map_quality, verdict_image,
};
