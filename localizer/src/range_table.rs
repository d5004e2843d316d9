//! Precomputed expected sonar ranges: for every cell of a tile and every
//! one of [`ConeGeometry::headings`] headings, the range a sonar centred on
//! that cell would read, as the nearest echo inside its cone.
//!
//! A table is built from an [`OccupancyRaster`] that covers the tile and
//! everything within the sonar's range of it. For each cell,
//! [`ConeGeometry::rays`] rays leave its centre at equal angles. A ray
//! marches over the raster, skipping ahead by the Euclidean distance field
//! where the nearest wall is far (sphere tracing) and cell by cell where it
//! is near, to the first occupied cell. A ray's range is the distance from
//! the centre to the nearest point of that cell, as [`deog_grid::cast_cone`]
//! measures it. A heading's expected range is the least range of the rays
//! within the cone's half-angle of it: the nearest echo in the cone,
//! moved [`ConeGeometry::surface_depth`] on to where the surface likely is.
//!
//! [`fill_table`] does not march each cell's rays: the rays of one
//! direction from every cell of the tile lie on parallel lines half a cell
//! apart, and one march along a line serves every cell on it up to the
//! first wall (a cell's ray moves sideways by at most a quarter of a
//! cell). That is 7.8 times quicker than [`fill_table_ray_by_ray`], which
//! marches each cell's own rays, and agrees with it to a centimetre in 93 %
//! of a furnished room's entries and to a cell in 99.5 % (BENCHMARKS.md).
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

/// [`ConeGeometry::surface_depth`] for a specular sonar's map, metres. The
/// cartographer maps such a sonar's readings by direction
/// (`deog_mapping::SonarMethod::Directional`), where the occupied cell
/// region I puts before a wall is freed only by readings from the side it
/// was heard from, which meet it in region I again: its walls stand
/// about a cell further out than a plain map's. Measured in `map2` with
/// `--sonar realistic` (20 seeds): 0.025 m gave a mean error after
/// convergence of 5.7 cm, 0.05 m 4.7 cm, 0.075 m 3.9 cm, 0.10 m 3.6 cm,
/// 0.125 m 3.8 cm, 0.15 m 4.5 cm (BENCHMARKS.md, localization).
pub const SPECULAR_SURFACE_DEPTH: f64 = 0.10;

