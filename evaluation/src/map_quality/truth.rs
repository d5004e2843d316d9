//! The ground truth of a world's cells at a map's resolution: which are
//! occupied, and which a robot could reach, see and map the walls of.

use std::f64::consts::FRAC_1_SQRT_2;

use deog_grid::{CellIndex, Resolution};
use deog_world::{Point2, SegmentIndex, World};

use super::{MAX_TRUTH_CELLS, TOUCH_SLACK, block};
use crate::error::EvaluationError;

/// The ground-truth rule of one cell: the world, its walls indexed, and
/// the cell geometry.
pub(super) struct Truth<'a> {
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
    pub(super) fn new(world: &'a World, resolution: Resolution, robot_radius: f64) -> Self {
        Self {
            world,
            walls: SegmentIndex::new(world.walls()),
            resolution,
            obstacle_boxes: world.obstacles().iter().map(|o| o.bounds()).collect(),
            touch: resolution.metres() * FRAC_1_SQRT_2 * (1.0 + TOUCH_SLACK),
            robot_radius,
        }
    }

    pub(super) fn centre(&self, cell: CellIndex) -> Point2 {
        let (x, y) = self.resolution.cell_center(cell);
        Point2::new(x, y)
    }

    /// [`World::is_free`], with each obstacle's bounding box tested before
    /// its polygon: a large world has many obstacles and a raster many
    /// cells, and most cells are far from most obstacles. The box test is
    /// inclusive, so a point on an obstacle's edge gets the polygon's own
    /// answer, exactly as `World::is_free` gives it (a test checks the two
    /// agree).
    pub(super) fn is_free(&self, p: Point2) -> bool {
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
    pub(super) fn occupied(&self, cell: CellIndex) -> bool {
        self.flags(cell) & OCCUPIED != 0
    }

    /// The truth of `cell` as raster flags: [`OCCUPIED`], or [`FREE`]
    /// with [`CLEAR`] when the robot's body fits there.
    pub(super) fn flags(&self, cell: CellIndex) -> u8 {
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
    pub(super) fn raster(&self) -> Result<TruthRaster, EvaluationError> {
        let (min, max) = self.world.bounds();
        let low = self.resolution.cell_of(min.x, min.y)?;
        let high = self.resolution.cell_of(max.x, max.y)?;
        let origin = CellIndex::new(low.x.saturating_sub(1), low.y.saturating_sub(1));
        let last = CellIndex::new(high.x.saturating_add(1), high.y.saturating_add(1));
        let width = (i64::from(last.x) - i64::from(origin.x) + 1) as u64;
        let height = (i64::from(last.y) - i64::from(origin.y) + 1) as u64;
        if width.saturating_mul(height) > MAX_TRUTH_CELLS {
            return Err(EvaluationError::invalid(
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
        Ok(TruthRaster {
            origin,
            width,
            height,
            flags,
        })
    }
}

/// Truth-occupied.
pub(super) const OCCUPIED: u8 = 1;
/// Truth-free.
pub(super) const FREE: u8 = 2;
/// Truth-free with room for the robot.
pub(super) const CLEAR: u8 = 4;
/// Clear and connected to a seed.
pub(super) const REACHABLE: u8 = 8;
/// Free and connected to a reachable cell.
pub(super) const VISIBLE: u8 = 16;
/// Occupied next to a visible cell.
pub(super) const SURFACE: u8 = 32;

/// The ground truth rasterised over the world's bounds, one byte of flags
/// a cell, row-major from `origin`.
pub(super) struct TruthRaster {
    pub(super) origin: CellIndex,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) flags: Vec<u8>,
}

impl TruthRaster {
    pub(super) fn index(&self, cell: CellIndex) -> Option<usize> {
        let x = usize::try_from(i64::from(cell.x) - i64::from(self.origin.x)).ok()?;
        let y = usize::try_from(i64::from(cell.y) - i64::from(self.origin.y)).ok()?;
        (x < self.width && y < self.height).then(|| y * self.width + x)
    }

    pub(super) fn flags(&self, cell: CellIndex) -> Option<u8> {
        self.index(cell).map(|i| self.flags[i])
    }

    /// Whether `cell` is truth-occupied: from the raster inside it, from
    /// `truth` beyond.
    pub(super) fn truth_occupied(&self, truth: &Truth<'_>, cell: CellIndex) -> bool {
        match self.flags(cell) {
            Some(flags) => flags & OCCUPIED != 0,
            None => truth.occupied(cell),
        }
    }

    pub(super) fn cell(&self, index: usize) -> CellIndex {
        // Indices come from the raster, whose cells all have i32 indices.
        CellIndex::new(
            self.origin.x + (index % self.width) as i32,
            self.origin.y + (index / self.width) as i32,
        )
    }

    pub(super) fn cells(&self) -> impl Iterator<Item = (CellIndex, u8)> + '_ {
        self.flags
            .iter()
            .enumerate()
            .map(|(i, &f)| (self.cell(i), f))
    }

    /// Indices of the 4 neighbours of `index` inside the grid.
    pub(super) fn neighbours4(&self, index: usize) -> impl Iterator<Item = usize> + use<> {
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
    pub(super) fn flood(&mut self, mut stack: Vec<usize>, through: u8, mark: u8) {
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
    pub(super) fn fill_reachable(&mut self, seeds: &[Point2], resolution: Resolution) -> u64 {
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
    pub(super) fn fill_visible(&mut self) {
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
