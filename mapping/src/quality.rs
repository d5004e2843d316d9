//! Map quality against a world's ground truth: how many observed cells a
//! map classifies right, how well its occupied cells sit on the walls, how
//! much of the walls it found, and how much of the free space a robot
//! could reach it covers.
//!
//! # Definitions
//! - **Map class** of an observed cell (raw value not
//!   [`LogOdds::UNKNOWN_RAW`]), by ROS map_server's thresholds: occupied
//!   when p > [`OCCUPIED_ABOVE`] (0.65), free when p < [`FREE_BELOW`]
//!   (0.196), uncertain otherwise.
//! - **Truth** of a cell: occupied when its square touches a wall or lies
//!   in an obstacle, free otherwise. "Touches a wall" is approximated by a
//!   wall passing within half the cell's diagonal of its centre (plus a
//!   relative 1e-9, so that a wall through a corner of the square counts
//!   however the arithmetic rounds). The disk of that radius holds the
//!   square, so no touching wall is missed; a wall passing within the disk
//!   but just outside the square (near a corner) also counts. "Lies in an
//!   obstacle" is the centre not being [`World::is_free`], which also
//!   makes every cell outside the world's bounds (or its boundary)
//!   occupied. A wall along a cell edge thus marks the cells on both
//!   sides of it.
//! - **Clear** cells: truth-free cells whose centre is at least the robot
//!   radius from every wall: where a robot's centre may be.
//! - **Reachable** cells: the clear cells 4-connected through clear cells
//!   to a seed (a robot's position); with no seeds, every clear cell. A
//!   seed starts the fill at its own cell when that is clear, else at the
//!   clear one of its 8 neighbours whose centre is nearest to it; a seed
//!   with neither (inside a wall, outside the world) is not used.
//! - **Visible** cells: the truth-free cells 4-connected through
//!   truth-free cells to a reachable cell: the free space around where the
//!   robots could go, up to the walls.
//! - **Surface** cells: truth-occupied cells with a visible cell among
//!   their 8 neighbours: the faces of the walls a robot could have seen.
//!
//! The figures ([`MapQuality`]) are then, over the observed cells only
//! (cells never observed are neither right nor wrong):
//! - `fraction_correct`: observed cells whose map class equals their truth
//!   (an uncertain cell is never right), over all observed cells;
//! - `occupied_precision`: map-occupied cells with a truth-occupied cell
//!   within one cell (their 3 × 3 block) over all map-occupied cells;
//! - `occupied_recall`: surface cells with a map-occupied cell within one
//!   cell over all surface cells;
//! - `coverage`: reachable cells the map classifies free over all
//!   reachable cells.
//!
//! A map with no observed cell is an error: there is nothing to judge. A
//! figure whose denominator is zero otherwise (no map-occupied cell, no
//! surface, nothing reachable) is `None`, `null` in JSON.

use std::f64::consts::FRAC_1_SQRT_2;
use std::fmt::Write as _;

use deog_grid::{CellIndex, LogOdds, Resolution, SCOUT_BODY_RADIUS_M, TileMap};
use deog_world::{Point2, SegmentIndex, World};

use crate::error::MappingError;

/// Probability above which a map cell is occupied (map_server's default).
pub const OCCUPIED_ABOVE: f64 = 0.65;
/// Probability below which a map cell is free (map_server's default).
pub const FREE_BELOW: f64 = 0.196;
/// The default robot radius: the Nomad Super Scout's body, metres.
pub const DEFAULT_ROBOT_RADIUS_M: f64 = SCOUT_BODY_RADIUS_M;
/// Largest ground-truth raster judged, in cells (the world's bounds at the
/// map's resolution): a few bytes each, so memory stays bounded when a
/// fine map meets a large world.
pub const MAX_TRUTH_CELLS: u64 = 1 << 26;
/// Largest accepted robot radius, metres.
pub const MAX_ROBOT_RADIUS_M: f64 = 100.0;

/// Relative slack on the half diagonal, so that a wall through a cell's
/// corner touches it whichever way the centre's arithmetic rounds.
const TOUCH_SLACK: f64 = 1e-9;

/// What to judge and against what.
#[derive(Debug, Clone, Copy)]
pub struct QualityInput<'a> {
    /// The map, cells as the server holds them.
    pub map: &'a TileMap,
    /// The ground truth.
    pub world: &'a World,
    /// Where robots were (metres, world frame), to find the free space
    /// they could reach; empty: all free space wide enough for a robot.
    pub seeds: &'a [Point2],
    /// The robots' radius, metres, at least 0.
    pub robot_radius_m: f64,
}

impl<'a> QualityInput<'a> {
    /// `map` against `world`, without seeds, for a Scout-sized robot.
    pub fn new(map: &'a TileMap, world: &'a World) -> Self {
        Self {
            map,
            world,
            seeds: &[],
            robot_radius_m: DEFAULT_ROBOT_RADIUS_M,
        }
    }
}

/// Observed cells by truth (rows) and map class (columns).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Confusion {
    /// Truth free, map free.
    pub free_as_free: u64,
    /// Truth free, map occupied.
    pub free_as_occupied: u64,
    /// Truth free, map uncertain.
    pub free_as_uncertain: u64,
    /// Truth occupied, map free.
    pub occupied_as_free: u64,
    /// Truth occupied, map occupied.
    pub occupied_as_occupied: u64,
    /// Truth occupied, map uncertain.
    pub occupied_as_uncertain: u64,
}

/// How good a map is; the definitions are in the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct MapQuality {
    /// The map's cell side, metres.
    pub resolution_m: f64,
    /// The robot radius used, metres.
    pub robot_radius_m: f64,
    /// Seeds given.
    pub seeds_given: u64,
    /// Seeds that started the fill of reachable cells.
    pub seeds_used: u64,
    /// Observed cells by truth and map class.
    pub confusion: Confusion,
    /// Cells the map classifies occupied.
    pub map_occupied: u64,
    /// Of those, the ones with a truth-occupied cell within one cell.
    pub map_occupied_near_truth: u64,
    /// Surface cells: truth-occupied cells bordering visible free space.
    pub surface_cells: u64,
    /// Of those, the ones with a map-occupied cell within one cell.
    pub surface_cells_found: u64,
    /// Reachable cells.
    pub reachable_cells: u64,
    /// Of those, the ones the map classifies free.
    pub reachable_cells_free: u64,
}

