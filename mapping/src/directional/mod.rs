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
//! most occupied observed bin if that bin decides it a wall: a cell is a
//! wall if it faces some way as a wall. Otherwise a bin that decides it
//! free wins over bins that only lean occupied; with no bin decided, the
//! most occupied lean stands (`combined`). What goes to
//! the map server is the change of that belief, so the server's map (and
//! every reader of it) stays one belief per cell.
//!
//! The view also guards the cones it maps: a cell it believes a wall hides
//! what lies behind it, so a reading that passed a known wall (a specular
//! miss, a multipath echo) frees nothing beyond it. It holds a bounded
//! number of tiles and forgets the least recently used; a forgotten tile
//! starts again from nothing (the server keeps what it was sent).
//!
//! Space no robot could have seen (`enclosure`): every
//! [`DirectionalSettings::enclosure_period`] frames the view floods from
//! the cells the robots stood on through every cell it does not hold as
//! occupied; a cell it holds free that the flood does not reach is
//! walled off from every path, so the free evidence it got
//! came through a grazed face, and the map is sent it as a wall
//! ([`DirectionalSettings::wall_probability`]).
//! The judgement is undone, as a change sent like any other, when a later
//! flood reaches the cell again.
//!
//! Directions are taken from the robot's centre, not from each sensor:
//! the evidence of one frame arrives merged over its cones. At 1 m the
//! Scout's sensors (0.2 m off centre) see a cell up to 12° from where the
//! centre does, well within a bin.

use deog_grid::{
    CellIndex, CellOffset, ClampLimits, ConeGuard, KeyMap, LogOdds, Pose2, Resolution, TileDelta,
    TileKey, TileSize,
};

use crate::error::MappingError;
use crate::map_view::{check_view, evict_least_recent};

mod enclosure;

/// Directions of the surface normal a cell keeps a belief for.
pub const DIRECTIONS: usize = 12;

/// The raw value of a bin that has received no evidence.
const UNSEEN: i16 = LogOdds::UNKNOWN_RAW;

/// A direction's belief above which it decides its cell a wall, raw:
/// ROS map_server's occupied threshold (0.65), by which the localizer and
/// the evaluation class the map's cells ([`deog_grid::OccupancyThresholds`]).
const DECIDED_OCCUPIED: i16 = 619;

/// A direction's belief below which it decides its cell free, raw: the
/// same readers' free threshold (0.196).
const DECIDED_FREE: i16 = -1411;

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
    /// Frames between two judgements of the space no robot could have
    /// seen (`enclosure`); 0: never judged.
    pub enclosure_period: u32,
    /// How far behind a wall, once heard, the free evidence that reached
    /// it through the wall is taken back, metres
    /// (`DirectionalView::shadow_behind`); 0: never.
    pub shadow_depth: f64,
}

impl Default for DirectionalSettings {
    /// Walls at 0.7, as [`crate::MapViewSettings`]; 1,024 tiles (108 MiB
    /// of 64-cell tiles, twelve beliefs a cell); enclosed space judged
    /// every 50 frames (5 s of a Scout's).
    fn default() -> Self {
        Self {
            wall_probability: 0.7,
            max_tiles: 1024,
            limits: ClampLimits::default(),
            enclosure_period: DEFAULT_ENCLOSURE_PERIOD,
            shadow_depth: DEFAULT_SHADOW_DEPTH_M,
        }
    }
}

impl DirectionalSettings {
    /// Checks the figures.
    pub fn validate(self) -> Result<Self, MappingError> {
        check_view(self.wall_probability, self.max_tiles)?;
        check_shadow_depth(self.shadow_depth)?;
        Ok(self)
    }
}

/// Checks a depth of [`DirectionalSettings::shadow_depth`]: 0 to
/// [`MAX_SHADOW_DEPTH_M`] metres.
pub(crate) fn check_shadow_depth(depth: f64) -> Result<(), MappingError> {
    if !(depth.is_finite() && (0.0..=MAX_SHADOW_DEPTH_M).contains(&depth)) {
        return Err(MappingError::invalid(
            "shadow_depth",
            format!("must be within 0 to {MAX_SHADOW_DEPTH_M} m, got {depth}"),
        ));
    }
    Ok(())
}

/// Frames between two judgements of enclosed space by default.
pub const DEFAULT_ENCLOSURE_PERIOD: u32 = 50;

/// How far behind a wall heard free evidence is taken back by default,
/// metres. The inside of an obstacle lies within a metre of some face in
/// the worlds measured; farther, the space behind a thin wall is more
/// often a room a doorway showed (BENCHMARKS.md, sonar mapping: 2 m
/// turned more of it into walls and cost the office map).
pub const DEFAULT_SHADOW_DEPTH_M: f64 = 1.0;

/// The deepest shadow allowed, metres.
const MAX_SHADOW_DEPTH_M: f64 = 10.0;

/// The directions, either side of the one a wall was heard from, whose
/// readings [`DirectionalView::shadow_behind`] takes back: a reading
/// through a wall met it this far from the wall's normal or less.
const SHADOW_FAN_DEG: f64 = 60.0;

/// Between two rays of that fan, degrees: a cell seen from 2 m behind one
/// wall cell is on some neighbouring wall cell's ray.
const SHADOW_RAY_STEP_DEG: f64 = 10.0;

