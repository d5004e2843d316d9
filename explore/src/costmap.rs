//! What driving through each cell costs: its clearance from the nearest
//! occupied cell, cells closer than the robot's radius lethal, cells
//! within the inflation distance dearer the closer they are, unknown
//! cells allowed at a premium (sonar maps have gaps; the follower's own
//! ranges keep the robot off walls the map has not got).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use deog_grid::Occupancy;

use crate::window::OccupancyWindow;

/// How the costmap is inflated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostParams {
    /// The robot's radius plus a margin, metres: closer to a wall is lethal.
    pub lethal_radius_m: f64,
    /// Up to this clearance, metres, a cell costs more the closer it is.
    pub inflation_m: f64,
    /// The most a cell's closeness multiplies its step cost by, on top of 1.
    pub proximity_weight: f64,
    /// What an unknown cell's step costs against a free one's.
    pub unknown_factor: f64,
}

impl Default for CostParams {
    fn default() -> Self {
        Self {
            lethal_radius_m: 0.28,
            inflation_m: 0.7,
            proximity_weight: 4.0,
            unknown_factor: 3.0,
        }
    }
}

/// Per cell of a window: its clearance and what a step into it costs.
#[derive(Debug, Clone)]
pub struct Costmap {
    clearance_m: Vec<f64>,
    step_factor: Vec<f64>,
    params: CostParams,
}

/// A cell in a min-heap by cost.
#[derive(PartialEq)]
pub(crate) struct MinQueued(pub f64, pub usize);

impl Eq for MinQueued {}

impl Ord for MinQueued {
    fn cmp(&self, other: &Self) -> Ordering {
        // A min-heap on the first field.
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

impl PartialOrd for MinQueued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Costmap {
    /// The costmap of `window`.
    pub fn inflate(window: &OccupancyWindow, params: CostParams) -> Self {
        let metres = window.resolution().metres();
        // Clearance past the inflation distance changes nothing: the
        // brushfire stops there, and farther cells count as open.
        let clearance_m = clearance(
            window,
            metres,
            params.inflation_m.max(params.lethal_radius_m) + metres,
        );
        let span = (params.inflation_m - params.lethal_radius_m).max(metres);
        let step_factor = clearance_m
            .iter()
            .enumerate()
            .map(|(index, &clear)| {
                if window.at(index) == Occupancy::Occupied || clear < params.lethal_radius_m {
                    return f64::INFINITY;
                }
                let closeness = ((params.inflation_m - clear) / span).clamp(0.0, 1.0);
                let unknown = if window.at(index) == Occupancy::Unknown {
                    params.unknown_factor
                } else {
                    1.0
                };
                (1.0 + params.proximity_weight * closeness) * unknown
            })
            .collect();
        Self {
            clearance_m,
            step_factor,
            params,
        }
    }

    /// Metres from the cell at `index` to the nearest occupied cell
    /// (infinite where none lies within the inflation distance).
    pub fn clearance_m(&self, index: usize) -> f64 {
        self.clearance_m[index]
    }

    /// What a step of one cell into the cell at `index` costs, in cells;
    /// infinite for a lethal cell.
    pub fn step_factor(&self, index: usize) -> f64 {
        self.step_factor[index]
    }

    /// Whether the cell at `index` is too close to a wall to enter.
    pub fn is_lethal(&self, index: usize) -> bool {
        self.step_factor[index].is_infinite()
    }

    /// The parameters it was inflated with.
    pub fn params(&self) -> CostParams {
        self.params
    }
}

/// Distance from each cell to the nearest occupied one, metres, up to
/// `limit_m` (infinite beyond): a brushfire over the 8-connected grid
/// (within a few per cent of the Euclidean distance).
fn clearance(window: &OccupancyWindow, metres: f64, limit_m: f64) -> Vec<f64> {
    let mut distance = vec![f64::INFINITY; window.len()];
    let mut queue = BinaryHeap::new();
    for (index, slot) in distance.iter_mut().enumerate() {
        if window.at(index) == Occupancy::Occupied {
            *slot = 0.0;
            queue.push(MinQueued(0.0, index));
        }
    }
    while let Some(MinQueued(d, index)) = queue.pop() {
        if d > distance[index] {
            continue;
        }
        for (next, length) in window.neighbours(index) {
            let candidate = d + length * metres;
            if candidate < distance[next] && candidate <= limit_m {
                distance[next] = candidate;
                queue.push(MinQueued(candidate, next));
            }
        }
    }
    distance
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::{CellIndex, Resolution};

    #[test]
    fn cells_near_walls_are_lethal_then_dearer_then_plain() {
        let resolution = Resolution::new(0.1).unwrap();
        let row = format!("#{}", ".".repeat(20));
        let window = OccupancyWindow::from_rows(&[&row], CellIndex::new(0, 0), resolution);
        let params = CostParams {
            lethal_radius_m: 0.25,
            inflation_m: 0.6,
            proximity_weight: 4.0,
            unknown_factor: 3.0,
        };
        let costmap = Costmap::inflate(&window, params);
        assert!((costmap.clearance_m(5) - 0.5).abs() < 1e-9);
        assert!(costmap.is_lethal(1) && costmap.is_lethal(2));
        assert!(!costmap.is_lethal(3));
        assert!(costmap.step_factor(3) > costmap.step_factor(5));
        assert_eq!(costmap.step_factor(10), 1.0);
    }

    #[test]
    fn unknown_cells_cost_more_than_free_ones() {
        let window =
            OccupancyWindow::from_rows(&["..??"], CellIndex::new(0, 0), Resolution::DEFAULT);
        let costmap = Costmap::inflate(&window, CostParams::default());
        assert_eq!(costmap.step_factor(0), 1.0);
        assert_eq!(costmap.step_factor(3), 3.0);
        assert!(costmap.clearance_m(0).is_infinite());
    }
}
