//! A sonar map fitted to all of a run's readings at once, through a
//! forward model of the specular sonar (after Thrun, 2003): rather than
//! each reading writing evidence into the cells it covers (an inverse
//! model, [`crate::sensors`]), the map is the one that best explains every
//! reading.
//!
//! The forward model is the specular sonar's physics. A cone is a fan of
//! rays; each ray stops in the first cell that stops sound. It echoes
//! when it strikes that cell's face within the critical incidence, and
//! otherwise sends nothing back, the cell still hiding what lies behind
//! it. A reading is the nearest echo of the fan (spread about the face by
//! the noise and the fan's gaps), an echo from nothing the map holds
//! (another robot, crosstalk), or none: a dropout, or no ray echoed.
//!
//! Each cell holds the probability that it stops sound, and its face's
//! orientation as a distribution over [`ORIENTATIONS`] bins of its normal
//! (first guessed from the line its occupied neighbours make). The fit is
//! an expectation–maximization:
//! - **Expectation**: for each reading, each ray's posterior over where
//!   it stopped, given the reading: in the cell that echoed at the range
//!   read (weighed against the other rays and a random echo), or silently
//!   in a cell it met at a grazing angle, or beyond. Each cell collects
//!   the expected stops and passes of every ray, and each stop's evidence
//!   for the orientations that explain it (an echo for faces square to the
//!   ray, a silent stop for faces it grazed).
//! - **Maximization**: a cell's probability becomes the share of the rays
//!   reaching it that stopped there; its orientation, the one its stops
//!   favour.
//!
//! Where an inverse model's cone writes free space over a wall it grazed
//! (or an arc of wall across a doorway it heard a jamb through), here a
//! grazing ray's silence is explained by the wall it stopped in, and a
//! doorway's far echoes by the rays that passed it. The rays of one fan
//! each take their own stop, so a wall that many rays met is supported by
//! all of them, where one cell's flip would be masked by its neighbours.
//!
//! Cells the readings judged too little, and cells no ray reached (behind
//! walls, inside obstacles), come out unknown, unless
//! [`ForwardSettings::keep_unreached`] keeps the first guess where no ray
//! reached.
//!
//! Batch, pure and synchronous: readings and a first guess in, a map out.
//! Its cost is a few walks of every reading's fan, one per round.

use deog_grid::{
    CellIndex, ClampLimits, LOG_ODDS_SCALE, Pose2, Resolution, SegmentCells, TileDelta, TileMap,
};

use crate::error::MappingError;

/// Bins of a cell's surface normal over a half turn (a face and its back
/// are one line).
pub const ORIENTATIONS: usize = 12;

/// The most rays a cone's fan may have.
pub const MAX_RAYS: usize = 32;

/// A cell fewer rays than this reached (stopped in or passed, in
/// expectation) comes out unknown.
const MIN_RAYS: f32 = 1.0;

/// The most cells a fit may span: 5 hectares at 5 cm (a building 220 m
/// square), about 2.2 GB at the fit's 110 bytes a cell.
pub const MAX_CELLS: usize = 20_000_000;

/// One sonar reading where it was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarReading {
    /// The transducer's pose: its position and the cone's axis.
    pub sensor: Pose2,
    /// The range read, metres; `None` for no echo.
    pub range: Option<f64>,
}

/// The forward model and the fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardSettings {
    /// Half the cone's opening angle, radians.
    pub half_angle: f64,
    /// Rays across the cone, both edges included.
    pub rays: usize,
    /// How far from a sonar cells are judged, metres; an echo farther is
    /// taken as no echo within it.
    pub reach: f64,
    /// The spread of an echo about the face that sent it, metres (the
    /// fan's rays a step apart, and the noise)...
    pub hit_sigma: f64,
    /// ...and its growth with the range read, per metre.
    pub range_sigma: f64,
    /// The share of readings that are echoes from nothing the map holds
    /// (other robots, crosstalk), spread evenly over `max_range`.
    pub random_weight: f64,
    /// The share of readings lost whatever lies ahead.
    pub dropout_weight: f64,
    /// The sonar's longest range, metres (the spread of random echoes).
    pub max_range: f64,
    /// Past this angle between a ray and a face's normal, radians, the
    /// face sends no echo back.
    pub critical_incidence: f64,
    /// The chance that a face struck within the critical incidence echoes.
    pub echo_probability: f64,
    /// The chance that a face struck past it still echoes.
    pub grazing_echo_probability: f64,
    /// The probability that a cell stops sound before any reading, and
    /// where a cell the first guess has not observed starts.
    pub prior: f64,
    /// How many rays' worth the prior counts for against a cell's own
    /// stops and passes.
    pub prior_weight: f64,
    /// Rounds of expectation and maximization.
    pub iterations: usize,
    /// A cell whose belief is weaker than this, nats, comes out unknown.
    pub decide_nats: f64,
    /// The strongest belief written, nats.
    pub belief_nats: f64,
    /// Cells no reading reached keep the first guess's belief, rather than
    /// coming out unknown.
    pub keep_unreached: bool,
}

