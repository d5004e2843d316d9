//! Cells: world metres to integer cell indices and back, for any sign.

use crate::error::{GridError, within};

/// Integer index of a square cell. Cell `(x, y)` covers
/// `[x·res, (x+1)·res) × [y·res, (y+1)·res)` in metres.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct CellIndex {
    /// Column, along +x.
    pub x: i32,
    /// Row, along +y.
    pub y: i32,
}

impl CellIndex {
    /// A cell index from its parts.
    pub const fn new(x: i32, y: i32) -> Self {
        Self { x, y }
    }
}

/// An inclusive rectangle of cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CellBox {
    /// Lowest corner, inclusive.
    pub min: CellIndex,
    /// Highest corner, inclusive.
    pub max: CellIndex,
}

impl CellBox {
    /// The box spanning both corners; `None` if `max` is below `min` on either axis.
    pub fn new(min: CellIndex, max: CellIndex) -> Option<Self> {
        (min.x <= max.x && min.y <= max.y).then_some(Self { min, max })
    }

    /// Width in cells.
    pub fn width(&self) -> u64 {
        (i64::from(self.max.x) - i64::from(self.min.x) + 1) as u64
    }

    /// Height in cells.
    pub fn height(&self) -> u64 {
        (i64::from(self.max.y) - i64::from(self.min.y) + 1) as u64
    }

    /// Whether `cell` lies inside.
    pub fn contains(&self, cell: CellIndex) -> bool {
        (self.min.x..=self.max.x).contains(&cell.x) && (self.min.y..=self.max.y).contains(&cell.y)
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &CellBox) -> CellBox {
        CellBox {
            min: CellIndex::new(self.min.x.min(other.min.x), self.min.y.min(other.min.y)),
            max: CellIndex::new(self.max.x.max(other.max.x), self.max.y.max(other.max.y)),
        }
    }

    /// The cells both boxes hold, if any.
    pub fn intersection(&self, other: &CellBox) -> Option<CellBox> {
        CellBox::new(
            CellIndex::new(self.min.x.max(other.min.x), self.min.y.max(other.min.y)),
            CellIndex::new(self.max.x.min(other.max.x), self.max.y.min(other.max.y)),
        )
    }
}

/// The side of a cell in metres.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct Resolution(f64);

impl Resolution {
    /// Smallest accepted cell side: 0.1 mm.
    pub const MIN_METRES: f64 = 1e-4;
    /// Largest accepted cell side: 100 m.
    pub const MAX_METRES: f64 = 100.0;
    /// The default, 5 cm, the usual figure for sonar maps.
    pub const DEFAULT: Resolution = Resolution(0.05);

    /// A cell side in metres, within [`Self::MIN_METRES`, `Self::MAX_METRES`].
    pub fn new(metres: f64) -> Result<Self, GridError> {
        within("resolution_m", metres, Self::MIN_METRES, Self::MAX_METRES).map(Self)
    }

    /// Metres per cell.
    pub fn metres(self) -> f64 {
        self.0
    }

    /// The cell holding the point `(x, y)` in metres. Points outside the i32
    /// range of cells, or non-finite, are an error.
    pub fn cell_of(self, x: f64, y: f64) -> Result<CellIndex, GridError> {
        Ok(CellIndex::new(
            self.axis_index("x", x)?,
            self.axis_index("y", y)?,
        ))
    }

    /// The centre of `cell` in metres.
    pub fn cell_center(self, cell: CellIndex) -> (f64, f64) {
        (
            (f64::from(cell.x) + 0.5) * self.0,
            (f64::from(cell.y) + 0.5) * self.0,
        )
    }

    /// The lower-left corner of `cell` in metres.
    pub fn cell_corner(self, cell: CellIndex) -> (f64, f64) {
        (f64::from(cell.x) * self.0, f64::from(cell.y) * self.0)
    }

    fn axis_index(self, field: &'static str, metres: f64) -> Result<i32, GridError> {
        let limit = f64::from(i32::MAX) * self.0;
        within(field, metres, f64::from(i32::MIN) * self.0, limit)?;
        // The bounds check above keeps the floor inside i32; `as` then
        // saturates rather than wrapping at the very edge.
        Ok((metres / self.0).floor() as i32)
    }
}

impl Default for Resolution {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn negative_coordinates_floor_towards_minus_infinity() {
        let res = Resolution::new(0.05).unwrap();
        assert_eq!(res.cell_of(-0.01, 0.01).unwrap(), CellIndex::new(-1, 0));
        assert_eq!(res.cell_of(-0.05, -0.051).unwrap(), CellIndex::new(-1, -2));
        assert_eq!(res.cell_of(0.0, 0.0).unwrap(), CellIndex::new(0, 0));
    }

    #[test]
    fn bad_input_is_an_error() {
        let res = Resolution::DEFAULT;
        assert!(matches!(
            res.cell_of(f64::NAN, 0.0),
            Err(GridError::NotFinite { field: "x", .. })
        ));
        assert!(matches!(
            res.cell_of(0.0, f64::INFINITY),
            Err(GridError::NotFinite { field: "y", .. })
        ));
        assert!(matches!(
            res.cell_of(1e12, 0.0),
            Err(GridError::OutOfRange { field: "x", .. })
        ));
        assert!(Resolution::new(0.0).is_err());
        assert!(Resolution::new(-0.05).is_err());
        assert!(Resolution::new(f64::NAN).is_err());
    }

    #[test]
    fn box_sizes_and_set_operations() {
        let a = CellBox::new(CellIndex::new(-2, -3), CellIndex::new(1, 0)).unwrap();
        assert_eq!((a.width(), a.height()), (4, 4));
        let b = CellBox::new(CellIndex::new(0, 0), CellIndex::new(5, 5)).unwrap();
        assert_eq!(
            a.intersection(&b),
            CellBox::new(CellIndex::new(0, 0), CellIndex::new(1, 0))
        );
        assert_eq!(
            a.union(&b),
            CellBox::new(CellIndex::new(-2, -3), CellIndex::new(5, 5)).unwrap()
        );
        assert!(CellBox::new(CellIndex::new(1, 0), CellIndex::new(0, 0)).is_none());
        let whole = CellBox::new(
            CellIndex::new(i32::MIN, i32::MIN),
            CellIndex::new(i32::MAX, i32::MAX),
        )
        .unwrap();
        assert_eq!(whole.width(), 1 << 32);
    }

    proptest! {
        #[test]
        fn cell_center_maps_back_to_its_cell(x in any::<i32>(), y in any::<i32>(), res in 0.001f64..10.0) {
            let res = Resolution::new(res).unwrap();
            let cell = CellIndex::new(x, y);
            let (cx, cy) = res.cell_center(cell);
            prop_assert_eq!(res.cell_of(cx, cy).unwrap(), cell);
        }

        #[test]
        fn point_lies_inside_its_cell(x in -1e6f64..1e6, y in -1e6f64..1e6) {
            let res = Resolution::DEFAULT;
            let cell = res.cell_of(x, y).unwrap();
            let (x0, y0) = res.cell_corner(cell);
            // One ulp of slack: x / res may round across a cell edge.
            let slack = 1e-9 * x.abs().max(1.0);
            prop_assert!(x0 <= x + slack && x < x0 + res.metres() + slack);
            let slack = 1e-9 * y.abs().max(1.0);
            prop_assert!(y0 <= y + slack && y < y0 + res.metres() + slack);
        }
    }
}
