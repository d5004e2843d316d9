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
//! - `observed_occupied_recall`: the same over the surface cells with an
//!   observed cell within one cell: of the walls the map looked at, the
//!   share it holds as walls (a wall it erased counts, one no robot came
//!   near does not);
//! - `coverage`: reachable cells the map classifies free over all
//!   reachable cells.
//!
//! A map with no observed cell is an error: there is nothing to judge. A
//! figure whose denominator is zero otherwise (no map-occupied cell, no
//! surface, nothing reachable) is `None`, `null` in JSON.

use deog_grid::{CellIndex, LogOdds, OccupancyThresholds, SCOUT_BODY_RADIUS_M, TileMap};
use deog_world::{Point2, World};

use crate::error::EvaluationError;
use truth::{REACHABLE, SURFACE, Truth, TruthRaster};
pub use verdict::{
    UNOBSERVED_FREE_RGB, UNOBSERVED_OCCUPIED_RGB, VERDICT_MAX_SIDE_PX, Verdict, VerdictImage,
    verdict_image, verdict_png,
};

/// Probability above which a map cell is occupied (map_server's default).
pub const OCCUPIED_ABOVE: f64 = OccupancyThresholds::DEFAULT_OCCUPIED;
/// Probability below which a map cell is free (map_server's default).
pub const FREE_BELOW: f64 = OccupancyThresholds::DEFAULT_FREE;
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
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
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
    /// Surface cells with an observed cell within one cell.
    pub surface_cells_observed: u64,
    /// Of those, the ones with a map-occupied cell within one cell.
    pub surface_cells_observed_found: u64,
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

    /// Observed surface cells found within one cell, over surface cells
    /// with an observed cell within one cell; `None` when the map observed
    /// no surface.
    pub fn observed_occupied_recall(&self) -> Option<f64> {
        ratio(
            self.surface_cells_observed_found,
            self.surface_cells_observed,
        )
    }

    /// Reachable cells mapped free, over reachable cells; `None` when
    /// nothing is reachable.
    pub fn coverage(&self) -> Option<f64> {
        ratio(self.reachable_cells_free, self.reachable_cells)
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
pub fn map_quality(input: &QualityInput<'_>) -> Result<MapQuality, EvaluationError> {
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
        surface_cells_observed: 0,
        surface_cells_observed_found: 0,
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
            let found = block(cell).any(|n| class_at(n) == Some(Class::Occupied));
            quality.surface_cells_found += u64::from(found);
            if block(cell).any(|n| class_at(n).is_some()) {
                quality.surface_cells_observed += 1;
                quality.surface_cells_observed_found += u64::from(found);
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
fn judged_truth<'a>(
    input: &QualityInput<'a>,
) -> Result<(Truth<'a>, TruthRaster, u64), EvaluationError> {
    let radius = input.robot_radius_m;
    if !(radius.is_finite() && (0.0..=MAX_ROBOT_RADIUS_M).contains(&radius)) {
        return Err(EvaluationError::invalid(
            "robot_radius_m",
            format!("must be within 0 to {MAX_ROBOT_RADIUS_M} m, got {radius}"),
        ));
    }
    for (i, seed) in input.seeds.iter().enumerate() {
        if !(seed.x.is_finite() && seed.y.is_finite()) {
            return Err(EvaluationError::invalid(
                format!("seeds[{i}]"),
                format!("not finite: ({}, {})", seed.x, seed.y),
            ));
        }
    }
    if input.map.observed_count() == 0 {
        return Err(EvaluationError::invalid(
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
) -> Result<(), EvaluationError> {
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

mod report;
pub use report::MapQualityRecord;
mod truth;
mod verdict;

#[cfg(test)]
mod tests;