impl Default for ForwardSettings {
    fn default() -> Self {
        Self {
            half_angle: 15f64.to_radians(),
            rays: 11,
            reach: 4.0,
            hit_sigma: 0.02,
            range_sigma: 0.01,
            random_weight: 0.05,
            dropout_weight: 0.03,
            max_range: 10.668,
            critical_incidence: 30f64.to_radians(),
            echo_probability: 0.95,
            grazing_echo_probability: 0.03,
            prior: 0.27,
            prior_weight: 0.3,
            iterations: 3,
            decide_nats: 1.5,
            belief_nats: 4.0,
            keep_unreached: false,
        }
    }
}

impl ForwardSettings {
    /// Checks every figure is finite and within its range; the error names
    /// the field.
    pub fn validate(&self) -> Result<Self, MappingError> {
        let check = |ok: bool, field: &str, value: f64| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(MappingError::invalid(
                    format!("forward model: {field}"),
                    format!("out of range: {value}"),
                ))
            }
        };
        let open_unit = |v: f64| v > 0.0 && v < 1.0;
        check(
            self.half_angle > 0.0 && self.half_angle < 1.4,
            "half_angle",
            self.half_angle,
        )?;
        check(
            (2..=MAX_RAYS).contains(&self.rays),
            "rays",
            self.rays as f64,
        )?;
        check(self.reach > 0.0 && self.reach <= 20.0, "reach", self.reach)?;
        check(self.hit_sigma > 0.0, "hit_sigma", self.hit_sigma)?;
        check(self.range_sigma >= 0.0, "range_sigma", self.range_sigma)?;
        check(
            self.random_weight > 0.0 && self.random_weight < 0.5,
            "random_weight",
            self.random_weight,
        )?;
        check(
            self.dropout_weight > 0.0 && self.dropout_weight < 0.5,
            "dropout_weight",
            self.dropout_weight,
        )?;
        check(self.max_range > 0.0, "max_range", self.max_range)?;
        check(
            (0.0..=std::f64::consts::FRAC_PI_2).contains(&self.critical_incidence),
            "critical_incidence",
            self.critical_incidence,
        )?;
        check(
            open_unit(self.echo_probability),
            "echo_probability",
            self.echo_probability,
        )?;
        check(
            open_unit(self.grazing_echo_probability),
            "grazing_echo_probability",
            self.grazing_echo_probability,
        )?;
        check(open_unit(self.prior), "prior", self.prior)?;
        check(
            self.prior_weight > 0.0 && self.prior_weight <= 100.0,
            "prior_weight",
            self.prior_weight,
        )?;
        check(
            (1..=50).contains(&self.iterations),
            "iterations",
            self.iterations as f64,
        )?;
        check(self.decide_nats >= 0.0, "decide_nats", self.decide_nats)?;
        check(
            self.belief_nats > self.decide_nats && self.belief_nats <= 30.0,
            "belief_nats",
            self.belief_nats,
        )?;
        Ok(*self)
    }
}

impl ForwardSettings {
    /// The model of a sonar of cone half-angle `half_angle` (radians) and
    /// longest range `max_range` (metres) whose faces go silent past
    /// `critical_incidence` (radians; `None` for a sonar every face
    /// echoes).
    pub fn for_sonar(half_angle: f64, max_range: f64, critical_incidence: Option<f64>) -> Self {
        Self {
            half_angle,
            max_range,
            critical_incidence: critical_incidence.unwrap_or(std::f64::consts::FRAC_PI_2),
            ..Self::default()
        }
    }
}

/// A ring's frame as readings where each was taken: the robot at `pose`
/// moving at `pace` (its pose a second earlier, seen from now, as
/// [`deog_grid::FrameMotion`] gives it), its sensors fired as `firing`
/// says; `ranges` in ring order, `None` for no echo (how a sensor says
/// so is its rig's business: [`echo_below`] for a plain maximum range).
/// Appended to `out`.
pub fn ring_readings(
    ring: &deog_grid::SensorRing,
    firing: deog_grid::RingFiring,
    pose: &Pose2,
    pace: Option<&Pose2>,
    ranges: impl IntoIterator<Item = Option<f64>>,
    out: &mut Vec<SonarReading>,
) {
    let fired = firing
        .robot_at_readings(ring.len(), pace)
        .map_or_else(|| ring.clone(), |at| ring.as_fired(&at));
    out.extend(
        fired
            .sensor_poses(pose)
            .zip(ranges)
            .map(|(sensor, range)| SonarReading { sensor, range }),
    );
}

/// `ranges` with each at `max_range` or more (or NaN) taken for no echo.
pub fn echo_below(ranges: &[f64], max_range: f64) -> impl Iterator<Item = Option<f64>> + '_ {
    ranges.iter().map(move |&r| (r < max_range).then_some(r))
}

