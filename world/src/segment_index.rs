//! A uniform grid of buckets over a world's walls, so that "which walls are
//! near this point" costs the walls nearby, not every wall of the world.
//!
//! Each wall is listed in every bucket of its cell bounding box (a diagonal
//! wall is listed in a few buckets it does not touch; that only makes it a
//! candidate early, never missed). A query walks the buckets of its square
//! in rings of growing Chebyshev distance from the query's cell, and visits a
//! wall in exactly one of them: the first cell of its box the walk reaches
//! ([`SegmentIndex::visit_outward`] says which). That rule needs no per-query
//! "seen" stamps, so queries allocate nothing, take `&self`, and the index is
//! `Sync`: many robots on many threads can share one.

use std::ops::ControlFlow;

use crate::error::WorldError;
use crate::geometry::{Point2, Segment};

/// The default bucket size, metres: about a Scout's diameter times two, so
/// a room holds a few buckets and a bucket a few walls.
pub const DEFAULT_CELL_SIZE_M: f64 = 1.0;

/// At most this many buckets; a larger world gets larger buckets, so memory
/// stays bounded whatever the world's extent.
const MAX_CELLS: f64 = (1u64 << 22) as f64;

/// Cell coordinates of the query point are clamped to this magnitude so that
/// ring arithmetic on a point far outside the world cannot overflow.
const MAX_CELL_COORD: f64 = (1u64 << 40) as f64;

/// One wall listed in one bucket, with its cell bounding box (inclusive) to
/// decide which bucket visits it.
#[derive(Debug, Clone, Copy)]
struct Entry {
    wall: usize,
    lo: (i64, i64),
    hi: (i64, i64),
}

/// An inclusive rectangle of cells.
#[derive(Debug, Clone, Copy)]
struct CellRect {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

impl CellRect {
    #[inline]
    fn intersect(&self, lo: (i64, i64), hi: (i64, i64)) -> CellRect {
        CellRect {
            x0: self.x0.max(lo.0),
            y0: self.y0.max(lo.1),
            x1: self.x1.min(hi.0),
            y1: self.y1.min(hi.1),
        }
    }
}

/// What [`SegmentIndex::visit_outward`] reports, nearest buckets first.
#[derive(Debug, Clone, Copy)]
pub enum Visit<'a> {
    /// A wall that may be within the query's radius, given once per query.
    Wall(&'a Segment),
    /// Every wall not yet given lies farther than this from the query's
    /// centre (metres), or farther than its radius.
    Cleared(f64),
}

/// Walls bucketed on a uniform grid, for nearest-wall and sonar queries.
#[derive(Debug, Clone)]
pub struct SegmentIndex {
    walls: Vec<Segment>,
    origin: Point2,
    cell: f64,
    inv_cell: f64,
    cols: i64,
    rows: i64,
    /// Bucket `y * cols + x` holds `entries[starts[i]..starts[i + 1]]`.
    starts: Vec<usize>,
    entries: Vec<Entry>,
    /// Whether every wall is a face with free space on its left
    /// ([`SegmentIndex::of_world`]).
    one_sided: bool,
}

impl SegmentIndex {
    /// Indexes `walls` with buckets of [`DEFAULT_CELL_SIZE_M`]. A wall with
    /// a non-finite coordinate is left out: it has no place on the grid, and
    /// a world's walls never have one ([`crate::Polygon`] checks).
    pub fn new(walls: Vec<Segment>) -> Self {
        Self::build(walls, DEFAULT_CELL_SIZE_M)
    }

    /// Indexes a world's walls as faces ([`crate::World::faces`]), each
    /// with free space on its left, so that a query may tell a surface
    /// seen from its free side from one seen through solid matter
    /// ([`SegmentIndex::one_sided`]).
    pub fn of_world(world: &crate::World) -> Self {
        Self {
            one_sided: true,
            ..Self::new(world.faces())
        }
    }

    /// Whether every wall is a face with free space on its left (an index
    /// [`SegmentIndex::of_world`]); `false`: walls with no known free side,
    /// seen alike from both.
    pub fn one_sided(&self) -> bool {
        self.one_sided
    }

