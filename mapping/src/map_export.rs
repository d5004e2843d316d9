//! A map's tiles to a ROS map_server image in its trinary form: the
//! thesis's "pgm creator", for any map, even one still being built.
//!
//! # Thresholds
//! A cell is written as occupied (pixel 0, black) when its probability is
//! above [`OCCUPIED_THRESH`] (0.65), free (pixel 254) when below
//! [`FREE_THRESH`] (0.196), and unknown (pixel 205) otherwise or when it was
//! never observed. These are the figures ROS's `map_saver` writes and
//! `map_server` reads by default, and the YAML written beside the image
//! names them. The pixel values are map_saver's too, and each reads back as
//! the class it was written for: 0 is p = 1 (> 0.65), 254 is p = 1/255
//! (< 0.196) and 205 is p = 50/255 ≈ 0.19608, just above 0.196 and well
//! below 0.65. So any map_server consumer (nav2, AMCL, [`MapImage::load`])
//! sees the cells exactly as deog classified them. With deog's default
//! clamp limits (0.12 and 0.97) a cell can reach either class; a cell that
//! saw as much evidence for as against stays unknown, as it should.
//!
//! The image covers the bounding box of the observed cells only, so a map
//! that grows in any direction exports without a margin of unknown.

use std::sync::OnceLock;

use deog_grid::{CellIndex, LogOdds, OccupancyThresholds, TileMap};
use deog_mapfile::{Cell, MapImage, Mode};

use crate::error::MappingError;

/// Probability above which an exported cell is occupied (map_server's
/// default `occupied_thresh`).
pub const OCCUPIED_THRESH: f64 = OccupancyThresholds::DEFAULT_OCCUPIED;
/// Probability below which an exported cell is free (map_server's default
/// `free_thresh`).
pub const FREE_THRESH: f64 = OccupancyThresholds::DEFAULT_FREE;
/// Pixel of an occupied cell: black, p = 1.
pub const OCCUPIED_PIXEL: u8 = 0;
/// Pixel of a free cell: map_saver's near white, p = 1/255.
pub const FREE_PIXEL: u8 = 254;
/// Pixel of an unknown cell: map_saver's gray, p = 50/255, between the
/// thresholds.
pub const UNKNOWN_PIXEL: u8 = 205;
/// Largest image exported, in pixels (1 byte each in memory): a map whose
/// observed cells span more is refused rather than exhausting memory.
pub const MAX_EXPORT_PIXELS: u64 = 1 << 30;

/// How many cells of an exported image fall in each class.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExportCounts {
    /// Cells above [`OCCUPIED_THRESH`].
    pub occupied: u64,
    /// Cells below [`FREE_THRESH`].
    pub free: u64,
    /// Cells observed but between the thresholds (written as unknown).
    pub uncertain: u64,
    /// Cells inside the image never observed (written as unknown).
    pub unobserved: u64,
}

impl ExportCounts {
    /// Cells written as unknown: uncertain plus unobserved.
    pub fn unknown(&self) -> u64 {
        self.uncertain + self.unobserved
    }
}

/// An exported map: the image and what it holds.
#[derive(Debug, Clone, PartialEq)]
pub struct MapExport {
    /// The map_server map, trinary, ready for
    /// [`deog_mapfile::write_map`] and [`deog_mapfile::to_png`].
    pub image: MapImage,
    /// The cells of the image by class.
    pub counts: ExportCounts,
    /// The lowest cell of the image (its lower-left pixel).
    pub min_cell: CellIndex,
}

/// The class of each raw log-odds value, decided once by the same
/// probability arithmetic a per-cell check would use: the probability rises
/// with the raw value, so each threshold is a raw cut.
#[derive(Debug, Clone, Copy)]
struct Classifier {
    /// Raw values at or above this are occupied.
    occupied_from: i32,
    /// Raw values below this are free.
    free_below: i32,
}

impl Classifier {
    /// The cuts, computed on first use.
    fn get() -> Self {
        static CUTS: OnceLock<Classifier> = OnceLock::new();
        *CUTS.get_or_init(|| Self {
            occupied_from: first_raw_where(|p| p > OCCUPIED_THRESH),
            free_below: first_raw_where(|p| p >= FREE_THRESH),
        })
    }

    /// The pixel of a cell holding `raw`, or `None` if never observed.
    fn pixel(self, raw: i16) -> Option<u8> {
        let raw_wide = i32::from(raw);
        if raw == LogOdds::UNKNOWN_RAW {
            None
        } else if raw_wide >= self.occupied_from {
            Some(OCCUPIED_PIXEL)
        } else if raw_wide < self.free_below {
            Some(FREE_PIXEL)
        } else {
            Some(UNKNOWN_PIXEL)
        }
    }
}

