//! The map as the search reads it: a score per cell, high where a wall
//! is or is near, and the stack of coarser grids whose cells each hold
//! the best score of a block of fine cells, so that one lookup bounds a
//! whole block of candidate positions from above.

use crate::error::LocalizerError;

/// What a cell of the map is, as the search grid is built from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchCell {
    /// Not observed.
    Unknown,
    /// Observed free: a robot may stand here.
    Free,
    /// Observed occupied: echoes come from here.
    Occupied,
}

/// Most cells a search grid may hold (a 400 × 400 m building at 0.1 m).
pub const MAX_SEARCH_CELLS: usize = 16_000_000;

/// A map's scores and the block maxima above them.
#[derive(Debug, Clone)]
pub struct SearchGrid {
    /// World position of the lower-left corner of cell (0, 0), metres.
    origin: [f64; 2],
    /// Side of a cell, metres.
    cell_m: f64,
    width: usize,
    height: usize,
    /// Level `d`: each cell `(x, y)`, for `x` in `-(2^d − 1)..width` and
    /// `y` likewise, the best score over fine cells `x..x + 2^d` by
    /// `y..y + 2^d` (cells off the grid score 0); stored shifted by
    /// `2^d − 1` on both axes. Level 0 is the scores themselves.
    scores: Vec<Level>,
    /// The same stack over "some cell of the block is free": candidate
    /// positions in a block with no free cell are not searched.
    free: Vec<Level>,
}

#[derive(Debug, Clone)]
struct Level {
    /// `2^d − 1`: how far the level reaches below cell 0.
    shift: usize,
    /// Cells a row.
    stride: usize,
    values: Vec<u8>,
}

impl Level {
    #[inline]
    fn at(&self, x: i64, y: i64) -> u8 {
        let (x, y) = (x + self.shift as i64, y + self.shift as i64);
        if x < 0 || y < 0 || x >= self.stride as i64 {
            return 0;
        }
        let i = y as usize * self.stride + x as usize;
        self.values.get(i).copied().unwrap_or(0)
    }

    /// The next level: blocks twice as wide, from this one's.
    fn doubled(&self, width: usize, height: usize) -> Self {
        let half = self.shift + 1;
        let shift = 2 * half - 1;
        let (w, h) = (width + shift, height + shift);
        // Along x first: max of this level at x and x + half.
        let old_h = height + self.shift;
        let mut along = vec![0u8; w * old_h];
        for y in 0..old_h {
            for x in 0..w {
                // New x index i stands for cell i − shift.
                let cx = x as i64 - shift as i64;
                let a = self.at_raw(cx, y);
                let b = self.at_raw(cx + half as i64, y);
                along[y * w + x] = a.max(b);
            }
        }
        let at_along = |x: usize, cy: i64| -> u8 {
            let row = cy + self.shift as i64;
            if row < 0 || row >= old_h as i64 {
                0
            } else {
                along[row as usize * w + x]
            }
        };
        let mut values = vec![0u8; w * h];
        for y in 0..h {
            let cy = y as i64 - shift as i64;
            for x in 0..w {
                values[y * w + x] = at_along(x, cy).max(at_along(x, cy + half as i64));
            }
        }
        Self {
            shift,
            stride: w,
            values,
        }
    }

    /// This level at cell column `cx` and stored row `row`.
    fn at_raw(&self, cx: i64, row: usize) -> u8 {
        let x = cx + self.shift as i64;
        if x < 0 || x >= self.stride as i64 {
            return 0;
        }
        self.values[row * self.stride + x as usize]
    }
}

