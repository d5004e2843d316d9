//! The likelihood field (Probabilistic Robotics, section 6.4; amcl's
//! `likelihood_field` model) for any rig: each echo's endpoint, the beam's
//! mount composed with the particle and carried the measured range along
//! the beam's axis, is judged by its distance `d` to the nearest occupied
//! cell:
//!
//! `p = z_hit · N(d; 0, σ_hit) + z_rand / max_range`
//!
//! with `d` clamped at [`LikelihoodFieldParams::max_distance`] and
//! `max_range` the beam's. No-echo readings are skipped: a field has
//! nothing to say about a ray that met nothing. A sonar's cone is taken
//! along its axis, as a laser's ray.
//!
//! **The map is being built while we localize.** An endpoint in space the
//! map has not seen (a tile the server does not have, or unknown cells
//! with no occupied cell within the maximum distance) is neither a hit
//! nor a miss: it is scored as an endpoint
//! [`LikelihoodFieldParams::unknown_distance`] from a wall would be. The
//! default, two σ (0.4 m), gives about the mean likelihood of an endpoint
//! spread evenly over the field's range: well below a hit, far above a
//! miss in known free space. Particles whose endpoints run into the
//! unknown are then not wiped out for it, nor favoured over those whose
//! endpoints meet the walls the map knows.
//!
//! **Beams and tempering.** Of a frame's readings, at most
//! [`LikelihoodFieldParams::max_beams`] evenly spread are scored (amcl's
//! `laser_max_beams`); consecutive laser beams see the same wall and
//! repeat each other's evidence. As in the beam model
//! ([`crate::beam_model`]), a particle's log-likelihood is `τ · Σₖ ln pₖ`
//! over the echoes scored, and the frame counts as `echoes · τ`
//! independent observations ([`SensorModel::observations`], taken from the
//! last frame scored). The default τ, 1/30, counts 60 laser beams as two.
//!
//! **Speed.** The distances come from per-tile distance fields
//! ([`crate::distance_field`]) held by [`LocalMap`], a byte a cell; the
//! model tabulates the log-likelihood of every code once, in the beam
//! model's fixed point, so a beam costs a pose transform, one byte read
//! and one table read, summed as integers.

use std::collections::HashMap;

use deog_grid::{Pose2, TileKey};
use deog_rig::{Reading, Rig};

use crate::beam_model::TABLE_SCALE;
use crate::distance_field::{FIELD_UNKNOWN, FieldCodes, FieldSpec, FieldWindow};
use crate::error::{LocalizerError, within};
use crate::local_map::LocalMap;
use crate::numeric::floor_i64;
use crate::refine::{InterpolatedField, RefineParams, refine_pose};
use crate::sensors::SensorModel;

/// The most readings a frame of one rig may hold, and so the most beams.
const MAX_BEAMS: usize = deog_rig::rig::MAX_READINGS;

/// The lowest tabulated log-likelihood of a beam, nats: keeps the integer
/// sum of the most beams far from overflow.
const FLOOR_NATS: f64 = -30.0;

/// Tiles the dense grid of [`LikelihoodField::tiles_needed`] may span;
/// beyond, a hash map counts them.
const DENSE_TILE_GRID: i64 = 1 << 18;

