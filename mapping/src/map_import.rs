//! A ROS map_server image to tile deltas for a deog map: seeding a map from
//! a drawn or saved one.
//!
//! Each pixel is read by map_server's own rules ([`MapImage::occupancy`]:
//! `negate`, `mode` and the image's thresholds). An occupied pixel becomes a
//! delta of the map's upper clamp limit and a free one of its lower limit,
//! so on an empty map the cell holds exactly that limit: as sure as deog's
//! updates ever make a cell, and no surer, so later sonar evidence can still
//! change it. An unknown pixel gives no delta and its cell stays unobserved.
//!
//! Pixel `(col, row_from_bottom)` is cell
//! `(round(origin.x / res) + col, round(origin.y / res) + row_from_bottom)`:
//! the image's grid must coincide with the map's, so the resolutions must
//! agree, the origin must sit on a cell corner and the image must not be
//! rotated. Applied to an empty map and exported with
//! [`crate::map_export::export_map`], an image gives back the same trinary
//! pixels where it had known cells.

use std::collections::BTreeMap;

use deog_grid::{CellIndex, ClampLimits, Resolution, TileDelta, TileKey, TileSize};
use deog_mapfile::{Cell, MapImage};

use crate::error::MappingError;
use crate::map_export::{FREE_THRESH, OCCUPIED_THRESH};

/// Largest relative difference between the image's resolution and the
/// map's that still counts as the same (decimal YAML round trips).
pub const RESOLUTION_TOLERANCE: f64 = 1e-9;
/// Largest distance, in cells, of the origin from a cell corner.
pub const ORIGIN_TOLERANCE_CELLS: f64 = 1e-6;
/// Largest cell index (either sign) an import may reach: the map server's
/// addressable range, 2^24 cells (839 km at 5 cm).
pub const MAX_ABS_CELL: i64 = 1 << 24;

/// The settings of the map an image is imported into.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImportTarget {
    /// The map's cell side.
    pub resolution: Resolution,
    /// The map's tile side.
    pub tile_size: TileSize,
    /// The map's clamp limits: what occupied and free pixels become.
    pub limits: ClampLimits,
}

/// An image turned into deltas.
#[derive(Debug, Clone, PartialEq)]
pub struct MapImport {
    /// One delta per tile holding a known pixel, in tile key order.
    pub deltas: Vec<TileDelta>,
    /// Pixels read as occupied.
    pub occupied: u64,
    /// Pixels read as free.
    pub free: u64,
    /// Pixels read as unknown (no delta).
    pub unknown: u64,
    /// The cell of the image's lower-left pixel.
    pub origin_cell: CellIndex,
}

/// The deltas that write `image` into a map with the settings of `target`.
/// Errors, naming the field, when the image's `resolution` differs from the
/// map's, its `origin` is not on a cell corner or is rotated, its `pixels`
/// do not number `width * height`, it reaches past the server's addressable
/// cells, or the map's clamp limits would not read back as occupied and
/// free (`clamp_max_probability` must exceed [`OCCUPIED_THRESH`] and
/// `clamp_min_probability` lie below [`FREE_THRESH`], else the import would
/// be lost on export).
pub fn import_map(image: &MapImage, target: &ImportTarget) -> Result<MapImport, MappingError> {
    check_limits(target.limits)?;
    let origin_cell = image_origin_cell(image, target.resolution)?;
    let (occupied_delta, free_delta) = (target.limits.max().raw(), target.limits.min().raw());
    let size = target.tile_size;
    let mut tiles: BTreeMap<TileKey, Vec<i16>> = BTreeMap::new();
    let mut result = MapImport {
        deltas: Vec::new(),
        occupied: 0,
        free: 0,
        unknown: 0,
        origin_cell,
    };
    for row in 0..image.height {
        for col in 0..image.width {
            let delta = match image.occupancy(col, row) {
                Cell::Occupied => {
                    result.occupied += 1;
                    occupied_delta
                }
                Cell::Free => {
                    result.free += 1;
                    free_delta
                }
                Cell::Unknown => {
                    result.unknown += 1;
                    continue;
                }
            };
            // In range: `whole_cells` checked origin + extent against
            // MAX_ABS_CELL, far inside i32.
            let cell = CellIndex::new(origin_cell.x + col as i32, origin_cell.y + row as i32);
            let (key, offset) = size.split(cell);
            let cells = tiles.entry(key).or_insert_with(|| vec![0; size.area()]);
            cells[offset.index(size)] = delta;
        }
    }
    result.deltas = tiles
        .into_iter()
        .map(|(key, cells)| TileDelta::from_raw(key, size, cells))
        .collect::<Result<_, _>>()?;
    Ok(result)
}

