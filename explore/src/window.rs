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
}