/// Wall cells a ray of that fan crosses before the cells behind the wall
/// begin: a wall is a cell or two thick; a ray along the wall meets more
/// and stops.
const WALL_THICKNESS_CELLS: usize = 2;

/// How far from a robot's centre the cells it stands on reach, metres:
/// well inside any robot's body.
const TREAD_RADIUS_M: f64 = 0.1;

/// How far from a robot's centre unobserved cells still let the flood of
/// [`enclosure`] through, metres: the sonar cones begin at the body's
/// edge, a little beyond it.
const NEAR_PATH_M: f64 = 0.4;

/// The belief above which an observed cell stops the flood of
/// [`enclosure`]: a cell the view leans to believe occupied.
const FLOOD_BLOCK: i16 = 0;

/// Judgements of enclosed space a tile stays judged after its last use:
/// the flood keeps to the tiles held, and a tile long unused may have
/// lost the path that joined it to a robot.
const JUDGED_FOR_PERIODS: u64 = 10;

/// A tile's beliefs, [`DIRECTIONS`] per cell, and each cell's
/// [`combined`] belief kept beside them (the cone guard asks for it at
/// every cell of every cone), which cells a robot stood on, which are
/// judged enclosed, which were seen only through a wall, and when it was
/// last used.
#[derive(Debug, Clone)]
pub(crate) struct DirectionalTile {
    bins: Box<[i16]>,
    combined: Box<[i16]>,
    /// Each cell's [`leaning`] belief, which the flood of [`enclosure`]
    /// goes by.
    leaning: Box<[i16]>,
    trodden: Box<[bool]>,
    near_path: Box<[bool]>,
    enclosed: Box<[bool]>,
    shadowed: Box<[bool]>,
    used: u64,
}

impl DirectionalTile {
    fn new(area: usize) -> Self {
        Self {
            bins: vec![UNSEEN; area * DIRECTIONS].into_boxed_slice(),
            combined: vec![UNSEEN; area].into_boxed_slice(),
            leaning: vec![UNSEEN; area].into_boxed_slice(),
            trodden: vec![false; area].into_boxed_slice(),
            near_path: vec![false; area].into_boxed_slice(),
            enclosed: vec![false; area].into_boxed_slice(),
            shadowed: vec![false; area].into_boxed_slice(),
            used: 0,
        }
    }

    /// The belief the map holds for cell `index`: its directions'
    /// ([`combined`]), or a wall's if it is judged enclosed or all it was
    /// told came through a wall ([`DirectionalView::shadow_behind`]).
    fn held(&self, index: usize, wall: i16) -> i16 {
        let belief = self.combined[index];
        if belief == UNSEEN && self.shadowed[index] {
            wall
        } else if self.enclosed[index] && belief != UNSEEN {
            belief.max(wall)
        } else {
            belief
        }
    }

    /// Cell `index`'s beliefs by direction.
    fn bins(&self, index: usize) -> &[i16] {
        &self.bins[index * DIRECTIONS..(index + 1) * DIRECTIONS]
    }

    /// Changes cell `index`'s beliefs by direction with `change`, keeping
    /// its combined belief.
    fn change_bins<R>(&mut self, index: usize, change: impl FnOnce(&mut [i16]) -> R) -> R {
        let bins = &mut self.bins[index * DIRECTIONS..(index + 1) * DIRECTIONS];
        let result = change(bins);
        let extremes = Extremes::of(bins);
        self.combined[index] = combined(extremes);
        self.leaning[index] = leaning(extremes);
        result
    }
}

/// The cartographer's own directional beliefs around the robot, bounded.
#[derive(Debug, Clone)]
pub struct DirectionalView {
    settings: DirectionalSettings,
    wall: i16,
    resolution: Resolution,
    tile_size: TileSize,
    tiles: KeyMap<TileKey, DirectionalTile>,
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
            tiles: KeyMap::default(),
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
    /// occupied observed direction, or a wall's if it is walled off from
    /// every robot's path; `None` if never observed (or forgotten).
    pub fn belief(&self, cell: CellIndex) -> Option<LogOdds> {
        let (key, offset) = self.tile_size.split(cell);
        let tile = self.tiles.get(&key)?;
        LogOdds::from_raw(tile.held(offset.index(self.tile_size), self.wall))
    }

    /// Tile `key`, if held: for a caller that asks about many cells of
    /// one tile in turn ([`Self::tile_shadows`]).
    pub(crate) fn tile(&self, key: TileKey) -> Option<&DirectionalTile> {
        self.tiles.get(&key)
    }

    /// Whether cell `index` of `tile` (one of this view's) hides what lies
    /// behind it, as [`ConeGuard::shadows`] says of the cell.
    pub(crate) fn tile_shadows(&self, tile: &DirectionalTile, index: usize) -> bool {
        tile.held(index, self.wall) >= self.wall
    }

    /// The tiles' size.
    pub(crate) fn tile_size(&self) -> TileSize {
        self.tile_size
    }

    /// Whether `cell` is judged walled off from every robot's path.
    pub fn is_enclosed(&self, cell: CellIndex) -> bool {
        let (key, offset) = self.tile_size.split(cell);
        self.tiles
            .get(&key)
            .is_some_and(|t| t.enclosed[offset.index(self.tile_size)])
    }

