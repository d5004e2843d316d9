//! A frame's scratch kept per tile: cells combined straight into the tile
//! deltas the frame will hand out, only for tiles it touches.
//!
//! A dense scratch over the frame's bounding box costs its whole area per
//! frame (zeroing it, then scanning it into tiles); a 360° laser reaching
//! 50 m at 5 cm spans 2000 × 2000 cells while its rays touch a few
//! hundred thousand. Here a touched tile's delta is made on first touch
//! and later touches find it through an index of the tiles the frame box
//! covers (a hash map when that box is huge), the last tile remembered,
//! since successive cells of a ray or a cone's row mostly share a tile.

use std::collections::HashMap;

use crate::cell::{CellBox, CellIndex};
use crate::frame::{FrameStats, combine};
use crate::tile::TileDelta;
use crate::tile_key::{TileKey, TileSize};

/// Largest tile box indexed densely (256 KiB of slots); beyond, a hash map.
const DENSE_TILES: u64 = 1 << 16;

const NO_SLOT: u32 = u32::MAX;

/// Adds cells to a [`TileScratch`], keeping the tile at hand and its count
/// in locals (registers, in a cell loop) rather than in the scratch.
#[derive(Debug)]
pub(crate) struct TileCursor<'a> {
    scratch: &'a mut TileScratch,
    key: TileKey,
    slot: u32,
    counted: usize,
}

impl TileCursor<'_> {
    /// Combines `delta` (nonzero) into `cell`'s scratch value.
    #[inline]
    pub(crate) fn add(&mut self, cell: CellIndex, delta: i16) {
        let (shift, mask) = (self.scratch.shift, self.scratch.mask);
        let key = TileKey::new(cell.x >> shift, cell.y >> shift);
        if self.slot == NO_SLOT || key != self.key {
            self.slot = self.scratch.slot(key);
            self.key = key;
        }
        let offset = (((cell.y & mask) as usize) << shift) | (cell.x & mask) as usize;
        let raw = self.scratch.tiles[self.slot as usize].raw_mut();
        let current = raw[offset];
        // A nonzero delta leaves a nonzero value: a cell is counted once.
        self.counted += usize::from(current == 0);
        raw[offset] = combine(current, delta);
    }
}

impl Drop for TileCursor<'_> {
    fn drop(&mut self) {
        self.scratch.cells += self.counted;
        self.scratch.last_key = self.key;
        self.scratch.last_slot = self.slot;
    }
}

/// Per-tile scratch for one frame at a time; its buffers are reused.
#[derive(Debug, Clone)]
pub(crate) struct TileScratch {
    tile_size: TileSize,
    shift: u32,
    mask: i32,
    first: TileKey,
    width: u64,
    height: u64,
    dense: Vec<u32>,
    sparse: HashMap<TileKey, u32>,
    tiles: Vec<TileDelta>,
    cells: usize,
    last_key: TileKey,
    last_slot: u32,
}

impl TileScratch {
    pub(crate) fn new(tile_size: TileSize) -> Self {
        Self {
            tile_size,
            shift: tile_size.cells().trailing_zeros(),
            mask: tile_size.cells() as i32 - 1,
            first: TileKey::new(0, 0),
            width: 0,
            height: 0,
            dense: Vec::new(),
            sparse: HashMap::new(),
            tiles: Vec::new(),
            cells: 0,
            last_key: TileKey::new(0, 0),
            last_slot: NO_SLOT,
        }
    }

    /// Starts a frame whose cells all lie in `frame_box`.
    pub(crate) fn begin(&mut self, frame_box: &CellBox) {
        let (first, last) = self.tile_size.tiles_covering(frame_box);
        self.first = first;
        self.width = (i64::from(last.x) - i64::from(first.x) + 1) as u64;
        self.height = (i64::from(last.y) - i64::from(first.y) + 1) as u64;
        self.dense.clear();
        self.sparse.clear();
        let area = self.width.saturating_mul(self.height);
        if area <= DENSE_TILES {
            self.dense.resize(area as usize, NO_SLOT);
        }
        self.tiles.clear();
        self.cells = 0;
        self.last_slot = NO_SLOT;
    }