/// What the fit found, beside the map.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForwardStats {
    /// Readings fitted.
    pub readings: usize,
    /// Cells some ray reached.
    pub cells_reached: usize,
    /// Cells that crossed p = 0.5 in the last round.
    pub last_changes: usize,
    /// The readings' log-likelihood in the last round, nats.
    pub log_likelihood: f64,
}

/// Fits a map to `readings` from the first guess `initial` (its cells'
/// probabilities, the orientations guessed from the lines its occupied
/// cells make). The map returned holds, at `limits`, the cells the
/// readings decide; see the module docs.
pub fn fit_forward(
    initial: &TileMap,
    readings: &[SonarReading],
    settings: &ForwardSettings,
    limits: ClampLimits,
) -> Result<(TileMap, ForwardStats), MappingError> {
    let settings = settings.validate()?;
    let window = window_of(initial.resolution(), readings, settings.reach)?;
    let mut fit = Fit::new(initial, window, settings);
    let mut stats = ForwardStats {
        readings: readings.len(),
        ..ForwardStats::default()
    };
    let mut rays = Vec::new();
    for _ in 0..settings.iterations {
        fit.clear_counts();
        let mut total = 0.0;
        for reading in readings {
            total += fit.expect(reading, &mut rays)?;
        }
        stats.log_likelihood = total;
        stats.last_changes = fit.maximize();
    }
    stats.cells_reached = fit.reached.iter().filter(|&&r| r).count();
    Ok((fit.into_map(initial, limits)?, stats))
}

/// The dense window of cells a fit works in.
#[derive(Debug)]
struct Window {
    res: Resolution,
    min: CellIndex,
    width: usize,
    height: usize,
}

impl Window {
    fn index(&self, cell: CellIndex) -> Option<usize> {
        let dx = i64::from(cell.x) - i64::from(self.min.x);
        let dy = i64::from(cell.y) - i64::from(self.min.y);
        (dx >= 0 && dy >= 0 && (dx as usize) < self.width && (dy as usize) < self.height)
            .then(|| dy as usize * self.width + dx as usize)
    }

    fn cell(&self, index: usize) -> CellIndex {
        CellIndex::new(
            self.min.x + (index % self.width) as i32,
            self.min.y + (index / self.width) as i32,
        )
    }

    fn len(&self) -> usize {
        self.width * self.height
    }
}

/// The cells within `reach` of any reading's sensor.
fn window_of(
    res: Resolution,
    readings: &[SonarReading],
    reach: f64,
) -> Result<Window, MappingError> {
    let mut bounds: Option<(f64, f64, f64, f64)> = None;
    for r in readings {
        let (x, y) = (r.sensor.x, r.sensor.y);
        if !(x.is_finite() && y.is_finite() && r.sensor.theta.is_finite()) {
            return Err(MappingError::invalid(
                "reading",
                "a sensor pose is not finite",
            ));
        }
        if r.range.is_some_and(|z| !(z.is_finite() && z >= 0.0)) {
            return Err(MappingError::invalid(
                "reading",
                format!("a range is not a distance: {:?}", r.range),
            ));
        }
        bounds = Some(match bounds {
            None => (x, y, x, y),
            Some((a, b, c, d)) => (a.min(x), b.min(y), c.max(x), d.max(y)),
        });
    }
    let Some((x0, y0, x1, y1)) = bounds else {
        return Err(MappingError::invalid("readings", "none to fit a map to"));
    };
    let min = res.cell_of(x0 - reach, y0 - reach)?;
    let max = res.cell_of(x1 + reach, y1 + reach)?;
    let width = (i64::from(max.x) - i64::from(min.x) + 1) as usize;
    let height = (i64::from(max.y) - i64::from(min.y) + 1) as usize;
    if width.saturating_mul(height) > MAX_CELLS {
        return Err(MappingError::invalid(
            "readings",
            format!("they span {width} × {height} cells, more than the {MAX_CELLS} one fit holds"),
        ));
    }
    Ok(Window {
        res,
        min,
        width,
        height,
    })
}

/// The density of an echo at `z` from a face somewhere between `near` and
/// `far` along the ray, the reading spread by `sigma` about it.
fn face_density(z: f32, near: f32, far: f32, sigma: f32) -> f32 {
    if far - near < 0.1 * sigma {
        let off = (z - near) / sigma;
        return (-0.5 * off * off).exp() / (sigma * 2.506_628_3);
    }
    // A logistic stands in for the normal's distribution function.
    let cdf = |x: f32| 1.0 / (1.0 + (-1.702 * x).exp());
    (cdf((z - near) / sigma) - cdf((z - far) / sigma)) / (far - near)
}

/// Where a ray from `origin` along `direction` (one axis) is within the
/// cell's edges `corner` and `corner + size`.
fn slab(origin: f64, direction: f64, corner: f64, size: f64) -> Slab {
    if direction.abs() < 1e-12 {
        return if (corner..corner + size).contains(&origin) {
            Slab(f64::NEG_INFINITY, f64::INFINITY)
        } else {
            Slab(f64::INFINITY, f64::NEG_INFINITY)
        };
    }
    let a = (corner - origin) / direction;
    let b = (corner + size - origin) / direction;
    Slab(a.min(b), a.max(b))
}

