//! The localizer's piece of the map: occupancy tiles fetched from the map
//! server as the particles need them, and each tile's expected-range table
//! and distance field built lazily from them, all within a memory budget.
//!
//! The map server owns the map; this is a cache of it. Tiles come in
//! through [`LocalMap::insert_tile`] (the network edge fetches them) and go
//! stale through [`LocalMap::tile_changed`] (the watch stream); the edge
//! fetches [`LocalMap::stale_tiles`] again. A tile's range table reads the
//! occupied cells of every tile within the sonar's range of it, so a tile
//! whose occupied cells changed outdates the tables of its neighbours too;
//! an outdated table keeps scoring until it is rebuilt: at once under a
//! large share of the particles, elsewhere one per correction that needs
//! it (oldest first), so that a change never stalls the filter while a
//! whole neighbourhood is rebuilt. A tile's distance
//! field ([`crate::distance_field`], for the likelihood field) reads the
//! tiles within its maximum distance, and is dropped and rebuilt by the
//! same rule; fields are small (a byte a cell) and live in the same
//! budget, least recently used first out. A map being built
//! changes all the time, but mostly in its log-odds, its free cells and
//! the one-cell ragged edges of its walls, none of which moves an expected
//! range by more than a cell: the tables stay until a tile's occupied
//! cells differ from those the tables were built with by more than that
//! (see `occupied_moved`). Before tables are built, the least recently
//! used ones make room; after a correction, [`LocalMap::evict_to_budget`]
//! drops tables and tiles outside the working set. Both keep a quarter of
//! the budget for the rest of the process (allocator overhead, buffers),
//! so that the process, not only the cache's count, grows by no more than
//! the budget.

use std::collections::{HashMap, HashSet};

use deog_grid::{
    CellBox, CellIndex, LogOdds, Occupancy, OccupancyThresholds, OccupancyView, Pose2, Resolution,
    SensorRing, Tile, TileKey, TileSize,
};
use rand::Rng;

use crate::distance_field::{DistanceField, FieldSpec, FieldWindow};
use crate::error::LocalizerError;
use crate::numeric::{cell_i32, round_i32};
use crate::range_table::{ConeGeometry, NO_ECHO, OccupancyRaster, RangeTable, fill_table};
use crate::search::SearchCell;

const UNKNOWN: u8 = 0;
const FREE: u8 = 1;
const OCCUPIED: u8 = 2;

/// Outdated range tables [`LocalMap::ensure_tables`] rebuilds per call
/// beyond those under the particles: one is a few tens of milliseconds,
/// and a map being built outdates the tables of a whole neighbourhood at
/// once, so rebuilding them all in one correction would stall the filter
/// for as long as a global start does.
const OUTDATED_REBUILDS_PER_CALL: usize = 1;

/// Largest raster built in one go, cells; bigger batches are split.
const MAX_RASTER_CELLS: u64 = 4_000_000;

/// Bytes per raster cell while it is built: its occupancy, the squared
/// distance transform (`f64`) and the distance field (`f32`).
const RASTER_BYTES_PER_CELL: u64 = 13;

/// How the budget is shared, in eighths: the raster tables are built from
/// takes at most two; two are left to the rest of the process, whose
/// buffers and allocator overhead grow with the work the cache brings
/// (memory freed but not yet returned, fragments, frames waiting while
/// tables are built); the range tables one correction needs take at most
/// four; what they leave holds the tiles' cells.
const RASTER_EIGHTHS: usize = 2;
const ALLOCATOR_EIGHTHS: usize = 2;
const TABLE_EIGHTHS: usize = 4;

/// The probability above which a localizer takes a cell of a specular
/// sonar's map for a wall. Such maps are built by direction
/// (`deog_mapping::SonarMethod::Directional`), whose cartographer sends at
/// exactly 0.7 the walls it inferred rather than heard: space walled off
/// from every path, and what was seen only through a wall. A sonar never
/// hears them (a heard face stands in front where they are right), and
/// where they are wrong the range tables would expect echoes from them.
/// Above 0.7 they are unknown space to the tables. Measured with `deog
/// bench localize --sonar realistic` (BENCHMARKS.md, localization): the
/// mean error after convergence 3.1 to 2.6 cm in map1 and 2.8 to 2.3 cm
/// in map2, convergence unchanged over 80 map1 seeds.
pub const SPECULAR_OCCUPIED_THRESHOLD: f64 = 0.75;

/// The probability above which a localizer takes a map's cell for a wall:
/// ROS map_server's occupied threshold, or [`SPECULAR_OCCUPIED_THRESHOLD`]
/// on a map built from a specular sonar's readings.
pub fn occupied_threshold_for_sonar(specular: bool) -> f64 {
    if specular {
        SPECULAR_OCCUPIED_THRESHOLD
    } else {
        OccupancyThresholds::DEFAULT_OCCUPIED
    }
}

/// How the map is cut and judged, and how much memory the cache may use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapSettings {
    /// Cell size.
    pub resolution: Resolution,
    /// Cells per tile side.
    pub tile_size: TileSize,
    /// Occupied and free thresholds.
    pub thresholds: OccupancyThresholds,
    /// The sonar cone the range tables are for.
    pub geometry: ConeGeometry,
    /// Bytes of tiles and tables the cache may hold after eviction.
    pub budget_bytes: usize,
}

/// One tile as the localizer holds it.
#[derive(Debug)]
struct MapTile {
    version: u64,
    /// Per cell: unknown, free or occupied. `None` until fetched.
    cells: Option<Box<[u8]>>,
    free_cells: u32,
    ranges: Option<RangeTable>,
    /// When its range table stopped matching the cells it reads (the
    /// clock's tick), `None` while it matches: the table still scores,
    /// until [`LocalMap::ensure_tables`] rebuilds it.
    outdated_since: Option<u64>,
    /// Its distance field, for [`LocalMap::field_spec`].
    field: Option<DistanceField>,
    last_used: u64,
    /// The server changed it since it was fetched.
    stale: bool,
    /// Its occupied cells when the tables near it were last outdated, one
    /// bit per cell: what later versions are compared with.
    reference: Box<[u64]>,
}

