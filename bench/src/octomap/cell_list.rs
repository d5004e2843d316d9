//! OctoMap's final map as the script exports it: the cells of the z = 0
//! layer, each with its log-odds, in a small binary file.
//!
//! Layout, little-endian throughout:
//!
//! ```text
//! magic    8 bytes   "DEOGOC01"
//! cells    u64
//! per cell: x, y     i32, i32   the cell's index (deog's: floor(metres / resolution))
//!           log-odds f32        nats, OctoMap's own value
//! ```

use std::collections::HashMap;
use std::io::{self, Read};

use anyhow::{Context, Result};
use deog_grid::{CellIndex, ClampLimits, LogOdds, Resolution, Tile, TileMap, TileSize};

/// The file's first eight bytes.
const MAGIC: &[u8; 8] = b"DEOGOC01";

/// One cell of the exported map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ExportedCell {
    /// Cell index along x.
    pub x: i32,
    /// Cell index along y.
    pub y: i32,
    /// The belief, nats (`ln(p / (1 − p))`).
    pub log_odds: f32,
}

/// Reads the file `bench/octomap_insert.py` writes.
pub(crate) fn read_cells(mut input: impl Read) -> io::Result<Vec<ExportedCell>> {
    let mut magic = [0u8; 8];
    input.read_exact(&mut magic)?;
    if &magic != MAGIC {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            "not a deog cell-list file (bad magic)",
        ));
    }
    let mut count = [0u8; 8];
    input.read_exact(&mut count)?;
    let count = u64::from_le_bytes(count);
    // Read the whole body at once: a map holds a million cells or so.
    let len = usize::try_from(count)
        .ok()
        .and_then(|n| n.checked_mul(12))
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidData, "cell count too large"))?;
    let mut body = Vec::new();
    input.take(len as u64).read_to_end(&mut body)?;
    if body.len() != len {
        return Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!(
                "{count} cells announced, {} bytes of them found",
                body.len()
            ),
        ));
    }
    Ok(body
        .chunks_exact(12)
        .map(|c| ExportedCell {
            x: i32::from_le_bytes([c[0], c[1], c[2], c[3]]),
            y: i32::from_le_bytes([c[4], c[5], c[6], c[7]]),
            log_odds: f32::from_le_bytes([c[8], c[9], c[10], c[11]]),
        })
        .collect())
}

/// The cells as a deog map of `resolution` and `tile_size`, each holding
/// OctoMap's belief rounded to deog's fixed point (a thousandth of a nat);
/// the cells OctoMap never observed are unknown. OctoMap clamped the
/// beliefs already; the map is given the default clamp (OctoMap's too),
/// which only matters to deltas applied later.
pub(crate) fn to_tile_map(
    cells: &[ExportedCell],
    resolution: Resolution,
    tile_size: TileSize,
) -> Result<TileMap> {
    let mut tiles: HashMap<_, Vec<i16>> = HashMap::new();
    for cell in cells {
        let (key, offset) = tile_size.split(CellIndex::new(cell.x, cell.y));
        let belief = LogOdds::from_nats(f64::from(cell.log_odds))
            .with_context(|| format!("OctoMap's cell ({}, {})", cell.x, cell.y))?;
        tiles
            .entry(key)
            .or_insert_with(|| vec![LogOdds::UNKNOWN_RAW; tile_size.area()])
            [offset.index(tile_size)] = belief.raw();
    }
    let mut map = TileMap::new(resolution, tile_size, ClampLimits::default());
    for (key, raw) in tiles {
        let bytes: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
        map.insert(key, Tile::from_dense_bytes(tile_size, &bytes)?)?;
    }
    Ok(map)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes the script writes (numpy's `<i4, <i4, <f4` records).
    fn file_of(cells: &[ExportedCell]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&(cells.len() as u64).to_le_bytes());
        for c in cells {
            out.extend_from_slice(&c.x.to_le_bytes());
            out.extend_from_slice(&c.y.to_le_bytes());
            out.extend_from_slice(&c.log_odds.to_le_bytes());
        }
        out
    }

    #[test]
    fn cells_read_back_as_written() {
        let cells = [
            ExportedCell {
                x: -3,
                y: 7,
                log_odds: 0.847,
            },
            ExportedCell {
                x: i32::MIN,
                y: i32::MAX,
                log_odds: -1.992,
            },
        ];
        assert_eq!(read_cells(file_of(&cells).as_slice()).expect("read"), cells);
        assert_eq!(read_cells(file_of(&[]).as_slice()).expect("empty"), []);
    }

    #[test]
    fn cells_become_a_map_with_their_beliefs_and_the_rest_unknown() {
        let size = TileSize::new(8).expect("size");
        let cells = [
            ExportedCell {
                x: -1,
                y: 0,
                log_odds: 0.847_298,
            },
            ExportedCell {
                x: 9,
                y: -17,
                log_odds: -0.405_465,
            },
            // Evidence that cancelled out is observed all the same.
            ExportedCell {
                x: 10,
                y: -17,
                log_odds: 0.0,
            },
        ];
        let map = to_tile_map(&cells, Resolution::DEFAULT, size).expect("map");
        assert_eq!(map.resolution(), Resolution::DEFAULT);
        assert_eq!((map.tile_count(), map.observed_count()), (2, 3));
        let raw = |x, y| map.get(CellIndex::new(x, y)).map(LogOdds::raw);
        assert_eq!(raw(-1, 0), Some(847));
        assert_eq!(raw(9, -17), Some(-405));
        assert_eq!(raw(10, -17), Some(0));
        assert_eq!(raw(0, 0), None);
        assert_eq!(raw(-2, 0), None);
    }

    #[test]
    fn a_file_of_another_kind_or_cut_short_is_refused() {
        let cells = [ExportedCell {
            x: 1,
            y: 2,
            log_odds: 0.5,
        }];
        let bytes = file_of(&cells);
        let mut wrong = bytes.clone();
        wrong[7] = b'9';
        assert_eq!(
            read_cells(wrong.as_slice()).expect_err("magic").kind(),
            io::ErrorKind::InvalidData
        );
        assert_eq!(
            read_cells(&bytes[..bytes.len() - 2])
                .expect_err("short")
                .kind(),
            io::ErrorKind::UnexpectedEof
        );
    }
}