/// A stretch of a ray: entry and exit distances.
#[derive(Debug, Clone, Copy)]
struct Slab(f64, f64);

impl Slab {
    /// Where the ray is within both stretches.
    fn and(self, other: Slab) -> (f64, f64) {
        (self.0.max(other.0), self.1.min(other.1))
    }
}

/// The angle of orientation bin `b`'s normal, radians in [0, π).
fn bin_angle(b: usize) -> f64 {
    (b as f64 + 0.5) * std::f64::consts::PI / ORIENTATIONS as f64
}

/// The angle between a ray heading `ray` and a face whose normal lies at
/// `normal`, folded into [0, π/2].
fn incidence(ray: f64, normal: f64) -> f64 {
    let d = (ray - normal).rem_euclid(std::f64::consts::PI);
    d.min(std::f64::consts::PI - d)
}

/// One ray of a reading: what a face at each orientation does to it.
#[derive(Debug, Clone, Copy)]
struct RayFaces {
    /// The chance a face of each orientation echoes it.
    echo: [f32; ORIENTATIONS],
    /// Its logarithm, and that of the chance it does not.
    ln_echo: [f32; ORIENTATIONS],
    ln_silent: [f32; ORIENTATIONS],
}

/// A cell along one ray, for the expectation.
#[derive(Debug, Clone, Copy)]
struct RayCell {
    cell: u32,
    /// The chance the ray stops here: this cell's probability times the
    /// chance it passed every cell before.
    stop: f32,
    /// The chance it echoes if it stops here.
    echo: f32,
    /// Where the ray enters and leaves the cell, metres.
    near: f32,
    far: f32,
}

/// One ray's walk: its cells in `cells[start..end]`.
#[derive(Debug, Clone, Copy)]
struct RayWalk {
    faces: RayFaces,
    start: usize,
    end: usize,
    /// The chance it passed every cell walked.
    through: f32,
    /// The density of its echo at the range read.
    echo_density: f32,
    /// The chance it sent no echo before the range read (or at all).
    quiet: f32,
}

/// The fit's state.
struct Fit {
    settings: ForwardSettings,
    window: Window,
    /// Per cell, the probability it stops sound.
    stop: Vec<f32>,
    /// Per cell, its orientation's distribution.
    orientation: Vec<[f32; ORIENTATIONS]>,
    /// Per cell, expected stops and passes over this round.
    stops: Vec<f32>,
    passes: Vec<f32>,
    /// Per cell and orientation: the log-likelihood of its stops this round.
    faces: Vec<[f32; ORIENTATIONS]>,
    /// Cells some ray reached.
    reached: Vec<bool>,
    /// Each ray's angle from the cone's axis.
    ray_angles: Vec<f64>,
    /// The cells of the reading being expected.
    cells: Vec<RayCell>,
}

impl Fit {
    fn new(initial: &TileMap, window: Window, settings: ForwardSettings) -> Self {
        let n = window.len();
        let mut stop = vec![settings.prior as f32; n];
        for (index, p) in stop.iter_mut().enumerate() {
            if let Some(b) = initial.get(window.cell(index)) {
                *p = (b.probability() as f32).clamp(0.05, 0.95);
            }
        }
        let ray_angles = (0..settings.rays)
            .map(|i| settings.half_angle * (2.0 * i as f64 / (settings.rays - 1) as f64 - 1.0))
            .collect();
        let mut fit = Self {
            settings,
            window,
            stop,
            orientation: vec![[1.0 / ORIENTATIONS as f32; ORIENTATIONS]; n],
            stops: vec![0.0; n],
            passes: vec![0.0; n],
            faces: vec![[0.0; ORIENTATIONS]; n],
            reached: vec![false; n],
            ray_angles,
            cells: Vec::new(),
        };
        fit.guess_orientations();
        fit
    }