impl ConeGeometry {
    /// The default geometry for a sonar that is specular past
    /// `max_incidence` radians (`None`: every wall echoes), on a map the
    /// cartographer built from its readings: a specular sonar's surfaces
    /// lie [`SPECULAR_SURFACE_DEPTH`] past the first occupied cell.
    pub fn for_sonar(max_incidence: Option<f64>) -> Self {
        let defaults = Self::default();
        Self {
            specular_max_incidence: max_incidence,
            surface_depth: if max_incidence.is_some() {
                SPECULAR_SURFACE_DEPTH
            } else {
                defaults.surface_depth
            },
            ..defaults
        }
    }

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

/// Lateral spacing, in cells, of the lines the rays of one direction share.
/// Each cell's ray is moved sideways onto the nearest line, at most a
/// quarter of a cell (1.25 cm at 5 cm cells): a tenth of what one degree
/// between a cone's rays spreads at a metre. One march along a line then
/// serves every cell on it up to the first wall, instead of one march a
/// cell.
const LINE_SPACING: f64 = 0.5;

/// Tile rows whose rays are gathered before their headings are reduced:
/// the scratch holds rows × width × rays squared gaps, 5.9 MB for a whole
/// tile of 64 × 64 cells and 360 rays, six times the table, and freed once
/// it is built (`deog bench localize-memory` stays within its budget).
/// Longer lines serve more cells: 16 rows took 40 % longer.
const STRIP_ROWS: i32 = 64;

/// Writes [`build_table`]'s entries into `table` (one [`ConeGeometry::stride`]
/// a cell of `tile`, row-major; entries past the tile's are left alone).
///
/// Rays of one direction are cast along shared lines (`LINE_SPACING`
/// apart) rather than one from each cell; [`fill_table_ray_by_ray`] casts
/// each cell's own, and the two agree but for rays that graze a corner.
pub fn fill_table(
    raster: &OccupancyRaster,
    tile: CellBox,
    res: Resolution,
    geometry: &ConeGeometry,
    table: &mut [u16],
) {
    let rays = geometry.rays();
    let directions = ray_directions(rays);
    let cast = Cast::new(res, geometry);
    let width = tile.width() as usize;
    let stride = geometry.stride();
    // Direction-major, so that a direction's casts write one run of memory
    // and each cone's minimum runs over whole rows of cells. The cones'
    // minima are taken over squared gaps and only each heading's nearest
    // is turned into millimetres: the conversion is monotonic, so that is
    // the same table with a third of the square roots.
    let mut strip_squared: Vec<f32> = Vec::new();
    let mut nearest: Vec<f32> = Vec::new();
    let mut ranges: Vec<u16> = Vec::new();
    let mut lines: Vec<SharedLine> = Vec::new();
    let mut free: Vec<bool> = Vec::new();
    let mut hits = StripHits::default();
    let mut first_row = tile.min.y;
    while first_row <= tile.max.y {
        let last_row = first_row.saturating_add(STRIP_ROWS - 1).min(tile.max.y);
        let strip = CellRect {
            x0: i64::from(tile.min.x) - i64::from(raster.bounds.min.x),
            y0: i64::from(first_row) - i64::from(raster.bounds.min.y),
            width,
            rows: (last_row - first_row + 1) as usize,
        };
        let cells = strip.width * strip.rows;
        strip_squared.clear();
        strip_squared.resize(cells * rays, f32::INFINITY);
        free.clear();
        free.extend((0..cells).map(|cell| {
            let (x, y) = (cell % strip.width, cell / strip.width);
            raster
                .slot(strip.x0 + x as i64, strip.y0 + y as i64)
                .is_none_or(|s| !raster.occupied[s])
        }));
        hits.centre(&strip);
        for (dir, squared) in directions.iter().zip(strip_squared.chunks_exact_mut(cells)) {
            cast.along_shared_lines(raster, &strip, &free, *dir, &mut lines, &mut hits);
            hits.squared_gaps(squared);
        }
        // A strip spans the tile's width: its cells are consecutive in
        // the table (which may hold fewer).
        let first = (first_row - tile.min.y) as usize * width * stride;
        let strip_table = table.get_mut(first..).unwrap_or_default();
        for h in 0..geometry.headings {
            nearest.clear();
            nearest.resize(cells, f32::INFINITY);
            let centre = (h * cast.rays_per_heading) as i64;
            let reach = cast.reach.min(rays / 2) as i64;
            for j in centre - reach..=centre + reach {
                let j = j.rem_euclid(rays as i64) as usize;
                let squared = &strip_squared[j * cells..(j + 1) * cells];
                for (n, &q) in nearest.iter_mut().zip(squared) {
                    // Not `f32::min`, whose care for NaN (there is none
                    // here) costs the vectorized loop three instructions.
                    *n = if q < *n { q } else { *n };
                }
            }
            ranges.clear();
            ranges.resize(cells, NO_ECHO);
            cast.store_gaps(&nearest, &mut ranges);
            for (entry, &range) in strip_table.chunks_exact_mut(stride).zip(&ranges) {
                entry[h] = range;
            }
        }
        for (entry, &free) in strip_table.chunks_exact_mut(stride).zip(&free) {
            if free {
                entry[geometry.headings] = entry[0];
            } else {
                entry.fill(0);
            }
        }
        first_row = last_row + 1;
    }
}

/// The reference for [`fill_table`]: each cell's own rays, every one
/// marched from the cell's centre. Slower by the number of cells a line
/// serves; kept so that the benchmark and the tests can hold the fast
/// build to it.
pub fn fill_table_ray_by_ray(
    raster: &OccupancyRaster,
    tile: CellBox,
    res: Resolution,
    geometry: &ConeGeometry,
    table: &mut [u16],
) {
    let rays = geometry.rays();
    let directions = ray_directions(rays);
    let cast = Cast::new(res, geometry);
    let mut ranges = vec![NO_ECHO; rays];
    let mut circle: Vec<u16> = Vec::with_capacity(rays + 2 * cast.reach);
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
            for (range, dir) in ranges.iter_mut().zip(&directions) {
                let nearest = match first_hit(raster, origin, *dir, cast.max_cells, cast.cos_cutoff)
                {
                    (_, Hit::Cell(x, y)) => gap_to_cell(origin, x, y),
                    _ => f64::INFINITY,
                };
                *range = cast.stored(nearest);
            }
            cast.nearest_in_cones(&ranges, &mut circle, entry);
        }
    }
}

