//! One plan, from a view of the map: the frontiers, the costs of every
//! cell from the robot and the goal worth most against the way there, and
//! the path to it ([`plan_on`]). Pure: the caller reads the map and the
//! other robots' goals, and runs this off its async workers.
//!
//! A plan is tried on the map's cells merged to about 10 cm, then on its
//! own cells with a narrower margin, then with a margin of a few
//! centimetres (a sonar's cones narrow gaps on the map). Frontiers left
//! out of reach even so are looked at from the reachable cell nearest
//! them; with no frontier left, the bands the map has seen but not decided
//! are looked at again from near, while the caller allows.

use deog_grid::{CellBox, CellIndex, Occupancy, OccupancyView, Pose2, Resolution};

use crate::costmap::{CostParams, Costmap};
use crate::error::ExploreError;
use crate::follow::{FollowParams, PathFollower};
use crate::frontier::{Frontier, find_frontiers, find_undecided};
use crate::goal::{Goal, GoalParams, approach_goal, choose_goal_keeping};
use crate::steering::{Plan, PlanRequest};
use crate::travel::TravelCosts;
use crate::window::OccupancyWindow;

/// Bands the map has seen but not decided shorter than this, metres, are
/// not worth a look.
pub const UNDECIDED_MIN_M: f64 = 0.3;
/// A frontier no path reaches is looked at from the reachable cell nearest
/// it, if one lies within this distance, metres.
pub const APPROACH_REACH_M: f64 = 2.0;
/// The margin past the body's radius of the last attempt at a plan, metres.
pub const SQUEEZE_MARGIN_M: f64 = 0.05;
/// A tight plan's share of the cruise speed, and of the distances at
/// which the robot slows and stops short of an echo.
pub const TIGHT_SPEED_SHARE: f64 = 0.5;

/// What every plan of one robot goes by.
#[derive(Debug, Clone, Copy)]
pub struct PlanSettings {
    /// The map's cells.
    pub resolution: Resolution,
    /// The costs on merged cells.
    pub costs: CostParams,
    /// The costs on the map's own cells, where a narrower margin suffices.
    pub fine_costs: CostParams,
    /// The last resort on the map's own cells: a margin of a few
    /// centimetres, for gaps a sonar's cones have narrowed on the map
    /// (the follower's own ranges still stop the robot short of a wall).
    pub squeeze_costs: CostParams,
    /// How goals are chosen.
    pub goals: GoalParams,
    /// How paths are followed.
    pub follow: FollowParams,
    /// Frontiers shorter than this are ignored, metres.
    pub min_frontier_m: f64,
    /// Map cells merged into a planning cell, per side.
    pub coarsening: u32,
}

impl PlanSettings {
    /// The settings for a robot of `body_radius_m` on a map of
    /// `resolution`, planning on cells of about `plan_resolution_m`.
    pub fn for_robot(
        body_radius_m: f64,
        resolution: Resolution,
        plan_resolution_m: f64,
        min_frontier_m: f64,
        follow: FollowParams,
    ) -> Self {
        let costs = CostParams {
            // Paths are planned on 10 cm cells: the margin covers their
            // half-diagonal as well as the pursuit's cutting of corners.
            lethal_radius_m: body_radius_m + 0.15,
            inflation_m: body_radius_m + 0.6,
            ..CostParams::default()
        };
        Self {
            resolution,
            costs,
            // On the map's own (5 cm) cells the half-diagonal is smaller,
            // so a gap 5 cm narrower still lets the robot through.
            fine_costs: CostParams {
                lethal_radius_m: body_radius_m + 0.15 - resolution.metres(),
                ..costs
            },
            squeeze_costs: CostParams {
                lethal_radius_m: body_radius_m + SQUEEZE_MARGIN_M,
                ..costs
            },
            goals: GoalParams::default(),
            follow,
            min_frontier_m,
            coarsening: (plan_resolution_m / resolution.metres()).round().max(1.0) as u32,
        }
    }
}

/// What one plan found, and how much it looked at.
#[derive(Debug, Clone)]
pub struct PlanOutcome {
    /// The plan.
    pub plan: Plan,
    /// Whether its goal is a band the map has seen but not decided.
    pub looked_again: bool,
    /// Cells of the window it was planned on.
    pub cells: usize,
    /// Frontiers found on it.
    pub frontiers: usize,
}

/// One attempt at a plan, on cells of one size.
struct Attempt {
    window: OccupancyWindow,
    costs: TravelCosts,
    chosen: Option<Goal>,
    frontiers: Vec<Frontier>,
    known_nearby: bool,
}

