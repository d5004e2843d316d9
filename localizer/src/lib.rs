//! Monte Carlo Localization on a deog map.
//!
//! # Layout
//! This crate will hold the particle filter (motion model, sonar beam model,
//! resampling, KLD sampling, recovery). The expected range of a beam comes from
//! [`deog_grid::cast_cone`]. It holds no code yet.
