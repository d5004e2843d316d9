//! Per-tile distance fields: for every cell of a tile, how far its centre
//! lies from the nearest occupied cell's centre, as the likelihood field
//! ([`crate::sensors::likelihood_field`]) judges a beam's endpoint by.
//!
//! A field is built from an [`OccupancyRaster`] covering the tile and
//! everything within [`FieldSpec::max_distance`] of it, whose exact
//! Euclidean distance transform it quantizes to one byte a cell: codes 0
//! to [`FIELD_FAR`] step evenly from 0 to the maximum distance (farther
//! reads as the maximum, as amcl clamps it), and [`FIELD_UNKNOWN`] marks
//! a cell that is itself unknown with no occupied cell within the maximum
//! distance: space the map has not seen, where an endpoint says nothing.
//! One tile of 64 × 64 cells takes 4 KiB, a 240th of its range table.
//!
//! [`FieldWindow`] lays the fields of a block of tiles out for lookups:
//! a scoring loop reads one byte per beam.

use std::collections::HashMap;

use deog_grid::{CellBox, CellIndex, Resolution, TileKey, TileSize};

use crate::error::{LocalizerError, within};
use crate::numeric::floor_i64;
use crate::range_table::OccupancyRaster;

/// The code of the maximum distance and beyond.
pub const FIELD_FAR: u8 = 254;

/// The code of an unknown cell far from any occupied one.
pub const FIELD_UNKNOWN: u8 = 255;

/// How a field is quantized.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldSpec {
    /// Distances at or past this, metres, read as this (amcl's
    /// `laser_likelihood_max_dist`); the field reads the occupied cells
    /// within it of the tile.
    pub max_distance: f64,
}

impl FieldSpec {
    /// The spec if the maximum distance is within [0.05, 20] m.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("max_distance", self.max_distance, 0.05, 20.0)?;
        Ok(self)
    }

    /// Metres between consecutive codes.
    pub fn step(&self) -> f64 {
        self.max_distance / f64::from(FIELD_FAR)
    }

    /// Cells a field reads beyond its tile on every side.
    pub fn margin_cells(&self, res: Resolution) -> i32 {
        (self.max_distance / res.metres()).ceil() as i32 + 1
    }

    /// The code of a distance, metres (rounded to the nearest step).
    pub fn code_of(&self, distance: f64) -> u8 {
        let steps = (distance / self.step() + 0.5).max(0.0);
        if steps >= f64::from(FIELD_FAR) {
            FIELD_FAR
        } else {
            steps as u8
        }
    }

    /// The distance a code stands for, metres; `None` for
    /// [`FIELD_UNKNOWN`].
    pub fn distance_of(&self, code: u8) -> Option<f64> {
        (code != FIELD_UNKNOWN).then(|| f64::from(code) * self.step())
    }
}

/// One tile's field: a code per cell, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DistanceField {
    codes: Box<[u8]>,
}

impl DistanceField {
    /// The field of `tile` from `raster`, which must cover `tile` widened
    /// by [`FieldSpec::margin_cells`] (cells it lacks count as free and
    /// unoccupied); `unknown(i)` says whether the tile's cell `i`
    /// (row-major) is unknown.
    pub fn build(
        raster: &OccupancyRaster,
        tile: CellBox,
        res: Resolution,
        spec: &FieldSpec,
        unknown: impl Fn(usize) -> bool,
    ) -> Self {
        let mut codes = Vec::with_capacity(tile.width() as usize * tile.height() as usize);
        let cell_m = res.metres();
        for cy in tile.min.y..=tile.max.y {
            for cx in tile.min.x..=tile.max.x {
                let distance = raster
                    .distance_cells(CellIndex::new(cx, cy))
                    .map_or(f64::INFINITY, |d| f64::from(d) * cell_m);
                let code = spec.code_of(distance);
                codes.push(if code == FIELD_FAR && unknown(codes.len()) {
                    FIELD_UNKNOWN
                } else {
                    code
                });
            }
        }
        Self {
            codes: codes.into_boxed_slice(),
        }
    }

