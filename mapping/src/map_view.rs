//! The cartographer's bounded view of the map it writes to: the tiles
//! around the robot, as the map server last gave them plus the
//! cartographer's own deltas since, so that a sonar cone can stop at the
//! walls the map already holds ([`crate::SonarMethod::KeepWalls`]).
//!
//! The view holds at most a fixed number of tiles and forgets the least
//! recently used first; a forgotten tile is simply fetched again. It never
//! decides anything on its own: a tile it lacks reads as unknown, and the
//! process feeding it (`deog map`) fetches the tiles a frame reaches
//! before the frame is mapped ([`MapView::missing_around`]).

use deog_grid::{
    CellBox, CellIndex, CellOffset, ClampLimits, ConeGuard, KeyMap, LogOdds, Pose2, Resolution,
    Tile, TileDelta, TileKey, TileSize,
};

use crate::error::MappingError;

/// How big a view is and what it calls a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapViewSettings {
    /// A cell at or above this probability of occupancy is a wall no
    /// reading may free.
    pub wall_probability: f64,
    /// A cell at or above this probability of occupancy hides what lies
    /// behind it: a cone's evidence stops a cell past it. At most
    /// `wall_probability`.
    pub shadow_probability: f64,
    /// Tiles held at most.
    pub max_tiles: usize,
    /// The map's clamp limits, applied to the cartographer's own deltas as
    /// the server applies them.
    pub limits: ClampLimits,
    /// With [`crate::SonarMethod::Directional`]: frames between two
    /// judgements of the space no robot could have seen
    /// ([`crate::DirectionalSettings::enclosure_period`]); 0: never.
    pub enclosure_period: u32,
    /// With [`crate::SonarMethod::Directional`]: how far behind a wall,
    /// once heard, the free evidence that reached cells through it is
    /// taken back, metres
    /// ([`crate::DirectionalSettings::shadow_depth`]); 0: never.
    pub shadow_depth: f64,
}

impl Default for MapViewSettings {
    /// Walls at 0.7 (about eight agreeing echoes of the mapping sonar
    /// model at 2 m; BENCHMARKS.md, realistic sonar); 4,096 tiles (32 MiB
    /// of 64-cell tiles).
    fn default() -> Self {
        Self {
            wall_probability: 0.7,
            shadow_probability: 0.7,
            max_tiles: 4096,
            limits: ClampLimits::default(),
            enclosure_period: crate::directional::DEFAULT_ENCLOSURE_PERIOD,
            shadow_depth: crate::directional::DEFAULT_SHADOW_DEPTH_M,
        }
    }
}

impl MapViewSettings {
    /// Checks the figures.
    pub fn validate(self) -> Result<Self, MappingError> {
        check_view(self.wall_probability, self.max_tiles)?;
        if !(self.shadow_probability > 0.5 && self.shadow_probability <= self.wall_probability) {
            return Err(MappingError::invalid(
                "shadow_probability",
                format!(
                    "must be in (0.5, wall_probability = {}], got {}",
                    self.wall_probability, self.shadow_probability
                ),
            ));
        }
        crate::directional::check_shadow_depth(self.shadow_depth)?;
        Ok(self)
    }
}

/// Checks what every view of the map is given: the probability from which
/// a cell is a wall, and how many tiles it may hold.
pub(crate) fn check_view(wall_probability: f64, max_tiles: usize) -> Result<(), MappingError> {
    if !(wall_probability > 0.5 && wall_probability < 1.0) {
        return Err(MappingError::invalid(
            "wall_probability",
            format!("must be in (0.5, 1), got {wall_probability}"),
        ));
    }
    if max_tiles < 16 {
        return Err(MappingError::invalid(
            "max_tiles",
            format!("must be at least 16, got {max_tiles}"),
        ));
    }
    Ok(())
}

/// A tile of the view and when it was last used.
#[derive(Debug, Clone)]
struct ViewTile {
    tile: Tile,
    used: u64,
}

/// The tiles around the robot, bounded.
#[derive(Debug, Clone)]
pub struct MapView {
    settings: MapViewSettings,
    wall: i16,
    shadow: i16,
    resolution: Resolution,
    tile_size: TileSize,
    tiles: KeyMap<TileKey, ViewTile>,
    clock: u64,
}

