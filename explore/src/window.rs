//! A dense rectangle of a map's cells as free, occupied or unknown: what
//! the exploration's other steps read, copied once from any
//! [`OccupancyView`] so that they index an array rather than tiles.

use deog_grid::{CellBox, CellIndex, Occupancy, OccupancyView, Resolution};

use crate::error::ExploreError;

/// The most cells a window may hold (a 4,096 × 4,096 square: 204 m a side
/// at 5 cm).
pub const MAX_WINDOW_CELLS: u64 = 1 << 24;

/// A rectangle of cells, row-major from its lowest corner.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyWindow {
    origin: CellIndex,
    width: usize,
    height: usize,
    resolution: Resolution,
    cells: Vec<Occupancy>,
}

impl OccupancyWindow {
    /// The cells of `region` as `view` classifies them.
    pub fn from_view(
        view: &impl OccupancyView,
        region: CellBox,
        resolution: Resolution,
    ) -> Result<Self, ExploreError> {
        let (width, height) = (region.width(), region.height());
        if width.saturating_mul(height) > MAX_WINDOW_CELLS {
            return Err(ExploreError::WindowTooLarge {
                cells: width.saturating_mul(height),
                limit: MAX_WINDOW_CELLS,
            });
        }
        let mut cells = Vec::with_capacity((width * height) as usize);
        for y in region.min.y..=region.max.y {
            for x in region.min.x..=region.max.x {
                cells.push(view.occupancy(CellIndex::new(x, y)));
            }
        }
        Ok(Self {
            origin: region.min,
            width: width as usize,
            height: height as usize,
            resolution,
            cells,
        })
    }

    /// A window from rows of text, for tests and examples: `#` occupied,
    /// `.` free, anything else unknown; the first row is the highest.
    pub fn from_rows(rows: &[&str], origin: CellIndex, resolution: Resolution) -> Self {
        let height = rows.len();
        let width = rows.iter().map(|r| r.chars().count()).max().unwrap_or(0);
        let mut cells = vec![Occupancy::Unknown; width * height];
        for (row, text) in rows.iter().enumerate() {
            let y = height - 1 - row;
            for (x, c) in text.chars().enumerate() {
                cells[y * width + x] = match c {
                    '#' => Occupancy::Occupied,
                    '.' => Occupancy::Free,
                    _ => Occupancy::Unknown,
                };
            }
        }
        Self {
            origin,
            width,
            height,
            resolution,
            cells,
        }
    }

    /// Cells along x.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Cells along y.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Metres per cell.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// The lowest cell.
    pub fn origin(&self) -> CellIndex {
        self.origin
    }

    /// The index of `cell` in the window's arrays, if inside.
    pub fn index_of(&self, cell: CellIndex) -> Option<usize> {
        let x = i64::from(cell.x) - i64::from(self.origin.x);
        let y = i64::from(cell.y) - i64::from(self.origin.y);
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        Some(y as usize * self.width + x as usize)
    }

    /// The cell at array index `index`.
    pub fn cell_at(&self, index: usize) -> CellIndex {
        CellIndex::new(
            self.origin.x + (index % self.width) as i32,
            self.origin.y + (index / self.width) as i32,
        )
    }

    /// The state of the cell at array index `index`.
    pub fn at(&self, index: usize) -> Occupancy {
        self.cells[index]
    }

