//! Tiles: which tile holds a cell, where in the tile, and the store key of a
//! tile, which sorts as the tile indices do.

use crate::cell::{CellBox, CellIndex};
use crate::error::GridError;

/// Cells per tile side: a power of two, so that splitting a cell index into
/// tile and offset is a shift and a mask for either sign.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileSize(u32);

impl TileSize {
    /// Smallest accepted size.
    pub const MIN: u32 = 8;
    /// Largest accepted size; a 1024² tile of i16 cells is 2 MiB.
    pub const MAX: u32 = 1024;
    /// The default, 64 × 64 cells (3.2 m at 5 cm).
    pub const DEFAULT: TileSize = TileSize(64);

    /// A tile size, a power of two in [`Self::MIN`, `Self::MAX`].
    pub fn new(cells: u32) -> Result<Self, GridError> {
        if cells.is_power_of_two() && (Self::MIN..=Self::MAX).contains(&cells) {
            Ok(Self(cells))
        } else {
            Err(GridError::BadTileSize {
                value: cells,
                min: Self::MIN,
                max: Self::MAX,
            })
        }
    }

    /// Cells per side.
    pub fn cells(self) -> u32 {
        self.0
    }

    /// Cells per tile.
    pub fn area(self) -> usize {
        (self.0 * self.0) as usize
    }

    fn shift(self) -> u32 {
        self.0.trailing_zeros()
    }

    /// The tile holding `cell` and the cell's offset in it.
    pub fn split(self, cell: CellIndex) -> (TileKey, CellOffset) {
        let shift = self.shift();
        let mask = self.0 as i32 - 1;
        (
            // Arithmetic shifts floor towards minus infinity, so cell -1 lies
            // in tile -1 at offset size - 1.
            TileKey::new(cell.x >> shift, cell.y >> shift),
            CellOffset {
                x: (cell.x & mask) as u16,
                y: (cell.y & mask) as u16,
            },
        )
    }

    /// The cell at `offset` in tile `key`, if `key` is addressable.
    pub fn join(self, key: TileKey, offset: CellOffset) -> Result<CellIndex, GridError> {
        let origin = self.origin(key)?;
        Ok(CellIndex::new(
            origin.x | i32::from(offset.x),
            origin.y | i32::from(offset.y),
        ))
    }

    /// The lowest cell of tile `key`; an error for keys whose cells would
    /// not fit in i32 (absurd input from the wire).
    pub fn origin(self, key: TileKey) -> Result<CellIndex, GridError> {
        self.check(key)?;
        let shift = self.shift();
        Ok(CellIndex::new(key.x << shift, key.y << shift))
    }

    /// The cells of tile `key`.
    pub fn cell_box(self, key: TileKey) -> Result<CellBox, GridError> {
        let min = self.origin(key)?;
        let last = self.0 as i32 - 1;
        Ok(CellBox {
            min,
            max: CellIndex::new(min.x + last, min.y + last),
        })
    }

    /// Checks that every cell of tile `key` has an i32 index.
    pub fn check(self, key: TileKey) -> Result<TileKey, GridError> {
        let shift = self.shift();
        let range = (i32::MIN >> shift)..=(i32::MAX >> shift);
        if range.contains(&key.x) && range.contains(&key.y) {
            Ok(key)
        } else {
            Err(GridError::TileKeyOutOfRange {
                x: key.x,
                y: key.y,
                tile_size: self.0,
            })
        }
    }

    /// The range of tiles overlapping `cells`, inclusive on both ends.
    pub fn tiles_covering(self, cells: &CellBox) -> (TileKey, TileKey) {
        (self.split(cells.min).0, self.split(cells.max).0)
    }
}

impl Default for TileSize {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Index of a tile: tile `(x, y)` holds cells `size·x ..= size·x + size - 1`
/// along x, and likewise along y.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    /// Tile column.
    pub x: i32,
    /// Tile row.
    pub y: i32,
}

impl TileKey {
    /// Length of [`Self::to_store_bytes`].
    pub const STORE_LEN: usize = 8;

    /// A tile key from its parts.
    pub const fn new(x: i32, y: i32) -> Self {
        Self { x, y }
    }

