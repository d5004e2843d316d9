//! The simulator: a world of polygon obstacles, round differential-drive
//! robots carrying any sensor rig (the Super Scout II's ring of 16 sonars
//! by default, the Pioneer's sonar arrays, planar lasers), and the gRPC
//! `RobotService` that client programs drive them through.
//!
//! The world itself (geometry, world files, map_server images as worlds,
//! the wall index) is the `deog-world` crate; this crate puts robots in it.
//!
//! # Layout
//! - [`sonar`]: [`SonarRing`], each sonar's nearest echo inside its cone,
//!   with noise, specular loss ([`Specular`]; a grazed wall still hides
//!   what is behind it), crosstalk and dropouts ([`SonarParams`]).
//! - [`sonar_firing`]: [`SonarFiring`], when each sonar of a frame fires
//!   (all at once, or one at a time over the sensor period).
//! - [`sonar_preset`]: [`SonarPreset`], the named sonar figures the
//!   command line picks (`default`, `realistic`, `specular60`).
//! - [`laser`]: [`Lasers`], each laser ray's distance to the first wall,
//!   with Gaussian noise ([`LaserParams`]).
//! - [`rig_sensors`]: [`RigSensors`], a rig's sonars (grouped into rings by
//!   their figures) and lasers fired as one frame in the rig's beam order.
//! - [`robot`]: [`Robot`], a round differential drive, bumper and noisy
//!   odometry ([`ScoutParams`], [`OdometryNoise`]).
//! - [`simulation`]: [`Simulation`], a world with robots in it, advanced in
//!   physics steps, every robot carrying the rig of its [`SimConfig`] and
//!   firing it on a fixed period.
//! - [`convert`], [`service`], [`serve`](mod@serve): the gRPC edge:
//!   `RobotService` over a shared simulation with a real-time clock, capped
//!   robots and watch streams, an optional bearer token and TLS.
//! - [`wander`]: [`Wanderer`], the wandering policy: any rig's ranges in
//!   (judged by each beam's mount and direction), a velocity command out.
//! - [`data_file`]: the thesis's wanderer data file, `x y theta s1 ... s16`.
//! - [`error`]: the crate's one error type, [`SimError`].

pub mod convert;
pub mod data_file;
pub mod error;
pub mod laser;
pub mod rig_sensors;
pub mod robot;
pub mod serve;
pub mod service;
pub mod simulation;
pub mod sonar;
pub mod sonar_firing;
pub mod sonar_preset;
pub mod wander;

/// The rigs the simulation's robots carry ([`SimConfig::rig`]), for
/// callers that name one.
pub use deog_rig;
pub use error::SimError;
pub use laser::{LaserParams, Lasers};
pub use rig_sensors::RigSensors;
pub use robot::{OdometryNoise, Robot, ScoutParams};
pub use simulation::{RobotSnapshot, SimConfig, Simulation};
pub use sonar::{SonarParams, SonarRing, Specular};
pub use sonar_firing::SonarFiring;
pub use sonar_preset::SonarPreset;
pub use wander::{WanderParams, Wanderer};
