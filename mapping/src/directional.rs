//! Sonar evidence kept by direction ([`crate::SonarMethod::Directional`]),
//! after the idea of Konolige's MURIEL (1997): a sonar hears a surface
//! only when it meets it within the critical angle of its normal, so a
//! reading says something only about surfaces facing back at the sensor.
//! A wall swept at a grazing angle returns nothing, and the readings that
//! pass it say "no surface facing this way here", which is true, and must
//! not erase the echoes that the wall returned from straight ahead.
//!
//! Each cell of the view keeps one belief per direction of the surface
//! normal ([`DIRECTIONS`] bins of 30°, the Polaroid transducer's critical
//! angle). A cell's evidence from a frame goes to the two bins nearest to
//! the direction back at the robot. The cell's belief in the map is its
//! most occupied observed bin: a cell is a wall if it faces some way as a
//! wall, and free once every way it was seen from says free. What goes to
//! the map server is the change of that belief, so the server's map (and
//! every reader of it) stays one belief per cell.
//!
//! The view also guards the cones it maps: a cell it believes a wall hides
//! what lies behind it, so a reading that passed a known wall (a specular
//! miss, a multipath echo) frees nothing beyond it. It holds a bounded
//! number of tiles and forgets the least recently used; a forgotten tile
//! starts again from nothing (the server keeps what it was sent).
//!
//! Directions are taken from the robot's centre, not from each sensor:
//! the evidence of one frame arrives merged over its cones. At 1 m the
//! Scout's sensors (0.2 m off centre) see a cell up to 12° from where the
//! centre does, well within a bin.

use std::collections::HashMap;

use deog_grid::{
    CellIndex, CellOffset, ClampLimits, ConeGuard, LogOdds, Pose2, Resolution, TileDelta, TileKey,
    TileSize,
};

use crate::error::MappingError;
use crate::map_view::{check_view, evict_least_recent};

/// Directions of the surface normal a cell keeps a belief for.
pub const DIRECTIONS: usize = 12;

/// The raw value of a bin that has received no evidence.
const UNSEEN: i16 = LogOdds::UNKNOWN_RAW;

/// How big a directional view is and what it calls a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectionalSettings {
    /// A cell at or above this probability of occupancy (its most occupied
    /// direction) hides what lies behind it from later cones.
    pub wall_probability: f64,
    /// Tiles held at most.
    pub max_tiles: usize,
    /// Each direction's belief is clamped as the map clamps a cell, so
    /// that a direction can change its mind (a door opens).
    pub limits: ClampLimits,
}

impl Default for DirectionalSettings {
    /// Walls at 0.7, as [`crate::MapViewSettings`]; 1,024 tiles (96 MiB
    /// of 64-cell tiles, twelve beliefs a cell).
    fn default() -> Self {
        Self {
            wall_probability: 0.7,
            max_tiles: 1024,
            limits: ClampLimits::default(),
        }
    }
}

impl DirectionalSettings {
    /// Checks the figures.
    pub fn validate(self) -> Result<Self, MappingError> {
        check_view(self.wall_probability, self.max_tiles)?;
        Ok(self)
    }
}

/// A tile's beliefs, [`DIRECTIONS`] per cell, and when it was last used.
#[derive(Debug, Clone)]
struct DirectionalTile {
    bins: Box<[i16]>,
    used: u64,
}

/// The cartographer's own directional beliefs around the robot, bounded.
#[derive(Debug, Clone)]
pub struct DirectionalView {
    settings: DirectionalSettings,
    wall: i16,
    resolution: Resolution,
    tile_size: TileSize,
    tiles: HashMap<TileKey, DirectionalTile>,
    clock: u64,
}

