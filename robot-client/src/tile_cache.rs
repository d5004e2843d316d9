//! [`TileCache`]: a client's copy of a map's tiles, kept current by version.

use crate::client::MapClient;
use crate::convert::{cell_box_to_wire, tile_key_from_wire, tile_key_to_wire};
use crate::error::ClientError;
use deog_grid::{CellBox, CellIndex, LogOdds, Tile, TileKey, TileSize};
use deog_proto::v1 as pb;
use std::collections::{HashMap, HashSet};

/// Tiles of one map with the version each was read at.
#[derive(Debug, Clone)]
pub struct TileCache {
    map: String,
    tile_size: TileSize,
    tiles: HashMap<TileKey, (u64, Tile)>,
    /// Map version up to which every cached tile is known current.
    synced_version: u64,
    needs_resync: bool,
}

impl TileCache {
    /// An empty cache for `map`.
    pub fn new(map: impl Into<String>, tile_size: TileSize) -> Self {
        Self {
            map: map.into(),
            tile_size,
            tiles: HashMap::new(),
            synced_version: 0,
            needs_resync: false,
        }
    }

    /// Cells per tile side.
    pub fn tile_size(&self) -> TileSize {
        self.tile_size
    }

    /// Number of cached tiles.
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    /// Whether nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// Whether a watch event asked for a re-read.
    pub fn needs_resync(&self) -> bool {
        self.needs_resync
    }

    /// A cached tile and its version.
    pub fn tile(&self, key: TileKey) -> Option<(u64, &Tile)> {
        self.tiles.get(&key).map(|(v, t)| (*v, t))
    }

    /// Every cached tile with its key and version, in no particular order.
    pub fn tiles(&self) -> impl Iterator<Item = (TileKey, u64, &Tile)> {
        self.tiles.iter().map(|(k, (v, t))| (*k, *v, t))
    }

    /// The cached tiles, given up: each with its key and version.
    pub fn into_tiles(self) -> impl Iterator<Item = (TileKey, u64, Tile)> {
        self.tiles.into_iter().map(|(k, (v, t))| (k, v, t))
    }

    /// The belief of a cell, if its tile is cached and the cell observed.
    pub fn cell(&self, cell: CellIndex) -> Option<LogOdds> {
        let (key, offset) = self.tile_size.split(cell);
        self.tiles.get(&key).and_then(|(_, t)| t.get(offset))
    }

    /// Brings the tiles of `region` up to date, fetching only the tiles that
    /// changed since the last refresh; tiles the server no longer has there
    /// (the map was cleared) are dropped. Returns how many tiles were fetched.
    pub async fn refresh(
        &mut self,
        client: &MapClient,
        region: CellBox,
    ) -> Result<usize, ClientError> {
        // Read before the tiles: a change in between is fetched again next
        // time rather than missed.
        let version = client.map_info(&self.map).await?.version;
        let region_wire = cell_box_to_wire(region);
        let listed = client
            .tiles(pb::TileQuery {
                map: self.map.clone(),
                selection: Some(pb::tile_query::Selection::Region(region_wire)),
                newer_than_version: self.synced_version,
            })
            .await?;
        let mut fetched = 0;
        let mut stale = Vec::new();
        let mut present = HashSet::with_capacity(listed.len());
        for tile in listed {
            let key = tile
                .key
                .map(tile_key_from_wire)
                .ok_or_else(|| ClientError::Updates("tile without a key".into()))?;
            present.insert(key);
            if tile.cells.is_empty() {
                // Not newer than the sync point, which another region's
                // refresh may have moved: fetch it unless ours is current.
                if self
                    .tiles
                    .get(&key)
                    .is_none_or(|(cached, _)| *cached < tile.version)
                {
                    stale.push(tile_key_to_wire(key));
                }
                continue;
            }
            self.insert_wire(key, &tile)?;
            fetched += 1;
        }
        let (min, max) = self.tile_size.tiles_covering(&region);
        self.tiles.retain(|key, _| {
            let inside = (min.x..=max.x).contains(&key.x) && (min.y..=max.y).contains(&key.y);
            !inside || present.contains(key)
        });
        if !stale.is_empty() {
            for tile in client
                .tiles(pb::TileQuery {
                    map: self.map.clone(),
                    selection: Some(pb::tile_query::Selection::Keys(pb::TileKeys {
                        keys: stale,
                    })),
                    newer_than_version: 0,
                })
                .await?
            {
                if let Some(key) = tile.key {
                    self.insert_wire(tile_key_from_wire(key), &tile)?;
                    fetched += 1;
                }
            }
        }
        self.synced_version = self.synced_version.max(version);
        self.needs_resync = false;
        Ok(fetched)
    }

    /// Applies one event of a `WatchTiles` stream.
    pub fn apply_event(&mut self, event: &pb::TileEvent) -> Result<(), ClientError> {
        match &event.event {
            Some(pb::tile_event::Event::Changed(tile)) => {
                let Some(key) = tile.key.map(tile_key_from_wire) else {
                    return Ok(());
                };
                if tile.cells.is_empty() {
                    // Only told that it changed: drop ours so it is re-read.
                    self.tiles.remove(&key);
                    self.needs_resync = true;
                } else {
                    self.insert_wire(key, tile)?;
                }
            }
            Some(pb::tile_event::Event::Cleared(_)) => {
                self.tiles.clear();
                self.synced_version = 0;
            }
            Some(pb::tile_event::Event::Resync(_)) => self.needs_resync = true,
            None => {}
        }
        Ok(())
    }

    fn insert_wire(&mut self, key: TileKey, tile: &pb::Tile) -> Result<(), ClientError> {
        if self.tiles.get(&key).is_some_and(|(v, _)| *v > tile.version) {
            return Ok(());
        }
        let cells = Tile::from_dense_bytes(self.tile_size, &tile.cells)?;
        self.tiles.insert(key, (tile.version, cells));
        Ok(())
    }
}
