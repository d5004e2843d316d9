//! Which frontier to drive to: information gain (the frontier's length)
//! against travel cost, discounted near goals other robots have taken
//! (Burgard, Moors, Stachniss and Schneider, 2005), never one blacklisted
//! after it could not be reached; and, when none can be reached, where to
//! look at one from.

use std::collections::BinaryHeap;

use deog_grid::CellIndex;

use crate::costmap::MinQueued;
use crate::frontier::Frontier;
use crate::travel::TravelCosts;
use crate::window::OccupancyWindow;

/// How goals are scored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalParams {
    /// Metres of travel one metre of frontier is worth.
    pub gain_weight: f64,
    /// Goals of other robots within this distance, metres, take from a
    /// frontier's worth.
    pub claim_radius_m: f64,
    /// How much a claimed frontier's gain is cut (0: not at all, 1: all),
    /// falling off linearly to nothing at the claim radius.
    pub claim_discount: f64,
    /// A blacklisted place bars frontier cells within this distance, metres.
    pub blacklist_radius_m: f64,
    /// What a robot's current goal is worth on top of its score, weighted
    /// metres: a new goal must beat it by this much, so that a robot does
    /// not swing between two frontiers of about the same worth.
    pub persistence_m: f64,
    /// A frontier keeps being the current goal's while one of its cells
    /// lies within this distance of it, metres.
    pub current_radius_m: f64,
}

impl Default for GoalParams {
    fn default() -> Self {
        Self {
            gain_weight: 3.0,
            claim_radius_m: 4.0,
            claim_discount: 0.9,
            blacklist_radius_m: 0.6,
            persistence_m: 4.0,
            current_radius_m: 1.0,
        }
    }
}

/// A chosen goal.
#[derive(Debug, Clone, PartialEq)]
pub struct Goal {
    /// The frontier cell driven to.
    pub cell: CellIndex,
    /// Its centre, metres.
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// The length of its frontier, metres.
    pub frontier_m: f64,
    /// The travel cost to it, weighted metres.
    pub travel_m: f64,
    /// Its score: gain less travel.
    pub score: f64,
    /// The centres of its frontier's cells, metres.
    pub frontier_cells: Vec<(f64, f64)>,
    /// Whether it is no frontier cell but the reachable cell nearest an
    /// unreachable frontier ([`approach_goal`]).
    pub approach: bool,
}

/// Places not to drive to, each until a time.
#[derive(Debug, Clone, Default)]
pub struct Blacklist {
    /// (x, y, until, radius: `None` for the caller's).
    entries: Vec<(f64, f64, f64, Option<f64>)>,
    /// Where goals failed before ([`Blacklist::bar_failure`]), kept when
    /// their bars run out.
    failures: Vec<(f64, f64)>,
}

impl Blacklist {
    /// Bars the place (x, y) until `until_s`, within the radius
    /// [`Blacklist::bars`] is asked with.
    pub fn add(&mut self, x: f64, y: f64, until_s: f64) {
        self.entries.push((x, y, until_s, None));
    }

    /// Bars the cells within `radius_m` of (x, y) until `until_s`.
    pub fn add_within(&mut self, x: f64, y: f64, radius_m: f64, until_s: f64) {
        self.entries.push((x, y, until_s, Some(radius_m)));
    }

    /// Bars a goal at (x, y) the robot failed to reach at `now_s`: for
    /// `first_s` seconds, or for `again_s` when a goal within `radius_m`
    /// of it failed before (a place tried twice is given up). Returns
    /// whether it was the first failure there.
    pub fn bar_failure(
        &mut self,
        (x, y): (f64, f64),
        now_s: f64,
        (first_s, again_s): (f64, f64),
        radius_m: f64,
    ) -> bool {
        let again = self
            .failures
            .iter()
            .any(|&(fx, fy)| (fx - x).hypot(fy - y) <= radius_m);
        if again {
            self.add(x, y, now_s + again_s);
        } else {
            self.add(x, y, now_s + first_s);
            self.failures.push((x, y));
        }
        !again
    }

    /// Forgets entries that ran out by `now_s`.
    pub fn expire(&mut self, now_s: f64) {
        self.entries.retain(|&(_, _, until, _)| until > now_s);
    }

