//! Sensor rigs: what range sensors a robot carries and where.
//!
//! A rig lists a robot's range sensors (sonar cones and planar lasers),
//! each with its mount pose on the robot, its range limits and what a
//! no-echo reading looks like. Frames carry their rig's name; the map
//! server keeps rigs, so that every consumer reads a frame with the
//! geometry that made it. Every consumer works on the rig's beams: one
//! per reading of a frame, each a cone or a ray from its own mount.
//!
//! # Layout
//! - [`rig`]: the types, [`Rig`], [`RangeSensor`], [`Beam`] and the checks of a frame
//!   against its rig.
//! - [`file`](mod@file): rig files (TOML; the format is in `rigs/README.md`).
//! - [`builtin`]: the built-in rigs (`scout`, `pioneer3dx`, `laser180`)
//!   and [`load_rig_spec`], how a `--rig NAME|FILE` is resolved.
//! - [`error`]: the one error type, [`RigError`].

pub mod builtin;
pub mod error;
pub mod file;
pub mod rig;

pub use builtin::{BUILT_IN_RIGS, DEFAULT_RIG, built_in_rig, is_built_in, load_rig_spec, scout};
pub use error::RigError;
pub use file::{load_rig_file, parse_rig, rig_to_toml};
pub use rig::{Beam, BeamShape, NoEcho, RangeSensor, Reading, Rig, SensorKind};