    /// Each occupied cell's orientation from the line its occupied
    /// neighbours (two cells about) make: their principal axis is the
    /// face, its normal the orientation; where they make no line, every
    /// orientation alike.
    fn guess_orientations(&mut self) {
        let (w, h) = (self.window.width as i64, self.window.height as i64);
        let occupied = |stop: &[f32], x: i64, y: i64| {
            x >= 0 && y >= 0 && x < w && y < h && stop[(y * w + x) as usize] > 0.5
        };
        for index in 0..self.stop.len() {
            let (cx, cy) = ((index as i64) % w, (index as i64) / w);
            if !occupied(&self.stop, cx, cy) {
                continue;
            }
            let (mut n, mut sxx, mut syy, mut sxy) = (0.0f64, 0.0, 0.0, 0.0);
            for dy in -2..=2i64 {
                for dx in -2..=2i64 {
                    if occupied(&self.stop, cx + dx, cy + dy) {
                        let (fx, fy) = (dx as f64, dy as f64);
                        n += 1.0;
                        sxx += fx * fx;
                        syy += fy * fy;
                        sxy += fx * fy;
                    }
                }
            }
            if n < 3.0 {
                continue;
            }
            // Moments about the cell itself, which lies on the line.
            let (a, b, c) = (sxx / n, syy / n, sxy / n);
            let spread = ((a - b) * (a - b) + 4.0 * c * c).sqrt();
            if spread / (a + b).max(1e-9) < 0.6 {
                continue;
            }
            let along = 0.5 * (2.0 * c).atan2(a - b);
            let normal = along + std::f64::consts::FRAC_PI_2;
            let mut weights = [0.0f32; ORIENTATIONS];
            for (bin, weight) in weights.iter_mut().enumerate() {
                let off = incidence(bin_angle(bin), normal);
                *weight = (-(off * off) / (2.0 * 0.2f64.powi(2))).exp() as f32;
            }
            let total: f32 = weights.iter().sum();
            self.orientation[index] = weights.map(|v| v / total);
        }
    }

    fn clear_counts(&mut self) {
        self.stops.fill(0.0);
        self.passes.fill(0.0);
        self.faces.fill([0.0; ORIENTATIONS]);
    }

    /// What faces of each orientation do to a ray heading `heading`.
    fn ray_faces(&self, heading: f64) -> RayFaces {
        let s = &self.settings;
        let echo: [f32; ORIENTATIONS] = std::array::from_fn(|b| {
            if incidence(heading, bin_angle(b)) <= s.critical_incidence {
                s.echo_probability as f32
            } else {
                s.grazing_echo_probability as f32
            }
        });
        RayFaces {
            echo,
            ln_echo: echo.map(f32::ln),
            ln_silent: echo.map(|p| (1.0 - p).ln()),
        }
    }

    /// One reading's expected stops and passes, and its faces' evidence,
    /// added to the round's counts; its log-likelihood.
    fn expect(
        &mut self,
        reading: &SonarReading,
        rays: &mut Vec<RayWalk>,
    ) -> Result<f64, MappingError> {
        let s = self.settings;
        let echo = reading.range.filter(|&z| z < s.reach).map(|z| z as f32);
        let sigma = echo.map_or(s.hit_sigma, |z| s.hit_sigma + s.range_sigma * f64::from(z)) as f32;
        let length = echo.map_or(s.reach, |z| f64::from(z + 4.0 * sigma));
        let res = self.window.res.metres();
        let (x0, y0) = (reading.sensor.x, reading.sensor.y);
        rays.clear();
        self.cells.clear();
        for &angle in &self.ray_angles {
            let heading = reading.sensor.theta + angle;
            let faces = self.ray_faces(heading);
            let (dy, dx) = heading.sin_cos();
            let start = self.cells.len();
            let mut open = 1.0f32;
            let (mut echo_density, mut heard) = (0.0f32, 0.0f32);
            let walk =
                SegmentCells::new(self.window.res, x0, y0, x0 + length * dx, y0 + length * dy)?;
            for cell in walk {
                let Some(index) = self.window.index(cell) else {
                    break;
                };
                let (cx, cy) = self.window.res.cell_corner(cell);
                let (near, far) = slab(x0, dx, cx, res).and(slab(y0, dy, cy, res));
                let (near, far) = (near.max(0.0) as f32, far.max(0.0) as f32);
                let here = self.stop[index];
                let o = &self.orientation[index];
                let echoes: f32 = (0..ORIENTATIONS).map(|b| o[b] * faces.echo[b]).sum();
                let stop = open * here;
                match echo {
                    Some(z) => {
                        if z >= near - 4.0 * sigma && z <= far + 4.0 * sigma {
                            echo_density += stop * echoes * face_density(z, near, far, sigma);
                        }
                        if far < z - 2.0 * sigma {
                            heard += stop * echoes;
                        }
                    }
                    None => heard += stop * echoes,
                }
                self.cells.push(RayCell {
                    cell: index as u32,
                    stop,
                    echo: echoes,
                    near,
                    far,
                });
                open *= 1.0 - here;
                if open < 1e-4 {
                    break;
                }
            }
            rays.push(RayWalk {
                faces,
                start,
                end: self.cells.len(),
                through: open,
                echo_density,
                quiet: (1.0 - heard).max(1e-6),
            });
        }
        let modelled = (1.0 - s.random_weight - s.dropout_weight) as f32;
        let all_quiet: f32 = rays.iter().map(|r| r.quiet).product();
        // Per ray, the chance it sent the echo read; and the weight of the
        // rays' silence (before the echo, or throughout).
        let mut echoed = [0.0f32; MAX_RAYS];
        let (likelihood, silence) = match echo {
            None => {
                let like = s.dropout_weight as f32 + modelled * all_quiet;
                (like, modelled * all_quiet / like)
            }
            Some(_) => {
                let mut sum = 0.0f32;
                for (e, r) in echoed.iter_mut().zip(rays.iter()) {
                    *e = modelled * r.echo_density * all_quiet / r.quiet;
                    sum += *e;
                }
                let like = (s.random_weight / s.max_range) as f32 + sum;
                echoed.iter_mut().for_each(|e| *e /= like);
                // Whatever sent the echo, every other ray sent none before it.
                (like, 1.0)
            }
        };
        for (ray, &walk) in rays.iter().enumerate() {
            let r_echo = echoed[ray];
            if let (Some(z), true) = (echo, r_echo > 1e-6 && walk.echo_density > 0.0) {
                self.count_echo(&walk, z, sigma, r_echo);
            }
            let r_quiet = (silence - r_echo).max(0.0);
            if r_quiet > 1e-6 {
                self.count_silence(&walk, echo.map(|z| z - 2.0 * sigma), r_quiet);
            }
        }
        Ok(f64::from(likelihood.max(f32::MIN_POSITIVE)).ln())
    }

