//! An in-memory map of tiles: what a client holds of a map, and the
//! simplest thing to cast rays in.

use std::collections::HashMap;

use crate::cell::{CellBox, CellIndex, Resolution};
use crate::error::GridError;
use crate::log_odds::{ClampLimits, LogOdds};
use crate::raycast::{Occupancy, OccupancyThresholds, OccupancyView};
use crate::tile::{Tile, TileDelta};
use crate::tile_key::{TileKey, TileSize};

/// Tiles keyed by index, created on first touch, as on the server.
#[derive(Debug, Clone)]
pub struct TileMap {
    resolution: Resolution,
    tile_size: TileSize,
    limits: ClampLimits,
    thresholds: OccupancyThresholds,
    tiles: HashMap<TileKey, Tile>,
}

impl TileMap {
    /// An empty map.
    pub fn new(resolution: Resolution, tile_size: TileSize, limits: ClampLimits) -> Self {
        Self {
            resolution,
            tile_size,
            limits,
            thresholds: OccupancyThresholds::default(),
            tiles: HashMap::new(),
        }
    }

    /// Sets the probabilities above and below which a cell counts as
    /// occupied or free.
    pub fn with_thresholds(mut self, thresholds: OccupancyThresholds) -> Self {
        self.thresholds = thresholds;
        self
    }

    /// Metres per cell.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// Cells per tile side.
    pub fn tile_size(&self) -> TileSize {
        self.tile_size
    }

    /// Adds a tile delta, creating the tile if needed.
    pub fn apply(&mut self, delta: &TileDelta) -> Result<usize, GridError> {
        self.tile_size.check(delta.key)?;
        let tile = self
            .tiles
            .entry(delta.key)
            .or_insert_with(|| Tile::unknown(self.tile_size));
        tile.apply(delta, self.limits)
    }

    /// Replaces a tile wholesale (a fresh copy from the server).
    pub fn insert(&mut self, key: TileKey, tile: Tile) -> Result<(), GridError> {
        self.tile_size.check(key)?;
        if tile.size() != self.tile_size {
            return Err(GridError::BadCells {
                field: "tile",
                reason: format!(
                    "tile of size {} in a map of {}",
                    tile.size().cells(),
                    self.tile_size.cells()
                ),
            });
        }
        self.tiles.insert(key, tile);
        Ok(())
    }

    /// The belief of a cell; `None` if never observed.
    pub fn get(&self, cell: CellIndex) -> Option<LogOdds> {
        let (key, offset) = self.tile_size.split(cell);
        self.tiles.get(&key).and_then(|t| t.get(offset))
    }

    /// The tile `key`, if any cell of it was observed.
    pub fn tile(&self, key: TileKey) -> Option<&Tile> {
        self.tiles.get(&key)
    }

    /// The tiles.
    pub fn tiles(&self) -> impl Iterator<Item = (&TileKey, &Tile)> {
        self.tiles.iter()
    }

    /// Number of tiles.
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Number of cells ever observed.
    pub fn observed_count(&self) -> usize {
        self.tiles.values().map(Tile::observed_count).sum()
    }

    /// The box of all tiles' cells, `None` while empty.
    pub fn tile_bounds(&self) -> Option<CellBox> {
        self.tiles
            .keys()
            .filter_map(|k| self.tile_size.cell_box(*k).ok())
            .reduce(|a, b| a.union(&b))
    }
}

impl OccupancyView for TileMap {
    fn occupancy(&self, cell: CellIndex) -> Occupancy {
        self.thresholds.classify(self.get(cell))
    }
}