    /// Indexes `walls` with buckets of about `cell_size` metres (more if the
    /// world would need over 4 M buckets), leaving out non-finite walls.
    /// Errors on a cell size that is not finite or under 1 mm.
    pub fn with_cell_size(walls: Vec<Segment>, cell_size: f64) -> Result<Self, WorldError> {
        if !(cell_size.is_finite() && cell_size >= 1e-3) {
            return Err(WorldError::invalid(
                "cell_size",
                format!("must be a finite number of metres >= 0.001, got {cell_size}"),
            ));
        }
        Ok(Self::build(walls, cell_size))
    }

    /// The index, for a valid `cell_size`.
    fn build(walls: Vec<Segment>, cell_size: f64) -> Self {
        let finite = |p: Point2| p.x.is_finite() && p.y.is_finite();
        let walls: Vec<Segment> = walls
            .into_iter()
            .filter(|w| finite(w.a) && finite(w.b))
            .collect();
        let mut min = Point2::new(f64::INFINITY, f64::INFINITY);
        let mut max = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
        for w in &walls {
            for p in [w.a, w.b] {
                min = Point2::new(min.x.min(p.x), min.y.min(p.y));
                max = Point2::new(max.x.max(p.x), max.y.max(p.y));
            }
        }
        if walls.is_empty() {
            min = Point2::new(0.0, 0.0);
            max = min;
        }
        let (width, height) = (max.x - min.x, max.y - min.y);
        let mut cell = cell_size;
        while ((width / cell).floor() + 1.0) * ((height / cell).floor() + 1.0) > MAX_CELLS {
            cell *= 2.0;
        }
        let inv_cell = 1.0 / cell;
        // Both at most MAX_CELLS, so the conversions are exact.
        let cols = (width * inv_cell).floor() as i64 + 1;
        let rows = (height * inv_cell).floor() as i64 + 1;
        let mut index = Self {
            walls: Vec::new(),
            origin: min,
            cell,
            inv_cell,
            cols,
            rows,
            starts: Vec::new(),
            entries: Vec::new(),
            one_sided: false,
        };

        let boxes: Vec<((i64, i64), (i64, i64))> = walls
            .iter()
            .map(|w| {
                let lo = Point2::new(w.a.x.min(w.b.x), w.a.y.min(w.b.y));
                let hi = Point2::new(w.a.x.max(w.b.x), w.a.y.max(w.b.y));
                (index.cell_of(lo), index.cell_of(hi))
            })
            .collect();
        // Counting sort into one flat array: one allocation, buckets contiguous.
        let buckets = (cols * rows) as usize;
        let mut counts = vec![0usize; buckets + 1];
        for (lo, hi) in &boxes {
            for y in lo.1..=hi.1 {
                for x in lo.0..=hi.0 {
                    counts[(y * cols + x) as usize + 1] += 1;
                }
            }
        }
        for i in 0..buckets {
            counts[i + 1] += counts[i];
        }
        let total = counts[buckets];
        let mut fill = counts.clone();
        let mut entries = vec![
            Entry {
                wall: 0,
                lo: (0, 0),
                hi: (0, 0)
            };
            total
        ];
        for (wall, &(lo, hi)) in boxes.iter().enumerate() {
            for y in lo.1..=hi.1 {
                for x in lo.0..=hi.0 {
                    let slot = &mut fill[(y * cols + x) as usize];
                    entries[*slot] = Entry { wall, lo, hi };
                    *slot += 1;
                }
            }
        }
        index.walls = walls;
        index.starts = counts;
        index.entries = entries;
        index
    }

    /// The walls, in the order given.
    pub fn walls(&self) -> &[Segment] {
        &self.walls
    }

    /// The bucket size in use, metres.
    pub fn cell_size(&self) -> f64 {
        self.cell
    }

    /// Calls `f` once for every wall that may lie within `radius` of
    /// `center` (some may be farther). Visits nothing for a non-finite
    /// centre or a NaN or negative radius.
    pub fn for_each_near(&self, center: Point2, radius: f64, mut f: impl FnMut(&Segment)) {
        self.visit_outward(center, radius, |visit| {
            if let Visit::Wall(w) = visit {
                f(w);
            }
            ControlFlow::Continue(())
        });
    }