    /// Whether (x, y) lies within `radius` of a barred place (or within
    /// the place's own radius, when it was barred with one).
    pub fn bars(&self, x: f64, y: f64, radius: f64) -> bool {
        self.entries
            .iter()
            .any(|&(bx, by, _, own)| (bx - x).hypot(by - y) <= own.unwrap_or(radius))
    }

    /// Places barred now.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether nothing is barred.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// The best goal among `frontiers`, or `None` when no frontier can be
/// reached. Each frontier is driven to at its cheapest reachable cell not
/// barred; `claims` are other robots' goals.
pub fn choose_goal(
    window: &OccupancyWindow,
    frontiers: &[Frontier],
    costs: &TravelCosts,
    claims: &[(f64, f64)],
    blacklist: &Blacklist,
    params: &GoalParams,
) -> Option<Goal> {
    choose_goal_keeping(window, frontiers, costs, claims, blacklist, None, params)
}

/// As [`choose_goal`], for a robot already driving to `current`: the
/// frontier still holding it is worth `persistence_m` more.
pub fn choose_goal_keeping(
    window: &OccupancyWindow,
    frontiers: &[Frontier],
    costs: &TravelCosts,
    claims: &[(f64, f64)],
    blacklist: &Blacklist,
    current: Option<(f64, f64)>,
    params: &GoalParams,
) -> Option<Goal> {
    let mut best: Option<Goal> = None;
    for frontier in frontiers {
        let Some((index, travel_m)) = frontier
            .cells
            .iter()
            .filter(|&&index| costs.reaches(index))
            .filter(|&&index| {
                let (x, y) = window.centre_of(window.cell_at(index));
                !blacklist.bars(x, y, params.blacklist_radius_m)
            })
            .map(|&index| (index, costs.cost_m(index)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
        else {
            continue;
        };
        let cell = window.cell_at(index);
        let (x, y) = window.centre_of(cell);
        let claimed = claims
            .iter()
            .map(|&(cx, cy)| {
                let near = (cx - x)
                    .hypot(cy - y)
                    .min((cx - frontier.centroid.0).hypot(cy - frontier.centroid.1));
                (1.0 - near / params.claim_radius_m).clamp(0.0, 1.0)
            })
            .fold(0.0, f64::max);
        let gain = params.gain_weight * frontier.size_m * (1.0 - params.claim_discount * claimed);
        let kept = current.is_some_and(|(gx, gy)| {
            frontier.cells.iter().any(|&index| {
                let (fx, fy) = window.centre_of(window.cell_at(index));
                (fx - gx).hypot(fy - gy) <= params.current_radius_m
            })
        });
        let score = gain - travel_m + if kept { params.persistence_m } else { 0.0 };
        if best.as_ref().is_none_or(|b| score > b.score) {
            best = Some(Goal {
                cell,
                x,
                y,
                frontier_m: frontier.size_m,
                travel_m,
                score,
                frontier_cells: centres(window, frontier),
                approach: false,
            });
        }
    }
    best
}

/// When no frontier can be reached: the reachable cell nearest to one in
/// a straight line (within `reach_m`; the cheaper to reach among equals),
/// to look at it from near. A sonar's cone seen from afar closes the gap
/// between two pillars on the map; from near it fits through, and the
/// way opens. Frontier cells and cells barred by `blacklist` are not
/// used; `None` if no reachable cell lies within reach.
pub fn approach_goal(
    window: &OccupancyWindow,
    frontiers: &[Frontier],
    costs: &TravelCosts,
    blacklist: &Blacklist,
    reach_m: f64,
    params: &GoalParams,
) -> Option<Goal> {
    let metres = window.resolution().metres();
    let barred = |index: usize| {
        let (x, y) = window.centre_of(window.cell_at(index));
        blacklist.bars(x, y, params.blacklist_radius_m)
    };
    // Straight-line distance to the nearest frontier cell, and which
    // frontier, by a brushfire from every frontier cell not barred.
    let mut nearest = vec![(f64::INFINITY, usize::MAX); window.len()];
    let mut queue = BinaryHeap::new();
    for (which, frontier) in frontiers.iter().enumerate() {
        for &index in frontier.cells.iter().filter(|&&index| !barred(index)) {
            nearest[index] = (0.0, which);
            queue.push(MinQueued(0.0, index));
        }
    }
    while let Some(MinQueued(d, index)) = queue.pop() {
        if d > nearest[index].0 {
            continue;
        }
        for (next, length) in window.neighbours(index) {
            let candidate = d + length * metres;
            if candidate <= reach_m && candidate < nearest[next].0 {
                nearest[next] = (candidate, nearest[index].1);
                queue.push(MinQueued(candidate, next));
            }
        }
    }
    let (index, distance) = (0..window.len())
        .filter(|&index| nearest[index].0 > 0.0 && nearest[index].0.is_finite())
        .filter(|&index| costs.reaches(index) && !barred(index))
        .map(|index| (index, nearest[index].0))
        .min_by(|a, b| {
            a.1.total_cmp(&b.1)
                .then(costs.cost_m(a.0).total_cmp(&costs.cost_m(b.0)))
        })?;
    let frontier = &frontiers[nearest[index].1];
    let cell = window.cell_at(index);
    let (x, y) = window.centre_of(cell);
    Some(Goal {
        cell,
        x,
        y,
        frontier_m: frontier.size_m,
        travel_m: costs.cost_m(index),
        score: -distance,
        frontier_cells: centres(window, frontier),
        approach: true,
    })
}

/// The centres of a frontier's cells, metres.
fn centres(window: &OccupancyWindow, frontier: &Frontier) -> Vec<(f64, f64)> {
    frontier
        .cells
        .iter()
        .map(|&index| window.centre_of(window.cell_at(index)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{CostParams, Costmap};
    use crate::frontier::find_frontiers;
    use deog_grid::Resolution;

    fn corridor() -> OccupancyWindow {
        // A corridor open at both ends; the robot near the left end.
        let rows = [
            "##############################",
            "?............................?",
            "?............................?",
            "?............................?",
            "##############################",
        ];
        OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), Resolution::new(0.1).unwrap())
    }

    /// The corridor's frontiers are short: their gain must be worth its
    /// length for the claims to matter.
    fn params() -> GoalParams {
        GoalParams {
            gain_weight: 10.0,
            claim_radius_m: 1.0,
            ..GoalParams::default()
        }
    }

    fn setup() -> (OccupancyWindow, Vec<Frontier>, TravelCosts) {
        let window = corridor();
        let params = CostParams {
            lethal_radius_m: 0.05,
            inflation_m: 0.1,
            ..CostParams::default()
        };
        let costmap = Costmap::inflate(&window, params);
        let costs = TravelCosts::from(&window, &costmap, CellIndex::new(4, 2)).unwrap();
        let frontiers = find_frontiers(&window, 0.0);
        (window, frontiers, costs)
    }

    #[test]
    fn a_frontier_past_a_gap_too_narrow_is_looked_at_from_the_nearest_reachable_cell() {
        // A room whose right wall has a one-cell gap: too narrow for the
        // robot's radius, and past it an open space ending in unknown.
        let rows = [
            "##############",
            "#....#......??",
            "#....#......??",
            "#...........??",
            "#....#......??",
            "#....#......??",
            "##############",
        ];
        let window =
            OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), Resolution::new(0.1).unwrap());
        let costs_params = CostParams {
            lethal_radius_m: 0.15,
            inflation_m: 0.3,
            ..CostParams::default()
        };
        let costmap = Costmap::inflate(&window, costs_params);
        let costs = TravelCosts::from(&window, &costmap, CellIndex::new(2, 3)).unwrap();
        let frontiers = find_frontiers(&window, 0.0);
        assert_eq!(frontiers.len(), 1, "{frontiers:?}");
        let none = Blacklist::default();
        assert!(choose_goal(&window, &frontiers, &costs, &[], &none, &params()).is_none());
        let goal = approach_goal(&window, &frontiers, &costs, &none, 2.0, &params()).unwrap();
        // The reachable cell nearest the frontier in a straight line, the
        // cheapest of the three as near.
        assert!(goal.approach);
        assert_eq!(goal.cell, CellIndex::new(3, 3), "{goal:?}");
        assert!((goal.score + 0.8).abs() < 1e-9, "{goal:?}");
        assert_eq!(goal.frontier_cells.len(), frontiers[0].cells.len());
        // Once looked from there, the next nearest place not barred.
        let mut barred = Blacklist::default();
        barred.add_within(goal.x, goal.y, 0.05, 100.0);
        let next = approach_goal(&window, &frontiers, &costs, &barred, 2.0, &params()).unwrap();
        assert_eq!(next.cell.x, 3, "{next:?}");
        assert_ne!(next.cell, goal.cell);
        // Out of reach: nothing.
        assert!(approach_goal(&window, &frontiers, &costs, &none, 0.5, &params()).is_none());
    }

    #[test]
    fn the_nearer_of_two_equal_frontiers_wins() {
        let (window, frontiers, costs) = setup();
        let goal = choose_goal(
            &window,
            &frontiers,
            &costs,
            &[],
            &Blacklist::default(),
            &params(),
        )
        .unwrap();
        assert_eq!(goal.cell.x, 1, "{goal:?}");
    }

    #[test]
    fn a_frontier_another_robot_claimed_gives_way_to_a_farther_one() {
        let (window, frontiers, costs) = setup();
        let claims = [(0.15, 0.25)];
        let goal = choose_goal(
            &window,
            &frontiers,
            &costs,
            &claims,
            &Blacklist::default(),
            &params(),
        )
        .unwrap();
        assert_eq!(goal.cell.x, 28, "{goal:?}");
    }

    #[test]
    fn the_current_goal_holds_against_a_slightly_better_one() {
        let (window, frontiers, costs) = setup();
        let params = params();
        // The far end is about 2.1 m farther: worth keeping with a
        // persistence above that, not below.
        let far = Some((2.85, 0.25));
        let keeping = |persistence_m| {
            let params = GoalParams {
                persistence_m,
                ..params
            };
            choose_goal_keeping(
                &window,
                &frontiers,
                &costs,
                &[],
                &Blacklist::default(),
                far,
                &params,
            )
            .unwrap()
            .cell
            .x
        };
        assert_eq!(keeping(3.0), 28);
        assert_eq!(keeping(2.0), 1);
    }

    #[test]
    fn blacklisted_frontiers_are_skipped_until_they_expire() {
        let (window, frontiers, costs) = setup();
        let mut blacklist = Blacklist::default();
        blacklist.add(0.15, 0.25, 10.0);
        let params = params();
        let goal = choose_goal(&window, &frontiers, &costs, &[], &blacklist, &params).unwrap();
        assert_eq!(goal.cell.x, 28);
        blacklist.expire(10.0);
        assert!(blacklist.is_empty());
        let goal = choose_goal(&window, &frontiers, &costs, &[], &blacklist, &params).unwrap();
        assert_eq!(goal.cell.x, 1);
        // A frontier's cells barred one by one bar it too.
        let mut cells = Blacklist::default();
        for x in [0.15, 2.85] {
            for y in [0.15, 0.25, 0.35] {
                cells.add_within(x, y, 0.05, 10.0);
            }
        }
        assert_eq!(
            choose_goal(&window, &frontiers, &costs, &[], &cells, &params),
            None
        );
        // Everything barred: no goal.
        blacklist.add(0.15, 0.25, 20.0);
        blacklist.add(2.85, 0.25, 20.0);
        assert_eq!(
            choose_goal(&window, &frontiers, &costs, &[], &blacklist, &params),
            None
        );
    }

    #[test]
    fn a_place_failed_twice_stays_barred_longer() {
        let mut blacklist = Blacklist::default();
        let times = (60.0, 3600.0);
        assert!(blacklist.bar_failure((1.0, 1.0), 0.0, times, 0.6));
        blacklist.expire(61.0);
        assert!(blacklist.is_empty(), "the first bar ran out");
        // Failing again near the same place bars it for the longer time.
        assert!(!blacklist.bar_failure((1.3, 1.0), 100.0, times, 0.6));
        blacklist.expire(3000.0);
        assert!(blacklist.bars(1.3, 1.0, 0.6));
        // Elsewhere, a first failure again.
        assert!(blacklist.bar_failure((5.0, 1.0), 100.0, times, 0.6));
        blacklist.expire(3701.0);
        assert!(blacklist.is_empty());
    }
}