    /// Eight bytes, x then y, each big-endian with the sign bit flipped, so
    /// that byte order is the numeric order of `(x, y)`.
    pub fn to_store_bytes(self) -> [u8; Self::STORE_LEN] {
        let mut out = [0; Self::STORE_LEN];
        out[..4].copy_from_slice(&sortable(self.x));
        out[4..].copy_from_slice(&sortable(self.y));
        out
    }

    /// The key [`Self::to_store_bytes`] wrote.
    pub fn from_store_bytes(bytes: &[u8]) -> Result<Self, GridError> {
        let bytes: [u8; Self::STORE_LEN] = bytes.try_into().map_err(|_| GridError::BadCells {
            field: "tile key",
            reason: format!("expected {} bytes, got {}", Self::STORE_LEN, bytes.len()),
        })?;
        let half = |b: &[u8]| i32::from_be_bytes([b[0] ^ 0x80, b[1], b[2], b[3]]);
        Ok(Self::new(half(&bytes[..4]), half(&bytes[4..])))
    }
}

fn sortable(value: i32) -> [u8; 4] {
    let mut bytes = value.to_be_bytes();
    bytes[0] ^= 0x80;
    bytes
}

/// Position of a cell inside its tile, each coordinate in `0..size`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CellOffset {
    /// Column inside the tile.
    pub x: u16,
    /// Row inside the tile.
    pub y: u16,
}

impl CellOffset {
    /// Row-major index of the cell in a tile's cell array.
    pub fn index(self, size: TileSize) -> usize {
        usize::from(self.y) * size.cells() as usize + usize::from(self.x)
    }

    /// The offset at row-major `index` of a tile of `size`.
    pub fn from_index(index: usize, size: TileSize) -> Self {
        let side = size.cells() as usize;
        Self {
            x: (index % side) as u16,
            y: (index / side) as u16,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sizes() -> impl Strategy<Value = TileSize> {
        (3u32..=10).prop_map(|p| TileSize::new(1 << p).unwrap())
    }

    #[test]
    fn minus_one_is_the_last_cell_of_tile_minus_one() {
        let size = TileSize::DEFAULT;
        let (key, offset) = size.split(CellIndex::new(-1, -64));
        assert_eq!(key, TileKey::new(-1, -1));
        assert_eq!(offset, CellOffset { x: 63, y: 0 });
    }

    #[test]
    fn bad_sizes_are_rejected() {
        for bad in [0, 1, 4, 48, 100, 2048, u32::MAX] {
            assert!(TileSize::new(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn absurd_keys_are_rejected() {
        let size = TileSize::DEFAULT;
        assert!(size.check(TileKey::new(i32::MAX, 0)).is_err());
        assert!(size.origin(TileKey::new(0, i32::MIN)).is_err());
        let edge = TileKey::new(i32::MAX >> 6, i32::MIN >> 6);
        let cells = size.cell_box(edge).unwrap();
        assert_eq!(cells.max.x, i32::MAX);
        assert_eq!(cells.min.y, i32::MIN);
    }

    #[test]
    fn store_key_rejects_wrong_length() {
        assert!(TileKey::from_store_bytes(&[0; 7]).is_err());
    }

    proptest! {
        #[test]
        fn split_then_join_is_identity(x in any::<i32>(), y in any::<i32>(), size in sizes()) {
            let cell = CellIndex::new(x, y);
            let (key, offset) = size.split(cell);
            prop_assert!(u32::from(offset.x) < size.cells() && u32::from(offset.y) < size.cells());
            prop_assert_eq!(size.join(key, offset).unwrap(), cell);
            prop_assert!(size.cell_box(key).unwrap().contains(cell));
            prop_assert_eq!(CellOffset::from_index(offset.index(size), size), offset);
        }

        #[test]
        fn store_bytes_round_trip(x in any::<i32>(), y in any::<i32>()) {
            let key = TileKey::new(x, y);
            prop_assert_eq!(TileKey::from_store_bytes(&key.to_store_bytes()).unwrap(), key);
        }

        #[test]
        fn store_bytes_sort_numerically(a in any::<(i32, i32)>(), b in any::<(i32, i32)>()) {
            let (ka, kb) = (TileKey::new(a.0, a.1), TileKey::new(b.0, b.1));
            prop_assert_eq!(ka.to_store_bytes().cmp(&kb.to_store_bytes()), ka.cmp(&kb));
        }
    }
}