fn ratio(part: u64, whole: u64) -> Option<f64> {
    (whole > 0).then(|| part as f64 / whole as f64)
}

impl MapQuality {
    /// Cells observed (judged).
    pub fn cells_observed(&self) -> u64 {
        let c = &self.confusion;
        c.free_as_free
            + c.free_as_occupied
            + c.free_as_uncertain
            + c.occupied_as_free
            + c.occupied_as_occupied
            + c.occupied_as_uncertain
    }

    /// Observed cells whose map class equals their truth.
    pub fn cells_correct(&self) -> u64 {
        self.confusion.free_as_free + self.confusion.occupied_as_occupied
    }

    /// Observed cells the map leaves between the thresholds.
    pub fn cells_uncertain(&self) -> u64 {
        self.confusion.free_as_uncertain + self.confusion.occupied_as_uncertain
    }

    /// Correct cells over observed cells; 0 when nothing was observed
    /// (which [`map_quality`] refuses anyway).
    pub fn fraction_correct(&self) -> f64 {
        ratio(self.cells_correct(), self.cells_observed()).unwrap_or(0.0)
    }

    /// Map-occupied cells near a truth-occupied one, over map-occupied
    /// cells; `None` when the map has no occupied cell.
    pub fn occupied_precision(&self) -> Option<f64> {
        ratio(self.map_occupied_near_truth, self.map_occupied)
    }

    /// Surface cells found within one cell, over surface cells; `None`
    /// when there is no surface.
    pub fn occupied_recall(&self) -> Option<f64> {
        ratio(self.surface_cells_found, self.surface_cells)
    }

    /// Reachable cells mapped free, over reachable cells; `None` when
    /// nothing is reachable.
    pub fn coverage(&self) -> Option<f64> {
        ratio(self.reachable_cells_free, self.reachable_cells)
    }

    /// One JSON object: every count, and the four fractions (`null` when
    /// undefined), under the names of the module docs.
    pub fn to_json(&self) -> String {
        let c = &self.confusion;
        let fields: [(&str, String); 20] = [
            ("resolution_m", number(Some(self.resolution_m))),
            ("robot_radius_m", number(Some(self.robot_radius_m))),
            ("seeds_given", self.seeds_given.to_string()),
            ("seeds_used", self.seeds_used.to_string()),
            ("cells_observed", self.cells_observed().to_string()),
            ("cells_correct", self.cells_correct().to_string()),
            ("cells_uncertain", self.cells_uncertain().to_string()),
            ("fraction_correct", number(Some(self.fraction_correct()))),
            ("map_occupied", self.map_occupied.to_string()),
            (
                "map_occupied_near_truth",
                self.map_occupied_near_truth.to_string(),
            ),
            ("occupied_precision", number(self.occupied_precision())),
            ("surface_cells", self.surface_cells.to_string()),
            ("surface_cells_found", self.surface_cells_found.to_string()),
            ("occupied_recall", number(self.occupied_recall())),
            ("reachable_cells", self.reachable_cells.to_string()),
            (
                "reachable_cells_free",
                self.reachable_cells_free.to_string(),
            ),
            ("coverage", number(self.coverage())),
            (
                "confusion",
                format!(
                    "{{\"free_as_free\": {}, \"free_as_occupied\": {}, \"free_as_uncertain\": {}, \
                     \"occupied_as_free\": {}, \"occupied_as_occupied\": {}, \
                     \"occupied_as_uncertain\": {}}}",
                    c.free_as_free,
                    c.free_as_occupied,
                    c.free_as_uncertain,
                    c.occupied_as_free,
                    c.occupied_as_occupied,
                    c.occupied_as_uncertain
                ),
            ),
            ("occupied_above", number(Some(OCCUPIED_ABOVE))),
            ("free_below", number(Some(FREE_BELOW))),
        ];
        let body: Vec<String> = fields
            .iter()
            .map(|(name, value)| format!("  \"{name}\": {value}"))
            .collect();
        format!("{{\n{}\n}}\n", body.join(",\n"))
    }

    /// The figures as markdown tables: the summary, then the confusion
    /// counts.
    pub fn table(&self) -> String {
        let observed = self.cells_observed();
        let mut out = String::new();
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "map quality: {} m cells, robot radius {} m, {} of {} seeds used\n",
            self.resolution_m, self.robot_radius_m, self.seeds_used, self.seeds_given
        );
        let _ = writeln!(out, "| figure | value | cells |");
        let _ = writeln!(out, "|---|---:|---:|");
        let _ = writeln!(out, "| cells observed | {observed} | |");
        let rows = [
            (
                "fraction correct",
                Some(self.fraction_correct()),
                self.cells_correct(),
                observed,
            ),
            (
                "uncertain",
                ratio(self.cells_uncertain(), observed),
                self.cells_uncertain(),
                observed,
            ),
            (
                "occupied precision (±1 cell)",
                self.occupied_precision(),
                self.map_occupied_near_truth,
                self.map_occupied,
            ),
            (
                "occupied recall (±1 cell)",
                self.occupied_recall(),
                self.surface_cells_found,
                self.surface_cells,
            ),
            (
                "coverage of reachable free space",
                self.coverage(),
                self.reachable_cells_free,
                self.reachable_cells,
            ),
        ];
        for (name, value, part, whole) in rows {
            let value = value.map_or_else(|| "n/a".to_string(), |v| format!("{v:.4}"));
            let _ = writeln!(out, "| {name} | {value} | {part} of {whole} |");
        }
        let c = &self.confusion;
        let _ = writeln!(out, "\n| truth \\ map | free | occupied | uncertain |");
        let _ = writeln!(out, "|---|---:|---:|---:|");
        let _ = writeln!(
            out,
            "| free | {} | {} | {} |",
            c.free_as_free, c.free_as_occupied, c.free_as_uncertain
        );
        let _ = writeln!(
            out,
            "| occupied | {} | {} | {} |",
            c.occupied_as_free, c.occupied_as_occupied, c.occupied_as_uncertain
        );
        out
    }
}

/// A JSON number, or `null` for an undefined or non-finite one (JSON has
/// no NaN). Rust's shortest round-trip form never uses an exponent, so it
/// is valid JSON as it stands.
fn number(value: Option<f64>) -> String {
    match value {
        Some(v) if v.is_finite() => format!("{v}"),
        _ => "null".to_string(),
    }
}

