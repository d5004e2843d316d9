//! Walking a line segment through the grid: every cell the segment passes
//! through, in order from its start to its end, each once (the traversal
//! of Amanatides and Woo, 1987).
//!
//! The walk works in cell units and counts its steps: from the start cell
//! it takes exactly `|Δcol|` steps along x and `|Δrow|` along y, choosing at
//! each step the axis whose next cell boundary the segment crosses first.
//! Counting, rather than comparing travelled distances, makes the walk end
//! in the end cell whatever the rounding, and consecutive cells are always
//! 4-neighbours. Where the segment passes exactly through a cell corner,
//! the walk goes through one of the two cells that share the corner (both
//! touch the segment there).

use crate::cell::{CellIndex, Resolution};
use crate::error::GridError;

/// The cells a segment passes through, start to end; see the module docs.
#[derive(Debug, Clone)]
pub struct SegmentCells {
    cell: CellIndex,
    step_x: i32,
    step_y: i32,
    // Parameter t in [0, 1] along the segment where it crosses the next
    // cell boundary on each axis, and the change of t per cell.
    next_x: f64,
    next_y: f64,
    delta_x: f64,
    delta_y: f64,
    // Steps left on each axis; the current cell is still to be yielded
    // while `pending`.
    left_x: u32,
    left_y: u32,
    pending: bool,
}

impl SegmentCells {
    /// The walk from `(x0, y0)` to `(x1, y1)`, metres, on a grid of `res`.
    /// Fails for a non-finite point or one beyond the grid.
    pub fn new(res: Resolution, x0: f64, y0: f64, x1: f64, y1: f64) -> Result<Self, GridError> {
        let start = res.cell_of(x0, y0)?;
        let end = res.cell_of(x1, y1)?;
        // The same division `cell_of` floors, so the boundaries below are
        // those of the cells it chose.
        let m = res.metres();
        let (u0, v0) = (x0 / m, y0 / m);
        let (du, dv) = (x1 / m - u0, y1 / m - v0);
        let (step_x, next_x, delta_x) = axis(u0, start.x, du);
        let (step_y, next_y, delta_y) = axis(v0, start.y, dv);
        Ok(Self {
            cell: start,
            step_x,
            step_y,
            next_x,
            next_y,
            delta_x,
            delta_y,
            left_x: end.x.abs_diff(start.x),
            left_y: end.y.abs_diff(start.y),
            pending: true,
        })
    }
}

/// The step direction along one axis, the parameter of the first boundary
/// crossed and the parameter per cell, for a segment starting at `u` (cell
/// units) in cell `index` and moving `du` cell units over its length.
#[inline]
fn axis(u: f64, index: i32, du: f64) -> (i32, f64, f64) {
    if du > 0.0 {
        (1, (f64::from(index) + 1.0 - u) / du, 1.0 / du)
    } else if du < 0.0 {
        (-1, (f64::from(index) - u) / du, -1.0 / du)
    } else {
        (0, f64::INFINITY, f64::INFINITY)
    }
}

impl Iterator for SegmentCells {
    type Item = CellIndex;

    #[inline]
    fn next(&mut self) -> Option<CellIndex> {
        if self.pending {
            self.pending = false;
            return Some(self.cell);
        }
        // Both counts are exact, so neither step leaves the cells between
        // the two ends (which `cell_of` gave as i32 indices).
        if self.left_x > 0 && (self.left_y == 0 || self.next_x < self.next_y) {
            self.left_x -= 1;
            self.cell.x += self.step_x;
            self.next_x += self.delta_x;
        } else if self.left_y > 0 {
            self.left_y -= 1;
            self.cell.y += self.step_y;
            self.next_y += self.delta_y;
        } else {
            return None;
        }
        Some(self.cell)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.len();
        (n, Some(n))
    }
}

impl ExactSizeIterator for SegmentCells {
    fn len(&self) -> usize {
        self.left_x as usize + self.left_y as usize + usize::from(self.pending)
    }
}

