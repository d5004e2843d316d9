//! Frontiers (Yamauchi, 1997): known-free cells beside unknown ones, the
//! edge of what has been seen, clustered into the stretches a robot would
//! drive to.

use std::collections::VecDeque;

use deog_grid::Occupancy;

use crate::window::OccupancyWindow;

/// One stretch of frontier.
#[derive(Debug, Clone, PartialEq)]
pub struct Frontier {
    /// Its cells, as indices of the window.
    pub cells: Vec<usize>,
    /// Its length, metres (cells times the resolution).
    pub size_m: f64,
    /// The mean of its cells' centres, metres.
    pub centroid: (f64, f64),
}

/// Unknown space, metres, straight out from a frontier cell, that makes
/// it one: a wall whose inside the sensor never marked, or a sliver
/// between two readings, is thinner than that and leads nowhere.
pub const FRONTIER_DEPTH_M: f64 = 0.3;

/// Whether the cell at `index` is a frontier cell: free, with unknown
/// space [`FRONTIER_DEPTH_M`] deep (at least one cell) straight out from
/// one of its sides (beyond the window's edge counts as unknown).
pub fn is_frontier_cell(window: &OccupancyWindow, index: usize) -> bool {
    if window.at(index) != Occupancy::Free {
        return false;
    }
    let depth = ((FRONTIER_DEPTH_M / window.resolution().metres()) - 1e-9)
        .ceil()
        .max(1.0) as i64;
    let (width, height) = (window.width() as i64, window.height() as i64);
    let (x, y) = ((index as i64) % width, (index as i64) / width);
    let unknown = |nx: i64, ny: i64| {
        nx < 0
            || ny < 0
            || nx >= width
            || ny >= height
            || window.at((ny * width + nx) as usize) == Occupancy::Unknown
    };
    [(1, 0), (-1, 0), (0, 1), (0, -1)]
        .iter()
        .any(|&(dx, dy)| (1..=depth).all(|k| unknown(x + k * dx, y + k * dy)))
}

/// The window's frontiers of at least `min_size_m`, 8-connected cells
/// clustered, largest first.
pub fn find_frontiers(window: &OccupancyWindow, min_size_m: f64) -> Vec<Frontier> {
    clusters(window, min_size_m, |index| is_frontier_cell(window, index))
}

/// Once no frontier is left: the free cells beside cells the map has
/// observed but not decided (`undecided`, by window index: neither free
/// nor occupied), clustered as frontiers are, of at least `min_size_m`.
/// A sonar's cone seen from afar leaves such bands along walls and round
/// pillars; seen again from near, they settle. Cells past the end of
/// `undecided` count as decided.
pub fn find_undecided(
    window: &OccupancyWindow,
    undecided: &[bool],
    min_size_m: f64,
) -> Vec<Frontier> {
    let (width, height) = (window.width() as i64, window.height() as i64);
    clusters(window, min_size_m, |index| {
        if window.at(index) != Occupancy::Free {
            return false;
        }
        let (x, y) = ((index as i64) % width, (index as i64) / width);
        [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            nx >= 0
                && ny >= 0
                && nx < width
                && ny < height
                && undecided.get((ny * width + nx) as usize) == Some(&true)
        })
    })
}