    /// The distance from `p` to the nearest wall, or `limit` if no wall is
    /// nearer. NaN for a non-finite `p`; a NaN `limit` means no limit.
    pub fn min_distance(&self, p: Point2, limit: f64) -> f64 {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return f64::NAN;
        }
        let limit = if limit.is_nan() {
            f64::INFINITY
        } else {
            limit.max(0.0)
        };
        let mut best2 = limit * limit;
        self.visit_outward(p, limit, |visit| match visit {
            Visit::Wall(w) => {
                best2 = best2.min(distance2(w, p));
                ControlFlow::Continue(())
            }
            // Nothing unvisited can beat the best: stop walking outwards.
            Visit::Cleared(d) if d * d >= best2 => ControlFlow::Break(()),
            Visit::Cleared(_) => ControlFlow::Continue(()),
        });
        best2.sqrt().min(limit)
    }

    /// Walks the buckets within `radius` of `center` in rings of growing
    /// distance, giving `f` each wall that may be within `radius` once
    /// ([`Visit::Wall`]) and, after each ring, how far the walk has
    /// [`Visit::Cleared`]. `f` stops the walk by returning `Break`.
    ///
    /// A wall is given in the first ring that reaches a cell of its
    /// bounding box, so a wall is never given later than a ring containing
    /// any of its points: this is what makes `Cleared` a true bound.
    pub fn visit_outward<'a>(
        &'a self,
        center: Point2,
        radius: f64,
        mut f: impl FnMut(Visit<'a>) -> ControlFlow<()>,
    ) {
        let Some(q) = self.query_rect(center, radius) else {
            return;
        };
        let cx = ((center.x - self.origin.x) * self.inv_cell)
            .floor()
            .clamp(-MAX_CELL_COORD, MAX_CELL_COORD) as i64;
        let cy = ((center.y - self.origin.y) * self.inv_cell)
            .floor()
            .clamp(-MAX_CELL_COORD, MAX_CELL_COORD) as i64;
        let k_min = gap(q.x0, q.x1, cx).max(gap(q.y0, q.y1, cy));
        let k_max = (cx - q.x0)
            .abs()
            .max((q.x1 - cx).abs())
            .max((cy - q.y0).abs())
            .max((q.y1 - cy).abs());
        for k in k_min..=k_max {
            let y_lo = (cy - k).max(q.y0);
            let y_hi = (cy + k).min(q.y1);
            for y in y_lo..=y_hi {
                if (y - cy).abs() == k {
                    for x in (cx - k).max(q.x0)..=(cx + k).min(q.x1) {
                        if self.visit_bucket(x, y, &q, cx, cy, &mut f).is_break() {
                            return;
                        }
                    }
                } else {
                    for x in [cx - k, cx + k] {
                        // At k == 0 both are the same cell, handled above.
                        if x >= q.x0
                            && x <= q.x1
                            && self.visit_bucket(x, y, &q, cx, cy, &mut f).is_break()
                        {
                            return;
                        }
                    }
                }
            }
            // The square of rings 0..=k around (cx, cy): every point outside
            // it is at least this far from the centre.
            let left = self.origin.x + (cx - k) as f64 * self.cell;
            let right = self.origin.x + (cx + k + 1) as f64 * self.cell;
            let bottom = self.origin.y + (cy - k) as f64 * self.cell;
            let top = self.origin.y + (cy + k + 1) as f64 * self.cell;
            let cleared = (center.x - left)
                .min(right - center.x)
                .min(center.y - bottom)
                .min(top - center.y)
                .max(0.0);
            if f(Visit::Cleared(cleared)).is_break() {
                return;
            }
        }
    }

    /// Gives `f` the walls of bucket (x, y) whose designated cell it is.
    fn visit_bucket<'a>(
        &'a self,
        x: i64,
        y: i64,
        q: &CellRect,
        cx: i64,
        cy: i64,
        f: &mut impl FnMut(Visit<'a>) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let bucket = (y * self.cols + x) as usize;
        let range = self.starts[bucket]..self.starts[bucket + 1];
        for entry in &self.entries[range] {
            let spanned = entry.lo != entry.hi;
            if spanned && designated(q.intersect(entry.lo, entry.hi), cx, cy) != (x, y) {
                continue;
            }
            f(Visit::Wall(&self.walls[entry.wall]))?;
        }
        ControlFlow::Continue(())
    }