/// The likelihood field's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LikelihoodFieldParams {
    /// Weight of hits (amcl's `laser_z_hit`).
    pub z_hit: f64,
    /// Weight of random readings, spread evenly over the beam's range
    /// (amcl's `laser_z_rand`).
    pub z_rand: f64,
    /// σ of a hit's distance from the nearest occupied cell, metres
    /// (amcl's `laser_sigma_hit`).
    pub sigma_hit: f64,
    /// Distances past this, metres, count as this (amcl's
    /// `laser_likelihood_max_dist`); how far the distance fields reach.
    pub max_distance: f64,
    /// The most readings of a frame scored, evenly spread over the rig's
    /// readings (amcl's `laser_max_beams`).
    pub max_beams: usize,
    /// τ: the exponent applied to the product of the scored beams'
    /// likelihoods.
    pub tempering: f64,
    /// τ while the filter has not settled on a pose (global localization,
    /// recovery); `None`: [`Self::tempering`]. A softer τ while searching
    /// keeps look-alike places alive until the frames tell them apart; a
    /// sharper one once settled follows the robot closely.
    pub search_tempering: Option<f64>,
    /// An endpoint in unknown space scores as one this far from an
    /// occupied cell, metres.
    pub unknown_distance: f64,
    /// Beam skipping (amcl's `do_beamskip`): a beam whose endpoint lies
    /// within `beam_skip_distance` of a wall for fewer than this share of
    /// the particles is left out of the frame, for every particle: it most
    /// likely met something the map does not hold (a person, a moved box),
    /// and scoring it would pull the filter off the pose the other beams
    /// agree on. 0 scores every beam.
    pub beam_skip_threshold: f64,
    /// How near a wall an endpoint must fall to agree with the map,
    /// metres (amcl's `beam_skip_distance`).
    pub beam_skip_distance: f64,
    /// When more than this share of the beams would be left out, none is
    /// (the particles disagree with most beams: the filter is searching,
    /// not tracking; amcl's `beam_skip_error_threshold`).
    pub beam_skip_error_threshold: f64,
    /// The reported estimate refined by matching the frame's echoes, every
    /// one of them, against the distance field ([`crate::refine`]); `None`
    /// reports the filter's estimate as it is.
    pub refine: Option<RefineParams>,
}

impl Default for LikelihoodFieldParams {
    /// amcl's figures for the likelihood field (z_hit 0.95, z_rand 0.05,
    /// σ 0.2 m, 2 m, 60 beams) and its beam skipping (0.3 of the
    /// particles within 0.5 m, unless over 0.9 of the beams would go);
    /// τ 1/30; unknown space at two σ; the estimate refined with
    /// [`RefineParams::default`]. On the real laser logs, whose odometry
    /// is far worse, 180 beams at τ 0.5 tracked best (BENCHMARKS.md, real
    /// logs).
    fn default() -> Self {
        Self {
            z_hit: 0.95,
            z_rand: 0.05,
            sigma_hit: 0.2,
            max_distance: 2.0,
            max_beams: 60,
            tempering: 1.0 / 30.0,
            search_tempering: None,
            unknown_distance: 0.4,
            beam_skip_threshold: 0.3,
            beam_skip_distance: 0.5,
            beam_skip_error_threshold: 0.9,
            refine: Some(RefineParams::default()),
        }
    }
}

impl LikelihoodFieldParams {
    /// The parameters if each is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("z_hit", self.z_hit, 0.0, 1.0)?;
        within("z_rand", self.z_rand, 1e-4, 1.0)?;
        within("sigma_hit", self.sigma_hit, 0.005, 5.0)?;
        self.field_spec()?;
        if !(1..=MAX_BEAMS).contains(&self.max_beams) {
            return Err(LocalizerError::Invalid(format!(
                "max_beams must be in [1, {MAX_BEAMS}], got {}",
                self.max_beams
            )));
        }
        within("tempering", self.tempering, 1e-3, 1.0)?;
        if let Some(search) = self.search_tempering {
            within("search_tempering", search, 1e-3, 1.0)?;
        }
        within(
            "unknown_distance",
            self.unknown_distance,
            0.0,
            self.max_distance,
        )?;
        within("beam_skip_threshold", self.beam_skip_threshold, 0.0, 1.0)?;
        within(
            "beam_skip_distance",
            self.beam_skip_distance,
            0.0,
            self.max_distance,
        )?;
        within(
            "beam_skip_error_threshold",
            self.beam_skip_error_threshold,
            0.0,
            1.0,
        )?;
        if let Some(refine) = self.refine {
            refine.validate()?;
        }
        Ok(self)
    }

    /// The distance fields these parameters read.
    pub fn field_spec(&self) -> Result<FieldSpec, LocalizerError> {
        FieldSpec {
            max_distance: self.max_distance,
        }
        .validate()
    }

    /// `ln p` of an endpoint `distance` metres from the nearest occupied
    /// cell, on a beam of `max_range` metres.
    pub fn log_likelihood(&self, distance: f64, max_range: f64) -> f64 {
        let d = distance.min(self.max_distance);
        let sigma = self.sigma_hit;
        let gaussian =
            (-0.5 * (d / sigma).powi(2)).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt());
        (self.z_hit * gaussian + self.z_rand / max_range).ln()
    }
}

