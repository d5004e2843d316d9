//! Precomputed expected sonar ranges: for every cell of a tile and every
//! one of [`ConeGeometry::headings`] headings, the range a sonar centred on
//! that cell would read, as the nearest echo inside its cone.
//!
//! A table is built from an [`OccupancyRaster`] that covers the tile and
//! everything within the sonar's range of it. For each cell,
//! [`ConeGeometry::rays`] rays leave its centre at equal angles; each
//! marches over the raster, skipping ahead by the Euclidean distance field
//! where the nearest wall is far (sphere tracing) and cell by cell where it
//! is near, to the first occupied cell. A ray's range is the distance from
//! the centre to the nearest point of that cell, as [`deog_grid::cast_cone`]
//! measures it. A heading's expected range is the least range of the rays
//! within the cone's half-angle of it: the nearest echo in the cone,
//! moved [`ConeGeometry::surface_depth`] on to where the surface likely is.
//!
//! Ranges are stored as whole millimetres in a `u16`: [`NO_ECHO`] when no
//! occupied cell lies within the maximum range, 0 for a cell that is itself
//! occupied (a sensor inside a wall). Each cell's headings are followed by
//! its first again, so interpolation never wraps. One tile of 64 × 64 cells
//! and 120 headings takes 968 KiB.
//!
//! [`expected_range_by_marching`] is the plain reference: one cone, each
//! ray walked cell by cell, nothing precomputed.

use deog_grid::{CellBox, CellIndex, Occupancy, OccupancyView, Resolution};

use crate::error::{LocalizerError, within};

/// Stored range meaning no echo within the maximum range.
pub const NO_ECHO: u16 = u16::MAX;

/// The sonar cone and the angular resolution of the tables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeGeometry {
    /// Half the cone's opening angle, radians.
    pub half_angle: f64,
    /// The largest range the sonar reports, metres.
    pub max_range: f64,
    /// Headings per full turn stored for each cell.
    pub headings: usize,
    /// Rays cast per heading step (the rays are `headings · rays_per_heading`
    /// per full turn).
    pub rays_per_heading: usize,
    /// Sonar is specular: a wall struck more than this far from its normal
    /// (radians) sends the sound away, and that ray brings no echo (another
    /// ray of the cone may still). `None`: every wall echoes. The wall's
    /// normal is the distance field's gradient just before the hit.
    pub specular_max_incidence: Option<f64>,
    /// Metres added to every echo's range: how far past the near face of
    /// the first occupied cell a ray meets the surface that echoes. In the
    /// sonar maps the cartographer builds that cell usually stands in
    /// front of the surface: region I of the sonar model reaches its
    /// tolerance (5 cm) short of the reading, so the free cell before a
    /// wall is marked occupied too. 0 measures to the cell's near face.
    pub surface_depth: f64,
}

impl Default for ConeGeometry {
    /// The Scout's sonar (15° half-angle, 10.668 m), headings every 3°,
    /// rays every 1°, on a map the cartographer built (surfaces a cell,
    /// 5 cm, behind the first occupied cell's near face: measured best,
    /// BENCHMARKS.md, localization).
    fn default() -> Self {
        Self {
            half_angle: 15f64.to_radians(),
            max_range: 10.668,
            headings: 120,
            rays_per_heading: 3,
            specular_max_incidence: None,
            surface_depth: 0.05,
        }
    }
}

impl ConeGeometry {
    /// The geometry if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("half_angle", self.half_angle, 1e-3, 1.4)?;
        within("max_range", self.max_range, 0.1, 60.0)?;
        within("surface_depth", self.surface_depth, 0.0, 1.0)?;
        if let Some(angle) = self.specular_max_incidence {
            within(
                "specular_max_incidence",
                angle,
                0.0,
                std::f64::consts::FRAC_PI_2,
            )?;
        }
        if !(4..=1024).contains(&self.headings) || !(1..=16).contains(&self.rays_per_heading) {
            return Err(LocalizerError::Invalid(format!(
                "headings must be in [4, 1024] and rays_per_heading in [1, 16], got {} and {}",
                self.headings, self.rays_per_heading
            )));
        }
        Ok(self)
    }

    /// Rays per full turn.
    pub fn rays(&self) -> usize {
        self.headings * self.rays_per_heading
    }

    /// Cells a table reaches beyond its tile on every side.
    pub fn margin_cells(&self, res: Resolution) -> i32 {
        (self.max_range / res.metres()).ceil() as i32 + 2
    }

    /// Entries per cell in a table: every heading, then the first again,
    /// so that interpolating between neighbouring headings never wraps.
    pub fn stride(&self) -> usize {
        self.headings + 1
    }

    /// Bytes of one tile's table.
    pub fn table_bytes(&self, tile_area: usize) -> usize {
        tile_area * self.stride() * std::mem::size_of::<u16>()
    }
}