/// `rays` unit vectors at equal angles, the first along +x.
fn ray_directions(rays: usize) -> Vec<(f64, f64)> {
    (0..rays)
        .map(|j| {
            let a = j as f64 * std::f64::consts::TAU / rays as f64;
            (a.cos(), a.sin())
        })
        .collect()
}

/// A rectangle of cells in raster coordinates.
struct CellRect {
    x0: i64,
    y0: i64,
    width: usize,
    rows: usize,
}

/// Per cell of a strip: its centre, and the centre of the occupied cell
/// its ray in the current direction meets first (infinitely far for no
/// echo). The casts record the hits one cell at a time, in the lines'
/// order; the gaps are then worked out for the whole strip in a loop the
/// compiler vectorizes.
#[derive(Debug, Default)]
struct StripHits {
    centre_x: Vec<f32>,
    centre_y: Vec<f32>,
    hit_x: Vec<f32>,
    hit_y: Vec<f32>,
}

impl StripHits {
    /// Sets the cells' centres (raster coordinates) for `strip`, and no
    /// hits.
    fn centre(&mut self, strip: &CellRect) {
        let cells = strip.width * strip.rows;
        self.centre_x.clear();
        self.centre_y.clear();
        for cell in 0..cells {
            let (x, y) = (cell % strip.width, cell / strip.width);
            self.centre_x.push((strip.x0 + x as i64) as f32 + 0.5);
            self.centre_y.push((strip.y0 + y as i64) as f32 + 0.5);
        }
        self.hit_x.clear();
        self.hit_x.resize(cells, f32::INFINITY);
        self.hit_y.clear();
        self.hit_y.resize(cells, f32::INFINITY);
    }

    /// Each cell's squared gap, in cells, from its centre to the nearest
    /// point of its hit cell. Single precision: exact to a thousandth of a
    /// millimetre at these ranges, and quicker.
    fn squared_gaps(&self, squared: &mut [f32]) {
        let cells = self
            .centre_x
            .iter()
            .zip(&self.centre_y)
            .zip(self.hit_x.iter().zip(&self.hit_y));
        for (q, ((&cx, &cy), (&hx, &hy))) in squared.iter_mut().zip(cells) {
            let (gap_x, gap_y) = ((hx - cx).abs() - 0.5, (hy - cy).abs() - 0.5);
            // Not `f32::max`: no NaN comes here (a hit is finite or
            // infinite), and its care for one costs instructions.
            let gap_x = if gap_x > 0.0 { gap_x } else { 0.0 };
            let gap_y = if gap_y > 0.0 { gap_y } else { 0.0 };
            *q = gap_x * gap_x + gap_y * gap_y;
        }
    }
}

/// One line's last march: cells whose projection on the line falls in
/// `[start, end)` (along the direction) see first the occupied cell
/// centred on `hit` (raster coordinates; infinitely far for no echo, so
/// that the gap needs no branch).
#[derive(Debug, Clone, Copy)]
struct SharedLine {
    start: f64,
    end: f64,
    hit: (f32, f32),
}

