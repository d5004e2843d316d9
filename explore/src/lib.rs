//! Frontier exploration on an occupancy grid, pure: no I/O, no async. The
//! edge (`deog explore`) reads the shared map, runs these steps, and
//! drives the robot.
//!
//! # Layout
//! - [`window`]: [`OccupancyWindow`], a rectangle of the map's cells as
//!   free, occupied or unknown, copied once from any `OccupancyView`.
//! - [`costmap`]: [`Costmap`], each cell's clearance from walls, lethal
//!   within the robot's radius, dearer within the inflation distance,
//!   unknown cells at a premium.
//! - [`travel`]: [`TravelCosts`], Dijkstra from the robot over the
//!   costmap: the cost to every cell at once and the path to any.
//! - [`frontier`]: [`find_frontiers`], free cells beside unknown ones,
//!   clustered.
//! - [`goal`]: [`choose_goal`], gain against travel, discounted near other
//!   robots' goals, never a blacklisted place; [`choose_goal_keeping`]
//!   holds a robot to its current goal unless another is clearly better.
//! - [`follow`]: [`PathFollower`], pure pursuit along a path, slowing and
//!   stopping for what the robot's own ranges see ahead.
//! - [`planning`]: [`plan_on`], one plan from a view of the map: on
//!   merged cells, then the map's own, then squeezing through; a look
//!   from near at frontiers out of reach or at bands not yet decided.
//! - [`steering`]: [`Steering`], the decisions one robot state at a
//!   time: the plan to follow, when to ask for the next, a goal reached
//!   or stalled and what that bars, looking about, and when the map is
//!   explored; the edge drives, publishes and plans as it says.
//! - [`dead_reckoning`]: [`DeadReckoning`], a localizer's newest
//!   estimate carried forward by odometry: the pose to steer from when
//!   no true pose is known.
//! - [`error`]: [`ExploreError`], what the steps refuse.

pub mod costmap;
pub mod dead_reckoning;
pub mod error;
pub mod follow;
pub mod frontier;
pub mod goal;
pub mod planning;
pub mod steering;
pub mod travel;
pub mod window;

pub use costmap::{CostParams, Costmap};
pub use dead_reckoning::DeadReckoning;
pub use error::ExploreError;
pub use follow::{Clearance, FollowCommand, FollowParams, PathFollower};
pub use frontier::{Frontier, find_frontiers, find_undecided};
pub use goal::{Blacklist, Goal, GoalParams, approach_goal, choose_goal, choose_goal_keeping};
pub use planning::{PlanOutcome, PlanSettings, plan_on};
pub use steering::{Decision, Plan, PlanRequest, Steering, SteeringEvent, SteeringParams};
pub use travel::TravelCosts;
pub use window::OccupancyWindow;
