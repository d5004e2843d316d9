//! Monte Carlo Localization of a sonar robot on a deog map.
//!
//! Everything here is pure and synchronous: the `deog localize` process
//! fetches tiles and frames over the network and feeds them in.
//!
//! # Layout
//! - [`step`]: [`step::Localizer`], one frame through the filter on its
//!   cached map (refresh, predict, fetch, correct, evict), the same for the
//!   process and the bench; tiles come from a [`step::TileSource`].
//! - [`filter`]: [`filter::Mcl`], the particle filter (augmented MCL,
//!   KLD-sampling, clusters kept through resampling).
//! - [`sensors`]: the sensor side behind [`sensors::SensorModel`]; the
//!   sonar ring ([`sensors::SonarCone`]) is one implementation.
//! - [`motion`]: the odometry motion model.
//! - [`local_map`]: [`local_map::LocalMap`], the cache of the server's
//!   tiles and their expected-range tables within a memory budget.
//! - [`range_table`]: per-tile expected sonar ranges, and the plain
//!   reference they are checked against.
//! - [`beam_model`]: the likelihood of a measured range given the
//!   expected one.
//! - [`sampling`], [`cluster`], [`gaussian`]: resampling and the KLD
//!   bound, particle clusters and the estimate, normal draws.
//!
//! How well it localizes is judged in `deog-evaluation`.

pub mod beam_model;
pub mod cluster;
pub mod error;
pub mod filter;
pub mod gaussian;
pub mod local_map;
pub mod motion;
pub mod range_table;
pub mod sampling;
pub mod sensors;
pub mod step;