    /// The state of `cell`; outside the window, unknown.
    pub fn occupancy_of(&self, cell: CellIndex) -> Occupancy {
        self.index_of(cell)
            .map_or(Occupancy::Unknown, |index| self.cells[index])
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether it holds no cell.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The array indices of the (up to 8) neighbours of `index`, with the
    /// length of the step to each in cells (1 or √2).
    pub fn neighbours(&self, index: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (x, y) = ((index % self.width) as i64, (index / self.width) as i64);
        const STEPS: [(i64, i64, f64); 8] = [
            (1, 0, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, std::f64::consts::SQRT_2),
            (1, -1, std::f64::consts::SQRT_2),
            (-1, 1, std::f64::consts::SQRT_2),
            (-1, -1, std::f64::consts::SQRT_2),
        ];
        STEPS.iter().filter_map(move |&(dx, dy, length)| {
            let (nx, ny) = (x + dx, y + dy);
            (nx >= 0 && ny >= 0 && nx < self.width as i64 && ny < self.height as i64)
                .then(|| ((ny as usize) * self.width + nx as usize, length))
        })
    }

    /// The centre of `cell`, metres.
    pub fn centre_of(&self, cell: CellIndex) -> (f64, f64) {
        self.resolution.cell_center(cell)
    }

    /// The same ground in cells `factor` times as large (planning on a
    /// 10 cm grid costs a quarter of a 5 cm one's): a coarse cell is
    /// occupied if any of its cells is, else free if at least as many of
    /// its cells are free as unknown, else unknown. Cell indices are the
    /// coarse grid's (`floor(fine / factor)`), so a pose maps to its
    /// coarse cell through the returned resolution.
    pub fn coarsened(&self, factor: u32) -> Result<Self, ExploreError> {
        if factor <= 1 {
            return Ok(self.clone());
        }
        let resolution =
            Resolution::new(self.resolution.metres() * f64::from(factor)).map_err(|error| {
                ExploreError::Invalid {
                    name: "factor",
                    reason: error.to_string(),
                }
            })?;
        let f = factor as i32;
        let coarse = |v: i32| v.div_euclid(f);
        let last = self.cell_at(self.len().saturating_sub(1));
        let origin = CellIndex::new(coarse(self.origin.x), coarse(self.origin.y));
        let width = (coarse(last.x) - origin.x + 1).max(0) as usize;
        let height = (coarse(last.y) - origin.y + 1).max(0) as usize;
        if self.is_empty() {
            return Ok(Self {
                origin,
                width: 0,
                height: 0,
                resolution,
                cells: Vec::new(),
            });
        }
        // Per coarse cell: (occupied, free, unknown) counts.
        let mut counts = vec![[0u16; 3]; width * height];
        for (index, &state) in self.cells.iter().enumerate() {
            let cell = self.cell_at(index);
            let (cx, cy) = (
                (coarse(cell.x) - origin.x) as usize,
                (coarse(cell.y) - origin.y) as usize,
            );
            let slot = match state {
                Occupancy::Occupied => 0,
                Occupancy::Free => 1,
                Occupancy::Unknown => 2,
            };
            counts[cy * width + cx][slot] += 1;
        }
        let cells = counts
            .into_iter()
            .map(|[occupied, free, unknown]| {
                if occupied > 0 {
                    Occupancy::Occupied
                } else if free > 0 && free >= unknown {
                    Occupancy::Free
                } else {
                    Occupancy::Unknown
                }
            })
            .collect();
        Ok(Self {
            origin,
            width,
            height,
            resolution,
            cells,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_read_top_down_and_index_both_ways() {
        let window =
            OccupancyWindow::from_rows(&["#..", "?.#"], CellIndex::new(-1, 5), Resolution::DEFAULT);
        assert_eq!((window.width(), window.height()), (3, 2));
        assert_eq!(
            window.occupancy_of(CellIndex::new(-1, 6)),
            Occupancy::Occupied
        );
        assert_eq!(
            window.occupancy_of(CellIndex::new(-1, 5)),
            Occupancy::Unknown
        );
        assert_eq!(
            window.occupancy_of(CellIndex::new(1, 5)),
            Occupancy::Occupied
        );
        assert_eq!(
            window.occupancy_of(CellIndex::new(9, 9)),
            Occupancy::Unknown
        );
        for index in 0..window.len() {
            assert_eq!(window.index_of(window.cell_at(index)), Some(index));
        }
        let corner = window.index_of(CellIndex::new(-1, 5)).unwrap();
        assert_eq!(window.neighbours(corner).count(), 3);
    }

    #[test]
    fn a_coarse_cell_is_occupied_if_any_part_is_and_free_if_mostly_known_free() {
        let fine = Resolution::new(0.05).unwrap();
        // Columns -3..=2, rows 0..=1 (printed top down): coarse columns
        // -2 (fine -3), -1 (fine -2, -1), 0 (fine 0, 1) and 1 (fine 2).
        let window = OccupancyWindow::from_rows(&["..?#??", ".?..??"], CellIndex::new(-3, 0), fine);
        let coarse = window.coarsened(2).unwrap();
        assert_eq!(coarse.resolution().metres(), 0.1);
        assert_eq!(coarse.origin(), CellIndex::new(-2, 0));
        assert_eq!((coarse.width(), coarse.height()), (4, 1));
        let states: Vec<Occupancy> = (0..coarse.len()).map(|i| coarse.at(i)).collect();
        assert_eq!(
            states,
            [
                Occupancy::Free,     // two free
                Occupancy::Free,     // two free, two unknown
                Occupancy::Occupied, // one wall among them
                Occupancy::Unknown,  // nothing known
            ]
        );
        // A pose maps to the coarse cell through the coarse resolution.
        let cell = coarse.resolution().cell_of(-0.15, 0.05).unwrap();
        assert_eq!(coarse.index_of(cell), Some(0));
        assert_eq!(window.coarsened(1).unwrap(), window);
    }
}
