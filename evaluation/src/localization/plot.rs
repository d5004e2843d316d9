//! The thesis's plots (its Figs. 7.5, 7.7, 7.9 to 7.11): the true path in
//! red against the estimated path in green, each kidnap marked with a blue
//! cross at the true pose before and after the jump and each recovery (the
//! first converged estimate after a kidnap) with an orange ring; drawn
//! over the map (never observed: grey, free: white, occupied: black, by
//! the map's thresholds) or on white, with a legend and a scale bar.
//!
//! # What is joined
//! Estimates before convergence (the filter still searching) are faint
//! green points, never joined: a line between two of them would cross the
//! map where no estimate ever was. Only consecutive converged estimates
//! are joined, and the line breaks at a kidnap and at a jump (see
//! `plot_path`).
//!
//! # Framing
//! The drawing covers the box holding every true and estimated position
//! and, with a map, every observed cell, widened on each side by a margin
//! of [`MIN_MARGIN_M`] or [`MARGIN_FRACTION`] of the box's longer side,
//! whichever is more. The image's longer side is [`MAX_SIDE_PX`] pixels,
//! its shorter side in proportion (rounded, at least 1 pixel), and +y
//! points up. The true path is not drawn across a kidnap jump (the robot
//! did not drive it).
//!
//! # Legend and scale bar
//! The legend (true path, estimate, estimate before convergence, kidnap,
//! recovery) and the scale bar (a round length, 1, 2 or 5 times a power of
//! ten metres, exactly that long at the plot's scale) each sit on a white
//! box in the corner that hides the fewest drawn pixels; a plot too small
//! for one leaves it out. Their text is dark blue-grey, never the walls'
//! black.

use deog_grid::{CellIndex, Occupancy, OccupancyView, Pose2, TileMap};
use deog_mapfile::scale_bar::{BarStyle, draw_scale_bar};
use deog_mapfile::{Canvas, Corner, Rect};

use super::plot_legend::draw_legend;
use super::plot_path::split_path;
use super::{EstimateSample, EvaluationError, Kidnap, Settling, TruthSample};

/// Pixels along the image's longer side.
pub const MAX_SIDE_PX: u32 = 1000;
/// Smallest margin around the drawing, metres.
pub const MIN_MARGIN_M: f64 = 0.5;
/// Margin as a fraction of the drawing's longer side, when that is more.
pub const MARGIN_FRACTION: f64 = 0.05;

/// The true path's colour.
pub const TRUTH_RGB: [u8; 3] = [220, 0, 0];
/// The estimated path's colour.
pub const ESTIMATE_RGB: [u8; 3] = [0, 170, 0];
/// Estimates before convergence: a faint green.
pub const BEFORE_CONVERGENCE_RGB: [u8; 3] = [110, 200, 110];
/// The kidnap crosses' colour.
pub const KIDNAP_RGB: [u8; 3] = [0, 0, 255];
/// The recovery rings' colour.
pub const RECOVERY_RGB: [u8; 3] = [255, 140, 0];
/// The legend's and the scale bar's text and the bar itself.
pub const TEXT_RGB: [u8; 3] = [40, 40, 70];
/// Behind the legend and the scale bar.
pub const LEGEND_BACKING_RGB: [u8; 3] = [255, 255, 255];
/// The legend's edge.
pub const LEGEND_EDGE_RGB: [u8; 3] = [150, 150, 150];
/// Background without a map, and free cells.
pub const FREE_RGB: [u8; 3] = [255, 255, 255];
/// Occupied cells.
pub const OCCUPIED_RGB: [u8; 3] = [0, 0, 0];
/// Cells never observed or undecided.
pub const UNKNOWN_RGB: [u8; 3] = [205, 205, 205];

/// Half the length of a kidnap cross's arm, pixels.
const CROSS_HALF_PX: i64 = 9;
/// Radius of a recovery ring, pixels.
const RING_RADIUS_PX: f64 = 9.0;
/// Pixels between the legend or the scale bar and the plot's edge.
const BOX_MARGIN_PX: u32 = 8;

/// One robot's paths.
#[derive(Debug, Clone, Copy)]
pub struct RobotPath<'a> {
    /// Its true poses, in sequence order.
    pub truth: &'a [TruthSample],
    /// The localizer's estimates, in sequence order.
    pub estimates: &'a [EstimateSample],
    /// The kidnaps found in the true poses, with their recoveries.
    pub kidnaps: &'a [Kidnap],
    /// The estimate's first settling (the report's convergence); with the
    /// kidnaps' recoveries it says which estimates are converged.
    pub convergence: Option<Settling>,
}