/// Occupied cells of a rectangle of the map, with a distance field.
#[derive(Debug, Clone)]
pub struct OccupancyRaster {
    bounds: CellBox,
    width: usize,
    height: usize,
    occupied: Vec<bool>,
    /// Distance from each cell's centre to the nearest occupied cell's
    /// centre, in cells.
    distance: Vec<f32>,
    /// The squared distances while the field is computed.
    squared: Vec<f64>,
}

impl OccupancyRaster {
    /// A raster of `bounds` with each cell's occupancy from `occupied`.
    pub fn new(bounds: CellBox, occupied: impl FnMut(CellIndex) -> bool) -> Self {
        let mut raster = Self {
            bounds,
            width: 0,
            height: 0,
            occupied: Vec::new(),
            distance: Vec::new(),
            squared: Vec::new(),
        };
        raster.refill(bounds, occupied);
        raster
    }

    /// Makes this the raster of `bounds`, in the memory it already holds
    /// where that is enough: a cache building one batch after another
    /// would otherwise allocate and free megabytes a batch.
    pub fn refill(&mut self, bounds: CellBox, mut occupied: impl FnMut(CellIndex) -> bool) {
        self.bounds = bounds;
        self.width = bounds.width() as usize;
        self.height = bounds.height() as usize;
        self.occupied.clear();
        for y in 0..self.height {
            for x in 0..self.width {
                self.occupied.push(occupied(CellIndex::new(
                    bounds.min.x + x as i32,
                    bounds.min.y + y as i32,
                )));
            }
        }
        distance_field(
            &self.occupied,
            self.width,
            self.height,
            &mut self.squared,
            &mut self.distance,
        );
    }

    /// Bytes the raster holds.
    pub fn held_bytes(&self) -> usize {
        self.occupied.capacity()
            + self.distance.capacity() * std::mem::size_of::<f32>()
            + self.squared.capacity() * std::mem::size_of::<f64>()
    }

    /// The cells the raster covers.
    pub fn bounds(&self) -> CellBox {
        self.bounds
    }

    /// The distance from `cell`'s centre to the nearest occupied cell's
    /// centre within the raster, in cells (exact; very large when none
    /// is); `None` outside the raster.
    pub fn distance_cells(&self, cell: CellIndex) -> Option<f32> {
        let x = i64::from(cell.x) - i64::from(self.bounds.min.x);
        let y = i64::from(cell.y) - i64::from(self.bounds.min.y);
        self.slot(x, y).map(|s| self.distance[s])
    }

    /// The unit normal of the nearest wall seen from free cell `(x, y)`:
    /// the distance field's gradient by central differences; `None` where
    /// it vanishes (a corner's diagonal, or cells at the raster's edge).
    fn normal_at(&self, x: i64, y: i64) -> Option<(f64, f64)> {
        let d = |x: i64, y: i64| self.slot(x, y).map(|s| f64::from(self.distance[s]));
        let gx = d(x + 1, y)? - d(x - 1, y)?;
        let gy = d(x, y + 1)? - d(x, y - 1)?;
        let norm = gx.hypot(gy);
        (norm > 1e-6).then(|| (gx / norm, gy / norm))
    }

    #[inline]
    fn slot(&self, x: i64, y: i64) -> Option<usize> {
        (x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height)
            .then(|| y as usize * self.width + x as usize)
    }
}