/// What a march along a ray meets first.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Hit {
    /// This occupied cell (raster coordinates) echoes.
    Cell(i64, i64),
    /// An occupied cell struck too far from its normal: no echo.
    Specular,
    /// Nothing within reach, or the ray left the raster.
    Nothing,
}

/// The figures every ray of a table shares, in cells.
struct Cast {
    cell_m: f64,
    max_cells: f64,
    max_range: f64,
    surface_depth: f64,
    cos_cutoff: Option<f64>,
    /// Rays on each side of a heading that lie inside the cone.
    reach: usize,
    rays_per_heading: usize,
    headings: usize,
}

impl Cast {
    fn new(res: Resolution, geometry: &ConeGeometry) -> Self {
        let cell_m = res.metres();
        let step = std::f64::consts::TAU / geometry.rays() as f64;
        Self {
            cell_m,
            max_cells: geometry.max_range / cell_m,
            max_range: geometry.max_range,
            surface_depth: geometry.surface_depth,
            cos_cutoff: geometry.specular_max_incidence.map(f64::cos),
            reach: (geometry.half_angle / step + 1e-9).floor() as usize,
            rays_per_heading: geometry.rays_per_heading,
            headings: geometry.headings,
        }
    }

    /// A ray's range in cells as stored: millimetres to the surface.
    fn stored(&self, cells: f64) -> u16 {
        to_millimetres(cells * self.cell_m + self.surface_depth, self.max_range)
    }

    /// Ranges as stored from squared gaps in cells (infinite: no echo).
    /// Kept apart from the casts in a loop of its own, which the compiler
    /// vectorizes: one square root a cell and direction is the hottest
    /// arithmetic of a table's build.
    fn store_gaps(&self, squared: &[f32], ranges: &mut [u16]) {
        let cell_mm = (self.cell_m * 1000.0) as f32;
        let depth_mm = (self.surface_depth * 1000.0) as f32;
        let max_mm = (self.max_range * 1000.0) as f32;
        for (range, &gap) in ranges.iter_mut().zip(squared) {
            let mm = gap.sqrt() * cell_mm + depth_mm;
            // Through i32, which converts four lanes at once.
            *range = if mm <= max_mm {
                (mm + 0.5).min(f32::from(NO_ECHO - 1)) as i32 as u16
            } else {
                NO_ECHO
            };
        }
    }

