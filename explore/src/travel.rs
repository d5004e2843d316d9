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

    mod properties {
        use super::*;
        use proptest::prelude::*;

        /// A window of up to 12 × 12 cells, each free, occupied or unknown,
        /// with a start on a free cell.
        fn window_and_start() -> impl Strategy<Value = (Vec<String>, (usize, usize))> {
            (2..12usize, 2..12usize).prop_flat_map(|(width, height)| {
                let row = prop::collection::vec(
                    prop::sample::select(vec!['.', '.', '.', '#', '?']),
                    width,
                )
                .prop_map(|cells| cells.into_iter().collect::<String>());
                (prop::collection::vec(row, height), (0..width, 0..height))
            })
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(200))]

            /// The costs are a shortest-path solution: no step into a
            /// cell the costmap lets one enter would make it cheaper, the
            /// cells reached are those a flood through enterable cells
            /// reaches, and each path goes from the start by neighbours
            /// through enterable cells at exactly the cost reported.
            #[test]
            fn costs_are_shortest_paths_and_paths_cost_what_they_say(
                (mut rows, (sx, sy)) in window_and_start(),
                proximity_weight in 0.0..4.0f64,
            ) {
                let height = rows.len();
                // The start on a free cell (rows run from the top down).
                let row = height - 1 - sy;
                rows[row].replace_range(sx..sx + 1, ".");
                let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
                let resolution = Resolution::new(0.1).unwrap();
                let window = OccupancyWindow::from_rows(&rows, CellIndex::new(-3, 5), resolution);
                let costmap = Costmap::inflate(&window, CostParams {
                    proximity_weight,
                    inflation_m: 0.25,
                    ..no_inflation()
                });
                let start = CellIndex::new(-3 + sx as i32, 5 + sy as i32);
                let costs = TravelCosts::from(&window, &costmap, start).unwrap();
                let start_index = window.index_of(start).unwrap();
                prop_assert_eq!(costs.cost_m(start_index), 0.0);

                // Bellman: no cheaper way into any enterable neighbour.
                for index in 0..window.len() {
                    if !costs.reaches(index) {
                        continue;
                    }
                    for (next, length) in window.neighbours(index) {
                        if costmap.is_lethal(next) {
                            continue;
                        }
                        let through = costs.cost_m(index) + length * costmap.step_factor(next) * 0.1;
                        prop_assert!(costs.cost_m(next) <= through + 1e-9);
                    }
                }

                // Reached: a flood from the start through enterable cells.
                let mut flooded = vec![false; window.len()];
                let mut stack = vec![start_index];
                flooded[start_index] = true;
                while let Some(index) = stack.pop() {
                    for (next, _) in window.neighbours(index) {
                        if !flooded[next] && !costmap.is_lethal(next) {
                            flooded[next] = true;
                            stack.push(next);
                        }
                    }
                }
                for (index, &flooded) in flooded.iter().enumerate() {
                    prop_assert_eq!(costs.reaches(index), flooded);
                }

                // Each path: from the start, by neighbours, at its cost.
                for goal in (0..window.len()).filter(|&i| costs.reaches(i)) {
                    let path = costs.path_to(&window, goal).unwrap();
                    prop_assert_eq!(path[0], start);
                    prop_assert_eq!(*path.last().unwrap(), window.cell_at(goal));
                    let mut cost = 0.0;
                    for step in path.windows(2) {
                        let (dx, dy) = (step[1].x - step[0].x, step[1].y - step[0].y);
                        prop_assert!(dx.abs() <= 1 && dy.abs() <= 1 && (dx, dy) != (0, 0));
                        let next = window.index_of(step[1]).unwrap();
                        prop_assert!(!costmap.is_lethal(next));
                        let length = if dx != 0 && dy != 0 { std::f64::consts::SQRT_2 } else { 1.0 };
                        cost += length * costmap.step_factor(next) * 0.1;
                    }
                    prop_assert!((cost - costs.cost_m(goal)).abs() < 1e-9);
                }
            }
        }
    }
}