/// The expected ranges of every cell of `tile` (row-major, each cell's
/// headings together), from `raster`, which must cover `tile` widened by
/// [`ConeGeometry::margin_cells`]; cells of the margin it lacks count as free.
pub fn build_table(
    raster: &OccupancyRaster,
    tile: CellBox,
    res: Resolution,
    geometry: &ConeGeometry,
) -> Box<[u16]> {
    let mut table = vec![0; tile.width() as usize * tile.height() as usize * geometry.stride()];
    fill_table(raster, tile, res, geometry, &mut table);
    table.into_boxed_slice()
}

/// One tile's table in memory of its own, mapped from the system and
/// returned to it when dropped. A cache that dropped and built tables of a
/// megabyte each on the heap would leave the allocator holding freed
/// pieces between its other allocations, and the process would grow past
/// what the cache holds.
#[derive(Debug)]
pub struct RangeTable {
    memory: memmap2::MmapMut,
    len: usize,
}

impl RangeTable {
    /// A table of `len` entries, all zero.
    pub fn zeroed(len: usize) -> Result<Self, LocalizerError> {
        let bytes = len.max(1) * std::mem::size_of::<u16>();
        let memory = memmap2::MmapMut::map_anon(bytes).map_err(|e| {
            LocalizerError::Invalid(format!("mapping {bytes} bytes for a range table: {e}"))
        })?;
        Ok(Self { memory, len })
    }

    /// [`build_table`] into memory of its own.
    pub fn build(
        raster: &OccupancyRaster,
        tile: CellBox,
        res: Resolution,
        geometry: &ConeGeometry,
    ) -> Result<Self, LocalizerError> {
        let mut table =
            Self::zeroed(tile.width() as usize * tile.height() as usize * geometry.stride())?;
        fill_table(raster, tile, res, geometry, &mut table);
        Ok(table)
    }
}

impl std::ops::Deref for RangeTable {
    type Target = [u16];

    fn deref(&self) -> &[u16] {
        // Page-aligned memory of at least `len` entries.
        &bytemuck::cast_slice(&self.memory[..])[..self.len]
    }
}

impl std::ops::DerefMut for RangeTable {
    fn deref_mut(&mut self) -> &mut [u16] {
        &mut bytemuck::cast_slice_mut(&mut self.memory[..])[..self.len]
    }
}

/// Writes [`build_table`]'s entries into `table` (one [`ConeGeometry::stride`]
/// a cell of `tile`, row-major; entries past the tile's are left alone).
pub fn fill_table(
    raster: &OccupancyRaster,
    tile: CellBox,
    res: Resolution,
    geometry: &ConeGeometry,
    table: &mut [u16],
) {
    let rays = geometry.rays();
    let directions: Vec<(f64, f64)> = (0..rays)
        .map(|j| {
            let a = j as f64 * std::f64::consts::TAU / rays as f64;
            (a.cos(), a.sin())
        })
        .collect();
    let cell_m = res.metres();
    let max_cells = geometry.max_range / cell_m;
    // Rays on each side of a heading that lie inside the cone.
    let step = std::f64::consts::TAU / rays as f64;
    let reach = (geometry.half_angle / step + 1e-9).floor() as i64;
    let mut ray_ranges = vec![f32::INFINITY; rays];
    let cos_cutoff = geometry.specular_max_incidence.map(f64::cos);
    let mut entries = table.chunks_exact_mut(geometry.stride());
    for cy in tile.min.y..=tile.max.y {
        for cx in tile.min.x..=tile.max.x {
            let Some(entry) = entries.next() else {
                return;
            };
            let rx = i64::from(cx) - i64::from(raster.bounds.min.x);
            let ry = i64::from(cy) - i64::from(raster.bounds.min.y);
            if raster.slot(rx, ry).is_some_and(|s| raster.occupied[s]) {
                entry.fill(0);
                continue;
            }
            let origin = (rx as f64 + 0.5, ry as f64 + 0.5);
            for (range, dir) in ray_ranges.iter_mut().zip(&directions) {
                *range = march(raster, origin, *dir, max_cells, cos_cutoff);
            }
            let (headings, wrap) = entry.split_at_mut(geometry.headings);
            for (h, slot) in headings.iter_mut().enumerate() {
                let centre = (h * geometry.rays_per_heading) as i64;
                let mut nearest = f32::INFINITY;
                for j in centre - reach..=centre + reach {
                    nearest = nearest.min(ray_ranges[j.rem_euclid(rays as i64) as usize]);
                }
                *slot = to_millimetres(
                    f64::from(nearest) * cell_m + geometry.surface_depth,
                    geometry.max_range,
                );
            }
            if let (Some(last), Some(first)) = (wrap.first_mut(), headings.first()) {
                *last = *first;
            }
        }
    }
}