/// The 8-connected clusters of the cells `member` picks, of at least
/// `min_size_m`, largest first.
fn clusters(
    window: &OccupancyWindow,
    min_size_m: f64,
    member: impl Fn(usize) -> bool,
) -> Vec<Frontier> {
    let metres = window.resolution().metres();
    let mut seen = vec![false; window.len()];
    let mut frontiers = Vec::new();
    for start in 0..window.len() {
        if seen[start] || !member(start) {
            continue;
        }
        let mut cells = Vec::new();
        let mut queue = VecDeque::from([start]);
        seen[start] = true;
        while let Some(index) = queue.pop_front() {
            cells.push(index);
            for (next, _) in window.neighbours(index) {
                if !seen[next] && member(next) {
                    seen[next] = true;
                    queue.push_back(next);
                }
            }
        }
        let size_m = cells.len() as f64 * metres;
        if size_m < min_size_m {
            continue;
        }
        let (sx, sy) = cells.iter().fold((0.0, 0.0), |(sx, sy), &index| {
            let (x, y) = window.centre_of(window.cell_at(index));
            (sx + x, sy + y)
        });
        let n = cells.len() as f64;
        frontiers.push(Frontier {
            cells,
            size_m,
            centroid: (sx / n, sy / n),
        });
    }
    frontiers.sort_by(|a, b| b.size_m.total_cmp(&a.size_m));
    frontiers
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::{CellIndex, Resolution};

    #[test]
    fn a_room_open_on_two_sides_has_two_frontiers() {
        // A room walled above and below, open (unknown) left and right.
        let rows = [
            "##########",
            "?........?",
            "?........?",
            "?........?",
            "##########",
        ];
        let resolution = Resolution::new(0.1).unwrap();
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        let frontiers = find_frontiers(&window, 0.0);
        assert_eq!(frontiers.len(), 2, "{frontiers:?}");
        for frontier in &frontiers {
            assert_eq!(frontier.cells.len(), 3);
            assert!((frontier.size_m - 0.3).abs() < 1e-9);
            assert!((frontier.centroid.1 - 0.25).abs() < 1e-9);
        }
        let xs: Vec<f64> = frontiers.iter().map(|f| f.centroid.0).collect();
        assert!(
            xs.iter().any(|x| (x - 0.15).abs() < 1e-9)
                && xs.iter().any(|x| (x - 0.85).abs() < 1e-9)
        );
        // Smaller than asked: none.
        assert!(find_frontiers(&window, 0.5).is_empty());
    }

    #[test]
    fn unknown_slivers_and_unmarked_walls_are_no_frontier() {
        // Two rooms, the wall between them marked on its faces but
        // unknown inside, the right room's far wall too; the left room
        // opens onto deep unknown (the window's edge).
        let rows = [
            "#############",
            "....#??#..#??",
            "....#??#..#??",
            "....#??#..#??",
            "#############",
        ];
        let resolution = Resolution::new(0.1).unwrap();
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        let frontiers = find_frontiers(&window, 0.0);
        // Only the left edge (the window's edge is unknown beyond).
        assert_eq!(frontiers.len(), 1, "{frontiers:?}");
        assert!((frontiers[0].centroid.0 - 0.05).abs() < 1e-9);
        // A wall never marked at all: two unknown cells between free ones.
        let rows = ["#######", "#..??.#", "#######"];
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        assert!(find_frontiers(&window, 0.0).is_empty());
    }

    #[test]
    fn the_unknown_depth_is_in_metres_whatever_the_cells() {
        // Unknown 0.25 m deep on 5 cm cells (5 cells): a sliver; 0.3 m
        // (6 cells): a frontier, as 3 cells of 10 cm are.
        let fine = Resolution::new(0.05).unwrap();
        let sliver = ["#########", "#..?????#", "#########"];
        let window = OccupancyWindow::from_rows(&sliver, CellIndex::new(0, 0), fine);
        assert!(find_frontiers(&window, 0.0).is_empty());
        let deep = ["##########", "#..??????#", "##########"];
        let window = OccupancyWindow::from_rows(&deep, CellIndex::new(0, 0), fine);
        assert_eq!(find_frontiers(&window, 0.0).len(), 1);
        let coarse = Resolution::new(0.1).unwrap();
        let three = ["#######", "#..???#", "#######"];
        let window = OccupancyWindow::from_rows(&three, CellIndex::new(0, 0), coarse);
        assert_eq!(find_frontiers(&window, 0.0).len(), 1);
    }

    #[test]
    fn undecided_bands_beside_free_cells_are_found_once_frontiers_are_gone() {
        // A closed room; the map is undecided along part of its top wall
        // (the flags are its unknown cells).
        let rows = [
            "##########",
            "#?????...#",
            "#........#",
            "#........#",
            "##########",
        ];
        // 5 cm cells: the band is shallower than a frontier's depth.
        let resolution = Resolution::new(0.05).unwrap();
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), resolution);
        assert!(
            find_frontiers(&window, 0.0).is_empty(),
            "a sliver, no frontier"
        );
        let undecided: Vec<bool> = (0..window.len())
            .map(|i| window.at(i) == Occupancy::Unknown)
            .collect();
        let bands = find_undecided(&window, &undecided, 0.0);
        assert_eq!(bands.len(), 1, "{bands:?}");
        // The five free cells below the band and the one beside its end.
        assert_eq!(bands[0].cells.len(), 6);
        assert!(
            bands[0]
                .cells
                .iter()
                .all(|&i| window.at(i) == Occupancy::Free)
        );
        // Too short for the size asked.
        assert!(find_undecided(&window, &undecided, 0.35).is_empty());
        // Nothing undecided: nothing to look at again.
        assert!(find_undecided(&window, &vec![false; window.len()], 0.0).is_empty());
    }

    #[test]
    fn a_closed_room_has_no_frontier() {
        let rows = ["#####", "#...#", "#...#", "#####"];
        let window = OccupancyWindow::from_rows(&rows, CellIndex::new(0, 0), Resolution::DEFAULT);
        assert!(find_frontiers(&window, 0.0).is_empty());
    }
}