impl DirectionalView {
    /// An empty view of a map of `resolution` and `tile_size`.
    pub fn new(
        resolution: Resolution,
        tile_size: TileSize,
        settings: DirectionalSettings,
    ) -> Result<Self, MappingError> {
        let settings = settings.validate()?;
        Ok(Self {
            wall: LogOdds::from_probability(settings.wall_probability)?.raw(),
            settings,
            resolution,
            tile_size,
            tiles: HashMap::new(),
            clock: 0,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &DirectionalSettings {
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

    /// The belief the map holds for `cell` from this view: its most
    /// occupied observed direction; `None` if never observed (or
    /// forgotten).
    pub fn belief(&self, cell: CellIndex) -> Option<LogOdds> {
        let (key, offset) = self.tile_size.split(cell);
        let tile = self.tiles.get(&key)?;
        let at = offset.index(self.tile_size) * DIRECTIONS;
        LogOdds::from_raw(combined(&tile.bins[at..at + DIRECTIONS]))
    }

    /// Takes one frame's plain evidence (`plain`, the sonar model's deltas
    /// for a robot at `robot`) into the directional beliefs and appends to
    /// `out` the change each touched cell's belief makes, one delta per
    /// tile that changed.
    pub fn absorb(
        &mut self,
        robot: &Pose2,
        plain: &[TileDelta],
        out: &mut Vec<TileDelta>,
    ) -> Result<(), MappingError> {
        self.clock += 1;
        let size = self.tile_size;
        let cells_per_tile = size.area();
        let bin_width = std::f64::consts::TAU / DIRECTIONS as f64;
        for delta in plain {
            size.check(delta.key)?;
            let origin = size.origin(delta.key)?;
            let clock = self.clock;
            let tile = self
                .tiles
                .entry(delta.key)
                .or_insert_with(|| DirectionalTile {
                    bins: vec![UNSEEN; cells_per_tile * DIRECTIONS].into_boxed_slice(),
                    used: 0,
                });
            tile.used = clock;
            let mut change: Option<TileDelta> = None;
            for (index, &d) in delta.raw().iter().enumerate() {
                if d == 0 {
                    continue;
                }
                let offset = CellOffset::from_index(index, size);
                let cell = CellIndex::new(
                    origin.x + i32::from(offset.x),
                    origin.y + i32::from(offset.y),
                );
                let (cx, cy) = self.resolution.cell_center(cell);
                // The direction back at the robot, in bins: the normal of
                // a surface this cell could have echoed from.
                let back = (robot.y - cy).atan2(robot.x - cx);
                let position = back.rem_euclid(std::f64::consts::TAU) / bin_width;
                let below = (position.floor() as usize) % DIRECTIONS;
                let above = (below + 1) % DIRECTIONS;
                let bins = &mut tile.bins[index * DIRECTIONS..(index + 1) * DIRECTIONS];
                let before = combined(bins);
                for b in [below, above] {
                    bins[b] = self.settings.limits.apply(bins[b], d);
                }
                let after = combined(bins);
                if after != before {
                    let base = if before == UNSEEN { 0 } else { before };
                    let step = (i32::from(after) - i32::from(base)) as i16;
                    change
                        .get_or_insert_with(|| TileDelta::zero(delta.key, size))
                        .raw_mut()[index] = step;
                }
            }
            out.extend(change);
        }
        self.evict();
        Ok(())
    }

    fn evict(&mut self) {
        evict_least_recent(&mut self.tiles, self.settings.max_tiles, |t| t.used);
    }
}

/// A cell's belief from its directions: the most occupied one if some
/// direction holds it occupied, else the freest observed one; [`UNSEEN`]
/// if none was observed.
#[inline]
fn combined(bins: &[i16]) -> i16 {
    let most = bins.iter().copied().max().unwrap_or(UNSEEN);
    if most > 0 {
        return most;
    }
    bins.iter()
        .copied()
        .filter(|&b| b != UNSEEN)
        .min()
        .unwrap_or(UNSEEN)
}

impl ConeGuard for DirectionalView {
    fn shadows(&self, cell: CellIndex) -> bool {
        self.belief(cell).is_some_and(|b| b.raw() >= self.wall)
    }

    /// A wall's cells still take the evidence of the readings that reach
    /// them: it lands in the directions those readings face, never in the
    /// one the wall echoed from.
    fn keeps(&self, _cell: CellIndex) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view() -> DirectionalView {
        DirectionalView::new(
            Resolution::DEFAULT,
            TileSize::new(16).expect("size"),
            DirectionalSettings::default(),
        )
        .expect("view")
    }

    /// One cell's delta.
    fn delta_for(cell: CellIndex, value: i16) -> TileDelta {
        let size = TileSize::new(16).expect("size");
        let (key, offset) = size.split(cell);
        let mut delta = TileDelta::zero(key, size);
        delta.raw_mut()[offset.index(size)] = value;
        delta
    }

    fn absorb(v: &mut DirectionalView, robot: Pose2, cell: CellIndex, value: i16) -> i16 {
        let mut out = Vec::new();
        v.absorb(&robot, &[delta_for(cell, value)], &mut out)
            .expect("absorb");
        out.iter()
            .map(|d| d.raw().iter().map(|&x| i32::from(x)).sum::<i32>())
            .sum::<i32>() as i16
    }

    #[test]
    fn misses_from_a_grazing_direction_leave_an_echo_from_the_front() {
        let mut v = view();
        let cell = CellIndex::new(40, 0);
        let (cx, cy) = Resolution::DEFAULT.cell_center(cell);
        // Echoes from straight in front of the wall (west of it) ...
        let front = Pose2::new(cx - 2.0, cy, 0.0);
        let mut sent = 0i32;
        for _ in 0..4 {
            sent += i32::from(absorb(&mut v, front, cell, 600));
        }
        let wall = v.belief(cell).expect("observed").raw();
        assert!(wall >= 2000, "four echoes make a wall: {wall}");
        assert_eq!(sent, i32::from(wall), "the server is sent the belief");
        // ... then many misses from the south, along the wall.
        let along = Pose2::new(cx, cy - 2.0, std::f64::consts::FRAC_PI_2);
        for _ in 0..20 {
            sent += i32::from(absorb(&mut v, along, cell, -400));
        }
        assert_eq!(v.belief(cell).expect("observed").raw(), wall);
        assert_eq!(sent, i32::from(wall));
        assert!(v.shadows(cell) && !v.keeps(cell));
        // Misses from the direction the echoes came from do free it.
        for _ in 0..20 {
            sent += i32::from(absorb(&mut v, front, cell, -400));
        }
        let now = v.belief(cell).expect("observed").raw();
        assert!(now < 0, "freed from the front: {now}");
        assert_eq!(sent, i32::from(now));
    }

    #[test]
    fn a_free_cell_seen_from_two_sides_is_as_free_as_its_freest_side() {
        let mut v = view();
        let cell = CellIndex::new(-7, 9);
        let (cx, cy) = Resolution::DEFAULT.cell_center(cell);
        absorb(&mut v, Pose2::new(cx - 1.0, cy, 0.0), cell, -900);
        absorb(&mut v, Pose2::new(cx, cy + 1.0, 0.0), cell, -300);
        assert_eq!(v.belief(cell).expect("observed").raw(), -900);
        assert!(v.belief(CellIndex::new(-6, 9)).is_none());
    }

    #[test]
    fn the_view_stays_bounded() {
        let mut v = DirectionalView::new(
            Resolution::DEFAULT,
            TileSize::new(16).expect("size"),
            DirectionalSettings {
                max_tiles: 16,
                ..DirectionalSettings::default()
            },
        )
        .expect("view");
        for x in 0..40 {
            absorb(
                &mut v,
                Pose2::new(0.0, 0.0, 0.0),
                CellIndex::new(16 * x, 0),
                500,
            );
            assert!(v.len() <= 16);
        }
        // The newest stays, the oldest went.
        assert!(v.belief(CellIndex::new(16 * 39, 0)).is_some());
        assert!(v.belief(CellIndex::new(0, 0)).is_none());
    }
}