/// A range in metres as stored: whole millimetres, [`NO_ECHO`] past `max_range`.
fn to_millimetres(range: f64, max_range: f64) -> u16 {
    if range.is_finite() && range <= max_range {
        (range * 1000.0).round().min(f64::from(NO_ECHO - 1)) as u16
    } else {
        NO_ECHO
    }
}

/// The distance in cells from `origin` (raster coordinates, cells) along
/// `dir` to the nearest point of the first occupied cell, or infinity if
/// none lies within `max_cells`, or if the ray strikes it with an incidence
/// whose cosine is below `cos_cutoff` (a specular reflection).
fn march(
    raster: &OccupancyRaster,
    origin: (f64, f64),
    dir: (f64, f64),
    max_cells: f64,
    cos_cutoff: Option<f64>,
) -> f32 {
    let mut t = 0.0f64;
    let mut last_free = None;
    loop {
        let (px, py) = (origin.0 + t * dir.0, origin.1 + t * dir.1);
        // Off the raster's low edges the ray has left it; elsewhere a cast
        // is the floor, without a libm call on baseline x86-64.
        if px < 0.0 || py < 0.0 {
            return f32::INFINITY;
        }
        let (ix, iy) = (px as i64, py as i64);
        let Some(slot) = raster.slot(ix, iy) else {
            return f32::INFINITY;
        };
        let (cx, cy) = (ix as f64, iy as f64);
        if raster.occupied[slot] {
            if let (Some(cutoff), Some((fx, fy))) = (cos_cutoff, last_free)
                && let Some((nx, ny)) = raster.normal_at(fx, fy)
                && -(dir.0 * nx + dir.1 * ny) < cutoff
            {
                return f32::INFINITY;
            }
            let gap_x = ((cx + 0.5 - origin.0).abs() - 0.5).max(0.0);
            let gap_y = ((cy + 0.5 - origin.1).abs() - 0.5).max(0.0);
            return (gap_x * gap_x + gap_y * gap_y).sqrt() as f32;
        }
        last_free = Some((ix, iy));
        // No occupied square comes closer than the distance between centres
        // less a cell's diagonal (half from each square).
        let clear = f64::from(raster.distance[slot]) - std::f64::consts::SQRT_2;
        if clear > 1.0 {
            t += clear;
        } else {
            // Step to the next cell boundary the ray crosses.
            let to_x = boundary(px, cx, dir.0);
            let to_y = boundary(py, cy, dir.1);
            t += to_x.min(to_y) + 1e-6;
        }
        if t > max_cells {
            return f32::INFINITY;
        }
    }
}

#[inline]
fn boundary(pos: f64, cell: f64, dir: f64) -> f64 {
    if dir > 1e-12 {
        (cell + 1.0 - pos) / dir
    } else if dir < -1e-12 {
        (cell - pos) / dir
    } else {
        f64::INFINITY
    }
}

/// Exact Euclidean distance from every cell to the nearest occupied cell,
/// in cells (Felzenszwalb and Huttenlocher's two-pass transform); a large
/// value where nothing is occupied.
fn distance_field(
    occupied: &[bool],
    width: usize,
    height: usize,
    squared: &mut Vec<f64>,
    distance: &mut Vec<f32>,
) {
    const FAR: f64 = 1e12;
    squared.clear();
    squared.extend(occupied.iter().map(|&o| if o { 0.0 } else { FAR }));
    let longest = width.max(height);
    let mut line = vec![0.0; longest];
    let mut out = vec![0.0; longest];
    let mut hull = vec![0usize; longest];
    let mut bounds = vec![0.0; longest + 1];
    for x in 0..width {
        for y in 0..height {
            line[y] = squared[y * width + x];
        }
        transform_line(&line[..height], &mut out[..height], &mut hull, &mut bounds);
        for y in 0..height {
            squared[y * width + x] = out[y];
        }
    }
    for y in 0..height {
        let row = &mut squared[y * width..(y + 1) * width];
        line[..width].copy_from_slice(row);
        transform_line(&line[..width], &mut out[..width], &mut hull, &mut bounds);
        row.copy_from_slice(&out[..width]);
    }
    distance.clear();
    distance.extend(squared.iter().map(|d| d.sqrt() as f32));
}

