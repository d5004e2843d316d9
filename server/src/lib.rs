//! The map server: the central storage of deog (the thesis's Centralized
//! Storage System, section 7.1).
//!
//! # Layout
//! This crate holds the gRPC `MapService` of `deog-proto` over an embedded
//! store. Its tile arithmetic is `deog-grid`'s [`Tile`](deog_grid::Tile); the
//! service itself is not written yet, and nothing here serves requests.