    /// The cell holding `p`, clamped to the grid.
    #[inline]
    fn cell_of(&self, p: Point2) -> (i64, i64) {
        let x = ((p.x - self.origin.x) * self.inv_cell).floor();
        let y = ((p.y - self.origin.y) * self.inv_cell).floor();
        (
            x.clamp(0.0, (self.cols - 1) as f64) as i64,
            y.clamp(0.0, (self.rows - 1) as f64) as i64,
        )
    }

    /// The grid's cells covering the square of half-side `radius` around
    /// `center`, or `None` when it misses the grid or the input is bad.
    #[inline]
    fn query_rect(&self, center: Point2, radius: f64) -> Option<CellRect> {
        if !(center.x.is_finite() && center.y.is_finite() && radius >= 0.0) || self.walls.is_empty()
        {
            return None;
        }
        let fx0 = ((center.x - radius - self.origin.x) * self.inv_cell).floor();
        let fx1 = ((center.x + radius - self.origin.x) * self.inv_cell).floor();
        let fy0 = ((center.y - radius - self.origin.y) * self.inv_cell).floor();
        let fy1 = ((center.y + radius - self.origin.y) * self.inv_cell).floor();
        let (last_x, last_y) = ((self.cols - 1) as f64, (self.rows - 1) as f64);
        if fx1 < 0.0 || fy1 < 0.0 || fx0 > last_x || fy0 > last_y {
            return None;
        }
        Some(CellRect {
            x0: fx0.max(0.0) as i64,
            y0: fy0.max(0.0) as i64,
            x1: fx1.min(last_x) as i64,
            y1: fy1.min(last_y) as i64,
        })
    }
}

/// How far `c` lies outside `lo..=hi`, in cells.
#[inline]
fn gap(lo: i64, hi: i64, c: i64) -> i64 {
    if c < lo {
        lo - c
    } else if c > hi {
        c - hi
    } else {
        0
    }
}

/// The cell of `r` (non-empty) that the ring walk around (cx, cy) visits a
/// wall in: of the cells of `r` in the nearest ring that meets `r`, the first
/// in row-major order. Any fixed choice in that ring would do; this one is
/// cheap to compute.
#[inline]
fn designated(r: CellRect, cx: i64, cy: i64) -> (i64, i64) {
    let k = gap(r.x0, r.x1, cx).max(gap(r.y0, r.y1, cy));
    let y = r.y0.max(cy - k);
    if (y - cy).abs() == k {
        // A top or bottom row of the ring: every cell of it counts.
        (r.x0.max(cx - k), y)
    } else if r.x0 <= cx - k && cx - k <= r.x1 {
        // A middle row: `r` lies wholly left or right of the ring's centre.
        (cx - k, y)
    } else {
        (cx + k, y)
    }
}