/// A beam's log-likelihood per field code, in units of `1 / TABLE_SCALE`
/// nats.
type CodeTable = [i32; 256];

/// The likelihood field of one rig's frames.
#[derive(Debug, Clone)]
pub struct LikelihoodField {
    rig: Rig,
    params: LikelihoodFieldParams,
    spec: FieldSpec,
    /// The readings scored, by index in the frame.
    scored: Vec<usize>,
    /// One table per distinct maximum range among the rig's beams.
    tables: Vec<CodeTable>,
    /// Each of the rig's beams' table.
    table_of: Vec<usize>,
    /// The last frame's echoes scored.
    echoes: usize,
    /// Field codes of every endpoint for every particle, while beams are
    /// judged for skipping.
    codes: Vec<u8>,
    /// Whether the filter is searching ([`SensorModel::set_searching`]).
    searching: bool,
}

/// An echo's endpoint in the robot's frame, metres, and its beam's table.
#[derive(Debug, Clone, Copy)]
struct Endpoint {
    x: f64,
    y: f64,
    table: usize,
}

impl LikelihoodField {
    /// The model of `rig`'s frames with `params`.
    pub fn new(rig: Rig, params: LikelihoodFieldParams) -> Result<Self, LocalizerError> {
        let params = params.validate()?;
        let spec = params.field_spec()?;
        let readings = rig.readings();
        let count = params.max_beams.min(readings);
        // Evenly spread, first and last included (amcl's step).
        let scored: Vec<usize> = if count == 1 {
            vec![0]
        } else {
            (0..count)
                .map(|i| i * (readings - 1) / (count - 1))
                .collect()
        };
        let mut ranges: Vec<f64> = Vec::new();
        let mut table_of = Vec::with_capacity(readings);
        for beam in rig.beams() {
            let at = match ranges.iter().position(|&r| r == beam.max_range) {
                Some(at) => at,
                None => {
                    ranges.push(beam.max_range);
                    ranges.len() - 1
                }
            };
            table_of.push(at);
        }
        let tables = ranges
            .iter()
            .map(|&max_range| code_table(&params, &spec, max_range))
            .collect();
        Ok(Self {
            echoes: scored.len(),
            codes: Vec::new(),
            searching: false,
            rig,
            params,
            spec,
            scored,
            tables,
            table_of,
        })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The parameters.
    pub fn params(&self) -> &LikelihoodFieldParams {
        &self.params
    }

    /// The readings scored, by index in the frame.
    pub fn scored_readings(&self) -> &[usize] {
        &self.scored
    }

    /// The τ frames are scored with now.
    pub fn tempering(&self) -> f64 {
        match self.params.search_tempering {
            Some(search) if self.searching => search,
            _ => self.params.tempering,
        }
    }

    /// The echoes among the scored readings of `readings`, as endpoints in
    /// the robot's frame; readings that are not ranges are passed over.
    fn endpoints(&self, readings: &[f64]) -> Vec<Endpoint> {
        let beams = self.rig.beams();
        self.scored
            .iter()
            .filter_map(|&i| {
                let beam = beams.get(i)?;
                let Some(Reading::Echo(range)) = beam.classify(*readings.get(i)?) else {
                    return None;
                };
                let (sin, cos) = beam.mount.theta.sin_cos();
                Some(Endpoint {
                    x: beam.mount.x + range * cos,
                    y: beam.mount.y + range * sin,
                    table: self.table_of[i],
                })
            })
            .collect()
    }

    /// Every echo of `readings`, scored or not, as an endpoint in the
    /// robot's frame.
    fn all_endpoints(&self, readings: &[f64]) -> Vec<(f64, f64)> {
        self.rig
            .beams()
            .iter()
            .zip(readings)
            .filter_map(|(beam, &range)| match beam.classify(range)? {
                Reading::Echo(range) => {
                    let (sin, cos) = beam.mount.theta.sin_cos();
                    Some((beam.mount.x + range * cos, beam.mount.y + range * sin))
                }
                Reading::NoEcho => None,
            })
            .collect()
    }

    /// Scores `poses` over the fields of `tiles` (built where missing),
    /// pushing onto `out`: with beam skipping when `may_skip`
    /// ([`Self::score_over`]), else every endpoint at every pose
    /// ([`Self::score_plain`]). Returns the fields built and the
    /// endpoints scored.
    fn score_in_fields(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        poses: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
        may_skip: bool,
    ) -> Result<(usize, usize), LocalizerError> {
        let endpoints = self.endpoints(readings);
        let built = map.ensure_fields(tiles, &self.spec)?;
        let scored = match (map.field_window(tiles), may_skip) {
            (FieldWindow::Dense(window), true) => self.score_over(&window, &endpoints, poses, out),
            (FieldWindow::Sparse(window), true) => self.score_over(&window, &endpoints, poses, out),
            (FieldWindow::Dense(window), false) => {
                self.score_plain(&window, &endpoints, poses, out)
            }
            (FieldWindow::Sparse(window), false) => {
                self.score_plain(&window, &endpoints, poses, out)
            }
        };
        Ok((built, scored))
    }

    /// Scores `particles` over `window`, pushing onto `out`; returns how
    /// many of the endpoints were scored (the rest skipped, see
    /// [`LikelihoodFieldParams::beam_skip_threshold`]).
    fn score_over(
        &mut self,
        window: &impl FieldCodes,
        endpoints: &[Endpoint],
        particles: &[Pose2],
        out: &mut Vec<f64>,
    ) -> usize {
        if self.params.beam_skip_threshold > 0.0 && particles.len() > 1 {
            return self.score_skipping(window, endpoints, particles, out);
        }
        self.score_plain(window, endpoints, particles, out)
    }

    /// As [`Self::score_over`], every endpoint scored at every pose, none
    /// skipped: each pose's score its own, whatever is scored with it.
    fn score_plain(
        &self,
        window: &impl FieldCodes,
        endpoints: &[Endpoint],
        particles: &[Pose2],
        out: &mut Vec<f64>,
    ) -> usize {
        let beams: Vec<(f64, f64, &CodeTable)> = endpoints
            .iter()
            .map(|e| (e.x, e.y, &self.tables[e.table]))
            .collect();
        let to_nats = self.tempering() / TABLE_SCALE;
        out.reserve(particles.len());
        for p in particles {
            let (sin, cos) = p.theta.sin_cos();
            let mut sum = 0i32;
            for &(ex, ey, table) in &beams {
                let x = p.x + cos * ex - sin * ey;
                let y = p.y + sin * ex + cos * ey;
                sum += table[usize::from(window.code_at(x, y))];
            }
            out.push(f64::from(sum) * to_nats);
        }
        endpoints.len()
    }

    /// As [`Self::score_over`] with beam skipping: a first pass finds each
    /// endpoint's field code for every particle and counts, per beam, the
    /// particles that put it near a wall; the second sums the beams enough
    /// particles agree on.
    fn score_skipping(
        &mut self,
        window: &impl FieldCodes,
        endpoints: &[Endpoint],
        particles: &[Pose2],
        out: &mut Vec<f64>,
    ) -> usize {
        let n = endpoints.len();
        let near = self.spec.code_of(self.params.beam_skip_distance);
        self.codes.clear();
        self.codes.reserve(particles.len() * n);
        let mut agree = vec![0u32; n];
        for p in particles {
            let (sin, cos) = p.theta.sin_cos();
            for (e, count) in endpoints.iter().zip(agree.iter_mut()) {
                let code = window.code_at(p.x + cos * e.x - sin * e.y, p.y + sin * e.x + cos * e.y);
                *count += u32::from(code <= near);
                self.codes.push(code);
            }
        }
        let least = self.params.beam_skip_threshold * particles.len() as f64;
        let mut keep: Vec<bool> = agree.iter().map(|&a| f64::from(a) >= least).collect();
        let kept = keep.iter().filter(|&&k| k).count();
        let skipped = n - kept;
        if skipped as f64 > self.params.beam_skip_error_threshold * n as f64 {
            keep.fill(true);
        }
        let beams: Vec<(bool, &CodeTable)> = endpoints
            .iter()
            .zip(&keep)
            .map(|(e, &k)| (k, &self.tables[e.table]))
            .collect();
        let to_nats = self.tempering() / TABLE_SCALE;
        out.reserve(particles.len());
        for codes in self.codes.chunks_exact(n.max(1)).take(particles.len()) {
            let mut sum = 0i32;
            for (&code, &(k, table)) in codes.iter().zip(&beams) {
                if k {
                    sum += table[usize::from(code)];
                }
            }
            out.push(f64::from(sum) * to_nats);
        }
        if n == 0 {
            out.extend(std::iter::repeat_n(0.0, particles.len()));
        }
        keep.iter().filter(|&&k| k).count()
    }
}

/// The log-likelihood of every field code for a beam of `max_range`.
fn code_table(params: &LikelihoodFieldParams, spec: &FieldSpec, max_range: f64) -> CodeTable {
    let fixed = |distance: f64| {
        let nats = params.log_likelihood(distance, max_range).max(FLOOR_NATS);
        (nats * TABLE_SCALE).round() as i32
    };
    let mut table = [0; 256];
    for (code, entry) in table.iter_mut().enumerate() {
        *entry = match spec.distance_of(code as u8) {
            Some(distance) => fixed(distance),
            None => fixed(params.unknown_distance),
        };
    }
    debug_assert_eq!(
        table[usize::from(FIELD_UNKNOWN)],
        fixed(params.unknown_distance)
    );
    table
}

impl SensorModel for LikelihoodField {
    fn readings(&self) -> usize {
        self.rig.readings()
    }