    /// Takes one frame's plain evidence (`plain`, the sonar model's deltas
    /// for a robot at `robot`) into the directional beliefs, marks the
    /// cells the robot stands on, and appends to `out` the change each
    /// touched cell's belief makes, one delta per tile that changed; every
    /// [`DirectionalSettings::enclosure_period`] frames also the changes of
    /// the judgement of enclosed space, merged into the same deltas.
    pub fn absorb(
        &mut self,
        robot: &Pose2,
        plain: &[TileDelta],
        out: &mut Vec<TileDelta>,
    ) -> Result<(), MappingError> {
        self.clock += 1;
        let start = out.len();
        let size = self.tile_size;
        let cells_per_tile = size.area();
        let wall = self.wall;
        let mut new_walls: Vec<(CellIndex, usize)> = Vec::new();
        for delta in plain {
            size.check(delta.key)?;
            let origin = size.origin(delta.key)?;
            let clock = self.clock;
            let tile = self
                .tiles
                .entry(delta.key)
                .or_insert_with(|| DirectionalTile::new(cells_per_tile));
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
                let below = direction_bin(robot.x - cx, robot.y - cy);
                let above = (below + 1) % DIRECTIONS;
                let before = tile.held(index, wall);
                let limits = self.settings.limits;
                tile.change_bins(index, |bins| {
                    for b in [below, above] {
                        bins[b] = limits.apply(bins[b], d);
                    }
                });
                let after = tile.held(index, wall);
                if after != before {
                    change
                        .get_or_insert_with(|| TileDelta::zero(delta.key, size))
                        .raw_mut()[index] = step(before, after);
                }
                // A wall heard: what was freed behind it came through it.
                if d > 0 && before < wall && after >= wall {
                    let bins = tile.bins(index);
                    if let Some(facing) = (0..DIRECTIONS).max_by_key(|&b| bins[b]) {
                        new_walls.push((cell, facing));
                    }
                }
            }
            out.extend(change);
        }
        if self.settings.shadow_depth > 0.0 {
            for (cell, facing) in new_walls {
                self.shadow_behind(cell, facing, out, start)?;
            }
        }
        self.tread(robot)?;
        let period = u64::from(self.settings.enclosure_period);
        if period > 0 && self.clock % period == 0 {
            self.judge_enclosure(out, start);
        }
        self.evict();
        Ok(())
    }

    /// Takes back the free evidence that reached the cells behind `wall`,
    /// just heard from direction bin `facing`, through it: along rays from
    /// the wall away from every direction within [`SHADOW_FAN_DEG`] of the
    /// one it was heard from, each cell loses the free belief of the two
    /// directions a reading down that ray gave, out to
    /// [`DirectionalSettings::shadow_depth`]. A ray stops at another wall
    /// (what lies beyond may be free space seen from its far side), at a
    /// cell a robot came near and at a tile not held. A cell left with no
    /// direction observed was seen only through walls and is held as one.
    /// The change of each cell's belief is added to `out[start..]`.
    ///
    /// A specular sonar frees the inside of an obstacle through a face it
    /// grazed before any reading has made that face a wall; once it is
    /// one, the guard stops later cones at it, and this undoes the earlier
    /// ones.
    fn shadow_behind(
        &mut self,
        wall_cell: CellIndex,
        facing: usize,
        out: &mut Vec<TileDelta>,
        start: usize,
    ) -> Result<(), MappingError> {
        let size = self.tile_size;
        let resolution = self.resolution;
        let wall = self.wall;
        let cell_m = resolution.metres();
        let bin_width = std::f64::consts::TAU / DIRECTIONS as f64;
        let (wx, wy) = resolution.cell_center(wall_cell);
        let steps = (self.settings.shadow_depth / (cell_m * 0.5)).ceil() as usize;
        let rays = (SHADOW_FAN_DEG / SHADOW_RAY_STEP_DEG).round() as i32;
        for k in -rays..=rays {
            // The direction from a cell behind the wall back through it.
            let back =
                facing as f64 * bin_width + (f64::from(k) * SHADOW_RAY_STEP_DEG).to_radians();
            let position = back.rem_euclid(std::f64::consts::TAU) / bin_width;
            let below = (position.floor() as usize) % DIRECTIONS;
            let above = (below + 1) % DIRECTIONS;
            let (dx, dy) = (-back.cos() * cell_m * 0.5, -back.sin() * cell_m * 0.5);
            let mut last = wall_cell;
            let mut thickness = 0;
            for i in 1..=steps {
                let cell = resolution.cell_of(wx + dx * i as f64, wy + dy * i as f64)?;
                if cell == last {
                    continue;
                }
                last = cell;
                let (key, offset) = size.split(cell);
                let Some(tile) = self.tiles.get_mut(&key) else {
                    break;
                };
                let index = offset.index(size);
                if tile.combined[index] >= wall {
                    thickness += 1;
                    if thickness > WALL_THICKNESS_CELLS || i > 2 * (WALL_THICKNESS_CELLS + 1) {
                        break;
                    }
                    continue;
                }
                if tile.near_path[index] {
                    break;
                }
                let before = tile.held(index, wall);
                let cleared = tile.change_bins(index, |bins| {
                    let mut cleared = false;
                    for b in [below, above] {
                        if bins[b] != UNSEEN && bins[b] <= 0 {
                            bins[b] = UNSEEN;
                            cleared = true;
                        }
                    }
                    cleared
                });
                if !cleared {
                    continue;
                }
                if tile.combined[index] == UNSEEN {
                    tile.shadowed[index] = true;
                }
                let after = tile.held(index, wall);
                if after != before {
                    add_change(out, start, key, size, index, step(before, after));
                }
            }
        }
        Ok(())
    }

    /// Marks the cells within [`TREAD_RADIUS_M`] of the robot's centre as
    /// stood on: where the flood of [`enclosure`] starts.
    fn tread(&mut self, robot: &Pose2) -> Result<(), MappingError> {
        let r = NEAR_PATH_M;
        let low = self.resolution.cell_of(robot.x - r, robot.y - r)?;
        let high = self.resolution.cell_of(robot.x + r, robot.y + r)?;
        let size = self.tile_size;
        let clock = self.clock;
        for y in low.y..=high.y {
            for x in low.x..=high.x {
                let cell = CellIndex::new(x, y);
                let (cx, cy) = self.resolution.cell_center(cell);
                let distance = (cx - robot.x).hypot(cy - robot.y);
                if distance > r {
                    continue;
                }
                let (key, offset) = size.split(cell);
                size.check(key)?;
                let tile = self
                    .tiles
                    .entry(key)
                    .or_insert_with(|| DirectionalTile::new(size.area()));
                tile.used = clock;
                tile.near_path[offset.index(size)] = true;
                if distance <= TREAD_RADIUS_M {
                    tile.trodden[offset.index(size)] = true;
                }
            }
        }
        Ok(())
    }

    /// Judges again which observed cells are walled off from every path a
    /// robot took, in the tiles used within the last
    /// [`JUDGED_FOR_PERIODS`] judgements, and adds the change of their
    /// beliefs to `out[start..]` (into a tile's delta there, or a new one).
    fn judge_enclosure(&mut self, out: &mut Vec<TileDelta>, start: usize) {
        let size = self.tile_size;
        let reached = enclosure::reached_from_trodden(&self.tiles, size, FLOOD_BLOCK);
        let since = self
            .clock
            .saturating_sub(JUDGED_FOR_PERIODS * u64::from(self.settings.enclosure_period));
        let wall = self.wall;
        for (key, reached) in reached {
            let Some(tile) = self.tiles.get_mut(&key) else {
                continue;
            };
            if tile.used < since {
                continue;
            }
            for (index, &reached) in reached.iter().enumerate() {
                let belief = tile.leaning[index];
                // Only the cells the view leans to believe free (the ones
                // the flood passes): raising the uncertain ones inside too
                // gained a point of cells right but walled off free pockets
                // by the walls' fringe, and cost the localizer
                // (BENCHMARKS.md, sonar mapping).
                let enclosed = !reached && belief != UNSEEN && belief <= FLOOD_BLOCK;
                if enclosed == tile.enclosed[index] {
                    continue;
                }
                let before = tile.held(index, wall);
                tile.enclosed[index] = enclosed;
                let after = tile.held(index, wall);
                if after != before {
                    add_change(out, start, key, size, index, step(before, after));
                }
            }
        }
    }

    fn evict(&mut self) {
        evict_least_recent(&mut self.tiles, self.settings.max_tiles, |t| t.used);
    }
}

