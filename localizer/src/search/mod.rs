//! Global search: the poses on a whole map (or in a window of it) that
//! best explain a robot's recent echoes, found coarse to fine by branch
//! and bound, so that its cost grows with how ambiguous the map is, not
//! with how much free space it has. The filter starts from its
//! hypotheses instead of particles spread over every free cell, and a
//! lost filter searches again from them; a SLAM back end finds loop
//! closures with the same search in a window.
//!
//! # Layout
//! - [`grid`]: [`SearchGrid`], the map's scores (high on and near walls)
//!   and their block maxima, one level per doubling of the block.
//! - [`cloud`]: [`ScanCloud`], echoes as points in the robot's frame
//!   (sonar cones as groups), and [`RecentFrames`], the last frames
//!   carried to the present by the odometry.
//! - [`branch_bound`]: [`search`] itself (whole, or in slices as a
//!   [`SearchJob`]), its [`SearchSettings`] and what
//!   it returns ([`SearchOutcome`], [`Hypothesis`]).
//!
//! Pure and synchronous, as the rest of the crate.

pub mod branch_bound;
pub mod cloud;
pub mod grid;

pub use branch_bound::{
    Hypothesis, SearchJob, SearchOutcome, SearchSettings, SearchWindow, score_pose, search,
};
pub use cloud::{RecentFrames, ScanCloud};
pub use grid::{MAX_SEARCH_CELLS, SearchCell, SearchGrid};

#[cfg(test)]
mod tests;