/// Counts of what the cache did, for logs and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Range tables built.
    pub tables_built: u64,
    /// Range tables dropped, by eviction or because their neighbourhood changed.
    pub tables_dropped: u64,
    /// Occupancy tiles dropped by eviction.
    pub tiles_evicted: u64,
    /// Distance fields built.
    pub fields_built: u64,
    /// Distance fields dropped, by eviction or because their
    /// neighbourhood changed.
    pub fields_dropped: u64,
    /// Tiles newly held (not those fetched again): what a grid of the
    /// held tiles, built before, lacks.
    pub tiles_added: u64,
}

/// The cached part of one map.
#[derive(Debug)]
pub struct LocalMap {
    settings: MapSettings,
    tiles: HashMap<TileKey, MapTile>,
    bytes: usize,
    clock: u64,
    margin_tiles: i32,
    stats: CacheStats,
    /// Dropped tables whose memory the next tables built reuse (counted in
    /// `bytes`): refilling a table costs less than mapping and touching a
    /// megabyte anew.
    spare: Vec<RangeTable>,
    /// The raster tables are built from, kept and refilled (counted in
    /// `bytes`): megabytes of it allocated and freed on the heap at every
    /// batch would leave the allocator holding pieces of them.
    raster: Option<OccupancyRaster>,
    /// How the held distance fields were built; `None` before the first.
    field_spec: Option<FieldSpec>,
    /// Tiles a distance field reads beyond its own on every side.
    field_margin_tiles: i32,
}

/// An empty map at the default resolution, 64-cell tiles and the default
/// cone, for the crate's unit tests.
#[cfg(test)]
impl LocalMap {
    pub(crate) fn empty_for_tests(budget_bytes: usize) -> Self {
        Self::new(MapSettings {
            resolution: Resolution::DEFAULT,
            tile_size: deog_grid::TileSize::new(64).expect("64 is a tile size"),
            thresholds: OccupancyThresholds::default(),
            geometry: ConeGeometry::default(),
            budget_bytes,
        })
        .expect("the defaults are valid")
    }
}