impl SearchGrid {
    /// A grid of `width` × `height` cells of `cell_m` metres whose cell
    /// (0, 0) has its lower-left corner at `origin`, its cells' states
    /// row-major in `cells`. A cell scores `exp(−d² / 2σ²)` (255 at a
    /// wall) for `d` its distance to the nearest occupied cell, out to
    /// 3σ; `levels` block sizes are kept, 1, 2, 4, … cells.
    pub fn new(
        origin: [f64; 2],
        cell_m: f64,
        width: usize,
        height: usize,
        cells: &[SearchCell],
        sigma_m: f64,
        levels: usize,
    ) -> Result<Self, LocalizerError> {
        crate::error::within("search cell_m", cell_m, 0.005, 10.0)?;
        crate::error::within("search sigma_m", sigma_m, 0.001, 10.0)?;
        if !(origin[0].is_finite() && origin[1].is_finite()) {
            return Err(LocalizerError::Invalid(
                "the search grid's origin must be finite".into(),
            ));
        }
        if width == 0 || height == 0 || width.saturating_mul(height) > MAX_SEARCH_CELLS {
            return Err(LocalizerError::Invalid(format!(
                "a search grid of {width} x {height} cells: must hold 1 to {MAX_SEARCH_CELLS}"
            )));
        }
        if cells.len() != width * height {
            return Err(LocalizerError::Invalid(format!(
                "{} cells given for a search grid of {width} x {height}",
                cells.len()
            )));
        }
        if !(1..=12).contains(&levels) {
            return Err(LocalizerError::Invalid(format!(
                "a search grid of {levels} levels: must be 1 to 12"
            )));
        }
        let reach = (3.0 * sigma_m / cell_m).ceil() as i64;
        let mut kernel = Vec::new();
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let d = (dx as f64).hypot(dy as f64) * cell_m;
                if d <= 3.0 * sigma_m + 1e-9 {
                    let value = 255.0 * (-d * d / (2.0 * sigma_m * sigma_m)).exp();
                    kernel.push((dx, dy, value.round() as u8));
                }
            }
        }
        let mut base = vec![0u8; width * height];
        let mut free = vec![0u8; width * height];
        for y in 0..height {
            for x in 0..width {
                match cells[y * width + x] {
                    SearchCell::Occupied => {
                        for &(dx, dy, value) in &kernel {
                            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                            if nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height
                            {
                                let i = ny as usize * width + nx as usize;
                                base[i] = base[i].max(value);
                            }
                        }
                    }
                    SearchCell::Free => free[y * width + x] = 1,
                    SearchCell::Unknown => {}
                }
            }
        }
        let stack = |values: Vec<u8>| {
            let mut out = vec![Level {
                shift: 0,
                stride: width,
                values,
            }];
            for _ in 1..levels {
                let next = out[out.len() - 1].doubled(width, height);
                out.push(next);
            }
            out
        };
        Ok(Self {
            origin,
            cell_m,
            width,
            height,
            scores: stack(base),
            free: stack(free),
        })
    }

    /// Side of a cell, metres.
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// Cells along x and y.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Block sizes kept: level `d` bounds blocks of `2^d` cells a side.
    pub fn levels(&self) -> usize {
        self.scores.len()
    }

    /// World position of the centre of cell `(x, y)`, metres.
    pub fn centre(&self, x: i64, y: i64) -> (f64, f64) {
        (
            self.origin[0] + (x as f64 + 0.5) * self.cell_m,
            self.origin[1] + (y as f64 + 0.5) * self.cell_m,
        )
    }

    /// The cell holding world position `(x, y)`; may lie off the grid.
    pub fn cell_at(&self, x: f64, y: f64) -> (i64, i64) {
        (
            ((x - self.origin[0]) / self.cell_m).floor() as i64,
            ((y - self.origin[1]) / self.cell_m).floor() as i64,
        )
    }

    /// Level `level`'s score at `(x, y)`: the best over the block of
    /// `2^level` cells a side from there; 0 off the grid.
    #[inline]
    pub fn score(&self, level: usize, x: i64, y: i64) -> u8 {
        self.scores[level].at(x, y)
    }

    /// Whether some cell of level `level`'s block at `(x, y)` is free.
    #[inline]
    pub fn any_free(&self, level: usize, x: i64, y: i64) -> bool {
        self.free[level].at(x, y) > 0
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        self.scores
            .iter()
            .chain(&self.free)
            .map(|l| l.values.len())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(width: usize, height: usize, walls: &[(usize, usize)], levels: usize) -> SearchGrid {
        let mut cells = vec![SearchCell::Free; width * height];
        for &(x, y) in walls {
            cells[y * width + x] = SearchCell::Occupied;
        }
        SearchGrid::new([0.0, 0.0], 0.1, width, height, &cells, 0.1, levels).expect("grid")
    }

    #[test]
    fn a_wall_scores_most_and_its_neighbours_less() {
        let g = grid(20, 20, &[(10, 10)], 1);
        assert_eq!(g.score(0, 10, 10), 255);
        let near = g.score(0, 11, 10);
        assert!(near > 100 && near < 255, "{near}");
        assert_eq!(g.score(0, 15, 10), 0);
        assert_eq!(g.score(0, -1, 10), 0);
        assert_eq!(g.score(0, 10, 25), 0);
    }

    #[test]
    fn every_level_is_the_block_maximum_of_the_scores() {
        let walls = [(3, 4), (17, 2), (9, 15), (0, 0), (19, 19)];
        let g = grid(20, 17, &walls.map(|(x, y)| (x, y.min(16))), 5);
        for level in 1..g.levels() {
            let side = 1i64 << level;
            for y in -side..20 {
                for x in -side..22 {
                    let mut best = 0;
                    let mut free = false;
                    for by in y..y + side {
                        for bx in x..x + side {
                            best = best.max(g.score(0, bx, by));
                            free |= g.any_free(0, bx, by);
                        }
                    }
                    assert_eq!(g.score(level, x, y), best, "level {level} at {x},{y}");
                    assert_eq!(g.any_free(level, x, y), free, "level {level} at {x},{y}");
                }
            }
        }
    }

    #[test]
    fn bad_sizes_are_refused() {
        let cells = vec![SearchCell::Free; 4];
        assert!(SearchGrid::new([0.0, 0.0], 0.1, 2, 2, &cells, 0.1, 3).is_ok());
        assert!(SearchGrid::new([0.0, 0.0], 0.1, 3, 2, &cells, 0.1, 3).is_err());
        assert!(SearchGrid::new([0.0, 0.0], 0.0, 2, 2, &cells, 0.1, 3).is_err());
        assert!(SearchGrid::new([f64::NAN, 0.0], 0.1, 2, 2, &cells, 0.1, 3).is_err());
        assert!(SearchGrid::new([0.0, 0.0], 0.1, 2, 2, &cells, 0.1, 0).is_err());
        assert!(SearchGrid::new([0.0, 0.0], 0.1, 0, 2, &[], 0.1, 3).is_err());
    }
}