/// A plan on `region` of `view` for `request`, away from the other robots'
/// goals `claims`. `undecided` says which cells the map has observed but
/// not decided; with no frontier left they are looked at again when
/// `look_again`.
pub fn plan_on(
    view: &impl OccupancyView,
    undecided: impl Fn(CellIndex) -> bool,
    region: CellBox,
    claims: &[(f64, f64)],
    request: &PlanRequest,
    look_again: bool,
    settings: &PlanSettings,
) -> Result<PlanOutcome, ExploreError> {
    let fine = OccupancyWindow::from_view(view, region, settings.resolution)?;
    let mut attempt = attempt(
        fine.coarsened(settings.coarsening)?,
        settings.costs,
        claims,
        request,
        settings,
    )?;
    // Nothing reachable on merged cells may be a gap they close: look
    // again on the map's own cells before giving up.
    let mut tight = false;
    if attempt.chosen.is_none() && settings.coarsening > 1 {
        attempt = self::attempt(fine.clone(), settings.fine_costs, claims, request, settings)?;
        tight = true;
    }
    // Still nothing, with frontiers left: squeeze through.
    if attempt.chosen.is_none() && !attempt.frontiers.is_empty() {
        attempt = self::attempt(fine, settings.squeeze_costs, claims, request, settings)?;
        tight = true;
    }
    // No frontier at all: look again, from near, at what the map has
    // seen but not decided, for a while.
    let mut looked_again = false;
    if attempt.chosen.is_none() && attempt.frontiers.is_empty() && look_again {
        attempt.chosen = undecided_goal(&attempt, &undecided, claims, request, settings);
        looked_again = attempt.chosen.is_some();
        tight = true;
    }
    // Frontiers left, none in reach even so: go and look at one from
    // as near as the robot can get.
    if attempt.chosen.is_none() && !attempt.frontiers.is_empty() {
        attempt.chosen = approach_goal(
            &attempt.window,
            &attempt.frontiers,
            &attempt.costs,
            &request.blacklist,
            APPROACH_REACH_M,
            &settings.goals,
        );
    }
    let Attempt {
        window,
        costs,
        chosen,
        frontiers,
        known_nearby,
    } = attempt;
    let (cells, found) = (window.len(), frontiers.len());
    let outcome = |plan| PlanOutcome {
        plan,
        looked_again,
        cells,
        frontiers: found,
    };
    let Some(goal) = chosen else {
        if !known_nearby {
            return Ok(outcome(Plan::LookAbout));
        }
        return Ok(outcome(Plan::Nothing { frontiers: found }));
    };
    let unreachable = |reason: &str| ExploreError::Invalid {
        name: "goal",
        reason: reason.to_string(),
    };
    let goal_index = window
        .index_of(goal.cell)
        .ok_or_else(|| unreachable("lies outside the window it was chosen on"))?;
    let path = costs
        .path_to(&window, goal_index)
        .ok_or_else(|| unreachable("was chosen as reachable but has no path"))?
        .into_iter()
        .map(|cell| window.centre_of(cell))
        .collect();
    // Through a tight gap the robot goes slower, and so may come
    // nearer an echo before it stops: between pillars it could not
    // pass otherwise.
    let follow = if tight {
        let f = settings.follow;
        FollowParams {
            cruise_speed: f.cruise_speed * TIGHT_SPEED_SHARE,
            stop_distance_m: f.stop_distance_m * TIGHT_SPEED_SHARE,
            slow_distance_m: f.slow_distance_m * TIGHT_SPEED_SHARE,
            ..f
        }
    } else {
        settings.follow
    };
    Ok(outcome(Plan::Go {
        goal,
        follower: PathFollower::new(path, follow)?,
        tight,
    }))
}

/// Inflates `window` with `params` and chooses a goal on it.
fn attempt(
    window: OccupancyWindow,
    params: CostParams,
    claims: &[(f64, f64)],
    request: &PlanRequest,
    settings: &PlanSettings,
) -> Result<Attempt, ExploreError> {
    let robot = cell_of(window.resolution(), request.pose)?;
    let costmap = Costmap::inflate(&window, params);
    let costs =
        TravelCosts::from(&window, &costmap, robot).ok_or_else(|| ExploreError::Invalid {
            name: "pose",
            reason: "lies outside the robot's own window".into(),
        })?;
    let known_nearby = window
        .neighbours(window.index_of(robot).unwrap_or(0))
        .any(|(i, _)| window.at(i) == Occupancy::Free);
    let frontiers = find_frontiers(&window, settings.min_frontier_m);
    let chosen = choose_goal_keeping(
        &window,
        &frontiers,
        &costs,
        claims,
        &request.blacklist,
        request.current,
        &settings.goals,
    );
    Ok(Attempt {
        frontiers,
        window,
        costs,
        chosen,
        known_nearby,
    })
}

/// The cell of `pose` at `resolution`.
fn cell_of(resolution: Resolution, pose: Pose2) -> Result<CellIndex, ExploreError> {
    resolution
        .cell_of(pose.x, pose.y)
        .map_err(|error| ExploreError::Invalid {
            name: "pose",
            reason: error.to_string(),
        })
}