impl LocalMap {
    /// An empty cache.
    pub fn new(settings: MapSettings) -> Result<Self, LocalizerError> {
        let geometry = settings.geometry.validate()?;
        let margin_cells = geometry.margin_cells(settings.resolution);
        let side = settings.tile_size.cells() as i32;
        Ok(Self {
            settings: MapSettings {
                geometry,
                ..settings
            },
            tiles: HashMap::new(),
            bytes: 0,
            clock: 0,
            margin_tiles: (margin_cells + side - 1) / side,
            stats: CacheStats::default(),
            spare: Vec::new(),
            raster: None,
            field_spec: None,
            field_margin_tiles: 0,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MapSettings {
        &self.settings
    }

    /// Bytes held now.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// What the cache has done so far.
    pub fn stats(&self) -> CacheStats {
        self.stats
    }

    /// Tiles held (fetched or known absent).
    pub fn tile_count(&self) -> usize {
        self.tiles.values().filter(|t| t.cells.is_some()).count()
    }

    /// The tile holding `cell`.
    pub fn tile_of(&self, cell: CellIndex) -> TileKey {
        self.settings.tile_size.split(cell).0
    }

    /// The tile under a point, metres.
    pub fn tile_at(&self, x: f64, y: f64) -> Result<TileKey, LocalizerError> {
        Ok(self.tile_of(self.settings.resolution.cell_of(x, y)?))
    }

    /// Stores the server's tile `key` at `version`; `None` means the server
    /// has no such tile (every cell unknown). Tables that read it are
    /// dropped if its occupancy changed.
    pub fn insert_tile(
        &mut self,
        key: TileKey,
        version: u64,
        tile: Option<&Tile>,
    ) -> Result<(), LocalizerError> {
        let area = self.settings.tile_size.area();
        let cells: Box<[u8]> = match tile {
            Some(t) => {
                if t.size() != self.settings.tile_size {
                    return Err(LocalizerError::Invalid(format!(
                        "tile ({}, {}) has {} cells a side, the map {}",
                        key.x,
                        key.y,
                        t.size().cells(),
                        self.settings.tile_size.cells()
                    )));
                }
                t.raw_cells()
                    .iter()
                    .map(
                        |&raw| match self.settings.thresholds.classify(LogOdds::from_raw(raw)) {
                            Occupancy::Unknown => UNKNOWN,
                            Occupancy::Free => FREE,
                            Occupancy::Occupied => OCCUPIED,
                        },
                    )
                    .collect()
            }
            None => vec![UNKNOWN; area].into_boxed_slice(),
        };
        let free_cells = cells.iter().filter(|&&c| c == FREE).count() as u32;
        let now = self.tick();
        let reference_bytes = area.div_ceil(64) * 8;
        let side = self.settings.tile_size.cells() as usize;
        let changed = match self.tiles.get_mut(&key) {
            Some(existing) => {
                let changed = occupied_moved(&existing.reference, &cells, side);
                if changed {
                    existing.reference = occupied_bits(&cells);
                }
                existing.stale = false;
                if existing.cells.is_none() {
                    self.bytes += area;
                }
                existing.cells = Some(cells);
                existing.version = version;
                existing.free_cells = free_cells;
                existing.last_used = now;
                changed
            }
            None => {
                let reference = occupied_bits(&cells);
                self.tiles.insert(
                    key,
                    MapTile {
                        version,
                        cells: Some(cells),
                        free_cells,
                        ranges: None,
                        outdated_since: None,
                        field: None,
                        last_used: now,
                        stale: false,
                        reference,
                    },
                );
                self.bytes += area + reference_bytes;
                self.stats.tiles_added += 1;
                true
            }
        };
        if changed {
            self.drop_tables_near(key);
        }
        Ok(())
    }

    /// The server says tile `key` changed. A held tile goes stale and
    /// keeps its tables until it is fetched again and its occupied cells
    /// turn out to differ; for a tile not held, whose cells are unknown,
    /// the tables that read it are outdated at once.
    pub fn tile_changed(&mut self, key: TileKey) {
        match self.tiles.get_mut(&key) {
            Some(tile) if tile.cells.is_some() => tile.stale = true,
            _ => self.drop_tables_near(key),
        }
    }

    /// Every held tile goes stale, every table is outdated and every field
    /// dropped (after the watch stream lost events, tiles never held may
    /// have changed too).
    pub fn all_changed(&mut self) {
        let now = self.tick();
        let keys: Vec<TileKey> = self.tiles.keys().copied().collect();
        for key in keys {
            if let Some(tile) = self.tiles.get_mut(&key) {
                tile.stale = tile.cells.is_some();
                if tile.ranges.is_some() {
                    tile.outdated_since.get_or_insert(now);
                }
                if let Some(field) = tile.field.take() {
                    self.bytes -= field.bytes();
                    self.stats.fields_dropped += 1;
                }
            }
        }
    }

    /// The held tiles the server changed since they were fetched, in key
    /// order: fetch them again and [`Self::insert_tile`] them.
    pub fn stale_tiles(&self) -> Vec<TileKey> {
        let mut keys: Vec<TileKey> = self
            .tiles
            .iter()
            .filter(|(_, t)| t.stale)
            .map(|(k, _)| *k)
            .collect();
        keys.sort();
        keys
    }

    /// The version of a held tile.
    pub fn version(&self, key: TileKey) -> Option<u64> {
        self.tiles
            .get(&key)
            .filter(|t| t.cells.is_some())
            .map(|t| t.version)
    }

    /// Tiles whose cells are needed, and not held, to build the tables of
    /// `keys` (each key and every tile within sonar range of it), sorted.
    pub fn missing_tiles(&self, keys: impl IntoIterator<Item = TileKey>) -> Vec<TileKey> {
        let mut missing = HashSet::new();
        for key in keys {
            if self
                .tiles
                .get(&key)
                .is_some_and(|t| t.ranges.is_some() && t.outdated_since.is_none())
            {
                continue;
            }
            for near in self.neighbourhood(key) {
                if self.tiles.get(&near).is_none_or(|t| t.cells.is_none()) {
                    missing.insert(near);
                }
            }
        }
        let mut missing: Vec<TileKey> = missing.into_iter().collect();
        missing.sort();
        missing
    }

    /// The tiles under the sensors of `ring` on a robot at `pose`, sorted,
    /// each with its range table built: the window that pose's beams are
    /// looked up in.
    pub fn tables_under(
        &mut self,
        ring: &SensorRing,
        pose: &Pose2,
    ) -> Result<Vec<TileKey>, LocalizerError> {
        let res = self.settings.resolution;
        let mut keys: Vec<TileKey> = ring
            .sensor_poses(pose)
            .filter_map(|s| res.cell_of(s.x, s.y).ok())
            .map(|c| self.tile_of(c))
            .collect();
        keys.sort();
        keys.dedup();
        self.ensure_tables(keys.iter().copied(), std::slice::from_ref(pose))?;
        Ok(keys)
    }

    /// Builds the range tables `keys` lack, and rebuilds outdated ones
    /// among them: those under a large share of `particles` (where the
    /// filter's weight is) and the oldest of the rest, one a call. From the
    /// tiles held (tiles not held count as unknown), first dropping least
    /// recently used tables of other tiles as the budget requires. Returns
    /// how many were built.
    pub fn ensure_tables(
        &mut self,
        keys: impl IntoIterator<Item = TileKey>,
        particles: &[Pose2],
    ) -> Result<usize, LocalizerError> {
        let keep: HashSet<TileKey> = keys.into_iter().collect();
        let rebuild = self.outdated_to_rebuild(&keep, particles);
        // Their tables go back to the spares they are rebuilt in.
        for key in rebuild {
            if let Some(t) = self.tiles.get_mut(&key)
                && let Some(table) = t.ranges.take()
            {
                self.spare.push(table);
                self.stats.tables_dropped += 1;
            }
        }
        let mut todo: Vec<TileKey> = keep
            .iter()
            .filter(|k| self.tiles.get(k).is_none_or(|t| t.ranges.is_none()))
            .copied()
            .collect();
        todo.sort();
        let count = todo.len();
        let size = self.settings.tile_size;
        let margin = self
            .settings
            .geometry
            .margin_cells(self.settings.resolution);
        // Batches of nearby tiles share one raster, as large as its share
        // of the budget allows.
        let raster_cells = self.raster_cells();
        let mut remaining = todo.as_slice();
        while !remaining.is_empty() {
            let (bounds, taken) = raster_batch(size, margin, raster_cells, remaining)?;
            // Room first, for the new tables and the raster, so that with
            // the process's share the cache stays within the budget
            // unless the correction's own tables do not fit.
            let needed = (bounds.width() * bounds.height() * RASTER_BYTES_PER_CELL) as usize;
            let held = self.raster.as_ref().map_or(0, OccupancyRaster::held_bytes);
            self.make_room(taken, needed.saturating_sub(held), &keep);
            let raster = self.fill_raster(bounds, held);
            let entries = size.area() * self.settings.geometry.stride();
            for key in &remaining[..taken] {
                // Checked when the batch was formed: cannot fail here.
                let tile_box = size.cell_box(*key)?;
                let mut table = match self.spare.pop() {
                    Some(spare) => {
                        self.bytes -= spare.len() * std::mem::size_of::<u16>();
                        spare
                    }
                    None => match RangeTable::zeroed(entries) {
                        Ok(table) => table,
                        Err(error) => {
                            self.raster = Some(raster);
                            return Err(error);
                        }
                    },
                };
                fill_table(
                    &raster,
                    tile_box,
                    self.settings.resolution,
                    &self.settings.geometry,
                    &mut table,
                );
                let now = self.tick();
                let bytes = table.len() * std::mem::size_of::<u16>();
                let tile = self.tiles.entry(*key).or_insert(MapTile {
                    version: 0,
                    cells: None,
                    free_cells: 0,
                    ranges: None,
                    outdated_since: None,
                    field: None,
                    last_used: now,
                    stale: false,
                    reference: Box::default(),
                });
                tile.ranges = Some(table);
                tile.outdated_since = None;
                tile.last_used = now;
                self.bytes += bytes;
                self.stats.tables_built += 1;
            }
            self.raster = Some(raster);
            remaining = &remaining[taken..];
        }
        Ok(count)
    }

    /// The outdated tables among `keys` to rebuild now: every one under
    /// at least a quarter of `particles` (sampled), then the oldest
    /// [`OUTDATED_REBUILDS_PER_CALL`] of the others.
    fn outdated_to_rebuild(&self, keys: &HashSet<TileKey>, particles: &[Pose2]) -> Vec<TileKey> {
        const SAMPLE: usize = 4096;
        let mut outdated: Vec<(u64, TileKey)> = keys
            .iter()
            .filter_map(|k| Some((self.tiles.get(k)?.outdated_since?, *k)))
            .collect();
        if outdated.is_empty() {
            return Vec::new();
        }
        outdated.sort();
        let step = particles.len().div_ceil(SAMPLE).max(1);
        let mut under: HashMap<TileKey, usize> = HashMap::new();
        let mut sampled = 0;
        for p in particles.iter().step_by(step) {
            sampled += 1;
            if let Ok(key) = self.tile_at(p.x, p.y) {
                *under.entry(key).or_default() += 1;
            }
        }
        let (heavy, rest): (Vec<_>, Vec<_>) = outdated
            .into_iter()
            .partition(|(_, k)| under.get(k).is_some_and(|&n| 4 * n >= sampled));
        heavy
            .into_iter()
            .chain(rest.into_iter().take(OUTDATED_REBUILDS_PER_CALL))
            .map(|(_, k)| k)
            .collect()
    }

    /// A fast read-only view of the tables of the tiles in `keys`' bounding
    /// box, for scoring particles; tiles without a table read as inside an
    /// obstacle. Marks those tiles used.
    pub fn window(&mut self, keys: &[TileKey]) -> RangeWindow<'_> {
        let now = self.tick();
        let (mut min, mut max) = match keys.first() {
            Some(k) => (*k, *k),
            None => (TileKey::new(0, 0), TileKey::new(0, 0)),
        };
        for k in keys {
            min = TileKey::new(min.x.min(k.x), min.y.min(k.y));
            max = TileKey::new(max.x.max(k.x), max.y.max(k.y));
        }
        for k in keys {
            if let Some(t) = self.tiles.get_mut(k) {
                t.last_used = now;
            }
        }
        let width = (i64::from(max.x) - i64::from(min.x) + 1) as usize;
        let height = (i64::from(max.y) - i64::from(min.y) + 1) as usize;
        let mut tables = vec![None; width * height];
        for y in 0..height {
            for x in 0..width {
                let key = TileKey::new(min.x + x as i32, min.y + y as i32);
                tables[y * width + x] = self.tiles.get(&key).and_then(|t| t.ranges.as_deref());
            }
        }
        let side = self.settings.tile_size.cells();
        RangeWindow {
            min,
            width: width as u32,
            height: height as u32,
            tables,
            shift: side.trailing_zeros(),
            mask: side as i32 - 1,
            headings: self.settings.geometry.headings,
            stride: self.settings.geometry.stride(),
            inv_res: 1.0 / self.settings.resolution.metres(),
            res_cm: self.settings.resolution.metres() * 100.0,
        }
    }

    /// Makes room for `tables` new tables, which take the spares' memory
    /// first, and `scratch` bytes beside them: frees spares beyond those
    /// tables, then drops least recently used tables outside `keep` (as
    /// spares while fewer than `tables`), until it fits the budget or no
    /// such table is left.
    fn make_room(&mut self, tables: usize, scratch: usize, keep: &HashSet<TileKey>) {
        let table_bytes = self
            .settings
            .geometry
            .table_bytes(self.settings.tile_size.area());
        let fresh = |spares: usize| tables.saturating_sub(spares) * table_bytes + scratch;
        let limit = self.limit();
        let fits = |map: &Self| map.bytes + fresh(map.spare.len()) <= limit;
        while !fits(self) && self.spare.len() > tables {
            self.free_spare();
        }
        if fits(self) {
            return;
        }
        let mut candidates: Vec<(u64, TileKey)> = self
            .tiles
            .iter()
            .filter(|(k, t)| t.ranges.is_some() && !keep.contains(k))
            .map(|(k, t)| (t.last_used, *k))
            .collect();
        candidates.sort();
        for (_, key) in candidates {
            if fits(self) {
                return;
            }
            if let Some(table) = self.tiles.get_mut(&key).and_then(|t| t.ranges.take()) {
                self.stats.tables_dropped += 1;
                if self.spare.len() < tables {
                    self.spare.push(table);
                } else {
                    self.bytes -= table.len() * std::mem::size_of::<u16>();
                }
            }
        }
    }

    /// What the cache may hold: the budget less the process's share.
    fn limit(&self) -> usize {
        self.settings.budget_bytes / 8 * (8 - ALLOCATOR_EIGHTHS)
    }

    /// Frees one spare table's memory.
    fn free_spare(&mut self) {
        if let Some(spare) = self.spare.pop() {
            self.bytes -= spare.len() * std::mem::size_of::<u16>();
        }
    }

    /// The most cells one raster may cover: its share of the budget.
    fn raster_cells(&self) -> u64 {
        ((self.settings.budget_bytes / 8 * RASTER_EIGHTHS) as u64 / RASTER_BYTES_PER_CELL)
            .min(MAX_RASTER_CELLS)
    }

    /// The raster, reused when there is one, filled with the occupied
    /// cells of `bounds`; `held` is what the old one counted in `bytes`.
    fn fill_raster(&mut self, bounds: CellBox, held: usize) -> OccupancyRaster {
        let raster = match self.raster.take() {
            Some(mut raster) => {
                raster.refill(bounds, |cell| self.cell_state(cell) == OCCUPIED);
                raster
            }
            None => OccupancyRaster::new(bounds, |cell| self.cell_state(cell) == OCCUPIED),
        };
        self.bytes = self.bytes - held + raster.held_bytes();
        raster
    }

    /// Drops least recently used tables, then fields, then tiles, outside
    /// `keep` until
    /// the cache fits its budget less the process's share (or nothing
    /// else can go).
    pub fn evict_to_budget(&mut self, keep: &HashSet<TileKey>) {
        let limit = self.limit();
        if self.bytes <= limit {
            return;
        }
        let mut candidates: Vec<(u64, TileKey)> = self
            .tiles
            .iter()
            .filter(|(k, _)| !keep.contains(k))
            .map(|(k, t)| (t.last_used, *k))
            .collect();
        candidates.sort();
        let area = self.settings.tile_size.area();
        while self.bytes > limit && !self.spare.is_empty() {
            self.free_spare();
        }
        if self.bytes > limit
            && let Some(raster) = self.raster.take()
        {
            self.bytes -= raster.held_bytes();
        }
        // Tables are large and rebuilt from tiles; tiles are small and cost
        // a fetch. Tables go first.
        for (_, key) in &candidates {
            if self.bytes <= limit {
                return;
            }
            if let Some(t) = self.tiles.get_mut(key)
                && let Some(table) = t.ranges.take()
            {
                self.bytes -= table.len() * std::mem::size_of::<u16>();
                self.stats.tables_dropped += 1;
            }
        }
        // Fields are small and cheap to rebuild: next.
        for (_, key) in &candidates {
            if self.bytes <= limit {
                return;
            }
            if let Some(t) = self.tiles.get_mut(key)
                && let Some(field) = t.field.take()
            {
                self.bytes -= field.bytes();
                self.stats.fields_dropped += 1;
            }
        }
        for (_, key) in &candidates {
            if self.bytes <= limit {
                return;
            }
            if let Some(t) = self.tiles.remove(key) {
                self.bytes -= t.reference.len() * 8;
                if t.cells.is_some() {
                    self.bytes -= area;
                    self.stats.tiles_evicted += 1;
                }
                if let Some(table) = t.ranges {
                    self.bytes -= table.len() * std::mem::size_of::<u16>();
                }
                if let Some(field) = t.field {
                    self.bytes -= field.bytes();
                }
            }
        }
    }

    /// The spec the held distance fields were built with, once any was.
    pub fn field_spec(&self) -> Option<FieldSpec> {
        self.field_spec
    }

    /// The distance field of tile `key`, if built.
    pub fn field(&self, key: TileKey) -> Option<&DistanceField> {
        self.tiles.get(&key).and_then(|t| t.field.as_ref())
    }

    /// Tiles whose cells are needed, and not held, to build the distance
    /// fields of `keys` with `spec` (each key and every tile within the
    /// maximum distance of it), sorted.
    pub fn missing_field_tiles(&self, keys: &[TileKey], spec: &FieldSpec) -> Vec<TileKey> {
        let current = self.field_spec == Some(*spec);
        let margin = self.field_margin_for(spec);
        let mut missing = HashSet::new();
        for &key in keys {
            if current && self.tiles.get(&key).is_some_and(|t| t.field.is_some()) {
                continue;
            }
            for near in tiles_around(key, margin) {
                if self.tiles.get(&near).is_none_or(|t| t.cells.is_none()) {
                    missing.insert(near);
                }
            }
        }
        let mut missing: Vec<TileKey> = missing.into_iter().collect();
        missing.sort();
        missing
    }

    /// Builds the distance fields `keys` lack with `spec`, from the tiles
    /// held (tiles not held count as unknown), first dropping least
    /// recently used tables and fields of other tiles as the budget
    /// requires. A spec other than the held fields' drops them all first.
    /// Returns how many were built.
    pub fn ensure_fields(
        &mut self,
        keys: &[TileKey],
        spec: &FieldSpec,
    ) -> Result<usize, LocalizerError> {
        let spec = spec.validate()?;
        if self.field_spec != Some(spec) {
            for tile in self.tiles.values_mut() {
                if let Some(field) = tile.field.take() {
                    self.bytes -= field.bytes();
                    self.stats.fields_dropped += 1;
                }
            }
            self.field_margin_tiles = self.field_margin_for(&spec);
            self.field_spec = Some(spec);
        }
        let keep: HashSet<TileKey> = keys.iter().copied().collect();
        let mut todo: Vec<TileKey> = keep
            .iter()
            .filter(|k| self.tiles.get(k).is_none_or(|t| t.field.is_none()))
            .copied()
            .collect();
        todo.sort();
        let count = todo.len();
        let (size, res) = (self.settings.tile_size, self.settings.resolution);
        let margin = spec.margin_cells(res);
        let raster_cells = self.raster_cells();
        let mut remaining = todo.as_slice();
        while !remaining.is_empty() {
            // Nearby tiles share one raster, as for the range tables.
            let (bounds, taken) = raster_batch(size, margin, raster_cells, remaining)?;
            let needed = (bounds.width() * bounds.height() * RASTER_BYTES_PER_CELL) as usize;
            let held = self.raster.as_ref().map_or(0, OccupancyRaster::held_bytes);
            self.make_room_for_fields(taken, needed.saturating_sub(held), &keep);
            let raster = self.fill_raster(bounds, held);
            for key in &remaining[..taken] {
                // Checked when the batch was formed: cannot fail here.
                let tile_box = size.cell_box(*key)?;
                let cells = self.tiles.get(key).and_then(|t| t.cells.as_deref());
                let field = DistanceField::build(&raster, tile_box, res, &spec, |i| {
                    cells.is_none_or(|c| c[i] == UNKNOWN)
                });
                let now = self.tick();
                self.bytes += field.bytes();
                self.stats.fields_built += 1;
                let tile = self.tiles.entry(*key).or_insert(MapTile {
                    version: 0,
                    cells: None,
                    free_cells: 0,
                    ranges: None,
                    outdated_since: None,
                    field: None,
                    last_used: now,
                    stale: false,
                    reference: Box::default(),
                });
                tile.field = Some(field);
                tile.last_used = now;
            }
            self.raster = Some(raster);
            remaining = &remaining[taken..];
        }
        Ok(count)
    }

    /// A read-only view of the distance fields of the tiles in `keys`, for
    /// scoring particles; a tile without a field reads as unknown. Marks
    /// those tiles used.
    pub fn field_window(&mut self, keys: &[TileKey]) -> FieldWindow<'_> {
        let now = self.tick();
        for k in keys {
            if let Some(t) = self.tiles.get_mut(k) {
                t.last_used = now;
            }
        }
        let tiles = &self.tiles;
        FieldWindow::new(
            keys.iter().map(|k| {
                (
                    *k,
                    tiles
                        .get(k)
                        .and_then(|t| t.field.as_ref())
                        .map(|f| f.codes()),
                )
            }),
            self.settings.resolution,
            self.settings.tile_size,
        )
    }

    /// How many distance fields a correction may need at once: half the
    /// budget, counting each field with its tile's cells (at least one).
    pub fn field_capacity(&self) -> usize {
        let area = self.settings.tile_size.area();
        let per_tile = 2 * area + area.div_ceil(64) * 8;
        (self.settings.budget_bytes / 8 * TABLE_EIGHTHS / per_tile).max(1)
    }

    /// Tiles a field of `spec` reads beyond its own on every side.
    fn field_margin_for(&self, spec: &FieldSpec) -> i32 {
        let side = self.settings.tile_size.cells() as i32;
        (spec.margin_cells(self.settings.resolution) + side - 1) / side
    }

    /// Makes room for `fields` new fields and `scratch` bytes beside them:
    /// frees spare tables, then drops least recently used range tables,
    /// then fields, outside `keep`, until it fits the budget or no such
    /// table or field is left.
    fn make_room_for_fields(&mut self, fields: usize, scratch: usize, keep: &HashSet<TileKey>) {
        let fresh = fields * self.settings.tile_size.area() + scratch;
        let limit = self.limit();
        let fits = |map: &Self| map.bytes + fresh <= limit;
        while !fits(self) && !self.spare.is_empty() {
            self.free_spare();
        }
        if fits(self) {
            return;
        }
        let mut candidates: Vec<(u64, TileKey)> = self
            .tiles
            .iter()
            .filter(|(k, t)| (t.ranges.is_some() || t.field.is_some()) && !keep.contains(k))
            .map(|(k, t)| (t.last_used, *k))
            .collect();
        candidates.sort();
        for (_, key) in &candidates {
            if fits(self) {
                return;
            }
            if let Some(table) = self.tiles.get_mut(key).and_then(|t| t.ranges.take()) {
                self.bytes -= table.len() * std::mem::size_of::<u16>();
                self.stats.tables_dropped += 1;
            }
        }
        for (_, key) in &candidates {
            if fits(self) {
                return;
            }
            if let Some(field) = self.tiles.get_mut(key).and_then(|t| t.field.take()) {
                self.bytes -= field.bytes();
                self.stats.fields_dropped += 1;
            }
        }
    }

    /// Known-free cells among the held tiles.
    pub fn free_cell_count(&self) -> u64 {
        self.tiles.values().map(|t| u64::from(t.free_cells)).sum()
    }

    /// A known-free cell drawn uniformly from the held tiles.
    pub fn sample_free_cell(&self, rng: &mut impl Rng) -> Result<CellIndex, LocalizerError> {
        let total = self.free_cell_count();
        if total == 0 {
            return Err(LocalizerError::NoFreeSpace);
        }
        let mut pick = rng.random_range(0..total);
        // Sorted keys make the draw independent of hash order.
        let mut keys: Vec<&TileKey> = self.tiles.keys().collect();
        keys.sort();
        for key in keys {
            let tile = &self.tiles[key];
            if pick >= u64::from(tile.free_cells) {
                pick -= u64::from(tile.free_cells);
                continue;
            }
            let cells = tile.cells.as_deref().ok_or(LocalizerError::NoFreeSpace)?;
            let index = cells
                .iter()
                .enumerate()
                .filter(|(_, c)| **c == FREE)
                .nth(pick as usize)
                .map(|(i, _)| i)
                .ok_or(LocalizerError::NoFreeSpace)?;
            let offset = deog_grid::CellOffset::from_index(index, self.settings.tile_size);
            return Ok(self.settings.tile_size.join(*key, offset)?);
        }
        Err(LocalizerError::NoFreeSpace)
    }

    /// How many range tables a correction may need at once: half the
    /// budget (at least one).
    pub fn table_capacity(&self) -> usize {
        let table = self
            .settings
            .geometry
            .table_bytes(self.settings.tile_size.area());
        (self.settings.budget_bytes / 8 * TABLE_EIGHTHS / table).max(1)
    }

    /// Held tiles with at least one known-free cell.
    pub fn free_tile_count(&self) -> usize {
        self.tiles.values().filter(|t| t.free_cells > 0).count()
    }

    /// Every held free cell, for the uniform prior (in tile order).
    pub fn free_cells(&self) -> Vec<CellIndex> {
        let mut keys: Vec<TileKey> = self.tiles.keys().copied().collect();
        keys.sort();
        self.free_cells_of(&keys)
    }

    /// The free cells of at most `max_tiles` held tiles: every one when
    /// no more tiles have free cells, else those of the tiles nearest
    /// `around` (ties broken by key). In tile order either way.
    pub fn free_cells_near(&self, around: CellIndex, max_tiles: usize) -> Vec<CellIndex> {
        let mut keys: Vec<TileKey> = self
            .tiles
            .iter()
            .filter(|(_, t)| t.free_cells > 0)
            .map(|(k, _)| *k)
            .collect();
        if keys.len() > max_tiles {
            let centre = self.tile_of(around);
            let distance = |k: &TileKey| {
                let dx = i64::from(k.x) - i64::from(centre.x);
                let dy = i64::from(k.y) - i64::from(centre.y);
                dx * dx + dy * dy
            };
            keys.sort_by_key(|k| (distance(k), *k));
            keys.truncate(max_tiles);
        }
        keys.sort();
        self.free_cells_of(&keys)
    }

    /// The free cells of the held tiles among `keys`, in the keys' order.
    fn free_cells_of(&self, keys: &[TileKey]) -> Vec<CellIndex> {
        let mut out = Vec::new();
        for key in keys {
            if let Some(cells) = self.tiles.get(key).and_then(|t| t.cells.as_deref()) {
                for (i, c) in cells.iter().enumerate() {
                    if *c == FREE
                        && let Ok(cell) = self.settings.tile_size.join(
                            *key,
                            deog_grid::CellOffset::from_index(i, self.settings.tile_size),
                        )
                    {
                        out.push(cell);
                    }
                }
            }
        }
        out
    }

    fn cell_state(&self, cell: CellIndex) -> u8 {
        let (key, offset) = self.settings.tile_size.split(cell);
        self.tiles
            .get(&key)
            .and_then(|t| t.cells.as_deref())
            .map_or(UNKNOWN, |cells| {
                cells[offset.index(self.settings.tile_size)]
            })
    }

    fn neighbourhood(&self, key: TileKey) -> impl Iterator<Item = TileKey> + use<> {
        tiles_around(key, self.margin_tiles)
    }

    /// Marks the range tables that read tile `key` outdated and drops the
    /// distance fields that read it.
    fn drop_tables_near(&mut self, key: TileKey) {
        let now = self.tick();
        let near: Vec<TileKey> = self.neighbourhood(key).collect();
        for k in near {
            if let Some(t) = self.tiles.get_mut(&k)
                && t.ranges.is_some()
            {
                t.outdated_since.get_or_insert(now);
            }
        }
        if self.field_spec.is_some() {
            for k in tiles_around(key, self.field_margin_tiles) {
                if let Some(t) = self.tiles.get_mut(&k)
                    && let Some(field) = t.field.take()
                {
                    self.bytes -= field.bytes();
                    self.stats.fields_dropped += 1;
                }
            }
        }
    }

    fn tick(&mut self) -> u64 {
        self.clock += 1;
        self.clock
    }
}

impl LocalMap {
    /// The held tiles as the global search reads them
    /// ([`crate::search::SearchGrid`]): cells of `factor` × `factor` map
    /// cells, occupied where any of theirs is, else free where any is;
    /// `None` when no tile is held. Origin (metres) of the first cell's
    /// lower-left corner, cells along x and y, and the cells row-major.
    pub fn search_cells(&self, factor: u32) -> Result<Option<SearchCells>, LocalizerError> {
        let factor = i64::from(factor.max(1));
        let Some(first) = self.tiles.keys().next() else {
            return Ok(None);
        };
        let (mut lo, mut hi) = (*first, *first);
        for key in self.tiles.keys() {
            lo = TileKey::new(lo.x.min(key.x), lo.y.min(key.y));
            hi = TileKey::new(hi.x.max(key.x), hi.y.max(key.y));
        }
        let size = self.settings.tile_size;
        let side = i64::from(size.cells());
        let min = size.origin(lo)?;
        let (min_x, min_y) = (i64::from(min.x), i64::from(min.y));
        let cells_x = (i64::from(hi.x) - i64::from(lo.x) + 1) * side;
        let cells_y = (i64::from(hi.y) - i64::from(lo.y) + 1) * side;
        let width = (cells_x + factor - 1) / factor;
        let height = (cells_y + factor - 1) / factor;
        let count = width.saturating_mul(height);
        if count > crate::search::MAX_SEARCH_CELLS as i64 {
            return Err(LocalizerError::Invalid(format!(
                "the map's {width} x {height} search cells are more than {}",
                crate::search::MAX_SEARCH_CELLS
            )));
        }
        let (width, height) = (width as usize, height as usize);
        let mut cells = vec![SearchCell::Unknown; width * height];
        for (key, tile) in &self.tiles {
            let Some(states) = tile.cells.as_deref() else {
                continue;
            };
            let origin = size.origin(*key)?;
            let (ox, oy) = (i64::from(origin.x) - min_x, i64::from(origin.y) - min_y);
            for (i, &state) in states.iter().enumerate() {
                if state == UNKNOWN {
                    continue;
                }
                let x = (ox + (i as i64 % side)) / factor;
                let y = (oy + (i as i64 / side)) / factor;
                let cell = &mut cells[y as usize * width + x as usize];
                match state {
                    OCCUPIED => *cell = SearchCell::Occupied,
                    _ if *cell == SearchCell::Unknown => *cell = SearchCell::Free,
                    _ => {}
                }
            }
        }
        let res = self.settings.resolution.metres();
        Ok(Some(SearchCells {
            origin: [min_x as f64 * res, min_y as f64 * res],
            cell_m: res * factor as f64,
            width,
            height,
            cells,
        }))
    }
}

/// The held map in the global search's cells ([`LocalMap::search_cells`]).
#[derive(Debug, Clone)]
pub struct SearchCells {
    /// World position of the first cell's lower-left corner, metres.
    pub origin: [f64; 2],
    /// Side of a cell, metres.
    pub cell_m: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// The cells, row-major from the lower-left.
    pub cells: Vec<SearchCell>,
}

impl OccupancyView for LocalMap {
    fn occupancy(&self, cell: CellIndex) -> Occupancy {
        match self.cell_state(cell) {
            FREE => Occupancy::Free,
            OCCUPIED => Occupancy::Occupied,
            _ => Occupancy::Unknown,
        }
    }
}

/// One bit per cell: occupied or not.
fn occupied_bits(cells: &[u8]) -> Box<[u64]> {
    let mut bits = vec![0u64; cells.len().div_ceil(64)];
    for (i, _) in cells.iter().enumerate().filter(|(_, c)| **c == OCCUPIED) {
        bits[i / 64] |= 1 << (i % 64);
    }
    bits.into_boxed_slice()
}

/// Whether a tile's occupied `cells` (row-major, `side` a row) moved from
/// `reference` by more than the ragged edge of a wall: a cell that turned
/// occupied or free counts only if none of its eight neighbours is
/// occupied both in the reference and now. A wall that grew or lost a cell
/// at its edge moves no expected range by more than a cell, a fraction of
/// the beam model's spread; a new obstacle or a vanished wall does. An
/// empty reference (none kept) always counts as moved.
fn occupied_moved(reference: &[u64], cells: &[u8], side: usize) -> bool {
    if reference.len() != cells.len().div_ceil(64) || side * side != cells.len() {
        return true;
    }
    let was = |i: usize| reference[i / 64] >> (i % 64) & 1 == 1;
    let is = |i: usize| cells[i] == OCCUPIED;
    for i in 0..cells.len() {
        if was(i) == is(i) {
            continue;
        }
        let (x, y) = (i % side, i / side);
        let mut anchored = false;
        for ny in y.saturating_sub(1)..=(y + 1).min(side - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(side - 1) {
                let j = ny * side + nx;
                anchored |= j != i && was(j) && is(j);
            }
        }
        if !anchored {
            return true;
        }
    }
    false
}

/// The tiles within `m` tiles of `key` (a square), `key` among them.
fn tiles_around(key: TileKey, m: i32) -> impl Iterator<Item = TileKey> {
    (-m..=m).flat_map(move |dy| {
        (-m..=m).filter_map(move |dx| {
            Some(TileKey::new(key.x.checked_add(dx)?, key.y.checked_add(dy)?))
        })
    })
}

/// The first tiles of `keys` (at least one) whose cells, each widened by
/// `margin`, fit one raster of at most `raster_cells`: its bounds and how
/// many they are.
fn raster_batch(
    size: TileSize,
    margin: i32,
    raster_cells: u64,
    keys: &[TileKey],
) -> Result<(CellBox, usize), LocalizerError> {
    let mut bounds = widen(size.cell_box(keys[0])?, margin);
    let mut taken = 1;
    for key in &keys[1..] {
        let candidate = bounds.union(&widen(size.cell_box(*key)?, margin));
        if candidate.width() * candidate.height() > raster_cells {
            break;
        }
        bounds = candidate;
        taken += 1;
    }
    Ok((bounds, taken))
}

fn widen(b: CellBox, by: i32) -> CellBox {
    let grow = |v: i32, d: i32| v.saturating_add(d);
    CellBox {
        min: CellIndex::new(grow(b.min.x, -by), grow(b.min.y, -by)),
        max: CellIndex::new(grow(b.max.x, by), grow(b.max.y, by)),
    }
}

/// Range tables of a block of tiles, laid out for fast lookups.
#[derive(Debug)]
pub struct RangeWindow<'a> {
    min: TileKey,
    width: u32,
    height: u32,
    tables: Vec<Option<&'a [u16]>>,
    shift: u32,
    mask: i32,
    headings: usize,
    stride: usize,
    inv_res: f64,
    /// A cell's side, centimetres.
    res_cm: f64,
}

