//! The Scout simulator: a world of polygon obstacles, differential-drive
//! Super Scout II robots with a ring of 16 sonars, and the gRPC
//! `RobotService` that client programs drive them through.
//!
//! # Layout
//! - [`geometry`]: points, wall segments and polygons.
//! - [`world`]: [`World`], obstacles inside an optional boundary.
//! - [`world_file`]: the TOML world file format: [`load_world`],
//!   [`parse_world`], and [`load_world_any`] for either kind of world.
//! - [`world_image`]: a ROS map_server map (YAML + PGM) as a [`World`].
//! - [`segment_index`]: [`SegmentIndex`], walls bucketed on a grid for
//!   nearest-wall and sonar queries.
//! - [`sonar`]: [`SonarRing`], each sonar's nearest echo inside its cone,
//!   with noise, specular loss ([`Specular`]) and dropouts ([`SonarParams`]).
//! - [`robot`]: [`Robot`], a Scout's differential drive, bumper and noisy
//!   odometry ([`ScoutParams`], [`OdometryNoise`]).
//! - [`simulation`]: [`Simulation`], a world with robots in it, advanced in
//!   physics steps, each robot's sonars firing on a fixed period.
//! - [`convert`], [`service`], [`serve`](mod@serve): the gRPC edge:
//!   `RobotService` over a shared simulation with a real-time clock.
//! - [`wander`]: [`Wanderer`], the wandering policy: ranges in, a velocity
//!   command out.
//! - [`data_file`]: the thesis's wanderer data file, `x y theta s1 ... s16`.
//! - [`error`]: the crate's one error type, [`SimError`].

pub mod convert;
pub mod data_file;
pub mod error;
pub mod geometry;
pub mod robot;
pub mod segment_index;
pub mod serve;
pub mod service;
pub mod simulation;
pub mod sonar;
pub mod wander;
pub mod world;
pub mod world_file;
pub mod world_image;

pub use error::SimError;
pub use geometry::{Point2, Polygon, Segment};
pub use robot::{OdometryNoise, Robot, ScoutParams};
pub use segment_index::SegmentIndex;
pub use simulation::{RobotSnapshot, SimConfig, Simulation};
pub use sonar::{SonarParams, SonarRing, Specular};
pub use wander::{WanderParams, Wanderer};
pub use world::World;
pub use world_file::{load_world, load_world_any, parse_world};
pub use world_image::{ImageWorldOptions, load_map_world, world_from_map};