    /// Ray `walk` echoed at `z` with probability `weight`: where it
    /// stopped, in proportion to each cell's share of its echo density.
    fn count_echo(&mut self, walk: &RayWalk, z: f32, sigma: f32, weight: f32) {
        let mut after = 0.0f32;
        for k in (walk.start..walk.end).rev() {
            let c = self.cells[k];
            let here = if z >= c.near - 4.0 * sigma && z <= c.far + 4.0 * sigma {
                c.stop * c.echo * face_density(z, c.near, c.far, sigma) / walk.echo_density
            } else {
                0.0
            };
            self.add(c.cell as usize, weight * here, weight * after);
            if here > 1e-7 {
                let faces = &mut self.faces[c.cell as usize];
                for (f, ln) in faces.iter_mut().zip(walk.faces.ln_echo) {
                    *f += weight * here * ln;
                }
            }
            after += here;
        }
    }

    /// Ray `walk` sent no echo up to `quiet_until` (or at all, for `None`)
    /// with probability `weight`: it stopped silently in a cell before
    /// that, or went on past it.
    fn count_silence(&mut self, walk: &RayWalk, quiet_until: Option<f32>, weight: f32) {
        let before = |c: &RayCell| quiet_until.is_none_or(|q| c.far < q);
        let mut on = walk.through;
        let mut silent_total = 0.0f32;
        for c in &self.cells[walk.start..walk.end] {
            if before(c) {
                silent_total += c.stop * (1.0 - c.echo);
            } else {
                on += c.stop;
            }
        }
        let norm = silent_total + on;
        if norm <= 0.0 {
            return;
        }
        let mut after = on / norm;
        for k in (walk.start..walk.end).rev() {
            let c = self.cells[k];
            if !before(&c) {
                continue;
            }
            let here = c.stop * (1.0 - c.echo) / norm;
            self.add(c.cell as usize, weight * here, weight * after);
            if here > 1e-7 {
                let faces = &mut self.faces[c.cell as usize];
                for (f, ln) in faces.iter_mut().zip(walk.faces.ln_silent) {
                    *f += weight * here * ln;
                }
            }
            after += here;
        }
    }

    fn add(&mut self, cell: usize, stops: f32, passes: f32) {
        self.stops[cell] += stops;
        self.passes[cell] += passes;
        self.reached[cell] = true;
    }

    /// Each reached cell's probability from its stops and passes, its
    /// orientation from its faces' evidence. Returns how many cells
    /// crossed p = 0.5.
    fn maximize(&mut self) -> usize {
        let prior = self.settings.prior as f32;
        let mut changes = 0;
        for index in 0..self.stop.len() {
            let (s, p) = (self.stops[index], self.passes[index]);
            if s + p <= 0.0 {
                continue;
            }
            let w = self.settings.prior_weight as f32;
            let m = ((s + w * prior) / (s + p + w)).clamp(0.01, 0.99);
            changes += usize::from((m > 0.5) != (self.stop[index] > 0.5));
            self.stop[index] = m;
            let f = &self.faces[index];
            if f.iter().any(|&v| v != 0.0) {
                let top = f.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let weights = f.map(|v| (v - top).exp());
                let total: f32 = weights.iter().sum();
                self.orientation[index] = weights.map(|v| v / total);
            }
        }
        changes
    }

