//! Monte Carlo Localization of a robot with sonars or lasers on a deog map.
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
//! - [`sensors`]: the sensor side behind [`sensors::SensorModel`]: the
//!   sonar ring's beam model ([`sensors::SonarCone`]), the likelihood
//!   field of any rig ([`sensors::LikelihoodField`]), and
//!   [`sensors::SensorChoice`] between them.
//! - [`motion`]: the odometry motion model.
//! - [`preset`]: named tunings for a kind of data (the simulator, a real
//!   robot's laser).
//! - [`local_map`]: [`local_map::LocalMap`], the cache of the server's
//!   tiles, their expected-range tables and their distance fields within
//!   a memory budget.
//! - [`range_table`]: per-tile expected sonar ranges, and the plain
//!   reference they are checked against; the occupancy raster and its
//!   exact distance transform both kinds of table are built from.
//! - [`distance_field`]: per-tile distances to the nearest occupied cell,
//!   a byte a cell, for the likelihood field.
//! - [`realign`]: a tracking filter whose frame stops fitting its pose
//!   moved onto where the frame fits, in a small window around it (a
//!   laser's tracking through wheels that slip).
//! - [`ambiguity`]: an estimate whose frame fits as well half a metre
//!   away (along a corridor) is not converged.
//! - [`refine`]: the filter's estimate refined by matching the frame
//!   against the distance field (Gauss–Newton), for the likelihood field.
//! - [`beam_model`]: the likelihood of a measured range given the
//!   expected one.
//! - [`search`]: the global search, branch and bound over a whole map's
//!   poses for those that explain the recent echoes: where a global start
//!   and a lost filter put their particles.
//! - [`searcher`]: [`searcher::Searcher`], the search beside the filter:
//!   a global start from its hypotheses, a lost filter's injections
//!   around them, and convergence believed only once a search finds no
//!   rival.
//! - [`sampling`], [`cluster`], [`gaussian`]: resampling and the KLD
//!   bound, particle clusters and the estimate, normal draws;
//!   [`numeric`]: small helpers for the hot loops.
//!
//! How well it localizes is judged in `deog-evaluation`.

pub mod ambiguity;
pub mod beam_model;
pub mod cluster;
pub mod distance_field;
pub mod error;
pub mod filter;
pub mod gaussian;
pub mod local_map;
pub mod motion;
pub mod numeric;
pub mod preset;
pub mod range_table;
pub mod realign;
pub mod refine;
pub mod sampling;
pub mod search;
pub mod searcher;
pub mod sensors;
pub mod step;