/// The cell of `image`'s lower-left pixel in a map of cells of
/// `resolution`, after checking that the image fits that map's grid: the
/// checks of [`import_map`] that do not depend on the map's tile size or
/// clamp limits, so a caller can run them before creating the map.
pub fn image_origin_cell(
    image: &MapImage,
    resolution: Resolution,
) -> Result<CellIndex, MappingError> {
    let res = resolution.metres();
    let image_res = image.resolution;
    if !(image_res.is_finite() && (image_res - res).abs() <= RESOLUTION_TOLERANCE * res) {
        return Err(MappingError::invalid(
            "resolution",
            format!("the image has {image_res} m per pixel, the map {res} m per cell"),
        ));
    }
    let (ox, oy, yaw) = image.origin;
    if yaw != 0.0 {
        return Err(MappingError::invalid(
            "origin",
            format!("yaw must be 0 (rotated maps cannot be imported), got {yaw}"),
        ));
    }
    let origin_cell = CellIndex::new(
        whole_cells("origin", "x", ox, res, image.width)?,
        whole_cells("origin", "y", oy, res, image.height)?,
    );
    let expected = u64::from(image.width) * u64::from(image.height);
    if image.width == 0 || image.height == 0 || image.pixels.len() as u64 != expected {
        return Err(MappingError::invalid(
            "pixels",
            format!(
                "{} x {} needs {expected} pixels (and neither may be 0), the image holds {}",
                image.width,
                image.height,
                image.pixels.len()
            ),
        ));
    }
    Ok(origin_cell)
}

/// Occupied and free cells at the clamp limits must read back as such.
fn check_limits(limits: ClampLimits) -> Result<(), MappingError> {
    let (max_p, min_p) = (limits.max().probability(), limits.min().probability());
    if max_p <= OCCUPIED_THRESH {
        return Err(MappingError::invalid(
            "clamp_max_probability",
            format!(
                "the map's upper clamp limit ({max_p:.4}) must exceed {OCCUPIED_THRESH}, or imported obstacles would not read as occupied"
            ),
        ));
    }
    if min_p >= FREE_THRESH {
        return Err(MappingError::invalid(
            "clamp_min_probability",
            format!(
                "the map's lower clamp limit ({min_p:.4}) must be below {FREE_THRESH}, or imported free space would not read as free"
            ),
        ));
    }
    Ok(())
}

