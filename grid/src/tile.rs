//! A tile's cells and a batch of deltas for them, with their packed byte
//! encodings (the wire and store formats).
//!
//! Cells are row-major: cell `(ox, oy)` is entry `oy · size + ox`. Dense
//! encoding is `size²` little-endian i16; sparse encoding is a list of
//! `(u16 index, i16 value)` pairs, little-endian, indices strictly increasing.

use crate::error::GridError;
use crate::log_odds::{ClampLimits, LogOdds};
use crate::tile_key::{CellOffset, TileKey, TileSize};

/// The beliefs of one tile's cells, raw fixed-point log-odds with
/// [`LogOdds::UNKNOWN_RAW`] for cells never observed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tile {
    size: TileSize,
    cells: Box<[i16]>,
}

impl Tile {
    /// A tile whose cells are all unknown.
    pub fn unknown(size: TileSize) -> Self {
        Self {
            size,
            cells: vec![LogOdds::UNKNOWN_RAW; size.area()].into_boxed_slice(),
        }
    }

    /// A tile from its dense encoding.
    pub fn from_dense_bytes(size: TileSize, bytes: &[u8]) -> Result<Self, GridError> {
        Ok(Self {
            size,
            cells: decode_dense("cells", size, bytes)?,
        })
    }

    /// The dense encoding.
    pub fn to_dense_bytes(&self) -> Vec<u8> {
        encode_dense(&self.cells)
    }

    /// Cells per side.
    pub fn size(&self) -> TileSize {
        self.size
    }

    /// Raw cells, row-major.
    pub fn raw_cells(&self) -> &[i16] {
        &self.cells
    }

    /// The belief of the cell at `offset`; `None` if never observed.
    pub fn get(&self, offset: CellOffset) -> Option<LogOdds> {
        LogOdds::from_raw(self.cells[offset.index(self.size)])
    }

    /// Number of cells ever observed.
    pub fn observed_count(&self) -> usize {
        self.cells
            .iter()
            .filter(|&&c| c != LogOdds::UNKNOWN_RAW)
            .count()
    }

    /// Adds `delta`'s cells, clamping each to `limits`; returns how many
    /// cells changed value. Fails, changing nothing, on a size mismatch.
    pub fn apply(&mut self, delta: &TileDelta, limits: ClampLimits) -> Result<usize, GridError> {
        if delta.deltas.len() != self.cells.len() {
            return Err(GridError::BadCells {
                field: "cells",
                reason: format!(
                    "delta has {} cells, tile has {}",
                    delta.deltas.len(),
                    self.cells.len()
                ),
            });
        }
        let mut changed = 0;
        for (cell, &d) in self.cells.iter_mut().zip(delta.deltas.iter()) {
            let next = limits.apply(*cell, d);
            changed += usize::from(next != *cell);
            *cell = next;
        }
        Ok(changed)
    }
}

/// Log-odds deltas for the cells of one tile, dense; 0 means no evidence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TileDelta {
    /// The tile the deltas are for.
    pub key: TileKey,
    deltas: Box<[i16]>,
}

impl TileDelta {
    /// A delta with no evidence for any cell.
    pub fn zero(key: TileKey, size: TileSize) -> Self {
        Self {
            key,
            deltas: vec![0; size.area()].into_boxed_slice(),
        }
    }

    /// A delta from raw values; their count must be the tile's area.
    pub fn from_raw(key: TileKey, size: TileSize, deltas: Vec<i16>) -> Result<Self, GridError> {
        if deltas.len() != size.area() {
            return Err(GridError::BadCells {
                field: "cells",
                reason: format!("expected {} cells, got {}", size.area(), deltas.len()),
            });
        }
        Ok(Self {
            key,
            deltas: deltas.into_boxed_slice(),
        })
    }

    /// From the dense encoding.
    pub fn from_dense_bytes(key: TileKey, size: TileSize, bytes: &[u8]) -> Result<Self, GridError> {
        Ok(Self {
            key,
            deltas: decode_dense("cells", size, bytes)?,
        })
    }

    /// From the sparse encoding.
    pub fn from_sparse_bytes(
        key: TileKey,
        size: TileSize,
        bytes: &[u8],
    ) -> Result<Self, GridError> {
        if bytes.len() % 4 != 0 {
            return Err(GridError::BadCells {
                field: "cells",
                reason: format!("sparse cells need 4 bytes each, got {} bytes", bytes.len()),
            });
        }
        let mut deltas = vec![0i16; size.area()];
        let mut previous: Option<usize> = None;
        for pair in bytes.chunks_exact(4) {
            let index = usize::from(u16::from_le_bytes([pair[0], pair[1]]));
            if index >= deltas.len() || previous.is_some_and(|p| index <= p) {
                return Err(GridError::BadCells {
                    field: "cells",
                    reason: format!(
                        "sparse index {index} out of order or past the tile's {} cells",
                        deltas.len()
                    ),
                });
            }
            deltas[index] = i16::from_le_bytes([pair[2], pair[3]]);
            previous = Some(index);
        }
        Ok(Self {
            key,
            deltas: deltas.into_boxed_slice(),
        })
    }

    /// The dense encoding.
    pub fn to_dense_bytes(&self) -> Vec<u8> {
        encode_dense(&self.deltas)
    }

    /// The sparse encoding of the nonzero deltas. Tiles up to 256² cells
    /// only, since indices are u16; larger ones must use the dense form.
    pub fn to_sparse_bytes(&self) -> Option<Vec<u8>> {
        if self.deltas.len() > usize::from(u16::MAX) + 1 {
            return None;
        }
        let mut out = Vec::with_capacity(self.nonzero_count() * 4);
        for (index, &d) in self.deltas.iter().enumerate().filter(|(_, d)| **d != 0) {
            out.extend_from_slice(&(index as u16).to_le_bytes());
            out.extend_from_slice(&d.to_le_bytes());
        }
        Some(out)
    }

