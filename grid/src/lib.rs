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
//! - [`sensor_ring`]: where a robot's sonars sit (the Scout's 16), and
//!   when they fire within a frame ([`RingFiring`]).
//! - [`sector`]: rasterising a sonar cone, each cell once.
//! - [`sonar_model`]: the analytical sonar model (thesis eqs. 3.1 to 3.4).
//! - [`segment_walk`]: every cell a line segment passes through, in order
//!   (Amanatides and Woo).
//! - [`ray_model`]: the inverse model of a laser's ray (OctoMap's hit and
//!   miss).
//! - [`frame`]: a sonar ring's frame folded into per-tile delta batches
//!   through a dense scratch, and the one-delta-per-cell rule.
//! - [`beam_frame`]: a frame of mixed beams (cones and rays, each with its
//!   own mount and model) folded by the same rule through a per-tile
//!   scratch (`tile_scratch`, private).
//! - [`raycast`]: ray and cone casting on an occupancy view.
//! - [`error`]: the crate's one error type.
//!
//! # Example
//! One Scout frame, a wall 2 m ahead of every sonar, folded into tiles and
//! applied to a map:
//! ```
//! use deog_grid::*;
//!
//! let model = SonarModel::new(SonarModelParams::default())?;
//! let mut integrator =
//!     FrameIntegrator::new(model, SensorRing::scout(), Resolution::DEFAULT, TileSize::DEFAULT);
//! let mut deltas = Vec::new();
//! let stats = integrator.integrate(&Pose2::new(0.0, 0.0, 0.0), &[2.0; 16], &mut deltas)?;
//! assert_eq!(stats.tiles, deltas.len());
//!
//! let mut map = TileMap::new(Resolution::DEFAULT, TileSize::DEFAULT, ClampLimits::default());
//! for delta in &deltas {
//!     map.apply(delta)?;
//! }
//! // Just past 2 m ahead lies region I, probably occupied; at 1 m, empty.
//! let wall = map.get(Resolution::DEFAULT.cell_of(2.2, 0.01)?).unwrap();
//! let floor = map.get(Resolution::DEFAULT.cell_of(1.0, 0.01)?).unwrap();
//! assert!(wall.probability() > 0.5 && floor.probability() < 0.5);
//! # Ok::<(), GridError>(())
//! ```

pub mod beam_frame;
pub mod cell;
pub mod error;
pub mod frame;
pub mod key_hash;
pub mod log_odds;
pub mod pose;
pub mod ray_model;
pub mod raycast;
pub mod sector;
pub mod segment_walk;
pub mod sensor_ring;
pub mod sonar_model;
pub mod tile;
pub mod tile_key;
pub mod tile_map;
mod tile_scratch;

pub use beam_frame::{BeamFrameIntegrator, BeamModel, BeamReading, FrameBeam};
pub use cell::{CellBox, CellIndex, Resolution};
pub use error::GridError;
pub use frame::{FrameIntegrator, FrameStats};
pub use key_hash::{KeyHasher, KeyMap, KeySet};
pub use log_odds::{ClampLimits, LOG_ODDS_SCALE, LogOdds};
pub use pose::{Pose2, normalize_angle};
pub use ray_model::{RayModel, RayModelParams};
pub use raycast::{Occupancy, OccupancyThresholds, OccupancyView, cast_cone, cast_ray};
pub use segment_walk::SegmentCells;
pub use sensor_ring::{
    FrameMotion, RingFiring, SCOUT_BODY_RADIUS_M, SCOUT_RING_RADIUS_M, SCOUT_SONAR_COUNT,
    SensorRing,
};
pub use sonar_model::{ConeGuard, Region, SonarModel, SonarModelParams};
pub use tile::{Tile, TileDelta};
pub use tile_key::{CellOffset, TileKey, TileSize};
pub use tile_map::TileMap;