    /// A cursor adding cells to this frame's scratch.
    pub(crate) fn cursor(&mut self) -> TileCursor<'_> {
        TileCursor {
            key: self.last_key,
            slot: self.last_slot,
            counted: 0,
            scratch: self,
        }
    }

    /// The slot of `key`'s delta, made on first touch.
    fn slot(&mut self, key: TileKey) -> u32 {
        let col = i64::from(key.x) - i64::from(self.first.x);
        let row = i64::from(key.y) - i64::from(self.first.y);
        let inside =
            (0..self.width as i64).contains(&col) && (0..self.height as i64).contains(&row);
        // Every cell lies in the frame box; were a key outside it, or the
        // box too large to index densely, the hash map serves.
        let index = if inside {
            (row as u64 * self.width + col as u64) as usize
        } else {
            usize::MAX
        };
        let existing = match self.dense.get(index) {
            Some(&slot) => slot,
            None => self.sparse.get(&key).copied().unwrap_or(NO_SLOT),
        };
        if existing != NO_SLOT {
            return existing;
        }
        let slot = self.tiles.len() as u32;
        self.tiles.push(TileDelta::zero(key, self.tile_size));
        match self.dense.get_mut(index) {
            Some(entry) => *entry = slot,
            None => {
                self.sparse.insert(key, slot);
            }
        }
        slot
    }

    /// Ends the frame: its tile deltas appended to `out`, rows of tiles
    /// from the lowest, each from the left.
    pub(crate) fn finish(&mut self, out: &mut Vec<TileDelta>) -> FrameStats {
        self.tiles.sort_unstable_by_key(|d| (d.key.y, d.key.x));
        let stats = FrameStats {
            cells: self.cells,
            tiles: self.tiles.len(),
        };
        out.append(&mut self.tiles);
        self.last_slot = NO_SLOT;
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flatten(deltas: &[TileDelta], size: TileSize) -> Vec<(CellIndex, i16)> {
        let mut cells = Vec::new();
        for delta in deltas {
            for (i, &d) in delta.raw().iter().enumerate().filter(|(_, d)| **d != 0) {
                let offset = crate::tile_key::CellOffset::from_index(i, size);
                cells.push((size.join(delta.key, offset).unwrap(), d));
            }
        }
        cells.sort_by_key(|(c, _)| (c.x, c.y));
        cells
    }

    #[test]
    fn cells_combine_per_tile_in_either_index() {
        let size = TileSize::new(8).unwrap();
        let cells = [
            (CellIndex::new(-1, -1), -300),
            (CellIndex::new(-1, -1), -500),
            (CellIndex::new(7, 0), -200),
            (CellIndex::new(7, 0), 40),
            (CellIndex::new(8, 0), 100),
            (CellIndex::new(8, 0), -900),
            (CellIndex::new(20, 30), 7),
        ];
        let expected = vec![
            (CellIndex::new(-1, -1), -500),
            (CellIndex::new(7, 0), 40),
            (CellIndex::new(8, 0), 100),
            (CellIndex::new(20, 30), 7),
        ];
        let small = CellBox::new(CellIndex::new(-1, -1), CellIndex::new(20, 30)).unwrap();
        let huge = CellBox::new(CellIndex::new(-1 << 20, -1), CellIndex::new(1 << 20, 30)).unwrap();
        for frame_box in [small, huge] {
            let mut scratch = TileScratch::new(size);
            for _ in 0..2 {
                scratch.begin(&frame_box);
                let mut cursor = scratch.cursor();
                for (cell, d) in cells {
                    cursor.add(cell, d);
                }
                drop(cursor);
                let mut out = Vec::new();
                let stats = scratch.finish(&mut out);
                assert_eq!((stats.cells, stats.tiles), (4, 4));
                let keys: Vec<_> = out.iter().map(|d| (d.key.x, d.key.y)).collect();
                assert_eq!(keys, [(-1, -1), (0, 0), (1, 0), (2, 3)]);
                assert_eq!(flatten(&out, size), expected);
            }
        }
    }
}
