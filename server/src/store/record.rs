//! The records a store keeps, and their byte encodings.
//!
//! Encodings are little-endian and start with a format byte, so that a later
//! version can read what an earlier one wrote.

use crate::error::StoreError;
use deog_grid::{CellBox, CellIndex, ClampLimits, Resolution, Tile, TileSize};

const FORMAT: u8 = 1;

/// The fixed settings of a map, chosen when it is created.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapSettings {
    /// Cell side.
    pub resolution: Resolution,
    /// Cells per tile side.
    pub tile_size: TileSize,
    /// Clamping limits as probabilities (min, max), as the client gave them.
    pub clamp_probabilities: (f64, f64),
    /// The same limits in log-odds.
    pub clamp: ClampLimits,
}

impl MapSettings {
    /// Settings from their parts; fails on invalid clamping limits.
    pub fn new(
        resolution: Resolution,
        tile_size: TileSize,
        clamp_probabilities: (f64, f64),
    ) -> Result<Self, deog_grid::GridError> {
        let clamp = ClampLimits::from_probabilities(clamp_probabilities.0, clamp_probabilities.1)?;
        Ok(Self {
            resolution,
            tile_size,
            clamp_probabilities,
            clamp,
        })
    }
}

/// A map's settings and running totals.
#[derive(Debug, Clone, PartialEq)]
pub struct MapRecord {
    /// Unique name.
    pub name: String,
    /// Fixed settings.
    pub settings: MapSettings,
    /// Incremented by every applied batch and every clear.
    pub version: u64,
    /// Stored tiles.
    pub tile_count: u64,
    /// Cells ever observed (since the last clear).
    pub cell_count: u64,
    /// Box of every observed cell; `None` while the map is empty.
    pub bounds: Option<CellBox>,
}

impl MapRecord {
    /// A new, empty map.
    pub fn new(name: String, settings: MapSettings) -> Self {
        Self {
            name,
            settings,
            version: 0,
            tile_count: 0,
            cell_count: 0,
            bounds: None,
        }
    }

    /// The encoded record (the name is kept by the store as the key).
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64);
        out.push(FORMAT);
        out.extend_from_slice(&self.settings.resolution.metres().to_le_bytes());
        out.extend_from_slice(&self.settings.tile_size.cells().to_le_bytes());
        out.extend_from_slice(&self.settings.clamp_probabilities.0.to_le_bytes());
        out.extend_from_slice(&self.settings.clamp_probabilities.1.to_le_bytes());
        out.extend_from_slice(&self.version.to_le_bytes());
        out.extend_from_slice(&self.tile_count.to_le_bytes());
        out.extend_from_slice(&self.cell_count.to_le_bytes());
        match self.bounds {
            None => out.push(0),
            Some(b) => {
                out.push(1);
                for v in [b.min.x, b.min.y, b.max.x, b.max.y] {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        out
    }

    /// Decodes a record stored under `name`.
    pub fn decode(name: &str, bytes: &[u8]) -> Result<Self, StoreError> {
        let corrupt = |reason: &str| StoreError::Corrupt {
            what: format!("map {name:?}"),
            reason: reason.to_string(),
        };
        let mut r = Reader(bytes);
        if r.u8().ok_or_else(|| corrupt("empty"))? != FORMAT {
            return Err(corrupt("unknown format"));
        }
        let short = || corrupt("truncated");
        let resolution = r.f64().ok_or_else(short)?;
        let tile_size = r.u32().ok_or_else(short)?;
        let cmin = r.f64().ok_or_else(short)?;
        let cmax = r.f64().ok_or_else(short)?;
        let version = r.u64().ok_or_else(short)?;
        let tile_count = r.u64().ok_or_else(short)?;
        let cell_count = r.u64().ok_or_else(short)?;
        let bounds = match r.u8().ok_or_else(short)? {
            0 => None,
            _ => {
                let mut v = [0i32; 4];
                for slot in &mut v {
                    *slot = r.u32().ok_or_else(short)? as i32;
                }
                CellBox::new(CellIndex::new(v[0], v[1]), CellIndex::new(v[2], v[3]))
            }
        };
        let settings = MapSettings::new(
            Resolution::new(resolution).map_err(|e| corrupt(&e.to_string()))?,
            TileSize::new(tile_size).map_err(|e| corrupt(&e.to_string()))?,
            (cmin, cmax),
        )
        .map_err(|e| corrupt(&e.to_string()))?;
        Ok(Self {
            name: name.to_string(),
            settings,
            version,
            tile_count,
            cell_count,
            bounds,
        })
    }
}

/// A stored tile: its cells and the map version at which it last changed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredTile {
    /// Map version of the last change.
    pub version: u64,
    /// The cells.
    pub tile: Tile,
}

