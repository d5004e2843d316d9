//! Travel costs from the robot to every cell of a window at once
//! (Dijkstra over the costmap), and the cheapest path to any of them.
//! One search prices every frontier.

use std::collections::BinaryHeap;

use deog_grid::CellIndex;

use crate::costmap::{Costmap, MinQueued};
use crate::window::OccupancyWindow;

/// No parent: the start, or a cell never reached.
const NONE: u32 = u32::MAX;

/// The cheapest cost from one start to each cell, and how to get there.
#[derive(Debug, Clone)]
pub struct TravelCosts {
    cost: Vec<f64>,
    parent: Vec<u32>,
    start: usize,
    metres: f64,
}

impl TravelCosts {
    /// Costs from `start` (which must lie in the window). A start too
    /// close to a wall is left: lethal cells may be crossed only on the
    /// way out of the lethal region the start is in, each step away from
    /// the wall.
    pub fn from(window: &OccupancyWindow, costmap: &Costmap, start: CellIndex) -> Option<Self> {
        let start = window.index_of(start)?;
        let mut cost = vec![f64::INFINITY; window.len()];
        let mut parent = vec![NONE; window.len()];
        let mut queue = BinaryHeap::new();
        cost[start] = 0.0;
        queue.push(MinQueued(0.0, start));
        while let Some(MinQueued(c, index)) = queue.pop() {
            if c > cost[index] {
                continue;
            }
            let escaping = costmap.is_lethal(index);
            for (next, length) in window.neighbours(index) {
                let factor = if costmap.is_lethal(next) {
                    if !(escaping && costmap.clearance_m(next) > costmap.clearance_m(index)) {
                        continue;
                    }
                    // Leaving a wall's reach: dear, but possible.
                    10.0
                } else {
                    costmap.step_factor(next)
                };
                let candidate = c + length * factor;
                if candidate < cost[next] {
                    cost[next] = candidate;
                    parent[next] = index as u32;
                    queue.push(MinQueued(candidate, next));
                }
            }
        }
        Some(Self {
            cost,
            parent,
            start,
            metres: window.resolution().metres(),
        })
    }

    /// The cost of reaching the cell at `index`, metres weighted by the
    /// costmap; infinite if it cannot be reached.
    pub fn cost_m(&self, index: usize) -> f64 {
        self.cost[index] * self.metres
    }

    /// Whether the cell at `index` can be reached.
    pub fn reaches(&self, index: usize) -> bool {
        self.cost[index].is_finite()
    }

    /// The cells from the start to the cell at `goal`, both included;
    /// `None` if it cannot be reached.
    pub fn path_to(&self, window: &OccupancyWindow, goal: usize) -> Option<Vec<CellIndex>> {
        if !self.reaches(goal) {
            return None;
        }
        let mut path = vec![window.cell_at(goal)];
        let mut at = goal;
        while at != self.start {
            let parent = self.parent[at];
            if parent == NONE {
                return None;
            }
            at = parent as usize;
            path.push(window.cell_at(at));
        }
        path.reverse();
        Some(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::CostParams;
    use deog_grid::Resolution;

    fn no_inflation() -> CostParams {
        CostParams {
            lethal_radius_m: 0.0,
            inflation_m: 0.0,
            proximity_weight: 0.0,
            unknown_factor: 3.0,
        }
    }

    #[test]
    fn a_path_goes_round_a_wall_and_never_through_it() {
        let rows = ["..........", "..........", "#########.", ".........."];
        let resolution = Resolution::new(0.1).unwrap();
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        let costmap = Costmap::inflate(&window, no_inflation());
        let costs = TravelCosts::from(&window, &costmap, CellIndex::new(0, 0)).unwrap();
        let goal = window.index_of(CellIndex::new(0, 3)).unwrap();
        let path = costs.path_to(&window, goal).unwrap();
        assert_eq!(path.first(), Some(&CellIndex::new(0, 0)));
        assert_eq!(path.last(), Some(&CellIndex::new(0, 3)));
        assert!(
            path.iter()
                .all(|c| window.occupancy_of(*c) != deog_grid::Occupancy::Occupied)
        );
        assert!(
            path.iter().any(|c| c.x == 9),
            "through the gap at the end: {path:?}"
        );
        // Each step is to a neighbour.
        assert!(
            path.windows(2)
                .all(|w| (w[0].x - w[1].x).abs() <= 1 && (w[0].y - w[1].y).abs() <= 1)
        );
        assert!(costs.cost_m(goal) > 1.6);
    }

    #[test]
    fn a_walled_off_cell_is_not_reached() {
        let rows = ["..#..", "..#..", "..#.."];
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), Resolution::DEFAULT);
        let costmap = Costmap::inflate(&window, no_inflation());
        let costs = TravelCosts::from(&window, &costmap, CellIndex::new(0, 1)).unwrap();
        let beyond = window.index_of(CellIndex::new(4, 1)).unwrap();
        assert!(!costs.reaches(beyond));
        assert_eq!(costs.path_to(&window, beyond), None);
        assert!(TravelCosts::from(&window, &costmap, CellIndex::new(40, 0)).is_none());
    }

    #[test]
    fn a_start_against_a_wall_gets_away_from_it() {
        let rows = ["#.........", "#.........", "#........."];
        let resolution = Resolution::new(0.1).unwrap();
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        let params = CostParams {
            lethal_radius_m: 0.25,
            ..CostParams::default()
        };
        let costmap = Costmap::inflate(&window, params);
        let start = CellIndex::new(1, 1);
        assert!(costmap.is_lethal(window.index_of(start).unwrap()));
        let costs = TravelCosts::from(&window, &costmap, start).unwrap();
        assert!(costs.reaches(window.index_of(CellIndex::new(9, 1)).unwrap()));
    }
}