impl MapView {
    /// An empty view of a map of `resolution` and `tile_size`.
    pub fn new(
        resolution: Resolution,
        tile_size: TileSize,
        settings: MapViewSettings,
    ) -> Result<Self, MappingError> {
        let settings = settings.validate()?;
        Ok(Self {
            wall: LogOdds::from_probability(settings.wall_probability)?.raw(),
            shadow: LogOdds::from_probability(settings.shadow_probability)?.raw(),
            settings,
            resolution,
            tile_size,
            tiles: KeyMap::default(),
            clock: 0,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MapViewSettings {
        &self.settings
    }

    /// Tiles held.
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    /// Whether no tile is held.
    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// Whether the view holds `key`.
    pub fn contains(&self, key: TileKey) -> bool {
        self.tiles.contains_key(&key)
    }

    /// The keys of the tiles within `radius` metres of `pose` (a box),
    /// each marked used.
    pub fn keys_around(&mut self, pose: &Pose2, radius: f64) -> Result<Vec<TileKey>, MappingError> {
        let corner = |dx: f64, dy: f64| self.resolution.cell_of(pose.x + dx, pose.y + dy);
        let radius = radius.max(0.0);
        let cells = CellBox::new(corner(-radius, -radius)?, corner(radius, radius)?)
            .ok_or_else(|| MappingError::invalid("pose", format!("{pose:?} is not finite")))?;
        let (first, last) = self.tile_size.tiles_covering(&cells);
        self.clock += 1;
        let mut keys = Vec::new();
        for y in first.y..=last.y {
            for x in first.x..=last.x {
                let key = TileKey::new(x, y);
                if let Some(held) = self.tiles.get_mut(&key) {
                    held.used = self.clock;
                }
                keys.push(key);
            }
        }
        Ok(keys)
    }

    /// Of the tiles within `radius` metres of `pose`, those the view lacks:
    /// what to fetch before mapping a frame taken there.
    pub fn missing_around(
        &mut self,
        pose: &Pose2,
        radius: f64,
    ) -> Result<Vec<TileKey>, MappingError> {
        let mut keys = self.keys_around(pose, radius)?;
        keys.retain(|key| !self.tiles.contains_key(key));
        Ok(keys)
    }

    /// Puts `tile` under `key`, as the map server holds it now (replacing
    /// what the view had); forgets the least recently used tiles past the
    /// limit.
    pub fn insert(&mut self, key: TileKey, tile: Tile) -> Result<(), MappingError> {
        if tile.size() != self.tile_size {
            return Err(MappingError::invalid(
                format!("tile {key:?}"),
                format!(
                    "has {} cells a side, the map {}",
                    tile.size().cells(),
                    self.tile_size.cells()
                ),
            ));
        }
        self.tile_size.check(key)?;
        self.clock += 1;
        self.tiles.insert(
            key,
            ViewTile {
                tile,
                used: self.clock,
            },
        );
        self.evict();
        Ok(())
    }

    /// Forgets every tile: each is read again when next needed.
    pub fn clear(&mut self) {
        self.tiles.clear();
    }

    /// Marks `key` as unknown everywhere (the server has no such tile).
    pub fn insert_unknown(&mut self, key: TileKey) -> Result<(), MappingError> {
        self.insert(key, Tile::unknown(self.tile_size))
    }

    /// Adds the cartographer's own deltas, as the server will; a delta for
    /// a tile the view lacks starts it from unknown.
    pub fn apply(&mut self, deltas: &[TileDelta]) -> Result<(), MappingError> {
        self.clock += 1;
        for delta in deltas {
            self.tile_size.check(delta.key)?;
            let size = self.tile_size;
            let held = self.tiles.entry(delta.key).or_insert_with(|| ViewTile {
                tile: Tile::unknown(size),
                used: 0,
            });
            held.used = self.clock;
            held.tile.apply(delta, self.settings.limits)?;
        }
        self.evict();
        Ok(())
    }

    fn evict(&mut self) {
        evict_least_recent(&mut self.tiles, self.settings.max_tiles, |t| t.used);
    }
}

/// Forgets the least recently used of `tiles` (by `used`, a clock) down to
/// seven eighths of `max_tiles` once there are more, so that eviction runs
/// once per many tiles.
pub(crate) fn evict_least_recent<T>(
    tiles: &mut KeyMap<TileKey, T>,
    max_tiles: usize,
    used: impl Fn(&T) -> u64,
) {
    if tiles.len() <= max_tiles {
        return;
    }
    let keep = max_tiles - max_tiles / 8;
    let mut ages: Vec<(u64, TileKey)> = tiles.iter().map(|(k, t)| (used(t), *k)).collect();
    ages.sort_unstable();
    for (_, key) in ages.iter().take(tiles.len() - keep) {
        tiles.remove(key);
    }
}

impl MapView {
    /// The raw belief of `cell`, `None` if unknown or not held.
    fn belief(&self, cell: CellIndex) -> Option<i16> {
        let (key, offset) = self.tile_size.split(cell);
        self.tiles
            .get(&key)
            .and_then(|t| t.tile.get(offset))
            .map(LogOdds::raw)
    }

    /// Tile `key`, if held: for a caller that asks about many cells of
    /// one tile in turn ([`Self::tile_shadows`]).
    pub(crate) fn tile(&self, key: TileKey) -> Option<&Tile> {
        self.tiles.get(&key).map(|held| &held.tile)
    }

    /// Whether the cell at `offset` of `tile` (one of this view's) hides
    /// what lies behind it, as [`ConeGuard::shadows`] says of the cell.
    pub(crate) fn tile_shadows(&self, tile: &Tile, offset: CellOffset) -> bool {
        tile.get(offset).is_some_and(|b| b.raw() >= self.shadow)
    }
}

impl ConeGuard for MapView {
    fn shadows(&self, cell: CellIndex) -> bool {
        let (key, offset) = self.tile_size.split(cell);
        self.tile(key).is_some_and(|t| self.tile_shadows(t, offset))
    }

    fn keeps(&self, cell: CellIndex) -> bool {
        self.belief(cell).is_some_and(|b| b >= self.wall)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(max_tiles: usize) -> MapView {
        MapView::new(
            Resolution::DEFAULT,
            TileSize::new(16).expect("size"),
            MapViewSettings {
                max_tiles,
                ..MapViewSettings::default()
            },
        )
        .expect("view")
    }

    #[test]
    fn own_deltas_make_walls_once_strong_enough() {
        let mut v = view(64);
        let size = TileSize::new(16).expect("size");
        let cell = CellIndex::new(3, -2);
        let (key, offset) = size.split(cell);
        let mut delta = TileDelta::zero(key, size);
        // logit(0.6) per echo, in the grid's fixed point.
        delta.raw_mut()[offset.index(size)] = LogOdds::from_probability(0.6).unwrap().raw();
        for echoes in 1..=5 {
            v.apply(std::slice::from_ref(&delta)).expect("apply");
            let wall = v.keeps(cell);
            // 0.6 three times: odds 1.5^3 = 3.4, p = 0.77 >= 0.7; twice
            // 2.25, p = 0.69.
            assert_eq!(wall, echoes >= 3, "after {echoes} echoes");
        }
        assert!(!v.keeps(CellIndex::new(4, -2)) && !v.shadows(CellIndex::new(4, -2)));
    }

    #[test]
    fn the_least_recently_used_tiles_go_first() {
        let mut v = view(16);
        let size = TileSize::new(16).expect("size");
        for x in 0..16 {
            v.insert_unknown(TileKey::new(x, 0)).expect("insert");
        }
        // Touch tile 0 so it is the most recent, then overflow.
        v.keys_around(&Pose2::new(0.1, 0.1, 0.0), 0.05)
            .expect("keys");
        v.insert_unknown(TileKey::new(100, 0)).expect("insert");
        assert!(v.len() <= 16);
        assert!(v.contains(TileKey::new(0, 0)));
        assert!(v.contains(TileKey::new(100, 0)));
        assert!(!v.contains(TileKey::new(1, 0)), "the oldest went first");
        // The view reads a forgotten tile as unknown, never as a wall.
        let (first, _) = size
            .tiles_covering(&CellBox::new(CellIndex::new(16, 0), CellIndex::new(16, 0)).unwrap());
        assert_eq!(first, TileKey::new(1, 0));
        assert!(!v.shadows(CellIndex::new(16, 0)));
    }

    #[test]
    fn missing_tiles_are_those_around_the_pose_not_held() {
        let mut v = view(64);
        // 16 cells of 5 cm: a tile is 0.8 m; 1 m around the origin spans
        // tiles -2..=1 each way.
        let missing = v.missing_around(&Pose2::new(0.0, 0.0, 0.0), 1.0).unwrap();
        assert_eq!(missing.len(), 16);
        v.insert_unknown(TileKey::new(0, 0)).unwrap();
        let missing = v.missing_around(&Pose2::new(0.0, 0.0, 0.0), 1.0).unwrap();
        assert_eq!(missing.len(), 15);
        assert!(!missing.contains(&TileKey::new(0, 0)));
    }

    #[test]
    fn bad_settings_and_tiles_are_refused() {
        let bad =
            |settings| MapView::new(Resolution::DEFAULT, TileSize::DEFAULT, settings).is_err();
        assert!(bad(MapViewSettings {
            wall_probability: 0.5,
            ..MapViewSettings::default()
        }));
        assert!(bad(MapViewSettings {
            wall_probability: f64::NAN,
            ..MapViewSettings::default()
        }));
        assert!(bad(MapViewSettings {
            shadow_probability: 0.9,
            ..MapViewSettings::default()
        }));
        assert!(bad(MapViewSettings {
            max_tiles: 3,
            ..MapViewSettings::default()
        }));
        let mut v = view(64);
        let wrong = Tile::unknown(TileSize::new(32).unwrap());
        assert!(v.insert(TileKey::new(0, 0), wrong).is_err());
    }
}