    /// The codes, row-major.
    pub fn codes(&self) -> &[u8] {
        &self.codes
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.codes.len()
    }
}

/// The fields of a block of tiles, laid out for lookups by position.
#[derive(Debug)]
pub enum FieldWindow<'a> {
    /// Every tile of the keys' bounding box, in a grid.
    Dense(DenseFields<'a>),
    /// The keys' tiles in a hash map: for keys far apart, whose bounding
    /// box would be mostly empty.
    Sparse(SparseFields<'a>),
}

/// A field lookup by position.
pub trait FieldCodes {
    /// The code of the cell under `(x, y)`, metres; [`FIELD_UNKNOWN`] in
    /// a tile without a field.
    fn code_at(&self, x: f64, y: f64) -> u8;
}

/// Where a window's cells are, shared by both layouts.
#[derive(Debug, Clone, Copy)]
struct Cells {
    shift: u32,
    mask: i64,
    inv_res: f64,
}

impl Cells {
    #[inline(always)]
    fn of(&self, x: f64, y: f64) -> (i64, i64) {
        (floor_i64(x * self.inv_res), floor_i64(y * self.inv_res))
    }

    #[inline(always)]
    fn index(&self, cx: i64, cy: i64) -> usize {
        (((cy & self.mask) << self.shift) + (cx & self.mask)) as usize
    }
}

/// [`FieldWindow::Dense`].
#[derive(Debug)]
pub struct DenseFields<'a> {
    min: TileKey,
    width: usize,
    height: usize,
    fields: Vec<Option<&'a [u8]>>,
    cells: Cells,
}

/// [`FieldWindow::Sparse`].
#[derive(Debug)]
pub struct SparseFields<'a> {
    fields: HashMap<TileKey, &'a [u8]>,
    cells: Cells,
}

impl<'a> FieldWindow<'a> {
    /// The window over `fields` (a tile and its field, if it has one), on
    /// a map of `res` and `size`: dense while the keys' bounding box holds
    /// at most four times as many tiles as there are keys (or 4,096).
    pub fn new(
        fields: impl IntoIterator<Item = (TileKey, Option<&'a [u8]>)>,
        res: Resolution,
        size: TileSize,
    ) -> Self {
        let side = size.cells();
        let cells = Cells {
            shift: side.trailing_zeros(),
            mask: i64::from(side) - 1,
            inv_res: 1.0 / res.metres(),
        };
        let present: Vec<(TileKey, &'a [u8])> = fields
            .into_iter()
            .filter_map(|(k, f)| f.map(|f| (k, f)))
            .collect();
        let (mut min, mut max) = match present.first() {
            Some((k, _)) => (*k, *k),
            None => (TileKey::new(0, 0), TileKey::new(0, 0)),
        };
        for (k, _) in &present {
            min = TileKey::new(min.x.min(k.x), min.y.min(k.y));
            max = TileKey::new(max.x.max(k.x), max.y.max(k.y));
        }
        let width = (i64::from(max.x) - i64::from(min.x) + 1) as u64;
        let height = (i64::from(max.y) - i64::from(min.y) + 1) as u64;
        if width * height > (4 * present.len() as u64).max(4096) {
            return Self::Sparse(SparseFields {
                fields: present.into_iter().collect(),
                cells,
            });
        }
        let (width, height) = (width as usize, height as usize);
        let mut grid = vec![None; width * height];
        for (k, f) in present {
            let x = (i64::from(k.x) - i64::from(min.x)) as usize;
            let y = (i64::from(k.y) - i64::from(min.y)) as usize;
            grid[y * width + x] = Some(f);
        }
        Self::Dense(DenseFields {
            min,
            width,
            height,
            fields: grid,
            cells,
        })
    }
}

impl FieldCodes for FieldWindow<'_> {
    fn code_at(&self, x: f64, y: f64) -> u8 {
        match self {
            Self::Dense(d) => d.code_at(x, y),
            Self::Sparse(s) => s.code_at(x, y),
        }
    }
}

impl FieldCodes for DenseFields<'_> {
    #[inline(always)]
    fn code_at(&self, x: f64, y: f64) -> u8 {
        let (cx, cy) = self.cells.of(x, y);
        let tx = (cx >> self.cells.shift) - i64::from(self.min.x);
        let ty = (cy >> self.cells.shift) - i64::from(self.min.y);
        // One unsigned comparison each catches both sides.
        if tx as u64 >= self.width as u64 || ty as u64 >= self.height as u64 {
            return FIELD_UNKNOWN;
        }
        match self.fields[ty as usize * self.width + tx as usize] {
            Some(field) => field
                .get(self.cells.index(cx, cy))
                .copied()
                .unwrap_or(FIELD_UNKNOWN),
            None => FIELD_UNKNOWN,
        }
    }
}