/// What to draw.
#[derive(Debug, Clone, Copy)]
pub struct PlotInput<'a> {
    /// The map to draw under the paths; `None`: a white background.
    pub map: Option<&'a TileMap>,
    /// The robots' paths.
    pub robots: &'a [RobotPath<'a>],
}

/// An RGB image and where it sits in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` RGB triples, top row first.
    pub rgb: Vec<u8>,
    /// World x of the image's left edge, metres.
    pub left_m: f64,
    /// World y of the image's top edge, metres.
    pub top_m: f64,
    /// Pixels per metre, on both axes.
    pub px_per_m: f64,
}

impl Raster {
    /// The colour at column `col`, row `row` (row 0 at the top); `None`
    /// outside the image.
    pub fn pixel(&self, col: u32, row: u32) -> Option<[u8; 3]> {
        if col >= self.width || row >= self.height {
            return None;
        }
        let i = 3 * (row as usize * self.width as usize + col as usize);
        Some([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }

    /// The pixel (column, row) holding world point `(x, y)`, metres;
    /// `None` outside the image.
    pub fn pixel_of(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        let (col, row) = self.position(x, y);
        let inside = |v: f64, size: u32| v >= 0.0 && v < f64::from(size);
        (inside(col, self.width) && inside(row, self.height)).then_some((col as u32, row as u32))
    }

    /// The image as an 8-bit RGB PNG.
    pub fn to_png(&self) -> Result<Vec<u8>, EvaluationError> {
        let mut out = Vec::new();
        let plot = |e: png::EncodingError| EvaluationError::Plot(format!("encoding the PNG: {e}"));
        let mut encoder = png::Encoder::new(&mut out, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(plot)?;
        writer.write_image_data(&self.rgb).map_err(plot)?;
        writer.finish().map_err(plot)?;
        Ok(out)
    }

    /// Fractional pixel coordinates of world point `(x, y)`.
    fn position(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.left_m) * self.px_per_m,
            (self.top_m - y) * self.px_per_m,
        )
    }

    fn set(&mut self, col: i64, row: i64, rgb: [u8; 3]) {
        if col < 0 || row < 0 || col >= i64::from(self.width) || row >= i64::from(self.height) {
            return;
        }
        let i = 3 * (row as usize * self.width as usize + col as usize);
        self.rgb[i..i + 3].copy_from_slice(&rgb);
    }

    /// A 2 × 2 dot at fractional pixel `(col, row)`, so lines read at 1000
    /// pixels.
    fn dot(&mut self, col: f64, row: f64, rgb: [u8; 3]) {
        let (c, r) = (col.floor() as i64, row.floor() as i64);
        for (dc, dr) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            self.set(c + dc, r + dr, rgb);
        }
    }

    /// A straight line between two world points.
    fn line(&mut self, a: (f64, f64), b: (f64, f64), rgb: [u8; 3]) {
        let (c0, r0) = self.position(a.0, a.1);
        let (c1, r1) = self.position(b.0, b.1);
        // Both ends lie in the framed box, so the step count is at most
        // about the image's diagonal.
        let steps = (c1 - c0).abs().max((r1 - r0).abs()).ceil().max(1.0) as u32;
        for i in 0..=steps {
            let t = f64::from(i) / f64::from(steps);
            self.dot(c0 + (c1 - c0) * t, r0 + (r1 - r0) * t, rgb);
        }
    }

    /// A diagonal cross centred on a world point.
    fn cross(&mut self, x: f64, y: f64, rgb: [u8; 3]) {
        let (col, row) = self.position(x, y);
        self.cross_at(col.floor() as i64, row.floor() as i64, CROSS_HALF_PX, rgb);
    }

    /// A diagonal cross centred on pixel `(c, r)`, arms `half` long.
    pub(crate) fn cross_at(&mut self, c: i64, r: i64, half: i64, rgb: [u8; 3]) {
        for d in -half..=half {
            for thick in 0..2 {
                self.set(c + d + thick, r + d, rgb);
                self.set(c + d + thick, r - d, rgb);
            }
        }
    }

    /// A ring about 2 pixels thick of `radius` pixels centred on pixel
    /// `(c, r)`.
    pub(crate) fn ring_at(&mut self, c: i64, r: i64, radius: f64, rgb: [u8; 3]) {
        let reach = radius.ceil() as i64 + 1;
        for dr in -reach..=reach {
            for dc in -reach..=reach {
                let distance = (dc as f64).hypot(dr as f64);
                if (distance - radius).abs() < 1.0 {
                    self.set(c + dc, r + dr, rgb);
                }
            }
        }
    }
}