    /// The decided cells as a map at `limits`; see the module docs.
    fn into_map(self, initial: &TileMap, limits: ClampLimits) -> Result<TileMap, MappingError> {
        let size = initial.tile_size();
        let mut map = TileMap::new(self.window.res, size, limits);
        let mut tiles: deog_grid::KeyMap<deog_grid::TileKey, TileDelta> = Default::default();
        for index in 0..self.stop.len() {
            let cell = self.window.cell(index);
            let belief = if self.stops[index] + self.passes[index] >= MIN_RAYS {
                let m = f64::from(self.stop[index]);
                let logit = (m / (1.0 - m)).ln();
                if logit.abs() < self.settings.decide_nats {
                    continue;
                }
                logit.clamp(-self.settings.belief_nats, self.settings.belief_nats)
            } else if self.settings.keep_unreached && !self.reached[index] {
                match initial.get(cell) {
                    Some(b) if b.raw() != 0 => b.nats(),
                    _ => continue,
                }
            } else {
                continue;
            };
            let raw = (belief * LOG_ODDS_SCALE).round() as i16;
            let (key, offset) = size.split(cell);
            tiles
                .entry(key)
                .or_insert_with(|| TileDelta::zero(key, size))
                .raw_mut()[offset.index(size)] = raw;
        }
        for delta in tiles.values() {
            map.apply(delta)?;
        }
        Ok(map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::{LogOdds, TileSize};

    const RES: f64 = 0.05;

    /// A specular sonar's reading of the wall `y = wall_y` (x in
    /// [-6, 6]): each ray of the fan that meets it within 30° of its
    /// normal echoes; the nearest echo is read.
    fn read_wall(sensor: Pose2, wall_y: f64) -> Option<f64> {
        let mut best: Option<f64> = None;
        for i in 0..=15 {
            let a = sensor.theta + 15f64.to_radians() * (2.0 * i as f64 / 15.0 - 1.0);
            let (s, c) = a.sin_cos();
            if s <= 1e-9 {
                continue;
            }
            let t = (wall_y - sensor.y) / s;
            let x = sensor.x + t * c;
            if t > 10.0 || x.abs() > 6.0 {
                continue;
            }
            // The wall's normal is along y: incidence is the angle from it.
            if s.acos() <= 30f64.to_radians() {
                best = Some(best.map_or(t, |b: f64| b.min(t)));
            }
        }
        best
    }

    fn map_with(cells: impl IntoIterator<Item = (i32, i32, f64)>) -> TileMap {
        let res = Resolution::new(RES).unwrap();
        let size = TileSize::new(64).unwrap();
        let mut map = TileMap::new(res, size, ClampLimits::default());
        for (x, y, nats) in cells {
            let (key, offset) = size.split(CellIndex::new(x, y));
            let mut delta = TileDelta::zero(key, size);
            delta.raw_mut()[offset.index(size)] = (nats * LOG_ODDS_SCALE) as i16;
            map.apply(&delta).unwrap();
        }
        map
    }

    fn class(map: &TileMap, x: i32, y: i32) -> Option<bool> {
        map.get(CellIndex::new(x, y))
            .map(LogOdds::nats)
            .filter(|n| n.abs() > 0.5)
            .map(|n| n > 0.0)
    }

    /// A Scout's readings of the wall `y = wall_y` along a straight drive
    /// at `y`, from x = -3 to 3.
    fn drive_along(y: f64, wall_y: f64) -> Vec<SonarReading> {
        let ring = deog_grid::SensorRing::scout();
        let mut readings = Vec::new();
        for step in 0..120 {
            let robot = Pose2::new(-3.0 + 0.05 * f64::from(step), y, 0.0);
            for sensor in ring.sensor_poses(&robot) {
                readings.push(SonarReading {
                    sensor,
                    range: read_wall(sensor, wall_y),
                });
            }
        }
        readings
    }

    fn fit(initial: &TileMap, readings: &[SonarReading]) -> (TileMap, ForwardStats) {
        fit_forward(
            initial,
            readings,
            &ForwardSettings::default(),
            ClampLimits::default(),
        )
        .expect("a fit")
    }

    /// A robot driving along a wall 1 m away: the wall, which its sonars
    /// meet mostly at grazing angles, stays; the space before it is free.
    #[test]
    fn a_wall_passed_along_stays_and_the_space_before_it_is_free() {
        let readings = drive_along(1.0, 2.0);
        // The first guess: the wall's cells (row 40 holds y in [2, 2.05))
        // and the rows before it free.
        let wall = (-100..100).map(|x| (x, 40, 2.0));
        let free = (-100..100).flat_map(|x| (15..40).map(move |y| (x, y, -2.0)));
        let (map, stats) = fit(&map_with(wall.chain(free)), &readings);
        assert_eq!(stats.readings, readings.len());
        assert!(stats.cells_reached > 1000, "{stats:?}");
        let walls = (-60..60)
            .filter(|&x| class(&map, x, 40) == Some(true))
            .count();
        let before = (-60..60)
            .flat_map(|x| (22..38).map(move |y| (x, y)))
            .filter(|&(x, y)| class(&map, x, y) == Some(false))
            .count();
        assert!(walls >= 110, "walls kept {walls} of 120, {stats:?}");
        assert!(before >= 120 * 16 * 9 / 10, "free before the wall {before}");
        // Nothing behind the wall was reached: unknown, not guessed.
        let behind = (-60..60)
            .flat_map(|x| (42..50).map(move |y| (x, y)))
            .filter(|&(x, y)| map.get(CellIndex::new(x, y)).is_some())
            .count();
        assert_eq!(behind, 0);
    }

    /// A wall the first guess put in front of the true one (an arc marked
    /// where an echo did not come from) is taken away: the readings that
    /// crossed it came back from the wall behind.
    #[test]
    fn a_wall_in_front_of_the_echoes_is_taken_away() {
        let readings = drive_along(0.5, 2.0);
        let wall = (-100..100).map(|x| (x, 40, 2.0));
        let arc = (-20..20).map(|x| (x, 30, 2.0));
        let free =
            (-100..100).flat_map(|x| (5..40).filter(|&y| y != 30).map(move |y| (x, y, -2.0)));
        let (map, _) = fit(&map_with(wall.chain(arc).chain(free)), &readings);
        let arc_left = (-20..20)
            .filter(|&x| class(&map, x, 30) == Some(true))
            .count();
        let arc_freed = (-20..20)
            .filter(|&x| class(&map, x, 30) == Some(false))
            .count();
        assert_eq!(arc_left, 0, "{arc_freed} of 40 freed");
        assert!(arc_freed >= 36, "{arc_freed} of 40 freed");
        let walls = (-60..60)
            .filter(|&x| class(&map, x, 40) == Some(true))
            .count();
        assert!(walls >= 110, "walls kept {walls} of 120");
    }

    /// The same fit with the first guess's unreached cells kept: behind
    /// the wall the guess stays.
    #[test]
    fn unreached_cells_keep_the_first_guess_when_asked() {
        let readings = drive_along(1.0, 2.0);
        let wall = (-100..100).map(|x| (x, 40, 2.0));
        let inside = (-100..100).map(|x| (x, 45, 3.0));
        let settings = ForwardSettings {
            keep_unreached: true,
            ..ForwardSettings::default()
        };
        let (map, _) = fit_forward(
            &map_with(wall.chain(inside)),
            &readings,
            &settings,
            ClampLimits::default(),
        )
        .unwrap();
        assert_eq!(class(&map, 0, 45), Some(true));
    }

    #[test]
    fn bad_input_is_an_error_naming_what_is_wrong() {
        let initial = map_with([(0, 0, 1.0)]);
        let settings = ForwardSettings::default();
        let limits = ClampLimits::default();
        let none = fit_forward(&initial, &[], &settings, limits).unwrap_err();
        assert!(none.to_string().contains("none to fit"), "{none}");
        let nan = SonarReading {
            sensor: Pose2::new(f64::NAN, 0.0, 0.0),
            range: None,
        };
        let err = fit_forward(&initial, &[nan], &settings, limits).unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
        let negative = SonarReading {
            sensor: Pose2::new(0.0, 0.0, 0.0),
            range: Some(-1.0),
        };
        let err = fit_forward(&initial, &[negative], &settings, limits).unwrap_err();
        assert!(err.to_string().contains("range"), "{err}");
        let far = [
            SonarReading {
                sensor: Pose2::new(0.0, 0.0, 0.0),
                range: None,
            },
            SonarReading {
                sensor: Pose2::new(1e6, 1e6, 0.0),
                range: None,
            },
        ];
        let err = fit_forward(&initial, &far, &settings, limits).unwrap_err();
        assert!(err.to_string().contains("cells"), "{err}");
        let bad = ForwardSettings {
            rays: 1,
            ..ForwardSettings::default()
        };
        let err = fit_forward(&initial, &far[..1], &bad, limits).unwrap_err();
        assert!(err.to_string().contains("rays"), "{err}");
    }

    #[test]
    fn a_ring_frame_becomes_readings_where_each_sonar_fired() {
        let ring = deog_grid::SensorRing::scout();
        let mut out = Vec::new();
        let ranges: Vec<f64> = (0..16).map(|k| if k == 3 { 10.668 } else { 1.0 }).collect();
        let pose = Pose2::new(1.0, 2.0, 0.5);
        ring_readings(
            &ring,
            deog_grid::RingFiring::Together,
            &pose,
            None,
            echo_below(&ranges, 10.668),
            &mut out,
        );
        assert_eq!(out.len(), 16);
        assert_eq!(out[3].range, None);
        assert_eq!(out[0].range, Some(1.0));
        let first = pose.compose(&ring.mounts()[0]);
        assert!((out[0].sensor.x - first.x).abs() < 1e-12);
        // Fired in turn while turning: the first sonar fired earlier, so
        // at another heading than the frame's.
        let mut turned = Vec::new();
        ring_readings(
            &ring,
            deog_grid::RingFiring::Sequential { period_s: 0.1 },
            &pose,
            Some(&Pose2::new(0.0, 0.0, -1.0)),
            echo_below(&ranges, 10.668),
            &mut turned,
        );
        assert!((turned[0].sensor.theta - out[0].sensor.theta).abs() > 0.05);
        assert!((turned[15].sensor.theta - out[15].sensor.theta).abs() < 1e-9);
    }
}
