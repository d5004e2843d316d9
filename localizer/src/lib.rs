//! Monte Carlo Localization of a sonar robot on a deog map, and the
//! measures that judge it.
//!
//! Everything here is pure and synchronous: the `deog localize` process
//! fetches tiles and frames over the network and feeds them in.
//!
//! # Layout
//! - [`evaluation`]: localization accuracy from true poses and estimates
//!   (the thesis's Tables 7.3 to 7.7, convergence, kidnap recovery) and the
//!   path plot.

pub mod beam_model;
pub mod cluster;
pub mod error;
pub mod evaluation;
pub mod filter;
pub mod gaussian;
pub mod local_map;
pub mod motion;
pub mod range_table;
pub mod sampling;