/// The squared distance from `p` to the wall `w`.
#[inline]
pub fn distance2(w: &Segment, p: Point2) -> f64 {
    let (dx, dy) = (w.b.x - w.a.x, w.b.y - w.a.y);
    let (px, py) = (p.x - w.a.x, p.y - w.a.y);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (px - t * dx, py - t * dy);
    ex * ex + ey * ey
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
        Segment::new(Point2::new(ax, ay), Point2::new(bx, by))
    }

    fn random_walls(rng: &mut ChaCha8Rng, n: usize) -> Vec<Segment> {
        (0..n)
            .map(|_| {
                let a = Point2::new(rng.random_range(-5.0..25.0), rng.random_range(-5.0..15.0));
                let len = if rng.random_bool(0.2) { 20.0 } else { 2.0 };
                let b = Point2::new(
                    a.x + rng.random_range(-len..len),
                    a.y + rng.random_range(-len..len),
                );
                Segment::new(a, b)
            })
            .collect()
    }

    #[test]
    fn a_long_wall_in_many_buckets_is_visited_once() {
        let walls = vec![seg(0.0, 0.0, 30.0, 0.0), seg(0.0, 0.0, 30.0, 20.0)];
        let index = SegmentIndex::new(walls);
        let mut seen = [0; 2];
        index.for_each_near(Point2::new(15.0, 5.0), 12.0, |w| {
            let i = index.walls().iter().position(|x| x == w).expect("a wall");
            seen[i] += 1;
        });
        assert_eq!(seen, [1, 1]);
    }

    #[test]
    fn visits_every_near_wall_exactly_once_from_anywhere() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let walls = random_walls(&mut rng, 300);
        let index = SegmentIndex::with_cell_size(walls.clone(), 0.7).expect("finite walls");
        for _ in 0..200 {
            let c = Point2::new(rng.random_range(-15.0..35.0), rng.random_range(-15.0..25.0));
            let radius = rng.random_range(0.0..12.0);
            let mut count = vec![0u32; walls.len()];
            index.for_each_near(c, radius, |w| {
                count[wall_id(&index, w)] += 1;
            });
            for (i, w) in walls.iter().enumerate() {
                assert!(count[i] <= 1, "wall {i} visited {} times", count[i]);
                if w.distance_to(c) <= radius {
                    assert_eq!(count[i], 1, "wall {i} within {radius} of {c:?} missed");
                }
            }
        }
    }

    /// Which of the index's walls `w` is (walls may repeat, so by address).
    fn wall_id(index: &SegmentIndex, w: &Segment) -> usize {
        (w as *const Segment as usize - index.walls().as_ptr() as usize) / size_of::<Segment>()
    }

    #[test]
    fn cleared_is_a_true_bound() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let walls = random_walls(&mut rng, 200);
        let index = SegmentIndex::new(walls.clone());
        for _ in 0..100 {
            let c = Point2::new(rng.random_range(-10.0..30.0), rng.random_range(-10.0..20.0));
            let radius = 11.0;
            let mut visited = vec![false; walls.len()];
            index.visit_outward(c, radius, |v| {
                match v {
                    Visit::Wall(w) => {
                        visited[wall_id(&index, w)] = true;
                    }
                    Visit::Cleared(d) => {
                        for (i, w) in walls.iter().enumerate() {
                            let dist = w.distance_to(c);
                            if !visited[i] && dist <= radius {
                                assert!(dist >= d - 1e-12, "unvisited wall at {dist} < {d}");
                            }
                        }
                    }
                }
                ControlFlow::Continue(())
            });
        }
    }

    #[test]
    fn min_distance_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let walls = random_walls(&mut rng, 150);
        let index = SegmentIndex::new(walls.clone());
        for _ in 0..500 {
            let p = Point2::new(rng.random_range(-10.0..30.0), rng.random_range(-10.0..20.0));
            let limit = rng.random_range(0.1..6.0);
            let brute = walls.iter().map(|w| w.distance_to(p)).fold(limit, f64::min);
            let fast = index.min_distance(p, limit);
            assert!((fast - brute).abs() < 1e-9, "{fast} vs {brute} at {p:?}");
        }
    }

    #[test]
    fn bad_input_is_an_error_or_visits_nothing() {
        let skipped =
            SegmentIndex::new(vec![seg(0.0, f64::NAN, 1.0, 1.0), seg(0.0, 0.0, 1.0, 0.0)]);
        assert_eq!(skipped.walls(), &[seg(0.0, 0.0, 1.0, 0.0)]);
        assert!(SegmentIndex::with_cell_size(vec![], 0.0).is_err());
        assert!(SegmentIndex::with_cell_size(vec![], f64::NAN).is_err());
        let index = SegmentIndex::new(vec![seg(0.0, 0.0, 1.0, 0.0)]);
        let mut n = 0;
        index.for_each_near(Point2::new(f64::NAN, 0.0), 5.0, |_| n += 1);
        index.for_each_near(Point2::new(0.0, 0.0), f64::NAN, |_| n += 1);
        index.for_each_near(Point2::new(0.0, 0.0), -1.0, |_| n += 1);
        assert_eq!(n, 0);
        assert!(index.min_distance(Point2::new(f64::NAN, 0.0), 1.0).is_nan());
        assert_eq!(index.min_distance(Point2::new(0.5, 3.0), 1.0), 1.0);
        let far = Point2::new(1e6, -1e6);
        assert_eq!(
            index.min_distance(far, f64::INFINITY),
            seg(0.0, 0.0, 1.0, 0.0).distance_to(far)
        );
        let empty = SegmentIndex::new(vec![]);
        assert_eq!(empty.min_distance(Point2::new(0.0, 0.0), 2.0), 2.0);
    }
}