impl FieldCodes for SparseFields<'_> {
    #[inline]
    fn code_at(&self, x: f64, y: f64) -> u8 {
        let (cx, cy) = self.cells.of(x, y);
        let key = TileKey::new(
            (cx >> self.cells.shift) as i32,
            (cy >> self.cells.shift) as i32,
        );
        self.fields
            .get(&key)
            .and_then(|f| f.get(self.cells.index(cx, cy)).copied())
            .unwrap_or(FIELD_UNKNOWN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cell_box(x0: i32, y0: i32, x1: i32, y1: i32) -> CellBox {
        CellBox::new(CellIndex::new(x0, y0), CellIndex::new(x1, y1)).unwrap()
    }

    #[test]
    fn codes_round_to_the_nearest_step_and_clamp_at_the_maximum() {
        let spec = FieldSpec { max_distance: 2.54 }.validate().unwrap();
        assert_eq!(spec.code_of(0.0), 0);
        assert_eq!(spec.code_of(0.014), 1);
        assert_eq!(spec.code_of(2.53), 253);
        assert_eq!(spec.code_of(2.6), FIELD_FAR);
        assert_eq!(spec.code_of(f64::INFINITY), FIELD_FAR);
        assert_eq!(spec.distance_of(FIELD_UNKNOWN), None);
        assert!(FieldSpec { max_distance: 0.0 }.validate().is_err());
        assert!(
            FieldSpec {
                max_distance: f64::NAN
            }
            .validate()
            .is_err()
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        /// Each cell's field is the distance to the nearest occupied
        /// cell by brute force, to within half a step; an unknown cell
        /// with nothing occupied within the maximum is marked unknown.
        #[test]
        fn the_field_is_the_brute_force_distance(
            occupied in prop::collection::vec((-12i32..28, -12i32..28), 0..12),
            unknown_below in -1i32..16,
            max_distance in 0.1f64..1.0,
        ) {
            let res = Resolution::DEFAULT;
            let spec = FieldSpec { max_distance }.validate().unwrap();
            let tile = cell_box(0, 0, 15, 15);
            let m = spec.margin_cells(res);
            let raster = OccupancyRaster::new(cell_box(-m, -m, 15 + m, 15 + m), |c| {
                occupied.contains(&(c.x, c.y))
            });
            // The rows below `unknown_below` are unknown.
            let unknown = |i: usize| ((i / 16) as i32) < unknown_below;
            let field = DistanceField::build(&raster, tile, res, &spec, unknown);
            let half = spec.step() / 2.0 + 1e-5;
            for (i, &code) in field.codes().iter().enumerate() {
                let (x, y) = ((i % 16) as f64, (i / 16) as f64);
                let brute = occupied
                    .iter()
                    .map(|&(ox, oy)| (f64::from(ox) - x).hypot(f64::from(oy) - y))
                    .fold(f64::INFINITY, f64::min)
                    * res.metres();
                match spec.distance_of(code) {
                    None => prop_assert!(unknown(i) && brute >= max_distance - half,
                        "cell {} marked unknown, {} m from a wall", i, brute),
                    Some(d) => {
                        prop_assert!((d - brute.min(max_distance)).abs() <= half,
                            "cell {}: brute force {} m, field {} m", i, brute, d);
                        prop_assert!(!unknown(i) || brute <= max_distance - half + 2e-5,
                            "unknown cell {} far from walls not marked", i);
                    }
                }
            }
        }
    }
}