    /// Casts direction `dir` from every free cell of `strip`, calling
    /// `record(cell, stored range)` with the cell's row-major index in the
    /// strip. Cells are visited in an order in which, on each line, the
    /// position along `dir` only grows, so one march serves them all up to
    /// its hit.
    fn along_shared_lines(
        &self,
        raster: &OccupancyRaster,
        strip: &CellRect,
        free: &[bool],
        dir: (f64, f64),
        lines: &mut Vec<SharedLine>,
        hits: &mut StripHits,
    ) {
        let normal = (-dir.1, dir.0);
        let lateral = |x: f64, y: f64| x * normal.0 + y * normal.1;
        let (left, bottom) = (strip.x0 as f64 + 0.5, strip.y0 as f64 + 0.5);
        let (right, top) = (
            left + (strip.width - 1) as f64,
            bottom + (strip.rows - 1) as f64,
        );
        let corners = [
            lateral(left, bottom),
            lateral(right, bottom),
            lateral(left, top),
            lateral(right, top),
        ];
        let low = corners.iter().copied().fold(f64::INFINITY, f64::min) - LINE_SPACING / 2.0;
        let high = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let count = ((high - low) / LINE_SPACING).floor() as usize + 2;
        lines.clear();
        lines.resize(
            count,
            SharedLine {
                start: f64::INFINITY,
                end: f64::NEG_INFINITY,
                hit: (f32::INFINITY, f32::INFINITY),
            },
        );
        // Far enough that a line's march covers every cell of the strip on it.
        let limit = self.max_cells + (strip.width + strip.rows) as f64;
        let per_spacing = 1.0 / LINE_SPACING;
        let (step_x, step_y) = (
            if dir.0 >= 0.0 { 1 } else { -1 },
            if dir.1 >= 0.0 { 1 } else { -1 },
        );
        for row in 0..strip.rows {
            let sy = if step_y > 0 {
                row
            } else {
                strip.rows - 1 - row
            };
            let sx0 = if step_x > 0 { 0 } else { strip.width - 1 };
            let (rx0, ry) = (strip.x0 + sx0 as i64, strip.y0 + sy as i64);
            let (ox0, oy) = (rx0 as f64 + 0.5, ry as f64 + 0.5);
            // Stepping one cell along the row moves these by fixed amounts.
            let (mut across, mut along) = (lateral(ox0, oy) - low, ox0 * dir.0 + oy * dir.1);
            let (across_step, along_step) =
                (f64::from(step_x) * normal.0, f64::from(step_x) * dir.0);
            for column in 0..strip.width {
                let sx = if step_x > 0 {
                    column
                } else {
                    strip.width - 1 - column
                };
                let cell = sy * strip.width + sx;
                if free[cell] {
                    // `across` is never negative: the float unit's rounding
                    // rather than a saturating cast (a band's edge may go to
                    // either line, each within a quarter of a cell).
                    let k = (crate::numeric::cell_i32(across * per_spacing).max(0) as usize)
                        .min(count - 1);
                    let line = &mut lines[k];
                    if !(line.start <= along && along < line.end) {
                        let centre = low + (k as f64 + 0.5) * LINE_SPACING;
                        let from = (
                            centre * normal.0 + along * dir.0,
                            centre * normal.1 + along * dir.1,
                        );
                        let (t, hit) = first_hit(raster, from, dir, limit, self.cos_cutoff);
                        *line = SharedLine {
                            start: along,
                            end: along + t,
                            hit: match hit {
                                Hit::Cell(x, y) => (x as f32 + 0.5, y as f32 + 0.5),
                                Hit::Specular | Hit::Nothing => (f32::INFINITY, f32::INFINITY),
                            },
                        };
                    }
                    hits.hit_x[cell] = line.hit.0;
                    hits.hit_y[cell] = line.hit.1;
                }
                across += across_step;
                along += along_step;
            }
        }
    }

    /// Each heading's nearest echo: the least of the ray ranges within the
    /// cone's half-angle of it, into `entry` (every heading, then the
    /// first again). `circle` is scratch: the ranges with `reach` of them
    /// repeated at each end, so no window wraps.
    fn nearest_in_cones(&self, ranges: &[u16], circle: &mut Vec<u16>, entry: &mut [u16]) {
        let rays = ranges.len();
        let reach = self.reach.min(rays / 2);
        circle.clear();
        circle.extend_from_slice(&ranges[rays - reach..]);
        circle.extend_from_slice(ranges);
        circle.extend_from_slice(&ranges[..reach]);
        let (headings, wrap) = entry.split_at_mut(self.headings);
        for (h, slot) in headings.iter_mut().enumerate() {
            let centre = h * self.rays_per_heading + reach;
            *slot = circle[centre - reach..=centre + reach]
                .iter()
                .fold(NO_ECHO, |a, &b| a.min(b));
        }
        if let (Some(last), Some(first)) = (wrap.first_mut(), headings.first()) {
            *last = *first;
        }
    }
}

/// The distance in cells from `origin` to the nearest point of cell
/// `(x, y)` (raster coordinates).
fn gap_to_cell(origin: (f64, f64), x: i64, y: i64) -> f64 {
    let gap_x = ((x as f64 + 0.5 - origin.0).abs() - 0.5).max(0.0);
    let gap_y = ((y as f64 + 0.5 - origin.1).abs() - 0.5).max(0.0);
    (gap_x * gap_x + gap_y * gap_y).sqrt()
}

/// A range in metres as stored: whole millimetres, [`NO_ECHO`] past `max_range`.
fn to_millimetres(range: f64, max_range: f64) -> u16 {
    if range.is_finite() && range <= max_range {
        // Rounds a range that is never negative, without a libm call.
        (range * 1000.0 + 0.5).min(f64::from(NO_ECHO - 1)) as u16
    } else {
        NO_ECHO
    }
}