/// The lowest observable raw value whose probability passes `passes`
/// (one past `i16::MAX` if none does), by bisection: `passes` must be false
/// below some value and true from it on, as a threshold on a rising
/// probability is.
fn first_raw_where(passes: impl Fn(f64) -> bool) -> i32 {
    let passes_at = |raw: i32| {
        // The range searched is the observable i16 values.
        LogOdds::from_raw(raw as i16).is_some_and(|l| passes(l.probability()))
    };
    let (mut lo, mut hi) = (i32::from(LogOdds::MIN.raw()), i32::from(i16::MAX) + 1);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if passes_at(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

/// Exports `map` as a trinary map_server image covering the bounding box of
/// its observed cells: the first image row the top (highest y), the origin
/// the world position of the lower-left pixel's lower-left corner, yaw 0,
/// `negate` 0, thresholds [`OCCUPIED_THRESH`] and [`FREE_THRESH`]. An error
/// if no cell was ever observed (there is no extent to export) or if the
/// image would exceed [`MAX_EXPORT_PIXELS`].
pub fn export_map(map: &TileMap) -> Result<MapExport, MappingError> {
    let size = map.tile_size();
    let Some((min, max)) = observed_bounds(map)? else {
        return Err(MappingError::invalid(
            "map",
            "no cell was ever observed: an empty map has nothing to export",
        ));
    };
    let width = i64::from(max.x) - i64::from(min.x) + 1;
    let height = i64::from(max.y) - i64::from(min.y) + 1;
    let pixels = width as u64 * height as u64;
    if pixels > MAX_EXPORT_PIXELS {
        return Err(MappingError::invalid(
            "map",
            format!(
                "its observed cells span {width} x {height} = {pixels} pixels, more than the {MAX_EXPORT_PIXELS} an export may hold"
            ),
        ));
    }
    // Both fit: the product does, and each is at least 1.
    let (width, height) = (width as usize, height as usize);
    let mut image = vec![UNKNOWN_PIXEL; pixels as usize];
    let classifier = Classifier::get();
    let mut counts = ExportCounts::default();
    let mut observed = 0u64;
    for (key, tile) in map.tiles() {
        let origin = size.origin(*key)?;
        let side = size.cells() as usize;
        for (index, &raw) in tile.raw_cells().iter().enumerate() {
            let Some(pixel) = classifier.pixel(raw) else {
                continue;
            };
            // Every observed cell lies in [min, max], so these are in range.
            let x = (i64::from(origin.x) + (index % side) as i64 - i64::from(min.x)) as usize;
            let y = (i64::from(origin.y) + (index / side) as i64 - i64::from(min.y)) as usize;
            // map_server's first row is the top of the map.
            image[(height - 1 - y) * width + x] = pixel;
            observed += 1;
            match pixel {
                OCCUPIED_PIXEL => counts.occupied += 1,
                FREE_PIXEL => counts.free += 1,
                _ => counts.uncertain += 1,
            }
        }
    }
    counts.unobserved = pixels - observed;
    let res = map.resolution().metres();
    Ok(MapExport {
        image: MapImage {
            width: width as u32,
            height: height as u32,
            resolution: res,
            origin: (f64::from(min.x) * res, f64::from(min.y) * res, 0.0),
            negate: false,
            occupied_thresh: OCCUPIED_THRESH,
            free_thresh: FREE_THRESH,
            mode: Mode::Trinary,
            pixels: image,
        },
        counts,
        min_cell: min,
    })
}

/// The lowest and highest observed cell, `None` if there is none.
fn observed_bounds(map: &TileMap) -> Result<Option<(CellIndex, CellIndex)>, MappingError> {
    let size = map.tile_size();
    let side = size.cells() as usize;
    let mut bounds: Option<(CellIndex, CellIndex)> = None;
    for (key, tile) in map.tiles() {
        // Rows and columns of the tile holding an observed cell.
        let mut cols = (usize::MAX, 0);
        let mut rows = (usize::MAX, 0);
        for (index, _) in tile
            .raw_cells()
            .iter()
            .enumerate()
            .filter(|&(_, &raw)| raw != LogOdds::UNKNOWN_RAW)
        {
            let (c, r) = (index % side, index / side);
            cols = (cols.0.min(c), cols.1.max(c));
            rows = (rows.0.min(r), rows.1.max(r));
        }
        if cols.0 == usize::MAX {
            continue;
        }
        let origin = size.origin(*key)?;
        // Offsets are below the tile size (at most 1024) and the tile's
        // cells fit in i32 (`origin` checked it).
        let lo = CellIndex::new(origin.x + cols.0 as i32, origin.y + rows.0 as i32);
        let hi = CellIndex::new(origin.x + cols.1 as i32, origin.y + rows.1 as i32);
        bounds = Some(match bounds {
            None => (lo, hi),
            Some((a, b)) => (
                CellIndex::new(a.x.min(lo.x), a.y.min(lo.y)),
                CellIndex::new(b.x.max(hi.x), b.y.max(hi.y)),
            ),
        });
    }
    Ok(bounds)
}

/// The class an export gives a cell holding the raw log-odds `raw`
/// ([`LogOdds::UNKNOWN_RAW`] for a cell never observed): what map_server
/// reads back from the exported pixel.
pub fn classify_raw(raw: i16) -> Cell {
    match Classifier::get().pixel(raw) {
        Some(OCCUPIED_PIXEL) => Cell::Occupied,
        Some(FREE_PIXEL) => Cell::Free,
        _ => Cell::Unknown,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::{ClampLimits, Resolution, TileDelta, TileSize};

    fn empty_map() -> TileMap {
        TileMap::new(
            Resolution::new(0.1).expect("resolution"),
            TileSize::new(8).expect("tile size"),
            ClampLimits::default(),
        )
    }

    /// Sets each cell to `raw` by one delta on an unknown cell.
    fn set(map: &mut TileMap, cells: &[(i32, i32, i16)]) {
        let size = map.tile_size();
        for &(x, y, raw) in cells {
            let (key, offset) = size.split(CellIndex::new(x, y));
            let mut delta = TileDelta::zero(key, size);
            delta.raw_mut()[offset.index(size)] = raw;
            map.apply(&delta).expect("apply");
        }
    }

    #[test]
    fn an_empty_map_is_an_error_saying_so() {
        let e = export_map(&empty_map()).expect_err("empty");
        assert!(e.to_string().contains("empty map"), "{e}");
    }

    #[test]
    fn the_image_covers_the_observed_cells_top_row_first() {
        let mut map = empty_map();
        // Across four tiles, negative coordinates included: occupied at the
        // top left, free at the bottom right, an even cell in between.
        set(&mut map, &[(-3, 2, 3000), (1, -1, -3000), (0, 0, 1)]);
        let export = export_map(&map).expect("export");
        let image = &export.image;
        assert_eq!((image.width, image.height), (5, 4));
        assert_eq!(export.min_cell, CellIndex::new(-3, -1));
        // The lower-left pixel's corner, metres.
        assert!((image.origin.0 + 0.3).abs() < 1e-12 && (image.origin.1 + 0.1).abs() < 1e-12);
        assert_eq!(image.origin.2, 0.0);
        assert!(!image.negate && image.mode == Mode::Trinary);
        #[rustfmt::skip]
        let expected = vec![
            0,   205, 205, 205, 205, // y = 2, the top row
            205, 205, 205, 205, 205, // y = 1
            205, 205, 205, 205, 205, // y = 0: (0, 0) observed but even
            205, 205, 205, 205, 254, // y = -1
        ];
        assert_eq!(image.pixels, expected);
        assert_eq!(
            export.counts,
            ExportCounts {
                occupied: 1,
                free: 1,
                uncertain: 1,
                unobserved: 17
            }
        );
        assert_eq!(export.counts.unknown(), 18);
        // map_server reads each pixel back as the class it was written for.
        assert_eq!(image.occupancy(0, 3), Cell::Occupied);
        assert_eq!(image.occupancy(4, 0), Cell::Free);
        assert_eq!(image.occupancy(3, 1), Cell::Unknown);
    }

    #[test]
    fn raw_cuts_agree_with_the_probability_thresholds_for_every_value() {
        for raw in i16::MIN..=i16::MAX {
            let expected = match LogOdds::from_raw(raw).map(LogOdds::probability) {
                None => Cell::Unknown,
                Some(p) if p > OCCUPIED_THRESH => Cell::Occupied,
                Some(p) if p < FREE_THRESH => Cell::Free,
                Some(_) => Cell::Unknown,
            };
            assert_eq!(classify_raw(raw), expected, "raw {raw}");
        }
    }

    #[test]
    fn exported_pixels_read_back_as_their_class() {
        let image = MapImage {
            width: 3,
            height: 1,
            resolution: 0.05,
            origin: (0.0, 0.0, 0.0),
            negate: false,
            occupied_thresh: OCCUPIED_THRESH,
            free_thresh: FREE_THRESH,
            mode: Mode::Trinary,
            pixels: vec![OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL],
        };
        assert_eq!(image.occupancy(0, 0), Cell::Occupied);
        assert_eq!(image.occupancy(1, 0), Cell::Free);
        assert_eq!(image.occupancy(2, 0), Cell::Unknown);
    }

    #[test]
    fn a_map_too_wide_to_export_is_refused() {
        let mut map = empty_map();
        set(&mut map, &[(-(1 << 20), 0, 3000), (1 << 20, 1 << 10, 3000)]);
        let e = export_map(&map).expect_err("too big");
        assert!(
            e.to_string().starts_with("map: its observed cells span"),
            "{e}"
        );
    }
}
