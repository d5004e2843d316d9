//! The ground truth of deog: worlds of polygon obstacles that robots drive
//! and sense in, read from TOML world files or ROS map_server images, and
//! indexed for nearest-wall and sonar queries; and a generated city, for
//! maps far larger than any world file. Pure: no async, no network.
//!
//! # Layout
//! - [`geometry`]: points, wall segments and polygons.
//! - [`world`]: [`World`], obstacles inside an optional boundary.
//! - [`world_file`]: the TOML world file format: [`load_world`],
//!   [`parse_world`], and [`load_world_any`] for either kind of world.
//! - [`world_image`]: a ROS map_server map (YAML + PGM) as a [`World`].
//! - [`builtin`]: [`BUILT_IN_WORLDS`], the `worlds/` files compiled in, and
//!   [`load_world_spec`], a world from what a user typed: a built-in name, a
//!   world file or a map_server map.
//! - [`city`](mod@city): [`City`], a generated city of blocks and streets
//!   as a map_server image, seeded ([`city()`]).
//! - [`segment_index`]: [`SegmentIndex`], walls bucketed on a grid for
//!   nearest-wall and sonar queries.
//! - [`error`]: the crate's one error type, [`WorldError`].
//!
//! ```
//! use deog_world::{Point2, parse_world};
//!
//! let world = parse_world(
//!     "name = \"box\"\nboundary = [[0, 0], [4, 0], [4, 3], [0, 3]]\n",
//!     "box.toml",
//! )?;
//! assert!(world.is_free(Point2::new(1.0, 1.0)));
//! assert_eq!(world.walls().len(), 4);
//! # Ok::<(), deog_world::WorldError>(())
//! ```

pub mod builtin;
pub mod city;
pub mod error;
pub mod geometry;
pub mod segment_index;
pub mod world;
pub mod world_file;
pub mod world_image;

pub use builtin::{BUILT_IN_WORLDS, load_world_spec};
pub use city::{City, city};
pub use error::WorldError;
pub use geometry::{Point2, Polygon, Segment};
pub use segment_index::SegmentIndex;
pub use world::World;
pub use world_file::{load_world, load_world_any, parse_world};
pub use world_image::{ImageWorldOptions, load_map_world, world_from_map};