impl Canvas for Raster {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn colour(&self, col: i64, row: i64) -> Option<[u8; 3]> {
        let col = u32::try_from(col).ok()?;
        let row = u32::try_from(row).ok()?;
        self.pixel(col, row)
    }

    fn paint(&mut self, col: i64, row: i64, rgb: [u8; 3]) {
        self.set(col, row, rgb);
    }
}

/// A box in world metres.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    min_x: f64,
    min_y: f64,
    max_x: f64,
    max_y: f64,
}

impl Bounds {
    fn point(x: f64, y: f64) -> Self {
        Self {
            min_x: x,
            min_y: y,
            max_x: x,
            max_y: y,
        }
    }

    fn union(self, other: Self) -> Self {
        Self {
            min_x: self.min_x.min(other.min_x),
            min_y: self.min_y.min(other.min_y),
            max_x: self.max_x.max(other.max_x),
            max_y: self.max_y.max(other.max_y),
        }
    }
}

/// Draws the paths of `input` (see the [module docs](self)).
pub fn render_plot(input: &PlotInput<'_>) -> Result<Raster, EvaluationError> {
    let mut bounds: Option<Bounds> = None;
    let mut include = |what: &str, pose: &Pose2| {
        if !(pose.x.is_finite() && pose.y.is_finite()) {
            return Err(EvaluationError::Plot(format!(
                "{what} position is not finite: ({}, {})",
                pose.x, pose.y
            )));
        }
        let point = Bounds::point(pose.x, pose.y);
        bounds = Some(bounds.map_or(point, |b| b.union(point)));
        Ok(())
    };
    for robot in input.robots {
        for t in robot.truth {
            include("a true", &t.pose)?;
        }
        for e in robot.estimates {
            include("an estimated", &e.pose)?;
        }
        for k in robot.kidnaps {
            include("a kidnap's", &k.from)?;
            include("a kidnap's", &k.to)?;
        }
    }
    if let Some(map) = input.map
        && let Some(cells) = observed_bounds(map)
    {
        bounds = Some(bounds.map_or(cells, |b| b.union(cells)));
    }
    let Some(b) = bounds else {
        return Err(EvaluationError::Plot(
            "nothing to draw: no pose and no observed map cell".into(),
        ));
    };

    let longer = (b.max_x - b.min_x).max(b.max_y - b.min_y);
    let margin = MIN_MARGIN_M.max(MARGIN_FRACTION * longer);
    let (width_m, height_m) = (
        b.max_x - b.min_x + 2.0 * margin,
        b.max_y - b.min_y + 2.0 * margin,
    );
    let px_per_m = f64::from(MAX_SIDE_PX) / width_m.max(height_m);
    let side = |metres: f64| {
        (metres * px_per_m)
            .round()
            .clamp(1.0, f64::from(MAX_SIDE_PX)) as u32
    };
    let (width, height) = (side(width_m), side(height_m));
    let mut raster = Raster {
        width,
        height,
        rgb: FREE_RGB.repeat(width as usize * height as usize),
        left_m: b.min_x - margin,
        top_m: b.max_y + margin,
        px_per_m,
    };

    if let Some(map) = input.map {
        draw_map(&mut raster, map);
    }
    let parts: Vec<_> = input.robots.iter().map(split_path).collect();
    // Faint points first, so every line and mark lies over them.
    for part in &parts {
        for e in &part.before_convergence {
            let (col, row) = raster.position(e.pose.x, e.pose.y);
            // A point a little larger than a line's dots, as it stands
            // alone.
            raster.dot(col, row, BEFORE_CONVERGENCE_RGB);
            raster.dot(col - 1.0, row - 1.0, BEFORE_CONVERGENCE_RGB);
        }
    }
    for robot in input.robots {
        for pair in robot.truth.windows(2) {
            let (a, b) = (&pair[0], &pair[1]);
            if robot.kidnaps.iter().any(|k| k.sequence == b.sequence) {
                continue;
            }
            raster.line((a.pose.x, a.pose.y), (b.pose.x, b.pose.y), TRUTH_RGB);
        }
        if let [only] = robot.truth {
            let (col, row) = raster.position(only.pose.x, only.pose.y);
            raster.dot(col, row, TRUTH_RGB);
        }
    }
    for part in &parts {
        for run in &part.runs {
            for pair in run.windows(2) {
                let (a, b) = (&pair[0].pose, &pair[1].pose);
                raster.line((a.x, a.y), (b.x, b.y), ESTIMATE_RGB);
            }
            if let [only] = run.as_slice() {
                let (col, row) = raster.position(only.pose.x, only.pose.y);
                raster.dot(col, row, ESTIMATE_RGB);
            }
        }
    }
    for robot in input.robots {
        for k in robot.kidnaps {
            raster.cross(k.from.x, k.from.y, KIDNAP_RGB);
            raster.cross(k.to.x, k.to.y, KIDNAP_RGB);
        }
    }
    for part in &parts {
        for e in &part.recoveries {
            let (col, row) = raster.position(e.pose.x, e.pose.y);
            raster.ring_at(
                col.floor() as i64,
                row.floor() as i64,
                RING_RADIUS_PX,
                RECOVERY_RGB,
            );
        }
    }
    draw_legend_and_scale_bar(&mut raster);
    Ok(raster)
}