/// What a ray from `origin` (raster coordinates, cells) along `dir` meets
/// first, and how far along it that is (infinite for [`Hit::Nothing`]):
/// the first occupied cell within `limit` cells, or [`Hit::Specular`] if
/// the ray strikes it with an incidence whose cosine is below `cos_cutoff`.
fn first_hit(
    raster: &OccupancyRaster,
    origin: (f64, f64),
    dir: (f64, f64),
    limit: f64,
    cos_cutoff: Option<f64>,
) -> (f64, Hit) {
    let mut t = 0.0f64;
    let mut last_free = None;
    // Per axis: how far along the ray one cell takes it, and the
    // boundary the ray crosses next (the cell's far side): a multiply a
    // step rather than a division.
    let step_x = crossing(dir.0);
    let step_y = crossing(dir.1);
    loop {
        let (px, py) = (origin.0 + t * dir.0, origin.1 + t * dir.1);
        // Off the raster's low edges the ray has left it; elsewhere a cast
        // is the floor, without a libm call on baseline x86-64.
        if px < 0.0 || py < 0.0 {
            return (f64::INFINITY, Hit::Nothing);
        }
        let (ix, iy) = (px as i64, py as i64);
        let Some(slot) = raster.slot(ix, iy) else {
            return (f64::INFINITY, Hit::Nothing);
        };
        if raster.occupied[slot] {
            if let (Some(cutoff), Some((fx, fy))) = (cos_cutoff, last_free)
                && let Some((nx, ny)) = raster.normal_at(fx, fy)
                && -(dir.0 * nx + dir.1 * ny) < cutoff
            {
                return (t, Hit::Specular);
            }
            return (t, Hit::Cell(ix, iy));
        }
        last_free = Some((ix, iy));
        // No occupied square comes closer than the distance between centres
        // less a cell's diagonal (half from each square).
        let clear = f64::from(raster.distance[slot]) - std::f64::consts::SQRT_2;
        if clear > 1.0 {
            t += clear;
        } else {
            // Step to the next cell boundary the ray crosses, or further
            // where the clearance allows.
            let to_x = step_x.to_boundary(px, ix as f64);
            let to_y = step_y.to_boundary(py, iy as f64);
            t += (to_x.min(to_y) + 1e-6).max(clear);
        }
        if t > limit {
            return (f64::INFINITY, Hit::Nothing);
        }
    }
}

/// A ray's crossing of one axis's cell boundaries: the inverse of its
/// component along the axis, and which side of a cell it leaves by.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    inverse: f64,
    far_side: f64,
}

fn crossing(dir: f64) -> Crossing {
    if dir > 1e-12 {
        Crossing {
            inverse: 1.0 / dir,
            far_side: 1.0,
        }
    } else if dir < -1e-12 {
        Crossing {
            inverse: 1.0 / dir,
            far_side: 0.0,
        }
    } else {
        Crossing {
            inverse: f64::INFINITY,
            far_side: f64::NAN,
        }
    }
}

