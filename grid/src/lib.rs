//! The pure core of deog: no async, no I/O, only arithmetic on grids.
//!
//! # Layout
//! - [`cell`]: world metres to integer cells and back, for any sign.
//! - [`tile_key`]: which tile holds a cell, its offset there, and the store
//!   key of a tile, which sorts numerically.
//! - [`log_odds`]: fixed-point log-odds, probability conversions and clamping;
//!   the Bayes update of the thesis's Fig. 7.1 as an addition.
//! - [`tile`]: a tile's cells, a batch of deltas for them, and their packed
//!   byte encodings.
//! - [`tile_map`]: an in-memory map of tiles.
//! - [`pose`]: planar poses and angles.
//! - [`sensor_ring`]: where a robot's sonars sit (the Scout's 16).
//! - [`sector`]: rasterising a sonar cone, each cell once.
//! - [`sonar_model`]: the analytical sonar model (thesis eqs. 3.1 to 3.4).
//! - [`frame`]: a whole frame folded into per-tile delta batches.
//! - [`raycast`]: ray and cone casting on an occupancy view.
//! - [`error`]: the crate's one error type.

pub mod cell;
pub mod error;
pub mod frame;
pub mod log_odds;
pub mod pose;
pub mod raycast;
pub mod sector;
pub mod sensor_ring;
pub mod sonar_model;
pub mod tile;
pub mod tile_key;
pub mod tile_map;

pub use cell::{CellBox, CellIndex, Resolution};
pub use error::GridError;
pub use frame::{FrameIntegrator, FrameStats};
pub use log_odds::{ClampLimits, LOG_ODDS_SCALE, LogOdds};
pub use pose::{Pose2, normalize_angle};
pub use raycast::{Occupancy, OccupancyThresholds, OccupancyView, cast_cone, cast_ray};
pub use sensor_ring::{SCOUT_BODY_RADIUS_M, SCOUT_RING_RADIUS_M, SCOUT_SONAR_COUNT, SensorRing};
pub use sonar_model::{Region, SonarModel, SonarModelParams};
pub use tile::{Tile, TileDelta};
pub use tile_key::{CellOffset, TileKey, TileSize};
pub use tile_map::TileMap;