impl StoredTile {
    /// Version, then the dense cells.
    pub fn encode(&self) -> Vec<u8> {
        let cells = self.tile.raw_cells();
        let mut out = Vec::with_capacity(8 + cells.len() * 2);
        out.extend_from_slice(&self.version.to_le_bytes());
        for c in cells {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out
    }

    /// Decodes a tile of `size`.
    pub fn decode(size: TileSize, bytes: &[u8]) -> Result<Self, StoreError> {
        let corrupt = |reason: String| StoreError::Corrupt {
            what: "tile".into(),
            reason,
        };
        if bytes.len() < 8 {
            return Err(corrupt("truncated".into()));
        }
        let (version, cells) = bytes.split_at(8);
        let version = u64::from_le_bytes(version.try_into().unwrap_or([0; 8]));
        let tile = Tile::from_dense_bytes(size, cells).map_err(|e| corrupt(e.to_string()))?;
        Ok(Self { version, tile })
    }
}

/// The frames a robot has published.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RobotSummary {
    /// Lowest stored sequence.
    pub first_sequence: u64,
    /// Highest stored sequence.
    pub last_sequence: u64,
    /// Number of stored frames.
    pub frame_count: u64,
}

impl RobotSummary {
    /// Three little-endian u64.
    pub fn encode(&self) -> [u8; 24] {
        let mut out = [0u8; 24];
        out[..8].copy_from_slice(&self.first_sequence.to_le_bytes());
        out[8..16].copy_from_slice(&self.last_sequence.to_le_bytes());
        out[16..].copy_from_slice(&self.frame_count.to_le_bytes());
        out
    }

    /// Decodes a summary.
    pub fn decode(bytes: &[u8]) -> Result<Self, StoreError> {
        let mut r = Reader(bytes);
        let short = || StoreError::Corrupt {
            what: "robot summary".into(),
            reason: "truncated".into(),
        };
        Ok(Self {
            first_sequence: r.u64().ok_or_else(short)?,
            last_sequence: r.u64().ok_or_else(short)?,
            frame_count: r.u64().ok_or_else(short)?,
        })
    }

    /// The summary after adding a frame with `sequence` (not stored before).
    pub fn with(self, sequence: u64) -> Self {
        if self.frame_count == 0 {
            return Self {
                first_sequence: sequence,
                last_sequence: sequence,
                frame_count: 1,
            };
        }
        Self {
            first_sequence: self.first_sequence.min(sequence),
            last_sequence: self.last_sequence.max(sequence),
            frame_count: self.frame_count + 1,
        }
    }
}

struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, rest) = self.0.split_first_chunk::<N>()?;
        self.0 = rest;
        Some(*head)
    }
    fn u8(&mut self) -> Option<u8> {
        self.take::<1>().map(|b| b[0])
    }
    fn u32(&mut self) -> Option<u32> {
        self.take().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Option<u64> {
        self.take().map(u64::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take().map(f64::from_le_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_record_round_trips() {
        let settings =
            MapSettings::new(Resolution::DEFAULT, TileSize::DEFAULT, (0.2, 0.9)).unwrap();
        let mut record = MapRecord::new("lab".into(), settings);
        record.version = 7;
        record.tile_count = 3;
        record.cell_count = 99;
        record.bounds = CellBox::new(CellIndex::new(-5, -6), CellIndex::new(10, 11));
        assert_eq!(MapRecord::decode("lab", &record.encode()).unwrap(), record);
        assert!(MapRecord::decode("lab", &record.encode()[..20]).is_err());
    }

    #[test]
    fn stored_tile_round_trips() {
        let size = TileSize::new(8).unwrap();
        let tile = StoredTile {
            version: 42,
            tile: Tile::unknown(size),
        };
        assert_eq!(StoredTile::decode(size, &tile.encode()).unwrap(), tile);
        assert!(StoredTile::decode(size, &tile.encode()[..30]).is_err());
    }

    #[test]
    fn robot_summary_tracks_range() {
        let s = RobotSummary::default().with(5).with(3).with(9);
        assert_eq!(
            (s.first_sequence, s.last_sequence, s.frame_count),
            (3, 9, 3)
        );
        assert_eq!(RobotSummary::decode(&s.encode()).unwrap(), s);
    }
}