/// Adds `delta` to cell `index` of tile `key` in `out[start..]`: into the
/// tile's delta there, or a new one.
fn add_change(
    out: &mut Vec<TileDelta>,
    start: usize,
    key: TileKey,
    size: TileSize,
    index: usize,
    delta: i16,
) {
    let position = match out[start..].iter().position(|d| d.key == key) {
        Some(p) => start + p,
        None => {
            out.push(TileDelta::zero(key, size));
            out.len() - 1
        }
    };
    let sum = &mut out[position].raw_mut()[index];
    *sum = sum.saturating_add(delta);
}

/// The delta that takes a cell's belief from `before` to `after`; a cell
/// seen first starts from even odds, as the map's cells do.
fn step(before: i16, after: i16) -> i16 {
    let base = if before == UNSEEN { 0 } else { before };
    (i32::from(after) - i32::from(base)) as i16
}

/// tan 30° and tan 60°: where [`direction_bin`]'s bins part within a
/// quarter turn.
const TAN_30: f64 = 0.577_350_269_189_625_8;
const TAN_60: f64 = 1.732_050_807_568_877_2;

/// The bin of direction `(dx, dy)`, `⌊atan2(dy, dx) / 30°⌋` with the angle
/// taken in `[0°, 360°)`, by comparisons rather than an arctangent (a
/// tenth of the mapping's time went to `atan2`, its remainder and its
/// `floor`): the
/// quarter turn from the signs, the third of it from `tan 30°` and
/// `tan 60°`. The same bin as the arctangent's but within a rounding
/// error of a boundary; `(0, 0)` is bin 0, as `atan2(0, 0)` is 0.
#[inline]
fn direction_bin(dx: f64, dy: f64) -> usize {
    const _: () = assert!(DIRECTIONS == 12, "direction_bin parts the turn in twelfths");
    // Turned back by the quarter turns before it, the direction lies in
    // [0°, 90°): along u, v towards it.
    let (quarter, u, v) = if dx > 0.0 && dy >= 0.0 {
        (0, dx, dy)
    } else if dx <= 0.0 && dy > 0.0 {
        (1, dy, -dx)
    } else if dx < 0.0 {
        (2, -dx, -dy)
    } else if dy < 0.0 {
        (3, -dy, dx)
    } else {
        return 0;
    };
    let third = if v < u * TAN_30 {
        0
    } else if v < u * TAN_60 {
        1
    } else {
        2
    };
    quarter * 3 + third
}

