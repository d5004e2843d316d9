//! Maps from frames and back out: the cartographer's frame-to-deltas step
//! and map_server export and import of a map's tiles. Pure: the processes
//! do the I/O; how good a map is is judged in `deog-evaluation`.
//!
//! # Layout
//! - [`cartographer`]: [`Cartographer`], one frame to per-tile deltas from
//!   the chosen pose ([`PoseChoice`]).
//! - [`map_view`]: [`MapView`], the cartographer's bounded view of the
//!   map it writes to, whose walls a sonar cone stops at
//!   ([`SonarMethod::KeepWalls`]).
//! - [`directional`]: [`DirectionalView`], sonar evidence kept per
//!   direction of the surface normal, so that a wall swept at a grazing
//!   angle keeps the echoes it returned ([`SonarMethod::Directional`]).
//! - [`forward`]: [`fit_forward`], a sonar map fitted to all of a run's
//!   readings at once through a forward model of the specular sonar.
//! - [`estimates`]: [`EstimateBook`], which frames a localizer's converged
//!   estimates place (mapping without ground truth).
//! - [`sensors`]: the inverse sensor models behind
//!   [`sensors::InverseSensorModel`]: the sonar ring's cones
//!   ([`sensors::SonarCone`]) and any rig's cones and laser rays
//!   ([`sensors::RigBeams`]).
//! - [`map_export`]: [`export_map`], a map's tiles to a trinary map_server
//!   image covering its observed cells ([`MapExport`]).
//! - [`map_import`]: [`import_map`], a map_server image to tile deltas at
//!   the map's clamp limits ([`MapImport`]).
//! - [`error`]: the crate's one error type, [`MappingError`].

pub mod cartographer;
pub mod directional;
pub mod error;
pub mod estimates;
pub mod forward;
pub mod map_export;
pub mod map_import;
pub mod map_view;
pub mod sensors;

pub use cartographer::{
    Cartographer, FrameInput, PoseChoice, SPECULAR_MAX_FREE_RANGE, SPECULAR_OCCUPIED_AXIS_FACTOR,
    SonarMethod, mapping_sonar_model, specular_sonar_mapping,
};
pub use directional::{DEFAULT_ENCLOSURE_PERIOD, DirectionalSettings, DirectionalView};
pub use error::MappingError;
pub use estimates::{EstimateBook, EstimateLookup};
pub use forward::{
    ForwardSettings, ForwardStats, SonarReading, echo_below, fit_forward, ring_readings,
};
pub use map_export::{ExportCounts, MapExport, export_map};
pub use map_import::{ImportTarget, MapImport, image_origin_cell, import_map};
pub use map_view::{MapView, MapViewSettings};