/// One dimension of the squared distance transform: `out[q] = min_p (q − p)² + f[p]`.
fn transform_line(f: &[f64], out: &mut [f64], hull: &mut [usize], bounds: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    hull[0] = 0;
    bounds[0] = f64::NEG_INFINITY;
    bounds[1] = f64::INFINITY;
    let intersect = |q: usize, p: usize| -> f64 {
        let (qf, pf) = (q as f64, p as f64);
        ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * qf - 2.0 * pf)
    };
    for q in 1..n {
        let mut s = intersect(q, hull[k]);
        while s <= bounds[k] {
            if k == 0 {
                break;
            }
            k -= 1;
            s = intersect(q, hull[k]);
        }
        if s <= bounds[k] {
            // Only reachable with k == 0: q replaces the first parabola.
            hull[0] = q;
            bounds[0] = f64::NEG_INFINITY;
            bounds[1] = f64::INFINITY;
            continue;
        }
        k += 1;
        hull[k] = q;
        bounds[k] = s;
        bounds[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, slot) in out.iter_mut().enumerate() {
        while bounds[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - hull[k] as f64;
        *slot = d * d + f[hull[k]];
    }
}

/// The plain reference: the range a sonar at `(x, y)` heading `heading`
/// would read, by walking each of the cone's rays (as many as the table
/// uses) cell by cell from the sensor, with nothing precomputed. `None` for
/// no echo.
pub fn expected_range_by_marching(
    view: &impl OccupancyView,
    res: Resolution,
    geometry: &ConeGeometry,
    x: f64,
    y: f64,
    heading: f64,
) -> Option<f64> {
    let cell_m = res.metres();
    let (ox, oy) = (x / cell_m, y / cell_m);
    if view.occupancy(CellIndex::new(ox.floor() as i32, oy.floor() as i32)) == Occupancy::Occupied {
        return Some(0.0);
    }
    let step = std::f64::consts::TAU / geometry.rays() as f64;
    let reach = (geometry.half_angle / step + 1e-9).floor() as i64;
    let max_cells = geometry.max_range / cell_m;
    let mut nearest = f64::INFINITY;
    for j in -reach..=reach {
        let a = heading + j as f64 * step;
        let dir = (a.cos(), a.sin());
        let mut t = 0.0f64;
        while t <= max_cells.min(nearest) {
            let (px, py) = (ox + t * dir.0, oy + t * dir.1);
            let (cx, cy) = (px.floor(), py.floor());
            if view.occupancy(CellIndex::new(cx as i32, cy as i32)) == Occupancy::Occupied {
                let gap_x = ((cx + 0.5 - ox).abs() - 0.5).max(0.0);
                let gap_y = ((cy + 0.5 - oy).abs() - 0.5).max(0.0);
                nearest = nearest.min(gap_x.hypot(gap_y));
                break;
            }
            t += boundary(px, cx, dir.0).min(boundary(py, cy, dir.1)) + 1e-6;
        }
    }
    let range = nearest * cell_m + geometry.surface_depth;
    (range <= geometry.max_range).then_some(range)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;
    use std::collections::HashSet;

    struct Cells(HashSet<CellIndex>);

    impl OccupancyView for Cells {
        fn occupancy(&self, cell: CellIndex) -> Occupancy {
            if self.0.contains(&cell) {
                Occupancy::Occupied
            } else {
                Occupancy::Free
            }
        }
    }

    fn raster_of(cells: &Cells, bounds: CellBox) -> OccupancyRaster {
        OccupancyRaster::new(bounds, |c| cells.0.contains(&c))
    }

    fn cell_box(x0: i32, y0: i32, x1: i32, y1: i32) -> CellBox {
        CellBox::new(CellIndex::new(x0, y0), CellIndex::new(x1, y1)).unwrap()
    }

    #[test]
    fn a_refilled_raster_is_the_raster_of_its_new_bounds() {
        let walls = |c: CellIndex| (c.x + 2 * c.y) % 7 == 0;
        let mut reused = OccupancyRaster::new(cell_box(-5, -5, 40, 30), walls);
        for bounds in [cell_box(0, 0, 9, 6), cell_box(-3, 2, 20, 25)] {
            reused.refill(bounds, walls);
            let fresh = OccupancyRaster::new(bounds, walls);
            assert_eq!(reused.bounds, fresh.bounds);
            assert_eq!(reused.occupied, fresh.occupied);
            assert_eq!(reused.distance, fresh.distance);
        }
    }

    #[test]
    fn distance_field_is_euclidean() {
        let (w, h) = (9, 7);
        let mut occ = vec![false; w * h];
        occ[3 * w + 4] = true;
        occ[0] = true;
        let (mut squared, mut d) = (Vec::new(), Vec::new());
        distance_field(&occ, w, h, &mut squared, &mut d);
        for y in 0..h {
            for x in 0..w {
                let to_a = ((x as f64 - 4.0).powi(2) + (y as f64 - 3.0).powi(2)).sqrt();
                let to_b = ((x as f64).powi(2) + (y as f64).powi(2)).sqrt();
                assert_abs_diff_eq!(f64::from(d[y * w + x]), to_a.min(to_b), epsilon = 1e-5);
            }
        }
    }

    /// The default geometry measuring to the first occupied cell's near
    /// face, as the exact figures below are worked out.
    fn near_face() -> ConeGeometry {
        ConeGeometry {
            surface_depth: 0.0,
            ..ConeGeometry::default()
        }
    }

    #[test]
    fn surface_depth_moves_echoes_only() {
        // The wall of `wall_ahead_reads_its_distance`: with the default
        // depth every echo reads 5 cm farther; no echo stays no echo, and
        // a sensor inside the wall still reads 0.
        let res = Resolution::DEFAULT;
        let mut set: HashSet<CellIndex> = (-200..=200).map(|y| CellIndex::new(40, y)).collect();
        set.insert(CellIndex::new(3, 3));
        let cells = Cells(set);
        let deep = ConeGeometry::default();
        assert_abs_diff_eq!(deep.surface_depth, 0.05);
        let margin = deep.margin_cells(res);
        let raster = raster_of(&cells, cell_box(-margin, -margin, 3 + margin, 3 + margin));
        let tile = cell_box(0, 0, 3, 3);
        let near = build_table(&raster, tile, res, &near_face());
        let far = build_table(&raster, tile, res, &deep);
        for (a, b) in near.iter().zip(far.iter()) {
            match *a {
                NO_ECHO => assert_eq!(*b, NO_ECHO),
                0 => assert_eq!(*b, 0),
                a => assert!(b.abs_diff(a + 50) <= 1, "{a} mm became {b} mm"),
            }
        }
        assert_eq!(far[0], 2025);
        let reference = expected_range_by_marching(&cells, res, &deep, 0.025, 0.025, 0.0);
        assert_abs_diff_eq!(reference.unwrap(), 2.025, epsilon = 1e-9);
        assert!(
            ConeGeometry {
                surface_depth: -0.01,
                ..deep
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn wall_ahead_reads_its_distance() {
        // A wall of cells at x = 40 (2.00 m to 2.05 m); a sensor in cell 0
        // (centre 0.025 m) facing +x reads 2.0 - 0.025 = 1.975 m.
        let res = Resolution::DEFAULT;
        let wall = Cells((-200..=200).map(|y| CellIndex::new(40, y)).collect());
        let geometry = near_face();
        let margin = geometry.margin_cells(res);
        let tile = cell_box(0, 0, 3, 3);
        let raster = raster_of(&wall, cell_box(-margin, -margin, 3 + margin, 3 + margin));
        let table = build_table(&raster, tile, res, &geometry);
        assert_eq!(table.len(), 16 * geometry.stride());
        // Cell (0, 0), heading 0: the nearest point of the wall straight ahead.
        assert_eq!(table[0], 1975);
        // Heading 180°: nothing within 10.668 m.
        assert_eq!(table[geometry.headings / 2], NO_ECHO);
        // Heading 30°: the cone (15° to 45°) meets the wall first at 15°:
        // 1.975 / cos 15° = 2.045 m, within a ray's spacing.
        let h30 = geometry.headings / 12;
        let expected = 1.975 / 15f64.to_radians().cos();
        assert_abs_diff_eq!(f64::from(table[h30]) / 1000.0, expected, epsilon = 0.01);
    }

    #[test]
    fn specular_walls_answer_only_near_their_normal() {
        // The wall of `wall_ahead_reads_its_distance`, with echoes lost past
        // 40° of incidence: straight ahead it still answers; at 60° off its
        // normal (a cone from 45° to 75°) it does not.
        let res = Resolution::DEFAULT;
        let wall = Cells((-400..=400).map(|y| CellIndex::new(40, y)).collect());
        let geometry = ConeGeometry {
            specular_max_incidence: Some(40f64.to_radians()),
            ..near_face()
        };
        let margin = geometry.margin_cells(res);
        let raster = raster_of(&wall, cell_box(-margin, -margin, margin, margin));
        let table = build_table(&raster, cell_box(0, 0, 0, 0), res, &geometry);
        assert_eq!(table[0], 1975);
        assert_eq!(table[geometry.headings / 6], NO_ECHO);
        // 30°: the cone's near edge (15°) still meets the wall within 40°.
        let h30 = geometry.headings / 12;
        assert_abs_diff_eq!(
            f64::from(table[h30]) / 1000.0,
            1.975 / 15f64.to_radians().cos(),
            epsilon = 0.01
        );
        assert!(
            ConeGeometry {
                specular_max_incidence: Some(2.0),
                ..geometry
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn occupied_cells_read_zero() {
        let res = Resolution::DEFAULT;
        let cells = Cells([CellIndex::new(1, 1)].into_iter().collect());
        let geometry = near_face();
        let m = geometry.margin_cells(res);
        let raster = raster_of(&cells, cell_box(-m, -m, 3 + m, 3 + m));
        let table = build_table(&raster, cell_box(0, 0, 3, 3), res, &geometry);
        let at = |x: usize, y: usize, h: usize| table[(y * 4 + x) * geometry.stride() + h];
        assert_eq!(at(1, 1, 0), 0);
        // Its neighbour to the left sees it at 0 m (touching squares).
        assert_eq!(at(0, 1, 0), 25);
        assert!(at(3, 3, 0) != 0);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// The table, built with distance-field skipping, agrees with the
        /// plain cell-by-cell reference for random clutter.
        #[test]
        fn table_matches_the_reference(
            blocks in prop::collection::vec((-60i32..60, -60i32..60, 1i32..6, 1i32..6), 1..25),
            cell_x in 0i32..8, cell_y in 0i32..8, heading in 0usize..120,
        ) {
            let res = Resolution::DEFAULT;
            let mut set = HashSet::new();
            for (x, y, w, h) in blocks {
                for dx in 0..w { for dy in 0..h { set.insert(CellIndex::new(x + dx, y + dy)); } }
            }
            let cells = Cells(set);
            let geometry = ConeGeometry { max_range: 3.0, ..ConeGeometry::default() };
            let m = geometry.margin_cells(res);
            let raster = raster_of(&cells, cell_box(-m, -m, 7 + m, 7 + m));
            let table = build_table(&raster, cell_box(0, 0, 7, 7), res, &geometry);
            let got = table[(cell_y as usize * 8 + cell_x as usize) * geometry.stride() + heading];
            let (cx, cy) = res.cell_center(CellIndex::new(cell_x, cell_y));
            let angle = heading as f64 * std::f64::consts::TAU / geometry.headings as f64;
            let reference = expected_range_by_marching(&cells, res, &geometry, cx, cy, angle);
            match reference {
                None => prop_assert_eq!(got, NO_ECHO),
                Some(r) => prop_assert!((f64::from(got) / 1000.0 - r).abs() <= 0.0011,
                    "table {} mm, reference {} m", got, r),
            }
        }
    }
}