/// A cell's most occupied direction and its freest observed one, read in
/// one pass over its directions: what [`combined`] and [`leaning`] decide
/// by. Both [`UNSEEN`] if no direction was observed.
#[derive(Debug, Clone, Copy)]
struct Extremes {
    most: i16,
    freest: i16,
}

impl Extremes {
    #[inline]
    fn of(bins: &[i16]) -> Self {
        let mut most = UNSEEN;
        let mut freest = i16::MAX;
        for &b in bins {
            most = most.max(b);
            if b != UNSEEN {
                freest = freest.min(b);
            }
        }
        if most == UNSEEN {
            freest = UNSEEN;
        }
        Self { most, freest }
    }
}

/// A cell's belief as its directions lean: the most occupied if any
/// leans occupied, else the freest observed; [`UNSEEN`] if none was
/// observed. The flood of [`enclosure`] goes by it: a cell any direction
/// leans to believe a wall stops it, so that free pockets by a wall's
/// fringe are not walled off. Going by [`combined`] there cost map1's
/// localizer (BENCHMARKS.md, sonar mapping).
#[inline]
fn leaning(Extremes { most, freest }: Extremes) -> i16 {
    if most > 0 { most } else { freest }
}

/// A cell's belief from its directions, decided as the map's readers
/// class cells ([`DECIDED_OCCUPIED`], [`DECIDED_FREE`]): the most occupied
/// direction if it reads as a wall; else the freest if it reads as free;
/// else (nothing decided) the most occupied if it leans occupied, the
/// freest if none does; [`UNSEEN`] if none was observed.
///
/// A direction that only leans occupied does not outweigh one that
/// decided the cell free: the arc of a reading that met a wall square on
/// lies a little in front of the wall off its axis, and leaves the free
/// cells there leaning occupied in the direction it faced, while the
/// readings that crossed them say free. Taking the lean over the decision
/// left them uncertain, the largest share of wrong cells (BENCHMARKS.md,
/// sonar mapping).
#[inline]
fn combined(Extremes { most, freest }: Extremes) -> i16 {
    if most > DECIDED_OCCUPIED {
        return most;
    }
    if most > 0 && freest >= DECIDED_FREE {
        most
    } else {
        freest
    }
}