    fn reach(&self) -> f64 {
        self.rig.reach()
    }

    fn observations(&self) -> f64 {
        self.echoes.max(1) as f64 * self.tempering()
    }

    fn check_frame(&self, readings: &[f64]) -> Result<(), LocalizerError> {
        self.rig
            .check_frame(readings)
            .map_err(|e| LocalizerError::Invalid(e.to_string()))
    }

    /// The tiles the scored echoes' endpoints fall in, over every
    /// particle, sorted; when they are more than the map's
    /// [`LocalMap::field_capacity`], those met most often.
    fn tiles_needed(&self, map: &LocalMap, particles: &[Pose2], readings: &[f64]) -> Vec<TileKey> {
        let endpoints = self.endpoints(readings);
        endpoint_tiles(map, particles, &endpoints, map.field_capacity())
    }

    fn missing_tiles(&self, map: &LocalMap, needed: &[TileKey]) -> Vec<TileKey> {
        map.missing_field_tiles(needed, &self.spec)
    }

    fn tile_capacity(&self, map: &LocalMap) -> usize {
        map.field_capacity()
    }

    fn score_particles(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        particles: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError> {
        self.echoes = self.endpoints(readings).len();
        let (built, scored) = self.score_in_fields(map, tiles, particles, readings, out, true)?;
        self.echoes = scored;
        Ok(built)
    }

    fn score_poses(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        poses: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError> {
        Ok(self
            .score_in_fields(map, tiles, poses, readings, out, false)?
            .0)
    }

    fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<f64, LocalizerError> {
        self.check_frame(readings)?;
        let pose = pose.validate("pose")?;
        let particles = std::slice::from_ref(&pose);
        let tiles = self.tiles_needed(map, particles, readings);
        let mut out = Vec::with_capacity(1);
        self.score_particles(map, &tiles, particles, readings, &mut out)?;
        Ok(out[0])
    }

    fn set_searching(&mut self, searching: bool) {
        self.searching = searching;
    }

    /// A laser's likelihood peaks within centimetres and a degree: the
    /// mean of a mode spread over bins misses the peak, and over the
    /// Intel log's global starts judging modes at their mean lost 4 of 20
    /// (BENCHMARKS.md, real logs).
    fn judges_modes_at_mean(&self) -> bool {
        false
    }

    fn refines(&self) -> bool {
        self.params.refine.is_some()
    }

    fn refine_pose(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<Option<Pose2>, LocalizerError> {
        let Some(params) = self.params.refine else {
            return Ok(None);
        };
        self.check_frame(readings)?;
        let endpoints = self.all_endpoints(readings);
        map.ensure_fields(tiles, &self.spec)?;
        let cell_m = map.settings().resolution.metres();
        let window = map.field_window(tiles);
        let field = InterpolatedField::new(&window, self.spec, cell_m);
        Ok(refine_pose(&field, &endpoints, pose, &params).map(|r| r.pose))
    }
}

/// The tiles `endpoints` (robot frame) fall in over every particle,
/// sorted; at most `capacity`, those met most often.
fn endpoint_tiles(
    map: &LocalMap,
    particles: &[Pose2],
    endpoints: &[Endpoint],
    capacity: usize,
) -> Vec<TileKey> {
    if endpoints.is_empty() || particles.is_empty() {
        return Vec::new();
    }
    let settings = map.settings();
    let inv_res = 1.0 / settings.resolution.metres();
    let shift = settings.tile_size.cells().trailing_zeros();
    // Every endpoint lies within `radius` of its particle.
    let radius = endpoints.iter().map(|e| e.x.hypot(e.y)).fold(0.0, f64::max);
    // A particle this near the origin has every endpoint in a cell the
    // grid can index; one farther off is passed over (its endpoints read
    // as unknown).
    let far = f64::from(i32::MAX) / inv_res - radius - 1.0;
    let usable = |p: &&Pose2| p.x.abs() < far && p.y.abs() < far;
    let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in particles.iter().filter(usable) {
        lo_x = lo_x.min(p.x);
        lo_y = lo_y.min(p.y);
        hi_x = hi_x.max(p.x);
        hi_y = hi_y.max(p.y);
    }
    if lo_x > hi_x {
        return Vec::new();
    }
    // The tile under a point, as the field window finds it: the cell,
    // then its tile.
    let tile_of = |x: f64, y: f64| {
        (
            floor_i64(x * inv_res) >> shift,
            floor_i64(y * inv_res) >> shift,
        )
    };
    let mut counts = TileCounts::new(
        tile_of(lo_x - radius, lo_y - radius),
        tile_of(hi_x + radius, hi_y + radius),
    );
    for p in particles.iter().filter(usable) {
        let (sin, cos) = p.theta.sin_cos();
        // Neighbouring beams mostly end in the same tile: count a tile
        // once per run of them.
        let mut last = (i64::MIN, i64::MIN);
        for e in endpoints {
            let x = p.x + cos * e.x - sin * e.y;
            let y = p.y + sin * e.x + cos * e.y;
            let tile = tile_of(x, y);
            if tile != last {
                counts.add(tile);
                last = tile;
            }
        }
    }
    let mut ranked = counts.into_counts();
    if ranked.len() > capacity {
        ranked.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        ranked.truncate(capacity);
    }
    let mut keys: Vec<TileKey> = ranked.into_iter().map(|(k, _)| k).collect();
    keys.sort();
    keys
}

/// Counts of tiles met: a grid over the box they can lie in while it is
/// small, else a hash map.
enum TileCounts {
    Grid {
        min: (i64, i64),
        width: i64,
        counts: Vec<u32>,
    },
    Map(HashMap<(i64, i64), u32>),
}

impl TileCounts {
    /// Counts of the tiles from `lo` to `hi`.
    fn new(lo: (i64, i64), hi: (i64, i64)) -> Self {
        let (width, height) = (hi.0 - lo.0 + 1, hi.1 - lo.1 + 1);
        if width > 0 && height > 0 && width.saturating_mul(height) <= DENSE_TILE_GRID {
            Self::Grid {
                min: lo,
                width,
                counts: vec![0; (width * height) as usize],
            }
        } else {
            Self::Map(HashMap::new())
        }
    }

    /// One more meeting with `tile`.
    #[inline]
    fn add(&mut self, tile: (i64, i64)) {
        match self {
            Self::Grid { min, width, counts } => {
                let (x, y) = (tile.0 - min.0, tile.1 - min.1);
                if (0..*width).contains(&x)
                    && let Some(n) = counts.get_mut((y * *width + x) as usize)
                {
                    *n += 1;
                }
            }
            Self::Map(map) => *map.entry(tile).or_default() += 1,
        }
    }

    /// The tiles met, with their counts.
    fn into_counts(self) -> Vec<(TileKey, u32)> {
        let key = |(x, y): (i64, i64)| TileKey::new(x as i32, y as i32);
        match self {
            Self::Grid { min, width, counts } => counts
                .into_iter()
                .enumerate()
                .filter(|(_, n)| *n > 0)
                .map(|(i, n)| {
                    let i = i as i64;
                    (key((min.0 + i % width, min.1 + i / width)), n)
                })
                .collect(),
            Self::Map(map) => map.into_iter().map(|(t, n)| (key(t), n)).collect(),
        }
    }
}