impl std::iter::FusedIterator for SegmentCells {}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::HashSet;

    const RES: Resolution = Resolution::DEFAULT;

    fn walk(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<CellIndex> {
        let cells = SegmentCells::new(RES, x0, y0, x1, y1).unwrap();
        let n = cells.len();
        let out: Vec<_> = cells.collect();
        assert_eq!(out.len(), n, "len() promised {n} cells");
        out
    }

    /// Whether the segment meets the closed square of `cell` grown by
    /// `slack` metres on every side (Liang and Barsky's clipping).
    fn touches(cell: CellIndex, (x0, y0): (f64, f64), (x1, y1): (f64, f64), slack: f64) -> bool {
        let (cx, cy) = RES.cell_corner(cell);
        let m = RES.metres();
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [
            (-(x1 - x0), x0 - (cx - slack)),
            (x1 - x0, (cx + m + slack) - x0),
            (-(y1 - y0), y0 - (cy - slack)),
            (y1 - y0, (cy + m + slack) - y0),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return false;
                }
            } else {
                let t = q / p;
                if p < 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
            }
        }
        t0 <= t1
    }

    #[test]
    fn an_axis_aligned_segment_walks_one_row() {
        let cells = walk(0.01, 0.01, 0.26, 0.01);
        assert_eq!(
            cells,
            (0..=5).map(|x| CellIndex::new(x, 0)).collect::<Vec<_>>()
        );
        let back = walk(0.26, -0.01, 0.01, -0.01);
        assert_eq!(
            back,
            (0..=5)
                .rev()
                .map(|x| CellIndex::new(x, -1))
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_point_is_its_own_cell() {
        assert_eq!(walk(-0.03, 0.07, -0.03, 0.07), vec![CellIndex::new(-1, 1)]);
        assert_eq!(walk(0.011, 0.012, 0.049, 0.001), vec![CellIndex::new(0, 0)]);
    }

    #[test]
    fn a_shallow_diagonal_takes_one_step_up_where_it_crosses_the_row() {
        // From (0.025, 0.025) to (0.225, 0.075): y = 0.05 is crossed at
        // x = 0.125, in column 2.
        let cells = walk(0.025, 0.025, 0.225, 0.075);
        let expected =
            [(0, 0), (1, 0), (2, 0), (2, 1), (3, 1), (4, 1)].map(|(x, y)| CellIndex::new(x, y));
        assert_eq!(cells, expected);
    }

    #[test]
    fn points_beyond_the_grid_are_errors() {
        assert!(SegmentCells::new(RES, 0.0, 0.0, 1e12, 0.0).is_err());
        assert!(SegmentCells::new(RES, f64::NAN, 0.0, 1.0, 0.0).is_err());
    }

    proptest! {
        /// Every visited cell touches the segment, consecutive cells are
        /// 4-neighbours, none repeats, the first holds the start and the
        /// last the end, and every point along the segment lies in a
        /// visited cell.
        #[test]
        fn the_walk_is_exact(
            x0 in -30.0f64..30.0, y0 in -30.0f64..30.0,
            x1 in -30.0f64..30.0, y1 in -30.0f64..30.0,
        ) {
            let cells = walk(x0, y0, x1, y1);
            prop_assert_eq!(cells[0], RES.cell_of(x0, y0).unwrap());
            prop_assert_eq!(*cells.last().unwrap(), RES.cell_of(x1, y1).unwrap());
            for pair in cells.windows(2) {
                let (a, b) = (pair[0], pair[1]);
                prop_assert_eq!(a.x.abs_diff(b.x) + a.y.abs_diff(b.y), 1, "{:?} then {:?}", a, b);
            }
            for cell in &cells {
                prop_assert!(touches(*cell, (x0, y0), (x1, y1), 1e-9), "{:?} is off the segment", cell);
            }
            let distinct: HashSet<_> = cells.iter().copied().collect();
            prop_assert_eq!(distinct.len(), cells.len());
            for i in 0..=1000 {
                let t = f64::from(i) / 1000.0;
                let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
                let cell = RES.cell_of(x, y).unwrap();
                // A point on a cell boundary may be counted in either cell.
                let near_edge = [x, y].iter().any(|c| {
                    let f = c / RES.metres();
                    (f - f.round()).abs() < 1e-7
                });
                prop_assert!(near_edge || distinct.contains(&cell), "{:?} at t = {} missed", cell, t);
            }
        }

        /// Short segments inside a few cells, where rounding matters most.
        #[test]
        fn short_walks_are_exact(
            x0 in -0.2f64..0.2, y0 in -0.2f64..0.2,
            x1 in -0.2f64..0.2, y1 in -0.2f64..0.2,
        ) {
            let cells = walk(x0, y0, x1, y1);
            prop_assert_eq!(cells[0], RES.cell_of(x0, y0).unwrap());
            prop_assert_eq!(*cells.last().unwrap(), RES.cell_of(x1, y1).unwrap());
            for pair in cells.windows(2) {
                prop_assert_eq!(pair[0].x.abs_diff(pair[1].x) + pair[0].y.abs_diff(pair[1].y), 1);
            }
            for cell in &cells {
                prop_assert!(touches(*cell, (x0, y0), (x1, y1), 1e-9));
            }
        }
    }
}