impl ConeGuard for DirectionalView {
    fn shadows(&self, cell: CellIndex) -> bool {
        let (key, offset) = self.tile_size.split(cell);
        self.tile(key)
            .is_some_and(|t| self.tile_shadows(t, offset.index(self.tile_size)))
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
    use deog_grid::TileMap;

    fn view() -> DirectionalView {
        view_with(DirectionalSettings::default())
    }

    fn view_with(settings: DirectionalSettings) -> DirectionalView {
        DirectionalView::new(
            Resolution::DEFAULT,
            TileSize::new(16).expect("size"),
            settings,
        )
        .expect("view")
    }

    /// A view that judges enclosed space at every frame and takes nothing
    /// back behind walls.
    fn judging_view() -> DirectionalView {
        view_with(DirectionalSettings {
            enclosure_period: 1,
            shadow_depth: 0.0,
            ..DirectionalSettings::default()
        })
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

    /// Plain deltas giving each of `cells` its value, one per tile.
    fn deltas_for(cells: &[(CellIndex, i16)]) -> Vec<TileDelta> {
        let size = TileSize::new(16).expect("size");
        let mut by_key: KeyMap<TileKey, TileDelta> = KeyMap::default();
        for &(cell, value) in cells {
            let (key, offset) = size.split(cell);
            by_key
                .entry(key)
                .or_insert_with(|| TileDelta::zero(key, size))
                .raw_mut()[offset.index(size)] = value;
        }
        by_key.into_values().collect()
    }

    #[test]
    fn free_evidence_that_came_through_a_wall_is_taken_back_once_it_is_heard() {
        let size = TileSize::new(16).expect("size");
        let mut v = view_with(DirectionalSettings {
            enclosure_period: 0,
            ..DirectionalSettings::default()
        });
        let mut server = TileMap::new(Resolution::DEFAULT, size, ClampLimits::default());
        let absorb_all = |v: &mut DirectionalView,
                          server: &mut TileMap,
                          robot: Pose2,
                          cells: &[(CellIndex, i16)]| {
            let mut out = Vec::new();
            v.absorb(&robot, &deltas_for(cells), &mut out)
                .expect("absorb");
            for delta in &out {
                server.apply(delta).expect("apply");
            }
        };
        let (_, row_y) = Resolution::DEFAULT.cell_center(CellIndex::new(0, 5));
        let west = Pose2::new(-1.0, row_y, 0.0);
        // A cone from the west frees a row straight through where a wall
        // (the column of cells x = 20, 1.0 m) stands, not yet heard ...
        let row: Vec<(CellIndex, i16)> = (0..=45)
            .filter(|&x| x != 20)
            .map(|x| (CellIndex::new(x, 5), -500))
            .collect();
        absorb_all(&mut v, &mut server, west, &row);
        // ... and one cell behind it is also seen free from the east.
        let east = Pose2::new(3.5, row_y, std::f64::consts::PI);
        absorb_all(&mut v, &mut server, east, &[(CellIndex::new(30, 5), -500)]);
        let belief =
            |v: &DirectionalView, x: i32| v.belief(CellIndex::new(x, 5)).expect("seen").raw();
        assert!((0..=45).filter(|&x| x != 20).all(|x| belief(&v, x) < 0));
        // Then the wall is heard from the west.
        let column: Vec<(CellIndex, i16)> =
            (0..=10).map(|y| (CellIndex::new(20, y), 2000)).collect();
        absorb_all(&mut v, &mut server, west, &column);
        let wall = LogOdds::from_probability(0.7).expect("wall").raw();
        for x in 0..20 {
            assert!(belief(&v, x) < 0, "in front of the wall, {x} stays free");
        }
        for x in (21..=40).filter(|&x| x != 30) {
            assert_eq!(
                belief(&v, x),
                wall,
                "behind the wall, {x} was seen only through it"
            );
            assert!(v.shadows(CellIndex::new(x, 5)));
        }
        assert!(belief(&v, 30) < 0, "seen from the east too, it stays free");
        for x in 42..=45 {
            assert!(belief(&v, x) < 0, "past the shadow's metre, {x} stays free");
        }
        // The server holds what the view holds.
        for x in 0..=45 {
            let cell = CellIndex::new(x, 5);
            assert_eq!(
                server.get(cell).map(|b| b.raw()),
                v.belief(cell).map(|b| b.raw()),
                "{x}"
            );
        }
        // A later reading from another side frees a shadowed cell.
        absorb_all(&mut v, &mut server, east, &[(CellIndex::new(25, 5), -500)]);
        assert!(belief(&v, 25) < 0);
    }

    #[test]
    fn a_shadow_deeper_than_ten_metres_or_not_a_number_is_refused() {
        for depth in [-0.1, 10.5, f64::NAN] {
            let settings = DirectionalSettings {
                shadow_depth: depth,
                ..DirectionalSettings::default()
            };
            let err = settings.validate().expect_err("refused");
            assert!(err.to_string().contains("shadow_depth"), "{err}");
            let view = crate::MapViewSettings {
                shadow_depth: depth,
                ..crate::MapViewSettings::default()
            };
            let err = view.validate().expect_err("refused");
            assert!(err.to_string().contains("shadow_depth"), "{err}");
        }
    }

    /// The cells of the square ring from `low` to `high` on both axes,
    /// and the cells inside it.
    fn square(low: i32, high: i32) -> (Vec<CellIndex>, Vec<CellIndex>) {
        let (mut ring, mut inside) = (Vec::new(), Vec::new());
        for y in low..=high {
            for x in low..=high {
                let cell = CellIndex::new(x, y);
                if x == low || x == high || y == low || y == high {
                    ring.push(cell);
                } else {
                    inside.push(cell);
                }
            }
        }
        (ring, inside)
    }

    #[test]
    fn space_walled_off_from_the_path_is_sent_as_a_wall_until_a_path_reaches_it() {
        let size = TileSize::new(16).expect("size");
        let mut v = judging_view();
        let mut server = TileMap::new(Resolution::DEFAULT, size, ClampLimits::default());
        let mut absorb_all = |v: &mut DirectionalView, robot: Pose2, cells: &[(CellIndex, i16)]| {
            let mut out = Vec::new();
            v.absorb(&robot, &deltas_for(cells), &mut out)
                .expect("absorb");
            let keys: Vec<TileKey> = out.iter().map(|d| d.key).collect();
            let mut unique = keys.clone();
            unique.sort();
            unique.dedup();
            assert_eq!(unique.len(), keys.len(), "one delta a tile");
            for delta in &out {
                server.apply(delta).expect("apply");
            }
            server.clone()
        };
        // A robot at (0.2, 0.2) m; free space west of a box of walls
        // whose ring crosses a tile edge (cells 12 to 24), its inside
        // freed as a specular cone frees it.
        let robot = Pose2::new(0.2, 0.2, 0.0);
        let (ring, inside) = square(12, 24);
        let outside: Vec<CellIndex> = (0..=30)
            .flat_map(|y| (0..12).map(move |x| CellIndex::new(x, y)))
            .collect();
        let mut cells: Vec<(CellIndex, i16)> = outside.iter().map(|&c| (c, -500)).collect();
        cells.extend(ring.iter().map(|&c| (c, 2000)));
        cells.extend(inside.iter().map(|&c| (c, -500)));
        let map = absorb_all(&mut v, robot, &cells);
        let wall = LogOdds::from_probability(0.7).expect("wall").raw();
        for &c in &inside {
            assert!(v.is_enclosed(c), "{c:?} is walled off");
            assert_eq!(v.belief(c).expect("observed").raw(), wall);
        }
        for &c in outside.iter().chain(&ring) {
            assert!(!v.is_enclosed(c), "{c:?} is not");
        }
        assert_eq!(v.belief(CellIndex::new(5, 5)).expect("seen").raw(), -500);
        assert_eq!(v.belief(ring[0]).expect("seen").raw(), 2000);
        let agree = |v: &DirectionalView, map: &TileMap| {
            for c in outside.iter().chain(&ring).chain(&inside) {
                assert_eq!(
                    map.get(*c).map(LogOdds::raw),
                    v.belief(*c).map(LogOdds::raw),
                    "the server holds the view's belief at {c:?}"
                );
            }
        };
        agree(&v, &map);
        // Misses from the robot free three cells of the west face: the
        // inside joins the path and is sent back as its readings left it.
        let door: Vec<(CellIndex, i16)> =
            (17..=19).map(|y| (CellIndex::new(12, y), -4000)).collect();
        let map = absorb_all(&mut v, robot, &door);
        for &c in &inside {
            assert!(!v.is_enclosed(c), "{c:?} is reached through the door");
            assert_eq!(v.belief(c).expect("observed").raw(), -500);
        }
        agree(&v, &map);
    }

    #[test]
    fn unobserved_space_lets_the_flood_through_only_near_the_path() {
        let mut v = judging_view();
        // Free cells that begin where the robot's cones begin (0.25 m
        // from its centre, unobserved cells between), and a patch seen
        // free 2 m away with nothing observed between.
        let robot = Pose2::new(0.0, 0.0, 0.0);
        let near: Vec<(CellIndex, i16)> = (5..20).map(|x| (CellIndex::new(x, 0), -500)).collect();
        let far: Vec<(CellIndex, i16)> = (60..64).map(|x| (CellIndex::new(x, 0), -500)).collect();
        let mut out = Vec::new();
        let plain = deltas_for(&[near.as_slice(), far.as_slice()].concat());
        v.absorb(&robot, &plain, &mut out).expect("absorb");
        assert!(near.iter().all(|&(c, _)| !v.is_enclosed(c)));
        assert!(far.iter().all(|&(c, _)| v.is_enclosed(c)));
    }

    #[test]
    fn with_no_period_nothing_is_judged() {
        let mut v = view();
        v.settings.enclosure_period = 0;
        let (ring, inside) = square(12, 24);
        let cells: Vec<(CellIndex, i16)> = ring
            .iter()
            .map(|&c| (c, 2000))
            .chain(inside.iter().map(|&c| (c, -500)))
            .collect();
        let mut out = Vec::new();
        for _ in 0..(2 * DEFAULT_ENCLOSURE_PERIOD) {
            v.absorb(&Pose2::new(0.2, 0.2, 0.0), &deltas_for(&cells), &mut out)
                .expect("absorb");
        }
        assert!(inside.iter().all(|&c| !v.is_enclosed(c)));
        assert!(v.belief(inside[0]).expect("seen").raw() < 0);
    }

    #[test]
    fn a_directions_bin_is_its_arctangents() {
        let by_arctangent = |dx: f64, dy: f64| {
            let angle = dy.atan2(dx).rem_euclid(std::f64::consts::TAU);
            (angle / (std::f64::consts::TAU / DIRECTIONS as f64)).floor() as usize % DIRECTIONS
        };
        // Along the axes, and in every bin's middle.
        for quarter in 0..4 {
            let angle = f64::from(quarter) * std::f64::consts::FRAC_PI_2;
            let (dx, dy) = (angle.cos().round(), angle.sin().round());
            assert_eq!(direction_bin(dx, dy), quarter as usize * 3, "{dx}, {dy}");
        }
        assert_eq!(
            direction_bin(-1.0, -0.0),
            6,
            "minus zero is half a turn too"
        );
        for bin in 0..DIRECTIONS {
            let angle = (bin as f64 + 0.5) * std::f64::consts::TAU / DIRECTIONS as f64;
            assert_eq!(direction_bin(angle.cos(), angle.sin()), bin);
        }
        // Cells around a robot anywhere, as absorb asks.
        let mut state = 99u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..100_000 {
            let (dx, dy) = (next() * 20.0 - 10.0, next() * 20.0 - 10.0);
            assert_eq!(direction_bin(dx, dy), by_arctangent(dx, dy), "{dx}, {dy}");
        }
        assert_eq!(direction_bin(0.0, 0.0), by_arctangent(0.0, 0.0));
    }

    #[test]
    fn the_decided_beliefs_are_the_map_readers_thresholds() {
        let thresholds = deog_grid::OccupancyThresholds::default();
        assert_eq!(DECIDED_OCCUPIED, thresholds.occupied().raw());
        assert_eq!(DECIDED_FREE, thresholds.free().raw());
    }

    #[test]
    fn a_direction_that_decides_outweighs_one_that_leans() {
        let mut bins = [UNSEEN; DIRECTIONS];
        assert_eq!(combined(Extremes::of(&bins)), UNSEEN, "nothing observed");
        // Leaning occupied one way, decided free another: free.
        bins[0] = 300;
        bins[3] = -2000;
        assert_eq!(combined(Extremes::of(&bins)), -2000);
        // Leaning free is no decision: the lean to occupied stands.
        bins[3] = -1000;
        assert_eq!(combined(Extremes::of(&bins)), 300);
        // A wall one way is a wall, whatever the others decided.
        bins[0] = 900;
        bins[3] = -2000;
        assert_eq!(combined(Extremes::of(&bins)), 900);
        // Nothing leans occupied: the freest.
        bins[0] = -200;
        bins[3] = -1000;
        assert_eq!(combined(Extremes::of(&bins)), -1000);
    }

    #[test]
    fn each_cells_kept_belief_is_its_directions_combined() {
        // Echoes and misses from robots all round, walls heard (so taken
        // back behind) and enclosure judged at every frame: whatever path
        // changes a cell's directions keeps its combined belief with them.
        let mut v = view_with(DirectionalSettings {
            enclosure_period: 1,
            ..DirectionalSettings::default()
        });
        let mut state = 12_345u64;
        let mut next = |n: u64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 33) % n
        };
        let mut out = Vec::new();
        for _ in 0..400 {
            let angle = next(360) as f64 * std::f64::consts::TAU / 360.0;
            let robot = Pose2::new(0.6 * angle.cos(), 0.6 * angle.sin(), angle);
            let cells: Vec<(CellIndex, i16)> = (0..20)
                .map(|_| {
                    let cell = CellIndex::new(next(40) as i32 - 20, next(40) as i32 - 20);
                    (cell, next(1600) as i16 - 700)
                })
                .collect();
            out.clear();
            v.absorb(&robot, &deltas_for(&cells), &mut out)
                .expect("absorb");
        }
        assert!(!v.is_empty());
        for tile in v.tiles.values() {
            for (index, &kept) in tile.combined.iter().enumerate() {
                let extremes = Extremes::of(tile.bins(index));
                assert_eq!(kept, combined(extremes), "cell {index}");
                assert_eq!(tile.leaning[index], leaning(extremes), "cell {index}");
            }
        }
    }