/// The legend, then the scale bar, each in the quietest corner left; the
/// font twice as large on plots big enough for it.
fn draw_legend_and_scale_bar(raster: &mut Raster) {
    let scale = if raster.width >= 800 && raster.height >= 300 {
        2
    } else {
        1
    };
    // Paths, marks and walls are busy; the background is not.
    let busy = |raster: &Raster, col: i64, row: i64| {
        raster
            .colour(col, row)
            .is_some_and(|rgb| rgb != FREE_RGB && rgb != UNKNOWN_RGB)
    };
    let legend = draw_legend(raster, scale, BOX_MARGIN_PX, busy);
    let taken: Vec<Rect> = legend.into_iter().collect();
    let style = BarStyle {
        ink: TEXT_RGB,
        backing: LEGEND_BACKING_RGB,
        scale,
        margin: BOX_MARGIN_PX,
    };
    let view = raster.clone();
    draw_scale_bar(
        raster,
        view.px_per_m,
        &style,
        &[
            Corner::BottomLeft,
            Corner::BottomRight,
            Corner::TopLeft,
            Corner::TopRight,
        ],
        &taken,
        |col, row| busy(&view, col, row),
    );
}

/// The box of `map`'s observed cells; `None` when none is.
fn observed_bounds(map: &TileMap) -> Option<Bounds> {
    let side = map.tile_size().cells() as usize;
    let resolution = map.resolution().metres();
    let mut cells: Option<(CellIndex, CellIndex)> = None;
    for (key, tile) in map.tiles() {
        // A key the map holds passed the map's own check.
        let Ok(origin) = map.tile_size().origin(*key) else {
            continue;
        };
        for (index, &raw) in tile.raw_cells().iter().enumerate() {
            if deog_grid::LogOdds::from_raw(raw).is_none() {
                continue;
            }
            let cell = CellIndex::new(
                origin.x + (index % side) as i32,
                origin.y + (index / side) as i32,
            );
            cells = Some(match cells {
                None => (cell, cell),
                Some((lo, hi)) => (
                    CellIndex::new(lo.x.min(cell.x), lo.y.min(cell.y)),
                    CellIndex::new(hi.x.max(cell.x), hi.y.max(cell.y)),
                ),
            });
        }
    }
    let (lo, hi) = cells?;
    Some(Bounds {
        min_x: f64::from(lo.x) * resolution,
        min_y: f64::from(lo.y) * resolution,
        max_x: (f64::from(hi.x) + 1.0) * resolution,
        max_y: (f64::from(hi.y) + 1.0) * resolution,
    })
}

/// Paints each pixel with the class of the map cell under its centre.
fn draw_map(raster: &mut Raster, map: &TileMap) {
    let resolution = map.resolution();
    for row in 0..raster.height {
        let y = raster.top_m - (f64::from(row) + 0.5) / raster.px_per_m;
        for col in 0..raster.width {
            let x = raster.left_m + (f64::from(col) + 0.5) / raster.px_per_m;
            // A point beyond the cell range is simply not on the map.
            let rgb = match resolution.cell_of(x, y).map(|cell| map.occupancy(cell)) {
                Ok(Occupancy::Free) => FREE_RGB,
                Ok(Occupancy::Occupied) => OCCUPIED_RGB,
                Ok(Occupancy::Unknown) | Err(_) => UNKNOWN_RGB,
            };
            raster.set(i64::from(col), i64::from(row), rgb);
        }
    }
}