impl RangeWindow<'_> {
    /// Stored headings per full turn.
    pub fn headings(&self) -> usize {
        self.headings
    }

    /// A heading as a position among the stored headings, in `[0, headings)`.
    #[inline]
    pub fn heading_position(&self, heading: f64) -> f64 {
        let h = self.headings as f64;
        let mut position = heading * (h / std::f64::consts::TAU);
        // Headings arrive within a few turns of zero: no division needed.
        while position < 0.0 {
            position += h;
        }
        while position >= h {
            position -= h;
        }
        position
    }

    /// The expected range in whole centimetres, clamped below
    /// `no_echo_slot`, or `no_echo_slot` itself for no echo, of a sonar at
    /// `(x, y)` pointing along `heading` (radians): the table of its cell,
    /// interpolated between the two nearest stored headings and corrected
    /// for where in the cell the sensor sits. `cos` and `sin` are those of
    /// `heading`. Outside the tables: 0, as inside an obstacle.
    #[inline]
    pub fn expected_slot(
        &self,
        x: f64,
        y: f64,
        heading: f64,
        (cos, sin): (f64, f64),
        no_echo_slot: usize,
    ) -> usize {
        let position = self.heading_position(heading);
        self.expected_slot_at(x, y, position, (cos, sin), no_echo_slot)
    }

    /// [`Self::expected_slot`] with the heading given as its position among
    /// the stored headings ([`Self::heading_position`]), in `[0, headings)`.
    #[inline(always)]
    pub fn expected_slot_at(
        &self,
        x: f64,
        y: f64,
        position: f64,
        (cos, sin): (f64, f64),
        no_echo_slot: usize,
    ) -> usize {
        let (fx, fy) = (x * self.inv_res, y * self.inv_res);
        // Rounded by the float unit: either cell of a point on their edge
        // does, since the offset below is taken from the cell chosen.
        let (cx, cy) = (cell_i32(fx), cell_i32(fy));
        // Wrapping: a negative tile becomes too large to pass the bounds.
        let tx = (cx >> self.shift).wrapping_sub(self.min.x) as u32;
        let ty = (cy >> self.shift).wrapping_sub(self.min.y) as u32;
        if tx >= self.width || ty >= self.height {
            return 0;
        }
        let Some(table) = self.tables[(ty * self.width + tx) as usize] else {
            return 0;
        };
        let index = (((cy & self.mask) << self.shift) + (cx & self.mask)) as usize;
        // `position` lies in [0, headings): so does `lower` (a stray one
        // falls outside the table and reads as 0).
        let lower = cell_i32(position);
        let frac = position - f64::from(lower);
        let at = index * self.stride + lower as u32 as usize;
        let Some(&[a, b]) = table.get(at..at + 2) else {
            return 0;
        };
        let millimetres = if a.min(b) == 0 {
            return 0;
        } else if a.max(b) == NO_ECHO {
            // Between an echo and none: take the nearer heading's.
            let nearer = if frac < 0.5 { a } else { b };
            if nearer == NO_ECHO {
                return no_echo_slot;
            }
            f64::from(nearer)
        } else {
            f64::from(a) + (f64::from(b) - f64::from(a)) * frac
        };
        // The table is for the cell's centre; move to the sensor.
        let off_x = fx - (f64::from(cx) + 0.5);
        let off_y = fy - (f64::from(cy) + 0.5);
        let centimetres = millimetres * 0.1 - (off_x * cos + off_y * sin) * self.res_cm;
        round_i32(centimetres).clamp(0, no_echo_slot as i32 - 1) as usize
    }
}