    #[test]
    fn the_view_stays_bounded() {
        let mut v = view_with(DirectionalSettings {
            max_tiles: 16,
            ..DirectionalSettings::default()
        });
        for x in 0..40 {
            absorb(
                &mut v,
                Pose2::new(0.0, 0.0, 0.0),
                CellIndex::new(16 * x, 0),
                500,
            );
            assert!(v.len() <= 16);
        }
        // The newest stays, and the robot's own tiles; the oldest went.
        assert!(v.belief(CellIndex::new(16 * 39, 0)).is_some());
        assert!(v.belief(CellIndex::new(0, 0)).is_some());
        assert!(v.belief(CellIndex::new(16, 0)).is_none());
    }

    mod properties {
        use super::*;
        use deog_grid::TileMap;
        use proptest::prelude::*;

        /// x, y (metres) and heading (radians).
        type RobotAt = (f64, f64, f64);
        /// A cell (x, y) and a plain delta for it.
        type CellEvidence = (i32, i32, i16);

        /// One frame: where the robot stood and the plain evidence of its
        /// cones, as (cell x, cell y, delta), all within 1.2 m of the
        /// origin, so that cells are told again and again, become walls
        /// and are taken back.
        fn frame() -> impl Strategy<Value = (RobotAt, Vec<CellEvidence>)> {
            (
                (0.0..1.2f64, 0.0..1.2f64, -3.2..3.2f64),
                prop::collection::vec(
                    (
                        0..24i32,
                        0..24i32,
                        (-1200..1200i16).prop_filter("nonzero", |d| *d != 0),
                    ),
                    1..60,
                ),
            )
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(64))]