    /// Raw deltas, row-major.
    pub fn raw(&self) -> &[i16] {
        &self.deltas
    }

    /// Mutable raw deltas, row-major.
    pub fn raw_mut(&mut self) -> &mut [i16] {
        &mut self.deltas
    }

    /// Number of cells with evidence.
    pub fn nonzero_count(&self) -> usize {
        self.deltas.iter().filter(|&&d| d != 0).count()
    }

    /// Adds `other`'s deltas to these, saturating; used to gather several
    /// frames into one batch before sending.
    pub fn accumulate(&mut self, other: &TileDelta) -> Result<(), GridError> {
        if other.deltas.len() != self.deltas.len() {
            return Err(GridError::BadCells {
                field: "cells",
                reason: "deltas of different tile sizes".into(),
            });
        }
        for (mine, &theirs) in self.deltas.iter_mut().zip(other.deltas.iter()) {
            *mine = mine.saturating_add(theirs).max(-i16::MAX);
        }
        Ok(())
    }
}

fn encode_dense(cells: &[i16]) -> Vec<u8> {
    cells.iter().flat_map(|c| c.to_le_bytes()).collect()
}

fn decode_dense(
    field: &'static str,
    size: TileSize,
    bytes: &[u8],
) -> Result<Box<[i16]>, GridError> {
    let expected = size.area() * 2;
    if bytes.len() != expected {
        return Err(GridError::BadCells {
            field,
            reason: format!(
                "dense cells of a {0}x{0} tile need {expected} bytes, got {1}",
                size.cells(),
                bytes.len()
            ),
        });
    }
    Ok(bytes
        .chunks_exact(2)
        .map(|b| i16::from_le_bytes([b[0], b[1]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const KEY: TileKey = TileKey::new(-3, 7);

    fn size() -> TileSize {
        TileSize::new(16).unwrap()
    }

    #[test]
    fn dense_round_trip_and_length_check() {
        let mut delta = TileDelta::zero(KEY, size());
        delta.raw_mut()[5] = -700;
        delta.raw_mut()[255] = 1200;
        let bytes = delta.to_dense_bytes();
        assert_eq!(
            TileDelta::from_dense_bytes(KEY, size(), &bytes).unwrap(),
            delta
        );
        assert!(TileDelta::from_dense_bytes(KEY, size(), &bytes[1..]).is_err());
        assert!(Tile::from_dense_bytes(size(), &bytes[..10]).is_err());
    }

    #[test]
    fn sparse_rejects_disorder_and_overflow() {
        let pair = |i: u16, v: i16| [i.to_le_bytes(), v.to_le_bytes()].concat();
        let ok = [pair(1, 5), pair(9, -5)].concat();
        assert_eq!(
            TileDelta::from_sparse_bytes(KEY, size(), &ok)
                .unwrap()
                .nonzero_count(),
            2
        );
        let unordered = [pair(9, 5), pair(1, -5)].concat();
        assert!(TileDelta::from_sparse_bytes(KEY, size(), &unordered).is_err());
        assert!(TileDelta::from_sparse_bytes(KEY, size(), &pair(256, 1)).is_err());
        assert!(TileDelta::from_sparse_bytes(KEY, size(), &ok[..3]).is_err());
    }

    #[test]
    fn apply_clamps_counts_and_rejects_mismatch() {
        let limits = ClampLimits::default();
        let mut tile = Tile::unknown(size());
        let mut delta = TileDelta::zero(KEY, size());
        delta.raw_mut()[0] = 10_000;
        delta.raw_mut()[1] = -50;
        assert_eq!(tile.apply(&delta, limits).unwrap(), 2);
        assert_eq!(tile.get(CellOffset { x: 0, y: 0 }), Some(limits.max()));
        assert_eq!(tile.get(CellOffset { x: 1, y: 0 }).unwrap().raw(), -50);
        assert_eq!(tile.get(CellOffset { x: 2, y: 0 }), None);
        assert_eq!(tile.observed_count(), 2);
        let before = tile.clone();
        let wrong = TileDelta::zero(KEY, TileSize::new(8).unwrap());
        assert!(tile.apply(&wrong, limits).is_err());
        assert_eq!(tile, before);
    }

    proptest! {
        #[test]
        fn sparse_round_trip(cells in proptest::collection::vec(any::<i16>(), 256)) {
            let cells: Vec<i16> = cells.into_iter().map(|c| c.max(-i16::MAX)).collect();
            let delta = TileDelta::from_raw(KEY, size(), cells).unwrap();
            let sparse = delta.to_sparse_bytes().unwrap();
            prop_assert_eq!(TileDelta::from_sparse_bytes(KEY, size(), &sparse).unwrap(), delta);
        }

        #[test]
        fn unclamped_application_commutes(a in proptest::collection::vec(-100i16..100, 256),
                                          b in proptest::collection::vec(-100i16..100, 256)) {
            let da = TileDelta::from_raw(KEY, size(), a).unwrap();
            let db = TileDelta::from_raw(KEY, size(), b).unwrap();
            let mut ab = Tile::unknown(size());
            ab.apply(&da, ClampLimits::NONE).unwrap();
            ab.apply(&db, ClampLimits::NONE).unwrap();
            let mut ba = Tile::unknown(size());
            ba.apply(&db, ClampLimits::NONE).unwrap();
            ba.apply(&da, ClampLimits::NONE).unwrap();
            prop_assert_eq!(ab, ba);
        }
    }
}