/// A map cell's class by the thresholds; `None` if never observed.
fn map_class(raw: i16) -> Option<Class> {
    let p = LogOdds::from_raw(raw)?.probability();
    Some(if p > OCCUPIED_ABOVE {
        Class::Occupied
    } else if p < FREE_BELOW {
        Class::Free
    } else {
        Class::Uncertain
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    Free,
    Occupied,
    Uncertain,
}

/// Judges `input.map` against `input.world`; see the [module docs](self)
/// for every definition. Errors on a map with no observed cell, a bad
/// robot radius or seed, or a world too large to rasterise at the map's
/// resolution.
pub fn map_quality(input: &QualityInput<'_>) -> Result<MapQuality, MappingError> {
    let map = input.map;
    let (truth, grid, seeds_used) = judged_truth(input)?;
    let class_at = |cell: CellIndex| map.get(cell).and_then(|b| map_class(b.raw()));
    let mut quality = MapQuality {
        resolution_m: map.resolution().metres(),
        robot_radius_m: input.robot_radius_m,
        seeds_given: input.seeds.len() as u64,
        seeds_used,
        confusion: Confusion::default(),
        map_occupied: 0,
        map_occupied_near_truth: 0,
        surface_cells: 0,
        surface_cells_found: 0,
        reachable_cells: 0,
        reachable_cells_free: 0,
    };
    let truth_occupied = |cell: CellIndex| grid.truth_occupied(&truth, cell);
    for_each_verdict(map, &truth_occupied, |cell, verdict| {
        let c = &mut quality.confusion;
        let slot = match verdict {
            Verdict::FreeAsFree => &mut c.free_as_free,
            Verdict::FreeAsOccupied => &mut c.free_as_occupied,
            Verdict::FreeAsUncertain => &mut c.free_as_uncertain,
            Verdict::OccupiedAsFree => &mut c.occupied_as_free,
            Verdict::OccupiedAsOccupied => &mut c.occupied_as_occupied,
            Verdict::OccupiedAsUncertain => &mut c.occupied_as_uncertain,
        };
        *slot += 1;
        if verdict.map_class() == Class::Occupied {
            quality.map_occupied += 1;
            if block(cell).any(truth_occupied) {
                quality.map_occupied_near_truth += 1;
            }
        }
    })?;
    for (cell, flags) in grid.cells() {
        if flags & SURFACE != 0 {
            quality.surface_cells += 1;
            if block(cell).any(|n| class_at(n) == Some(Class::Occupied)) {
                quality.surface_cells_found += 1;
            }
        }
        if flags & REACHABLE != 0 {
            quality.reachable_cells += 1;
            if class_at(cell) == Some(Class::Free) {
                quality.reachable_cells_free += 1;
            }
        }
    }
    Ok(quality)
}

/// Checks the input and builds the ground truth of the world's cells,
/// with the reachable, visible and surface cells marked; also returns how
/// many seeds started the reachable fill.
fn judged_truth<'a>(input: &QualityInput<'a>) -> Result<(Truth<'a>, Grid, u64), MappingError> {
    let radius = input.robot_radius_m;
    if !(radius.is_finite() && (0.0..=MAX_ROBOT_RADIUS_M).contains(&radius)) {
        return Err(MappingError::invalid(
            "robot_radius_m",
            format!("must be within 0 to {MAX_ROBOT_RADIUS_M} m, got {radius}"),
        ));
    }
    for (i, seed) in input.seeds.iter().enumerate() {
        if !(seed.x.is_finite() && seed.y.is_finite()) {
            return Err(MappingError::invalid(
                format!("seeds[{i}]"),
                format!("not finite: ({}, {})", seed.x, seed.y),
            ));
        }
    }
    if input.map.observed_count() == 0 {
        return Err(MappingError::invalid(
            "map",
            "has no observed cell: there is nothing to judge",
        ));
    }
    let truth = Truth::new(input.world, input.map.resolution(), radius);
    let mut grid = truth.raster()?;
    let seeds_used = grid.fill_reachable(input.seeds, input.map.resolution());
    grid.fill_visible();
    Ok((truth, grid, seeds_used))
}

/// Calls `visit` with the verdict of every observed cell of `map`.
fn for_each_verdict(
    map: &TileMap,
    truth_occupied: &impl Fn(CellIndex) -> bool,
    mut visit: impl FnMut(CellIndex, Verdict),
) -> Result<(), MappingError> {
    let side = map.tile_size().cells() as usize;
    for (key, tile) in map.tiles() {
        let origin = map.tile_size().origin(*key)?;
        for (index, &raw) in tile.raw_cells().iter().enumerate() {
            let Some(class) = map_class(raw) else {
                continue;
            };
            // The key passed the origin check, so every cell of the tile
            // has an i32 index and these sums cannot overflow.
            let cell = CellIndex::new(
                origin.x + (index % side) as i32,
                origin.y + (index / side) as i32,
            );
            visit(cell, Verdict::of(truth_occupied(cell), class));
        }
    }
    Ok(())
}

/// One observed cell judged: its truth, then its map class.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Free, mapped free: right.
    FreeAsFree,
    /// Free, mapped occupied.
    FreeAsOccupied,
    /// Free, mapped uncertain.
    FreeAsUncertain,
    /// Occupied, mapped free.
    OccupiedAsFree,
    /// Occupied, mapped occupied: right.
    OccupiedAsOccupied,
    /// Occupied, mapped uncertain.
    OccupiedAsUncertain,
}

impl Verdict {
    fn of(truth_occupied: bool, class: Class) -> Self {
        match (truth_occupied, class) {
            (false, Class::Free) => Self::FreeAsFree,
            (false, Class::Occupied) => Self::FreeAsOccupied,
            (false, Class::Uncertain) => Self::FreeAsUncertain,
            (true, Class::Free) => Self::OccupiedAsFree,
            (true, Class::Occupied) => Self::OccupiedAsOccupied,
            (true, Class::Uncertain) => Self::OccupiedAsUncertain,
        }
    }

    fn map_class(self) -> Class {
        match self {
            Self::FreeAsFree | Self::OccupiedAsFree => Class::Free,
            Self::FreeAsOccupied | Self::OccupiedAsOccupied => Class::Occupied,
            Self::FreeAsUncertain | Self::OccupiedAsUncertain => Class::Uncertain,
        }
    }