            /// What the view sends is the change of what it holds: the
            /// deltas, added up by a map as the server adds them, give
            /// every cell the view's belief, through taking back, the
            /// judgement of enclosed space and clamping alike.
            #[test]
            fn the_deltas_sent_add_up_to_the_views_beliefs(
                frames in prop::collection::vec(frame(), 1..30),
                enclosure_period in 0..4u32,
                shadow_depth in prop::sample::select(vec![0.0, 0.3, 1.0]),
            ) {
                let size = TileSize::new(16).expect("size");
                let mut view = view_with(DirectionalSettings {
                    enclosure_period,
                    shadow_depth,
                    ..DirectionalSettings::default()
                });
                let mut map = TileMap::new(Resolution::DEFAULT, size, ClampLimits::NONE);
                let mut touched = std::collections::BTreeSet::new();
                for ((x, y, theta), cells) in frames {
                    let mut plain: Vec<TileDelta> = Vec::new();
                    for (cx, cy, d) in cells {
                        let cell = CellIndex::new(cx, cy);
                        touched.insert((cx, cy));
                        let (key, offset) = size.split(cell);
                        let at = match plain.iter().position(|p| p.key == key) {
                            Some(at) => at,
                            None => {
                                plain.push(TileDelta::zero(key, size));
                                plain.len() - 1
                            }
                        };
                        let raw = &mut plain[at].raw_mut()[offset.index(size)];
                        *raw = raw.saturating_add(d);
                    }
                    let mut out = Vec::new();
                    view.absorb(&Pose2::new(x, y, theta), &plain, &mut out)
                        .expect("absorb");
                    for delta in &out {
                        map.apply(delta).expect("apply");
                    }
                }
                for (x, y) in (-40..64).flat_map(|x| (-40..64).map(move |y| (x, y))) {
                    let cell = CellIndex::new(x, y);
                    let held = view.belief(cell).map(LogOdds::raw);
                    let sent = map.get(cell).map(LogOdds::raw);
                    // A cell the view never held a belief for was sent nothing.
                    prop_assert_eq!(
                        sent.filter(|&raw| raw != 0 || held.is_some()),
                        held,
                        "cell ({}, {}), touched: {}", x, y, touched.contains(&(x, y))
                    );
                }
            }
        }
    }
}
