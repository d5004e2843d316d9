//! The Scout simulator: a world of polygon obstacles, differential-drive
//! Super Scout II robots with a ring of 16 sonars, and the gRPC
//! `RobotService` that client programs drive them through.
//!
//! The world itself (geometry, world files, map_server images as worlds,
//! the wall index) is the `deog-world` crate; this crate puts robots in it.
//!
//! # Layout
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
pub mod robot;
pub mod serve;
pub mod service;
pub mod simulation;
pub mod sonar;
pub mod wander;

pub use error::SimError;
pub use robot::{OdometryNoise, Robot, ScoutParams};
pub use simulation::{RobotSnapshot, SimConfig, Simulation};
pub use sonar::{SonarParams, SonarRing, Specular};
pub use wander::{WanderParams, Wanderer};