/// The best of the bands the map has observed but not decided, beside
/// free cells, on `attempt`'s window and costs (at the map's own cells);
/// `None` if none is reachable or worth a look.
fn undecided_goal(
    attempt: &Attempt,
    undecided: &impl Fn(CellIndex) -> bool,
    claims: &[(f64, f64)],
    request: &PlanRequest,
    settings: &PlanSettings,
) -> Option<Goal> {
    let window = &attempt.window;
    if window.resolution() != settings.resolution {
        return None;
    }
    let marked: Vec<bool> = (0..window.len())
        .map(|index| undecided(window.cell_at(index)))
        .collect();
    let bands = find_undecided(window, &marked, UNDECIDED_MIN_M);
    choose_goal_keeping(
        window,
        &bands,
        &attempt.costs,
        claims,
        &request.blacklist,
        request.current,
        &settings.goals,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::goal::Blacklist;

    /// A room of free cells x in 0..60, y in 0..40 (5 cm cells: 3 m × 2 m),
    /// walled but for an opening in its right wall, unknown beyond.
    struct Room {
        known: bool,
    }

    impl OccupancyView for Room {
        fn occupancy(&self, cell: CellIndex) -> Occupancy {
            let (x, y) = (cell.x, cell.y);
            let inside = (0..60).contains(&x) && (0..40).contains(&y);
            let wall = (-1..=60).contains(&x)
                && (-1..=40).contains(&y)
                && !inside
                && !(x == 60 && (10..30).contains(&y));
            if !self.known {
                Occupancy::Unknown
            } else if wall {
                Occupancy::Occupied
            } else if inside {
                Occupancy::Free
            } else {
                Occupancy::Unknown
            }
        }
    }

    fn settings() -> PlanSettings {
        PlanSettings::for_robot(0.2, Resolution::DEFAULT, 0.1, 0.5, FollowParams::default())
    }

    fn request(x: f64, y: f64) -> PlanRequest {
        PlanRequest {
            pose: Pose2::new(x, y, 0.0),
            now_s: 0.0,
            current: None,
            blacklist: Blacklist::default(),
        }
    }

    fn region() -> CellBox {
        CellBox::new(CellIndex::new(-40, -40), CellIndex::new(100, 80)).expect("a box")
    }

    /// One plan in the room (its cells `known` or not), no cell undecided
    /// and no other robot's goal.
    fn plan_in_room(
        known: bool,
        request: &PlanRequest,
        look_again: bool,
        settings: &PlanSettings,
    ) -> Result<PlanOutcome, ExploreError> {
        plan_on(
            &Room { known },
            |_| false,
            region(),
            &[],
            request,
            look_again,
            settings,
        )
    }

    #[test]
    fn the_opening_in_the_wall_is_the_goal_and_the_path_leads_there() {
        let outcome = plan_in_room(true, &request(0.5, 1.0), false, &settings()).expect("a plan");
        let Plan::Go {
            goal,
            follower,
            tight,
        } = outcome.plan
        else {
            panic!("no goal: {:?}", outcome.plan);
        };
        assert!(!tight, "the opening is a metre wide");
        assert!(goal.x > 2.7 && (0.5..1.5).contains(&goal.y), "{goal:?}");
        let path = follower.remaining();
        let first = path.first().expect("a path");
        assert!((first.0 - 0.5).hypot(first.1 - 1.0) < 0.2, "{first:?}");
        assert_eq!(follower.goal(), *path.last().expect("an end"));
        assert!(outcome.frontiers >= 1 && outcome.cells > 0);
    }

    #[test]
    fn nothing_known_around_the_robot_asks_for_a_look_about() {
        let outcome = plan_in_room(false, &request(0.5, 1.0), false, &settings()).expect("a plan");
        assert!(
            matches!(outcome.plan, Plan::LookAbout),
            "{:?}",
            outcome.plan
        );
    }

    #[test]
    fn a_barred_opening_leaves_its_frontier_but_nothing_to_go_to() {
        let mut barred = request(0.5, 1.0);
        barred.blacklist.add(3.0, 1.0, 100.0);
        let settings = PlanSettings {
            goals: GoalParams {
                blacklist_radius_m: 2.0,
                ..GoalParams::default()
            },
            ..settings()
        };
        let outcome = plan_in_room(true, &barred, true, &settings).expect("a plan");
        assert!(
            matches!(outcome.plan, Plan::Nothing { frontiers } if frontiers >= 1),
            "{:?}",
            outcome.plan
        );
        assert!(!outcome.looked_again);
    }

    #[test]
    fn a_plan_from_outside_the_window_is_refused() {
        let error =
            plan_in_room(true, &request(50.0, 50.0), false, &settings()).expect_err("outside");
        assert!(error.to_string().contains("pose"), "{error}");
    }
}
