//! The Scout simulator: a world of polygon obstacles, differential-drive
//! Super Scout II robots with a ring of 16 sonars, and the gRPC
//! `RobotService` that client programs drive them through.
//!
//! # Layout
//! - [`geometry`]: points, wall segments and polygons.
//! - [`world`]: [`World`], obstacles inside an optional boundary.
//! - [`error`]: the crate's one error type, [`SimError`].

pub mod error;
pub mod geometry;
pub mod world;

pub use error::SimError;
pub use geometry::{Point2, Polygon, Segment};
pub use world::World;