impl Crossing {
    /// How far along the ray, from `pos` in cell `cell`, the next
    /// boundary of this axis lies (infinite along the other axis).
    #[inline]
    fn to_boundary(self, pos: f64, cell: f64) -> f64 {
        if self.inverse.is_finite() {
            (cell + self.far_side - pos) * self.inverse
        } else {
            f64::INFINITY
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
        // A cell entered at `t` may lie nearer than `t` by up to its
        // diagonal: march on that far past the nearest found so far.
        while t <= max_cells.min(nearest + std::f64::consts::SQRT_2) {
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
    fn a_specular_sonar_expects_its_walls_deeper_in_its_maps() {
        let plain = ConeGeometry::for_sonar(None);
        assert_eq!(plain, ConeGeometry::default());
        let specular = ConeGeometry::for_sonar(Some(30f64.to_radians()))
            .validate()
            .unwrap();
        assert_eq!(specular.specular_max_incidence, Some(30f64.to_radians()));
        assert!(specular.surface_depth > plain.surface_depth);
        // The same wall reads that much farther.
        let res = Resolution::DEFAULT;
        let wall = Cells((-400..=400).map(|y| CellIndex::new(40, y)).collect());
        let margin = specular.margin_cells(res);
        let raster = raster_of(&wall, cell_box(-margin, -margin, margin, margin));
        let read = |g: &ConeGeometry| build_table(&raster, cell_box(0, 0, 0, 0), res, g)[0];
        let deeper = SPECULAR_SURFACE_DEPTH - plain.surface_depth;
        assert_eq!(
            i32::from(read(&specular)) - i32::from(read(&plain)),
            (deeper * 1000.0).round() as i32
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

    /// A 10 × 8 m room at 5 cm with walls, three boxes and a pillar
    /// (occupied cells), as the benchmark builds its tables in.
    fn furnished_room(cell: CellIndex) -> bool {
        let (x, y) = Resolution::DEFAULT.cell_center(cell);
        let inside = (-0.5..10.5).contains(&x) && (-0.5..8.5).contains(&y);
        let wall = !(0.1..=9.9).contains(&x) || !(0.1..=7.9).contains(&y);
        let boxes = [
            (2.0, 1.5, 3.2, 2.3),
            (6.0, 4.0, 6.5, 6.5),
            (6.5, 4.0, 8.0, 4.6),
            (4.1, 4.4, 4.3, 4.6),
        ];
        inside
            && (wall
                || boxes
                    .iter()
                    .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y)))
    }

    #[test]
    fn shared_lines_agree_with_each_cells_own_rays() {
        // Tile (1, 1) of the room, two boxes and the pillar inside it.
        let res = Resolution::DEFAULT;
        let geometry = ConeGeometry::default();
        let tile = cell_box(64, 64, 127, 127);
        let m = geometry.margin_cells(res);
        let raster =
            OccupancyRaster::new(cell_box(64 - m, 64 - m, 127 + m, 127 + m), furnished_room);
        let entries = 64 * 64 * geometry.stride();
        let (mut shared, mut own) = (vec![1u16; entries], vec![2u16; entries]);
        fill_table(&raster, tile, res, &geometry, &mut shared);
        fill_table_ray_by_ray(&raster, tile, res, &geometry, &mut own);
        let echoes = own.iter().filter(|&&r| r != NO_ECHO && r != 0).count();
        let share = |n: usize| n as f64 / entries as f64;
        let within = |mm: u16| {
            share(
                shared
                    .iter()
                    .zip(&own)
                    .filter(|(a, b)| a.abs_diff(**b) <= mm)
                    .count(),
            )
        };
        let bias = shared
            .iter()
            .zip(&own)
            .filter(|(a, b)| **a != NO_ECHO && **b != NO_ECHO)
            .map(|(a, b)| f64::from(*a) - f64::from(*b))
            .sum::<f64>()
            / echoes as f64;
        eprintln!(
            "{:.4} within 1 mm, {:.4} within 1 cm, {:.4} within 5 cm, bias {bias:.1} mm",
            within(1),
            within(10),
            within(50)
        );
        assert!(share(echoes) > 0.9, "the room echoes nearly everywhere");
        // A sideways move of a quarter cell can make a ray meet the next
        // cell of a slanting wall's staircase: a cell's difference at most.
        assert!(within(10) > 0.9, "{:.4} within 1 cm", within(10));
        assert!(within(50) > 0.99, "{:.4} within 5 cm", within(50));
        assert!(bias.abs() < 5.0, "bias {bias:.1} mm");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// Each cell's own rays, marched with distance-field skipping,
        /// agree with the plain cell-by-cell reference for random clutter.
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
            let mut table = vec![0; 64 * geometry.stride()];
            fill_table_ray_by_ray(&raster, cell_box(0, 0, 7, 7), res, &geometry, &mut table);
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