    /// The colour [`verdict_image`] paints it.
    pub fn rgb(self) -> [u8; 3] {
        match self {
            Self::FreeAsFree => [255, 255, 255],
            Self::OccupiedAsOccupied => [0, 0, 0],
            Self::FreeAsUncertain => [255, 200, 0],
            Self::FreeAsOccupied => [220, 0, 0],
            Self::OccupiedAsFree => [0, 90, 255],
            Self::OccupiedAsUncertain => [170, 0, 200],
        }
    }
}

/// Never observed, free in the world.
pub const UNOBSERVED_FREE_RGB: [u8; 3] = [205, 205, 205];
/// Never observed, occupied in the world (the walls, for orientation).
pub const UNOBSERVED_OCCUPIED_RGB: [u8; 3] = [120, 120, 120];

/// Where a map is right and wrong, one RGB pixel a cell over the world's
/// bounds (one cell more each side), the top row first: each observed
/// cell in its [`Verdict::rgb`], the rest in [`UNOBSERVED_FREE_RGB`] or
/// [`UNOBSERVED_OCCUPIED_RGB`] by the world's truth.
#[derive(Debug, Clone, PartialEq)]
pub struct VerdictImage {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` RGB triples, top row first.
    pub rgb: Vec<u8>,
    /// The cell of the bottom-left pixel.
    pub min_cell: CellIndex,
}

impl VerdictImage {
    /// The image with each pixel a `factor` × `factor` square (a factor
    /// of 0 counts as 1), so that small worlds can be seen.
    pub fn scaled(&self, factor: u32) -> VerdictImage {
        let factor = factor.max(1) as usize;
        let (width, height) = (self.width as usize, self.height as usize);
        let mut rgb = Vec::with_capacity(self.rgb.len() * factor * factor);
        for row in self.rgb.chunks_exact(3 * width).take(height) {
            let mut line = Vec::with_capacity(row.len() * factor);
            for pixel in row.chunks_exact(3) {
                for _ in 0..factor {
                    line.extend_from_slice(pixel);
                }
            }
            for _ in 0..factor {
                rgb.extend_from_slice(&line);
            }
        }
        VerdictImage {
            width: (width * factor) as u32,
            height: (height * factor) as u32,
            rgb,
            min_cell: self.min_cell,
        }
    }

    /// The scale factor that brings the longer side to at most
    /// `max_side` pixels (at least 1).
    pub fn fit_factor(&self, max_side: u32) -> u32 {
        (max_side / self.width.max(self.height).max(1)).max(1)
    }
}

/// Paints `input.map`'s verdicts over its world; the same errors as
/// [`map_quality`]. Observed cells beyond the world's bounds (all wrong
/// unless mapped occupied) are counted by [`map_quality`] but not drawn.
pub fn verdict_image(input: &QualityInput<'_>) -> Result<VerdictImage, MappingError> {
    let (truth, grid, _) = judged_truth(input)?;
    let (width, height) = (grid.width, grid.height);
    let mut rgb = Vec::with_capacity(3 * width * height);
    for row in (0..height).rev() {
        for col in 0..width {
            let colour = if grid.flags[row * width + col] & OCCUPIED != 0 {
                UNOBSERVED_OCCUPIED_RGB
            } else {
                UNOBSERVED_FREE_RGB
            };
            rgb.extend_from_slice(&colour);
        }
    }
    let truth_occupied = |cell: CellIndex| grid.truth_occupied(&truth, cell);
    for_each_verdict(input.map, &truth_occupied, |cell, verdict| {
        if let Some(i) = grid.index(cell) {
            let (col, row) = (i % width, height - 1 - i / width);
            let at = 3 * (row * width + col);
            rgb[at..at + 3].copy_from_slice(&verdict.rgb());
        }
    })?;
    // The raster's size passed MAX_TRUTH_CELLS, far below u32::MAX a side.
    Ok(VerdictImage {
        width: width as u32,
        height: height as u32,
        rgb,
        min_cell: grid.origin,
    })
}

/// The 3 × 3 block of cells centred on `cell`, itself included (fewer at
/// the very edge of the i32 range).
fn block(cell: CellIndex) -> impl Iterator<Item = CellIndex> {
    (-1..=1).flat_map(move |dy| {
        (-1..=1).filter_map(move |dx| {
            Some(CellIndex::new(
                cell.x.checked_add(dx)?,
                cell.y.checked_add(dy)?,
            ))
        })
    })
}

/// The ground-truth rule of one cell: the world, its walls indexed, and
/// the cell geometry.
struct Truth<'a> {
    world: &'a World,
    walls: SegmentIndex,
    resolution: Resolution,
    /// Each obstacle's bounding box, (min, max), in the world's order.
    obstacle_boxes: Vec<(Point2, Point2)>,
    /// Half the cell diagonal with its slack, metres.
    touch: f64,
    robot_radius: f64,
}

impl<'a> Truth<'a> {
    fn new(world: &'a World, resolution: Resolution, robot_radius: f64) -> Self {
        Self {
            world,
            walls: SegmentIndex::new(world.walls()),
            resolution,
            obstacle_boxes: world.obstacles().iter().map(|o| o.bounds()).collect(),
            touch: resolution.metres() * FRAC_1_SQRT_2 * (1.0 + TOUCH_SLACK),
            robot_radius,
        }
    }

    fn centre(&self, cell: CellIndex) -> Point2 {
        let (x, y) = self.resolution.cell_center(cell);
        Point2::new(x, y)
    }

    /// [`World::is_free`], with each obstacle's bounding box tested before
    /// its polygon: a large world has many obstacles and a raster many
    /// cells, and most cells are far from most obstacles. The box test is
    /// inclusive, so a point on an obstacle's edge gets the polygon's own
    /// answer, exactly as `World::is_free` gives it (a test checks the two
    /// agree).
    fn is_free(&self, p: Point2) -> bool {
        let (min, max) = self.world.bounds();
        let inside =
            |(lo, hi): (Point2, Point2)| p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y;
        inside((min, max))
            && self.world.boundary().is_none_or(|b| b.contains(p))
            && !self
                .world
                .obstacles()
                .iter()
                .zip(&self.obstacle_boxes)
                .any(|(o, &b)| inside(b) && o.contains(p))
    }

    /// Whether `cell` is truth-occupied.
    fn occupied(&self, cell: CellIndex) -> bool {
        self.flags(cell) & OCCUPIED != 0
    }

    /// The truth of `cell` as raster flags: [`OCCUPIED`], or [`FREE`]
    /// with [`CLEAR`] when the robot's body fits there.
    fn flags(&self, cell: CellIndex) -> u8 {
        let centre = self.centre(cell);
        // One query serves both tests. `min_distance` returns its limit
        // when no wall is nearer, so the limit must exceed the touch
        // distance for that test to mean anything; at the robot radius the
        // limit itself reads as "no wall nearer", which is what clear asks.
        let limit = (2.0 * self.touch).max(self.robot_radius);
        let nearest = self.walls.min_distance(centre, limit);
        if nearest <= self.touch || !self.is_free(centre) {
            OCCUPIED
        } else if nearest >= self.robot_radius {
            FREE | CLEAR
        } else {
            FREE
        }
    }

    /// The truth of every cell over the world's bounds plus one cell each
    /// side (so that both sides of an outer wall are judged); every cell
    /// beyond lies outside the bounds, hence occupied, and is never
    /// surface or reachable.
    fn raster(&self) -> Result<Grid, MappingError> {
        let (min, max) = self.world.bounds();
        let low = self.resolution.cell_of(min.x, min.y)?;
        let high = self.resolution.cell_of(max.x, max.y)?;
        let origin = CellIndex::new(low.x.saturating_sub(1), low.y.saturating_sub(1));
        let last = CellIndex::new(high.x.saturating_add(1), high.y.saturating_add(1));
        let width = (i64::from(last.x) - i64::from(origin.x) + 1) as u64;
        let height = (i64::from(last.y) - i64::from(origin.y) + 1) as u64;
        if width.saturating_mul(height) > MAX_TRUTH_CELLS {
            return Err(MappingError::invalid(
                "world",
                format!(
                    "{} spans {width} x {height} cells at {} m, more than the {MAX_TRUTH_CELLS} judged at most",
                    self.world.name(),
                    self.resolution.metres()
                ),
            ));
        }
        let (width, height) = (width as usize, height as usize);
        let mut flags = vec![0u8; width * height];
        for (i, flag) in flags.iter_mut().enumerate() {
            // Within the box checked above, so within i32.
            let cell = CellIndex::new(origin.x + (i % width) as i32, origin.y + (i / width) as i32);
            *flag = self.flags(cell);
        }
        Ok(Grid {
            origin,
            width,
            height,
            flags,
        })
    }
}

/// Truth-occupied.
const OCCUPIED: u8 = 1;
/// Truth-free.
const FREE: u8 = 2;
/// Truth-free with room for the robot.
const CLEAR: u8 = 4;
/// Clear and connected to a seed.
const REACHABLE: u8 = 8;
/// Free and connected to a reachable cell.
const VISIBLE: u8 = 16;
/// Occupied next to a visible cell.
const SURFACE: u8 = 32;

/// The ground truth rasterised over the world's bounds, one byte of flags
/// a cell, row-major from `origin`.
struct Grid {
    origin: CellIndex,
    width: usize,
    height: usize,
    flags: Vec<u8>,
}

impl Grid {
    fn index(&self, cell: CellIndex) -> Option<usize> {
        let x = usize::try_from(i64::from(cell.x) - i64::from(self.origin.x)).ok()?;
        let y = usize::try_from(i64::from(cell.y) - i64::from(self.origin.y)).ok()?;
        (x < self.width && y < self.height).then(|| y * self.width + x)
    }

    fn flags(&self, cell: CellIndex) -> Option<u8> {
        self.index(cell).map(|i| self.flags[i])
    }

    /// Whether `cell` is truth-occupied: from the raster inside it, from
    /// `truth` beyond.
    fn truth_occupied(&self, truth: &Truth<'_>, cell: CellIndex) -> bool {
        match self.flags(cell) {
            Some(flags) => flags & OCCUPIED != 0,
            None => truth.occupied(cell),
        }
    }

    fn cell(&self, index: usize) -> CellIndex {
        // Indices come from the raster, whose cells all have i32 indices.
        CellIndex::new(
            self.origin.x + (index % self.width) as i32,
            self.origin.y + (index / self.width) as i32,
        )
    }

    fn cells(&self) -> impl Iterator<Item = (CellIndex, u8)> + '_ {
        self.flags
            .iter()
            .enumerate()
            .map(|(i, &f)| (self.cell(i), f))
    }

    /// Indices of the 4 neighbours of `index` inside the grid.
    fn neighbours4(&self, index: usize) -> impl Iterator<Item = usize> + use<> {
        let (x, y, w, h) = (
            index % self.width,
            index / self.width,
            self.width,
            self.height,
        );
        [
            (x > 0).then(|| index - 1),
            (x + 1 < w).then(|| index + 1),
            (y > 0).then(|| index - w),
            (y + 1 < h).then(|| index + w),
        ]
        .into_iter()
        .flatten()
    }

    /// Marks `mark` on every cell with `through` reachable from `stack`
    /// through 4-neighbours (the starting cells are marked by the caller).
    fn flood(&mut self, mut stack: Vec<usize>, through: u8, mark: u8) {
        while let Some(index) = stack.pop() {
            for n in self.neighbours4(index) {
                let f = self.flags[n];
                if f & through != 0 && f & mark == 0 {
                    self.flags[n] |= mark;
                    stack.push(n);
                }
            }
        }
    }

    /// Marks the reachable cells from `seeds` (all clear cells if none);
    /// returns how many seeds started the fill.
    fn fill_reachable(&mut self, seeds: &[Point2], resolution: Resolution) -> u64 {
        if seeds.is_empty() {
            for f in &mut self.flags {
                if *f & CLEAR != 0 {
                    *f |= REACHABLE;
                }
            }
            return 0;
        }
        let mut starts = Vec::new();
        for seed in seeds {
            // A seed beyond the i32 range of cells lies far outside the
            // world: unused, like any seed without a clear cell.
            let Ok(cell) = resolution.cell_of(seed.x, seed.y) else {
                continue;
            };
            let clear = |c: CellIndex| self.index(c).filter(|&i| self.flags[i] & CLEAR != 0);
            let start = clear(cell).or_else(|| {
                block(cell)
                    .filter_map(|c| clear(c).map(|i| (c, i)))
                    .map(|(c, i)| {
                        let (x, y) = resolution.cell_center(c);
                        ((x - seed.x).hypot(y - seed.y), i)
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map(|(_, i)| i)
            });
            if let Some(i) = start {
                starts.push(i);
            }
        }
        let used = starts.len() as u64;
        for &i in &starts {
            self.flags[i] |= REACHABLE;
        }
        self.flood(starts, CLEAR, REACHABLE);
        used
    }

    /// Marks the visible cells (free, connected to a reachable one), then
    /// the surface cells (occupied, with a visible 8-neighbour).
    fn fill_visible(&mut self) {
        let mut starts = Vec::new();
        for (i, f) in self.flags.iter_mut().enumerate() {
            if *f & REACHABLE != 0 {
                *f |= VISIBLE;
                starts.push(i);
            }
        }
        self.flood(starts, FREE, VISIBLE);
        for i in 0..self.flags.len() {
            if self.flags[i] & OCCUPIED == 0 {
                continue;
            }
            let cell = self.cell(i);
            if block(cell).any(|n| self.flags(n).is_some_and(|f| f & VISIBLE != 0)) {
                self.flags[i] |= SURFACE;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    //! Worlds of 0.25 m cells (exact in binary), walls on cell edges, so
    //! every figure below is counted by hand.

    use std::collections::HashMap;

    use deog_grid::{ClampLimits, Tile, TileKey, TileSize};
    use deog_world::Polygon;

    use super::*;

    const FREE_RAW: i16 = -2000;
    const OCC_RAW: i16 = 2000;
    /// p ≈ 0.5: observed, between the thresholds.
    const UNCERTAIN_RAW: i16 = 0;

    fn res() -> Resolution {
        Resolution::new(0.25).unwrap()
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon {
        Polygon::rectangle(Point2::new(x0, y0), Point2::new(x1, y1))
    }

    /// A 3 x 2 m room (cells 0..=11 x 0..=7 inside) with a 0.5 x 0.5 m box
    /// at (1.0, 0.75)..(1.5, 1.25).
    ///
    /// Truth-occupied inside the room: the ring of cells along the walls
    /// (x = 0, x = 11, y = 0, y = 7) and the box's cells x 3..=6, y 2..=5
    /// (cells 3 and 6 touch the box's sides; (3, 2) and its like touch
    /// only its corner). Truth-free: x 1..=10, y 1..=6 minus the box, 44
    /// cells, each at least 0.375 m from every wall.
    fn room() -> World {
        World::new(
            "room",
            Some(rect(0.0, 0.0, 3.0, 2.0)),
            vec![rect(1.0, 0.75, 1.5, 1.25)],
        )
        .unwrap()
    }

    fn room_free(x: i32, y: i32) -> bool {
        (1..=10).contains(&x)
            && (1..=6).contains(&y)
            && !((3..=6).contains(&x) && (2..=5).contains(&y))
    }

    /// A 4 x 2 m room cut in two by a wall at x 2.0..2.5: the left room's
    /// free cells are x 1..=6, y 1..=6 (36), the right room's x 11..=14,
    /// y 1..=6 (24).
    fn two_rooms() -> World {
        World::new(
            "two-rooms",
            Some(rect(0.0, 0.0, 4.0, 2.0)),
            vec![rect(2.0, -0.5, 2.5, 2.5)],
        )
        .unwrap()
    }

    fn left_free(x: i32, y: i32) -> bool {
        (1..=6).contains(&x) && (1..=6).contains(&y)
    }

    fn right_free(x: i32, y: i32) -> bool {
        (11..=14).contains(&x) && (1..=6).contains(&y)
    }

    /// A map holding exactly `cells` (raw values), 8-cell tiles.
    fn map_of(cells: impl IntoIterator<Item = ((i32, i32), i16)>) -> TileMap {
        let size = TileSize::new(8).unwrap();
        let mut tiles: HashMap<TileKey, Vec<i16>> = HashMap::new();
        for ((x, y), raw) in cells {
            let (key, offset) = size.split(CellIndex::new(x, y));
            tiles
                .entry(key)
                .or_insert_with(|| vec![LogOdds::UNKNOWN_RAW; size.area()])[offset.index(size)] =
                raw;
        }
        let mut map = TileMap::new(res(), size, ClampLimits::NONE);
        for (key, raw) in tiles {
            let bytes: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
            map.insert(key, Tile::from_dense_bytes(size, &bytes).unwrap())
                .unwrap();
        }
        map
    }

    /// The truth of every cell in `xs` x `ys` as `free` says, written
    /// perfectly, with `edits` on top.
    fn perfect(
        xs: std::ops::RangeInclusive<i32>,
        ys: std::ops::RangeInclusive<i32>,
        free: impl Fn(i32, i32) -> bool,
        edits: &[((i32, i32), i16)],
    ) -> TileMap {
        let mut cells: HashMap<(i32, i32), i16> = HashMap::new();
        for y in ys {
            for x in xs.clone() {
                cells.insert((x, y), if free(x, y) { FREE_RAW } else { OCC_RAW });
            }
        }
        cells.extend(edits.iter().copied());
        map_of(cells)
    }

    fn judge(map: &TileMap, world: &World, seeds: &[Point2], radius: f64) -> MapQuality {
        map_quality(&QualityInput {
            map,
            world,
            seeds,
            robot_radius_m: radius,
        })
        .unwrap()
    }

    #[test]
    fn the_verdict_image_paints_each_cell_by_its_verdict() {
        let world = room();
        let map = map_of([
            ((1, 1), FREE_RAW),
            ((0, 0), OCC_RAW),
            ((2, 1), UNCERTAIN_RAW),
            ((1, 2), OCC_RAW),
            ((11, 0), FREE_RAW),
            ((0, 3), UNCERTAIN_RAW),
        ]);
        let image = verdict_image(&QualityInput::new(&map, &world)).unwrap();
        // The world's cells 0..=12 x 0..=8 and one more each side.
        assert_eq!((image.width, image.height), (15, 11));
        assert_eq!(image.min_cell, CellIndex::new(-1, -1));
        assert_eq!(image.rgb.len(), 15 * 11 * 3);
        let at = |x: i32, y: i32| {
            let (col, row) = ((x + 1) as usize, (9 - y) as usize);
            let i = 3 * (row * 15 + col);
            [image.rgb[i], image.rgb[i + 1], image.rgb[i + 2]]
        };
        assert_eq!(at(1, 1), Verdict::FreeAsFree.rgb());
        assert_eq!(at(0, 0), Verdict::OccupiedAsOccupied.rgb());
        assert_eq!(at(2, 1), Verdict::FreeAsUncertain.rgb());
        assert_eq!(at(1, 2), Verdict::FreeAsOccupied.rgb());
        assert_eq!(at(11, 0), Verdict::OccupiedAsFree.rgb());
        assert_eq!(at(0, 3), Verdict::OccupiedAsUncertain.rgb());
        // Never observed: the box's cell by its truth, a free cell, and
        // the cells beyond the walls.
        assert_eq!(at(4, 3), UNOBSERVED_OCCUPIED_RGB);
        assert_eq!(at(8, 4), UNOBSERVED_FREE_RGB);
        assert_eq!(at(-1, -1), UNOBSERVED_OCCUPIED_RGB);
        // The same cells as map_quality counts them.
        let q = judge(&map, &world, &[], 0.3);
        let c = q.confusion;
        assert_eq!(
            (c.free_as_free, c.occupied_as_occupied, c.free_as_uncertain),
            (1, 1, 1)
        );
        assert_eq!(
            (
                c.free_as_occupied,
                c.occupied_as_free,
                c.occupied_as_uncertain
            ),
            (1, 1, 1)
        );
        // Scaled: each pixel a square, in place.
        let big = image.scaled(3);
        assert_eq!((big.width, big.height), (45, 33));
        let big_at = |col: usize, row: usize| {
            let i = 3 * (row * 45 + col);
            [big.rgb[i], big.rgb[i + 1], big.rgb[i + 2]]
        };
        for (dc, dr) in [(0, 0), (2, 2), (1, 2)] {
            // Cell (2, 1): column 3, row 8 of the small image.
            assert_eq!(big_at(9 + dc, 24 + dr), Verdict::FreeAsUncertain.rgb());
        }
        assert_eq!(image.fit_factor(1000), 66);
        assert_eq!(image.fit_factor(10), 1);
        // The same refusals as map_quality.
        let empty = map_of([]);
        assert!(verdict_image(&QualityInput::new(&empty, &world)).is_err());
    }

    #[test]
    fn a_perfect_map_scores_one_everywhere() {
        let world = room();
        let map = perfect(0..=11, 0..=7, room_free, &[]);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.cells_observed(), 96);
        assert_eq!(q.fraction_correct(), 1.0);
        assert_eq!(q.cells_uncertain(), 0);
        assert_eq!((q.map_occupied, q.map_occupied_near_truth), (52, 52));
        assert_eq!(q.occupied_precision(), Some(1.0));
        // Walls: 8 + 8 + 10 + 10 cells of the ring, 12 of the box's 16
        // (its 4 inner cells see no free space).
        assert_eq!((q.surface_cells, q.surface_cells_found), (48, 48));
        assert_eq!(q.occupied_recall(), Some(1.0));
        assert_eq!((q.reachable_cells, q.reachable_cells_free), (44, 44));
        assert_eq!(q.coverage(), Some(1.0));
        assert_eq!(
            q.confusion,
            Confusion {
                free_as_free: 44,
                occupied_as_occupied: 52,
                ..Confusion::default()
            }
        );
    }

    #[test]
    fn the_truth_holds_beyond_the_walls_and_at_corners() {
        // Everything from well outside the world to well past it: cells
        // outside the room or the raster are occupied, and the cells that
        // touch the box only at a corner ((3, 2), (6, 2), (3, 5), (6, 5))
        // are occupied too.
        let world = room();
        let map = perfect(-4..=16, -4..=12, room_free, &[]);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.cells_observed(), 21 * 17);
        assert_eq!(q.fraction_correct(), 1.0);
        assert_eq!(q.occupied_precision(), Some(1.0));
        assert_eq!(q.occupied_recall(), Some(1.0));
        assert_eq!(q.coverage(), Some(1.0));
    }

    #[test]
    fn one_wrong_cell_costs_exactly_one_cell() {
        let world = room();
        // (8, 3) is open floor, two cells from the box.
        let map = perfect(0..=11, 0..=7, room_free, &[((8, 3), OCC_RAW)]);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.cells_observed(), 96);
        assert_eq!(q.cells_correct(), 95);
        assert_eq!(q.fraction_correct(), 95.0 / 96.0);
        assert_eq!(q.confusion.free_as_occupied, 1);
        assert_eq!(q.occupied_precision(), Some(52.0 / 53.0));
        assert_eq!(q.occupied_recall(), Some(1.0));
        assert_eq!(q.coverage(), Some(43.0 / 44.0));

        // Next to the box, the same mistake is within one cell of a wall:
        // wrong, but not imprecise.
        let map = perfect(0..=11, 0..=7, room_free, &[((7, 3), OCC_RAW)]);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.fraction_correct(), 95.0 / 96.0);
        assert_eq!(q.occupied_precision(), Some(1.0));
    }

    #[test]
    fn an_uncertain_cell_is_never_right() {
        let world = room();
        let map = perfect(0..=11, 0..=7, room_free, &[((8, 3), UNCERTAIN_RAW)]);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.cells_observed(), 96);
        assert_eq!(q.cells_uncertain(), 1);
        assert_eq!(q.confusion.free_as_uncertain, 1);
        assert_eq!(q.fraction_correct(), 95.0 / 96.0);
        assert_eq!(q.occupied_precision(), Some(1.0));
        assert_eq!(q.coverage(), Some(43.0 / 44.0));
    }

    #[test]
    fn a_missing_wall_lowers_recall_by_the_cells_not_found_within_one_cell() {
        let world = room();
        // The right wall's inner cells mapped free: (11, 0) and (11, 7) are
        // corners, (11, 1) and (11, 6) still have a mapped corner cell
        // diagonally next to them, (11, 2..=5) have nothing.
        let edits: Vec<_> = (0..=7).map(|y| ((11, y), FREE_RAW)).collect();
        let map = perfect(0..=11, 0..=7, room_free, &edits);
        let q = judge(&map, &world, &[], 0.3);
        assert_eq!(q.fraction_correct(), 88.0 / 96.0);
        assert_eq!(q.confusion.occupied_as_free, 8);
        assert_eq!(q.occupied_precision(), Some(1.0));
        assert_eq!((q.surface_cells, q.surface_cells_found), (48, 44));
        assert_eq!(q.occupied_recall(), Some(44.0 / 48.0));
    }

    #[test]
    fn seeds_choose_the_space_a_robot_could_reach() {
        let world = two_rooms();
        let free = |x, y| left_free(x, y) || right_free(x, y);
        // Only the left room is mapped.
        let map = perfect(0..=7, 0..=7, free, &[]);
        let left = Point2::new(0.8, 1.0);
        let right = Point2::new(3.0, 1.0);

        let q = judge(&map, &world, &[], 0.3);
        assert_eq!((q.seeds_given, q.seeds_used), (0, 0));
        assert_eq!((q.reachable_cells, q.reachable_cells_free), (60, 36));
        // The right room's walls count too: 8 + 8 + 4 + 4 cells unseen.
        assert_eq!((q.surface_cells, q.surface_cells_found), (52, 28));

        let q = judge(&map, &world, &[left], 0.3);
        assert_eq!((q.seeds_given, q.seeds_used), (1, 1));
        assert_eq!(q.coverage(), Some(1.0));
        // The left room's walls: x = 0, x = 7 (8 each), y = 0, y = 7 (6 each).
        assert_eq!((q.surface_cells, q.surface_cells_found), (28, 28));

        let q = judge(&map, &world, &[left, right], 0.3);
        assert_eq!(q.seeds_used, 2);
        assert_eq!(q.reachable_cells, 60);

        // A wider robot keeps 0.4 m off the walls: cells 2..=5 both ways.
        let q = judge(&map, &world, &[left], 0.4);
        assert_eq!((q.reachable_cells, q.reachable_cells_free), (16, 16));
        // A seed whose own cell is too near the wall starts from the
        // nearest clear neighbour.
        let q = judge(&map, &world, &[Point2::new(0.49, 0.55)], 0.4);
        assert_eq!((q.seeds_used, q.reachable_cells), (1, 16));

        // A seed inside the dividing wall or far away starts nothing.
        let q = judge(
            &map,
            &world,
            &[Point2::new(2.25, 1.0), Point2::new(1e12, 0.0)],
            0.3,
        );
        assert_eq!((q.seeds_given, q.seeds_used), (2, 0));
        assert_eq!(q.reachable_cells, 0);
        assert_eq!(q.coverage(), None);
        assert_eq!(q.occupied_recall(), None);
        assert_eq!(q.fraction_correct(), 1.0);
    }

    #[test]
    fn undefined_figures_are_none_and_null() {
        let world = room();
        // One free cell: no occupied cell to be precise about.
        let map = map_of([((8, 3), FREE_RAW)]);
        let q = judge(
            &map,
            &world,
            &[Point2::new(2.25, 0.5), Point2::new(-5.0, -5.0)],
            0.3,
        );
        assert_eq!(q.occupied_precision(), None);
        assert_eq!(q.occupied_recall(), Some(0.0));
        assert_eq!(q.coverage(), Some(1.0 / 44.0));
        let json = q.to_json();
        assert!(json.contains("\"occupied_precision\": null,"), "{json}");
        assert!(json.contains("\"fraction_correct\": 1,"), "{json}");
        assert!(json.contains("\"seeds_used\": 1,"), "{json}");
        assert!(json.contains("\"free_as_free\": 1,"), "{json}");
        let table = q.table();
        assert!(
            table.contains("| occupied precision (±1 cell) | n/a | 0 of 0 |"),
            "{table}"
        );
        assert!(
            table.contains("| coverage of reachable free space | 0.0227 | 1 of 44 |"),
            "{table}"
        );
        assert!(table.contains("| free | 1 | 0 | 0 |"), "{table}");
    }

    #[test]
    fn bad_input_is_an_error() {
        let world = room();
        let empty = map_of([]);
        let err = map_quality(&QualityInput::new(&empty, &world)).unwrap_err();
        assert!(err.to_string().contains("no observed cell"), "{err}");
        // Cells written but never observed are no better.
        let unknown = map_of([((3, 3), LogOdds::UNKNOWN_RAW)]);
        assert!(map_quality(&QualityInput::new(&unknown, &world)).is_err());

        let map = map_of([((8, 3), FREE_RAW)]);
        for radius in [f64::NAN, -0.1, f64::INFINITY, 1e3] {
            let input = QualityInput {
                robot_radius_m: radius,
                ..QualityInput::new(&map, &world)
            };
            let err = map_quality(&input).unwrap_err();
            assert!(err.to_string().contains("robot_radius_m"), "{err}");
        }
        let seeds = [Point2::new(1.0, 1.0), Point2::new(f64::NAN, 0.0)];
        let input = QualityInput {
            seeds: &seeds,
            ..QualityInput::new(&map, &world)
        };
        let err = map_quality(&input).unwrap_err();
        assert!(err.to_string().contains("seeds[1]"), "{err}");

        // 0.1 mm cells over a 3 x 2 m room: 6e8 cells, refused.
        let fine = Resolution::new(1e-4).unwrap();
        let mut tiny = TileMap::new(fine, TileSize::new(8).unwrap(), ClampLimits::NONE);
        let bytes: Vec<u8> = [FREE_RAW; 64]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        tiny.insert(
            TileKey::new(0, 0),
            Tile::from_dense_bytes(TileSize::new(8).unwrap(), &bytes).unwrap(),
        )
        .unwrap();
        let err = map_quality(&QualityInput::new(&tiny, &world)).unwrap_err();
        assert!(err.to_string().contains("cells"), "{err}");
    }

    #[test]
    fn the_truth_uses_the_worlds_own_free_space() {
        let office =
            deog_world::parse_world(include_str!("../../worlds/office.toml"), "office.toml")
                .unwrap();
        for world in [room(), two_rooms(), office] {
            let truth = Truth::new(&world, res(), 0.2);
            let (min, max) = world.bounds();
            // Every 0.125 m, on the walls and obstacle edges of the test
            // worlds too, and a little past the bounds.
            let steps = |lo: f64, hi: f64| {
                let n = ((hi - lo) / 0.125) as i32 + 8;
                (-4..n).map(move |k| lo + f64::from(k) * 0.125)
            };
            for y in steps(min.y, max.y) {
                for x in steps(min.x, max.x) {
                    let p = Point2::new(x, y);
                    assert_eq!(
                        truth.is_free(p),
                        world.is_free(p),
                        "{} {x} {y}",
                        world.name()
                    );
                }
            }
        }
    }
}