/// `metres / res` as a whole number of cells, checking that it is one
/// (within [`ORIGIN_TOLERANCE_CELLS`]) and that the `extent` pixels from it
/// stay within [`MAX_ABS_CELL`].
fn whole_cells(
    field: &str,
    axis: &str,
    metres: f64,
    res: f64,
    extent: u32,
) -> Result<i32, MappingError> {
    let cells = metres / res;
    let whole = cells.round();
    if !cells.is_finite() || (cells - whole).abs() > ORIGIN_TOLERANCE_CELLS {
        return Err(MappingError::invalid(
            field,
            format!(
                "{axis} = {metres} m is {cells} cells of {res} m, not a whole number: the image's pixels would straddle the map's cells"
            ),
        ));
    }
    let first = whole as i64;
    let last = first + i64::from(extent) - 1;
    if first < -MAX_ABS_CELL || last > MAX_ABS_CELL {
        return Err(MappingError::invalid(
            field,
            format!(
                "{axis}: the image spans cells {first} to {last}, beyond the map's ±{MAX_ABS_CELL}"
            ),
        ));
    }
    // Within ±2^24, so within i32.
    Ok(first as i32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map_export::{MapExport, export_map};
    use deog_grid::TileMap;
    use deog_mapfile::Mode;

    fn target(res: f64) -> ImportTarget {
        ImportTarget {
            resolution: Resolution::new(res).expect("resolution"),
            tile_size: TileSize::new(8).expect("tile size"),
            limits: ClampLimits::default(),
        }
    }

    /// A 10 x 6 image at 0.1 m, origin (-0.5, -0.2): an occupied frame (so
    /// the known cells span the whole image) around free and unknown cells,
    /// in odd gray values map_server still reads.
    fn synthetic() -> MapImage {
        let (width, height) = (10u32, 6u32);
        let mut pixels = Vec::new();
        for row in 0..height {
            for col in 0..width {
                let border = row == 0 || col == 0 || row == height - 1 || col == width - 1;
                pixels.push(if border {
                    10 // p = 0.96: occupied
                } else if (col + row) % 3 == 0 {
                    128 // p = 0.5: unknown
                } else {
                    240 // p = 0.06: free
                });
            }
        }
        MapImage {
            width,
            height,
            resolution: 0.1,
            origin: (-0.5, -0.2, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: Mode::Trinary,
            pixels,
        }
    }

    /// Imports into an empty in-memory map and exports it again.
    fn round_trip(image: &MapImage, target: &ImportTarget) -> (MapImport, MapExport) {
        let import = import_map(image, target).expect("import");
        let mut map = TileMap::new(target.resolution, target.tile_size, target.limits);
        for delta in &import.deltas {
            map.apply(delta).expect("apply");
        }
        (import, export_map(&map).expect("export"))
    }

    /// The trinary pixel of a class.
    fn trinary(cell: Cell) -> u8 {
        match cell {
            Cell::Occupied => 0,
            Cell::Free => 254,
            Cell::Unknown => 205,
        }
    }

    #[test]
    fn import_then_export_gives_back_the_same_trinary_pixels() {
        let image = synthetic();
        let (import, export) = round_trip(&image, &target(0.1));
        assert_eq!(import.origin_cell, CellIndex::new(-5, -2));
        assert_eq!(import.occupied, 28);
        assert_eq!(import.occupied + import.free + import.unknown, 60);
        // 10 x 6 cells from (-5, -2) lie in tiles x -1..=0, y -1..=0.
        assert_eq!(import.deltas.len(), 4);
        let out = &export.image;
        assert_eq!((out.width, out.height), (image.width, image.height));
        assert!((out.origin.0 - image.origin.0).abs() < 1e-12);
        assert!((out.origin.1 - image.origin.1).abs() < 1e-12);
        let expected: Vec<u8> = (0..image.height)
            .rev()
            .flat_map(|row| (0..image.width).map(move |col| (col, row)))
            .map(|(col, row)| trinary(image.occupancy(col, row)))
            .collect();
        assert_eq!(out.pixels, expected);
        assert_eq!(export.counts.occupied, import.occupied);
        assert_eq!(export.counts.free, import.free);
        assert_eq!(export.counts.unknown(), import.unknown);
    }

    #[test]
    fn occupied_and_free_cells_hold_the_clamp_limits() {
        let image = synthetic();
        let t = target(0.1);
        let import = import_map(&image, &t).expect("import");
        let mut map = TileMap::new(t.resolution, t.tile_size, t.limits);
        for delta in &import.deltas {
            map.apply(delta).expect("apply");
        }
        for row in 0..image.height {
            for col in 0..image.width {
                let cell = CellIndex::new(-5 + col as i32, -2 + row as i32);
                let expected = match image.occupancy(col, row) {
                    Cell::Occupied => Some(t.limits.max()),
                    Cell::Free => Some(t.limits.min()),
                    Cell::Unknown => None,
                };
                assert_eq!(map.get(cell), expected, "pixel ({col}, {row})");
            }
        }
        assert_eq!(map.observed_count() as u64, import.occupied + import.free);
    }

    #[test]
    fn mismatched_grids_are_refused_naming_the_field() {
        let image = synthetic();
        let e = import_map(&image, &target(0.05)).expect_err("resolution");
        assert!(e.to_string().starts_with("resolution: "), "{e}");
        // A decimal YAML's rounding is not a mismatch.
        let mut close = image.clone();
        close.resolution = 0.1 * (1.0 + 1e-12);
        close.origin.0 = -0.5 + 1e-9;
        assert!(import_map(&close, &target(0.1)).is_ok());

        let mut shifted = image.clone();
        shifted.origin.0 = -0.52;
        let e = import_map(&shifted, &target(0.1)).expect_err("origin");
        assert!(e.to_string().starts_with("origin: x = -0.52 m"), "{e}");
        let mut rotated = image.clone();
        rotated.origin.2 = 0.1;
        let e = import_map(&rotated, &target(0.1)).expect_err("yaw");
        assert!(e.to_string().starts_with("origin: yaw must be 0"), "{e}");
        let mut far = image.clone();
        far.origin.1 = 1e9;
        let e = import_map(&far, &target(0.1)).expect_err("far");
        assert!(
            e.to_string().starts_with("origin: y: the image spans"),
            "{e}"
        );
        let mut nan = image.clone();
        nan.origin.0 = f64::NAN;
        assert!(import_map(&nan, &target(0.1)).is_err());
        let mut short = image.clone();
        short.pixels.pop();
        let e = import_map(&short, &target(0.1)).expect_err("pixels");
        assert!(e.to_string().starts_with("pixels: 10 x 6 needs 60"), "{e}");
        let mut none = image.clone();
        (none.width, none.pixels) = (0, Vec::new());
        assert!(import_map(&none, &target(0.1)).is_err());
    }

    #[test]
    fn clamp_limits_that_would_not_read_back_are_refused() {
        let mut t = target(0.1);
        t.limits = ClampLimits::from_probabilities(0.3, 0.97).expect("limits");
        let e = import_map(&synthetic(), &t).expect_err("min");
        assert!(e.to_string().starts_with("clamp_min_probability: "), "{e}");
        t.limits = ClampLimits::from_probabilities(0.12, 0.6).expect("limits");
        let e = import_map(&synthetic(), &t).expect_err("max");
        assert!(e.to_string().starts_with("clamp_max_probability: "), "{e}");
    }

    /// Loads one of the real maps kept for the mapfile crate's tests.
    fn real_map(path: &str) -> MapImage {
        let path = format!(
            "{}/../mapfile/tests/data/{path}",
            env!("CARGO_MANIFEST_DIR")
        );
        MapImage::load(&path).expect("real map loads")
    }

    /// Every original pixel's class equals the exported one at the same
    /// world cell (outside the export: unknown), and the export lies within
    /// the original.
    fn assert_same_by_world_cell(original: &MapImage, import: &MapImport, export: &MapExport) {
        let out = &export.image;
        let dx = i64::from(import.origin_cell.x) - i64::from(export.min_cell.x);
        let dy = i64::from(import.origin_cell.y) - i64::from(export.min_cell.y);
        assert!(dx <= 0 && dy <= 0, "the export starts inside the original");
        assert!(i64::from(out.width) - dx <= i64::from(original.width));
        assert!(i64::from(out.height) - dy <= i64::from(original.height));
        assert!(out.pixels.iter().all(|p| [0, 205, 254].contains(p)));
        for row in 0..original.height {
            for col in 0..original.width {
                let (x, y) = (i64::from(col) + dx, i64::from(row) + dy);
                let exported = match (u32::try_from(x), u32::try_from(y)) {
                    (Ok(x), Ok(y)) => out.occupancy(x, y),
                    _ => Cell::Unknown,
                };
                assert_eq!(
                    exported,
                    original.occupancy(col, row),
                    "pixel ({col}, {row} from the bottom)"
                );
            }
        }
    }

    #[test]
    fn real_maps_survive_import_and_export() {
        for path in ["lse_arena.yaml", "turtlebot3_world/map.yaml"] {
            let original = real_map(path);
            let t = ImportTarget {
                resolution: Resolution::new(original.resolution).expect("resolution"),
                tile_size: TileSize::DEFAULT,
                limits: ClampLimits::default(),
            };
            let (import, export) = round_trip(&original, &t);
            assert!(import.occupied > 100 && import.free > 1000, "{path}");
            assert_eq!(export.counts.occupied, import.occupied, "{path}");
            assert_eq!(export.counts.free, import.free, "{path}");
            assert_same_by_world_cell(&original, &import, &export);
        }
    }
}
