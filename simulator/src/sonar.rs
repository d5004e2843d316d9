//! The sonar ring: what each of a robot's sonars reads in a world of walls.
//!
//! A Polaroid 6500 ranger reports the first echo to come back from anywhere
//! inside its cone, not the range along its axis. So a sonar's true range
//! is the distance from the sensor to the nearest wall point inside its
//! wedge (within ±half-angle of its axis): each wall is clipped to the wedge
//! (two half-planes through the sensor) and the nearest point of the clipped
//! piece is taken. Then, in this order: optional specular loss (with it
//! on, a grazed wall still hides what lies behind it: see [`occlusion`]),
//! optional crosstalk (a sonar hears a neighbour's shorter echo), noise
//! (the range times 1 + u, u uniform in ±`noise_fraction`), clamping to
//! [`min_range`, `max_range`], and dropouts (the reading becomes
//! `max_range`). Nothing within range reads `max_range`, with no noise.
//!
//! Speed: one frame walks the walls near the robot once, nearest buckets
//! first ([`SegmentIndex::visit_outward`]), testing each wall against the
//! wedges of the sonars not yet settled with a few multiplications (the
//! wedges' edge directions are computed once per frame; no `atan2`, and a
//! square root only for an echo that beats the sonar's best). A sonar is
//! settled once every wall still unvisited is provably farther than its
//! best echo; the frame ends when all are.
//!
//! [`min_range`]: SonarParams::min_range
//! [`max_range`]: SonarParams::max_range

pub mod occlusion;

use std::ops::ControlFlow;

use deog_grid::{Pose2, SensorRing, SonarModelParams};
use deog_world::segment_index::{Visit, distance2};
use deog_world::{Point2, Segment, SegmentIndex};
use rand::Rng;

use crate::error::SimError;
pub use crate::sonar_firing::SonarFiring;

/// The most sonars a [`SonarRing`] may have: a frame keeps its per-sonar
/// state on the stack and its unsettled sonars in one `u64` mask.
pub const MAX_SONARS: usize = 64;

/// What a wall struck at a grazing angle does to the echo. Sound reflects
/// off smooth walls like light off a mirror: past some angle of incidence
/// (between the ray and the wall's normal) little comes back to the sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Specular {
    /// Every wall inside the cone echoes, at any angle.
    Off,
    /// A wall struck past `max_incidence` (radians, from the wall's normal)
    /// gives no echo: a farther wall in the cone may answer, or none.
    Lost {
        /// Radians, in [0, π/2].
        max_incidence: f64,
    },
    /// A wall struck past `max_incidence` sends the sound on to bounce off
    /// something else before it returns, so it comes back late. Modelled as
    /// the range to that wall times `factor` (the longer path), without
    /// tracing the second bounce; a nearer direct echo still wins.
    Long {
        /// Radians, in [0, π/2].
        max_incidence: f64,
        /// The range multiplier, at least 1.
        factor: f64,
    },
}

/// Every figure of the simulated sonars. The defaults are the Polaroid 6500
/// of the Scout, equal to the grid's [`SonarModelParams`] so that the map
/// builder reads what the simulator writes: 0.1524 m (6 in) to 10.668 m
/// (35 ft), a 30° cone, ±1 % noise, no specular loss, no dropouts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarParams {
    /// The shortest range reported, metres; nearer echoes read this.
    pub min_range: f64,
    /// The longest range reported, metres; it also means "no echo".
    pub max_range: f64,
    /// Half the cone's opening angle, radians, below 80°.
    pub half_angle: f64,
    /// Noise: a range is multiplied by 1 + u, u uniform in
    /// [-noise_fraction, noise_fraction]. In [0, 0.5].
    pub noise_fraction: f64,
    /// Specular reflection, [`Specular::Off`] by default.
    pub specular: Specular,
    /// The probability that a reading is lost (reads `max_range`), [0, 1].
    pub dropout_probability: f64,
    /// The probability that a sonar hears a ring neighbour's echo (the
    /// previous or next sonar in ring order, the ring closing on itself)
    /// instead of its own, when that echo is shorter and so arrives first.
    /// In [0, 1]; 0 (off) by default.
    pub crosstalk_probability: f64,
    /// When each sonar fires within a sensor period:
    /// [`SonarFiring::Together`] (at the frame's pose) by default.
    pub firing: SonarFiring,
}

impl Default for SonarParams {
    fn default() -> Self {
        let model = SonarModelParams::default();
        Self {
            min_range: model.min_range,
            max_range: model.max_range,
            half_angle: model.half_angle,
            noise_fraction: 0.01,
            specular: Specular::Off,
            dropout_probability: 0.0,
            crosstalk_probability: 0.0,
            firing: SonarFiring::Together,
        }
    }
}

impl SonarParams {
    /// The default sonar without noise or dropouts: readings are the true
    /// ranges, clamped.
    pub fn exact() -> Self {
        Self {
            noise_fraction: 0.0,
            ..Self::default()
        }
    }

    /// The default sonar made to behave more like a real one: smooth walls
    /// lose their echo past 30° of incidence ([`Specular::Lost`]), 2 % of
    /// readings drop out, 1 % hear a neighbour (crosstalk), and the ring
    /// fires one sonar at a time ([`SonarFiring::Sequential`]).
    ///
    /// The 30° is a modelling choice: a sonar's range is the nearest wall
    /// point inside its cone, and with the default 15° half-angle that
    /// point is struck within 30° of the wall's normal while the sonar's
    /// axis is within 45° of it, so a smooth wall echoes while the sonar
    /// faces it within 45°.
    pub fn realistic() -> Self {
        Self {
            specular: Specular::Lost {
                max_incidence: 30f64.to_radians(),
            },
            dropout_probability: 0.02,
            crosstalk_probability: 0.01,
            firing: SonarFiring::Sequential,
            ..Self::default()
        }
    }

    /// Checks every figure is finite and within its documented range.
    pub fn validate(&self) -> Result<Self, SimError> {
        within("max_range", self.max_range, 0.01, 1000.0)?;
        within("min_range", self.min_range, 0.0, self.max_range)?;
        within("half_angle", self.half_angle, 1e-3, 80f64.to_radians())?;
        within("noise_fraction", self.noise_fraction, 0.0, 0.5)?;
        within("dropout_probability", self.dropout_probability, 0.0, 1.0)?;
        within(
            "crosstalk_probability",
            self.crosstalk_probability,
            0.0,
            1.0,
        )?;
        match self.specular {
            Specular::Off => {}
            Specular::Lost { max_incidence } => {
                within(
                    "specular.max_incidence",
                    max_incidence,
                    0.0,
                    std::f64::consts::FRAC_PI_2,
                )?;
            }
            Specular::Long {
                max_incidence,
                factor,
            } => {
                within(
                    "specular.max_incidence",
                    max_incidence,
                    0.0,
                    std::f64::consts::FRAC_PI_2,
                )?;
                within("specular.factor", factor, 1.0, 100.0)?;
            }
        }
        Ok(*self)
    }
}

/// Errors unless `value` is a number in `lo..=hi`.
fn within(field: &str, value: f64, lo: f64, hi: f64) -> Result<(), SimError> {
    if value >= lo && value <= hi {
        Ok(())
    } else {
        Err(SimError::invalid(
            field,
            format!("must be within [{lo}, {hi}], got {value}"),
        ))
    }
}

/// One sonar's mounting, robot frame, with its axis precomputed.
#[derive(Debug, Clone, Copy)]
struct Mount {
    x: f64,
    y: f64,
    cos: f64,
    sin: f64,
    /// Distance from the robot's centre, metres.
    radius: f64,
}

/// One sonar in the world for one frame: its position and the directions of
/// its wedge's two edges, world frame.
#[derive(Debug, Clone, Copy, Default)]
struct Wedge {
    x: f64,
    y: f64,
    /// The right (clockwise) edge; inside is to its left.
    rx: f64,
    ry: f64,
    /// The left (counter-clockwise) edge; inside is to its right.
    lx: f64,
    ly: f64,
}

/// A ring of simulated sonars: fires a frame of readings for a robot pose.
#[derive(Debug, Clone)]
pub struct SonarRing {
    mounts: Vec<Mount>,
    params: SonarParams,
    cos_half: f64,
    sin_half: f64,
    /// The largest mount radius: how far a sensor can be from the centre.
    reach: f64,
    /// cos² of the specular cut-off (0 when off: nothing is lost).
    cos2_incidence: f64,
    /// What a lost echo's range is multiplied by; infinite for "lost".
    specular_factor: f64,
    /// With specular loss on: the rays across a cone, as (cos, sin) of
    /// their angles from the axis ([`occlusion`]); empty when off.
    fan: Vec<(f64, f64)>,
}

impl SonarRing {
    /// A ring of sonars at `ring`'s mounts with `params`. Errors on bad
    /// params or more than [`MAX_SONARS`] sonars.
    ///
    /// ```
    /// use deog_grid::{Pose2, SensorRing};
    /// use deog_simulator::{SonarParams, SonarRing};
    /// use deog_world::{Point2, Segment, SegmentIndex};
    /// use rand::SeedableRng;
    ///
    /// // A wall 3 m ahead of the robot's centre, across its path.
    /// let wall = Segment::new(Point2::new(3.0, -5.0), Point2::new(3.0, 5.0));
    /// let index = SegmentIndex::new(vec![wall]);
    /// let sonars = SonarRing::new(SensorRing::scout(), SonarParams::exact())?;
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    /// let mut ranges = [0.0; 16];
    /// sonars.fire(&index, &Pose2::new(0.0, 0.0, 0.0), &mut rng, &mut ranges)?;
    /// // Sonar 0 sits on the ring, 0.2 m ahead of the centre.
    /// assert!((ranges[0] - 2.8).abs() < 1e-9);
    /// // Sonar 8 faces backwards: nothing there.
    /// assert_eq!(ranges[8], SonarParams::exact().max_range);
    /// # Ok::<(), deog_simulator::SimError>(())
    /// ```
    pub fn new(ring: SensorRing, params: SonarParams) -> Result<Self, SimError> {
        let params = params.validate()?;
        if ring.len() > MAX_SONARS {
            return Err(SimError::invalid(
                "sensor ring",
                format!("at most {MAX_SONARS} sonars, got {}", ring.len()),
            ));
        }
        let mounts: Vec<Mount> = ring
            .mounts()
            .iter()
            .map(|m| {
                let (sin, cos) = m.theta.sin_cos();
                Mount {
                    x: m.x,
                    y: m.y,
                    cos,
                    sin,
                    radius: m.x.hypot(m.y),
                }
            })
            .collect();
        let reach = mounts.iter().map(|m| m.radius).fold(0.0, f64::max);
        let (sin_half, cos_half) = params.half_angle.sin_cos();
        let (cos2_incidence, specular_factor) = match params.specular {
            Specular::Off => (0.0, 1.0),
            Specular::Lost { max_incidence } => (max_incidence.cos().powi(2), f64::INFINITY),
            Specular::Long {
                max_incidence,
                factor,
            } => (max_incidence.cos().powi(2), factor),
        };
        let fan = match params.specular {
            Specular::Off => Vec::new(),
            _ => occlusion::fan(params.half_angle),
        };
        Ok(Self {
            mounts,
            params,
            cos_half,
            sin_half,
            reach,
            cos2_incidence,
            specular_factor,
            fan,
        })
    }

    /// The Scout's 16 sonars with the default [`SonarParams`].
    pub fn scout() -> Self {
        Self::new(SensorRing::scout(), SonarParams::default())
            .expect("the Scout's ring and the default sonar figures are valid")
    }

    /// The figures in use.
    pub fn params(&self) -> &SonarParams {
        &self.params
    }

    /// Number of sonars (the length `fire` expects of its output).
    pub fn len(&self) -> usize {
        self.mounts.len()
    }

    /// Always false: a ring has at least one sonar.
    pub fn is_empty(&self) -> bool {
        self.mounts.is_empty()
    }

    /// One frame: writes each sonar's reading, in ring order, for a robot at
    /// `pose` (world frame) among the walls of `index`, with crosstalk,
    /// noise and dropouts drawn from `rng` (one draw per sonar when there
    /// is crosstalk, one per echo when there is noise and one per sonar
    /// when there are dropouts, so a given rng state always gives the same
    /// frame). Every sonar fires at `pose`, whatever [`SonarParams::firing`]
    /// says: [`fire_posed`](Self::fire_posed) takes a pose per sonar.
    /// Errors on a non-finite pose or an `out` whose length is not
    /// [`len`](Self::len).
    pub fn fire<R: Rng + ?Sized>(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        rng: &mut R,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.echoes(index, pose, out)?;
        self.finish(rng, out);
        Ok(())
    }

    /// One frame of sonars fired one after another: as [`fire`](Self::fire),
    /// but sonar `i` reads for a robot at `poses[i]`, the robot's pose when
    /// that sonar fired. Errors on a non-finite pose or a `poses` or `out`
    /// whose length is not [`len`](Self::len).
    pub fn fire_posed<R: Rng + ?Sized>(
        &self,
        index: &SegmentIndex,
        poses: &[Pose2],
        rng: &mut R,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.check_out(out)?;
        let n = self.mounts.len();
        if poses.len() != n {
            return Err(SimError::invalid(
                "poses",
                format!("expected one per sonar ({n}), got {}", poses.len()),
            ));
        }
        let Some(first) = poses.first() else {
            return Ok(());
        };
        let mut wedges = [Wedge::default(); MAX_SONARS];
        for ((w, m), pose) in wedges.iter_mut().zip(&self.mounts).zip(poses) {
            check_finite(pose)?;
            let (sin, cos) = pose.theta.sin_cos();
            *w = self.wedge(pose, cos, sin, m);
        }
        // Walk outward from the first pose; each sensor's distance from it
        // (with a hair for rounding) bounds what it can hear, as the mount
        // radius does for a frame fired at one pose.
        let center = Point2::new(first.x, first.y);
        let mut radii = [0.0; MAX_SONARS];
        for (r, w) in radii.iter_mut().zip(&wedges[..n]) {
            *r = (w.x - center.x).hypot(w.y - center.y) * (1.0 + 1e-9) + 1e-9;
        }
        let reach = radii.iter().copied().fold(0.0, f64::max);
        self.echoes_from(index, &wedges, center, |i| radii[i], reach, out);
        self.finish(rng, out);
        Ok(())
    }

    /// Crosstalk, noise, clamping and dropouts on a frame of echoes.
    fn finish<R: Rng + ?Sized>(&self, rng: &mut R, out: &mut [f64]) {
        let p = &self.params;
        if p.crosstalk_probability > 0.0 {
            self.crosstalk(rng, out);
        }
        for range in out.iter_mut() {
            if *range < p.max_range {
                if p.noise_fraction > 0.0 {
                    *range *= 1.0 + rng.random_range(-p.noise_fraction..=p.noise_fraction);
                }
                *range = range.clamp(p.min_range, p.max_range);
            }
            if p.dropout_probability > 0.0 && rng.random::<f64>() < p.dropout_probability {
                *range = p.max_range;
            }
        }
    }

    /// With probability `crosstalk_probability` (one draw per sonar, in
    /// ring order), a sonar hears the shorter of its two ring neighbours'
    /// echoes when it beats its own: that echo arrives first.
    #[cold]
    #[inline(never)]
    fn crosstalk<R: Rng + ?Sized>(&self, rng: &mut R, out: &mut [f64]) {
        let n = out.len();
        let mut own = [0.0; MAX_SONARS];
        own[..n].copy_from_slice(out);
        for (i, range) in out.iter_mut().enumerate() {
            if rng.random::<f64>() < self.params.crosstalk_probability && n > 1 {
                let previous = own[(i + n - 1) % n];
                let next = own[(i + 1) % n];
                *range = range.min(previous).min(next);
            }
        }
    }

    /// The readings without noise, crosstalk or dropouts: each sonar's
    /// nearest echo (after specular loss) clamped to [min_range, max_range].
    pub fn true_ranges(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.echoes(index, pose, out)?;
        for range in out.iter_mut() {
            *range = range.clamp(self.params.min_range, self.params.max_range);
        }
        Ok(())
    }

    /// Errors unless `out` has one slot per sonar.
    fn check_out(&self, out: &[f64]) -> Result<(), SimError> {
        let n = self.mounts.len();
        if out.len() == n {
            Ok(())
        } else {
            Err(SimError::invalid(
                "ranges",
                format!("expected {n} slots, got {}", out.len()),
            ))
        }
    }

    /// Each sonar's nearest echo, unclamped, or `max_range` for none.
    fn echoes(&self, index: &SegmentIndex, pose: &Pose2, out: &mut [f64]) -> Result<(), SimError> {
        check_finite(pose)?;
        self.check_out(out)?;
        let wedges = self.wedges(pose);
        let center = Point2::new(pose.x, pose.y);
        let radius = |i: usize| self.mounts[i].radius;
        self.echoes_from(index, &wedges, center, radius, self.reach, out);
        Ok(())
    }

    /// Each sonar's nearest echo from its wedge, unclamped, or `max_range`
    /// for none. Sensor `i` lies within `radius(i)` of `center`, and every
    /// sensor within `reach`.
    fn echoes_from(
        &self,
        index: &SegmentIndex,
        wedges: &[Wedge; MAX_SONARS],
        center: Point2,
        radius: impl Fn(usize) -> f64,
        reach: f64,
        out: &mut [f64],
    ) {
        if !matches!(self.params.specular, Specular::Off) {
            self.occluded_echoes(index, wedges, center, radius, reach, out);
            return;
        }
        let n = self.mounts.len();
        let max_range = self.params.max_range;
        let best = &mut out[..n];
        best.fill(max_range);
        // n <= MAX_SONARS = 64 (checked in `new`).
        let mut active: u64 = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        index.visit_outward(center, max_range + reach, |visit| match visit {
            Visit::Wall(wall) => {
                let dc2 = distance2(wall, center);
                let mut mask = active;
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    // The sensor is within `radius` of the centre: a wall at
                    // least best + radius from the centre cannot beat best.
                    let bound = best[i] + radius(i);
                    if dc2 < bound * bound {
                        best[i] = best[i].min(self.echo(&wedges[i], wall, best[i]));
                    }
                }
                ControlFlow::Continue(())
            }
            Visit::Cleared(cleared) => {
                let mut mask = active;
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if best[i] + radius(i) <= cleared {
                        active &= !(1u64 << i);
                    }
                }
                if active == 0 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            }
        });
    }

    /// Each sonar's wedge in the world for a robot at `pose`: one `sin_cos`
    /// per frame, the rest rotations.
    fn wedges(&self, pose: &Pose2) -> [Wedge; MAX_SONARS] {
        let (sin, cos) = pose.theta.sin_cos();
        let mut wedges = [Wedge::default(); MAX_SONARS];
        for (w, m) in wedges.iter_mut().zip(&self.mounts) {
            *w = self.wedge(pose, cos, sin, m);
        }
        wedges
    }

    /// The wedge of the sonar at `m` for a robot at `pose`, whose heading's
    /// cosine and sine are `cos` and `sin`.
    #[inline]
    fn wedge(&self, pose: &Pose2, cos: f64, sin: f64, m: &Mount) -> Wedge {
        let (ch, sh) = (self.cos_half, self.sin_half);
        let (ux, uy) = (cos * m.cos - sin * m.sin, sin * m.cos + cos * m.sin);
        Wedge {
            x: pose.x + cos * m.x - sin * m.y,
            y: pose.y + sin * m.x + cos * m.y,
            rx: ux * ch + uy * sh,
            ry: uy * ch - ux * sh,
            lx: ux * ch - uy * sh,
            ly: uy * ch + ux * sh,
        }
    }

    /// The echo `wall` gives the sonar `s`, if it beats `best`: the
    /// distance to the nearest point of the wall inside the wedge, times the
    /// specular factor when struck at a grazing angle; infinity for none.
    /// The same clipping as [`nearest_in_wedge`], written out: this is the
    /// hot loop of a frame without specular loss, kept as it was measured.
    #[inline]
    fn echo(&self, s: &Wedge, wall: &Segment, best: f64) -> f64 {
        let (ax, ay) = (wall.a.x - s.x, wall.a.y - s.y);
        let (bx, by) = (wall.b.x - s.x, wall.b.y - s.y);
        // Signed sides of each edge: >= 0 is the wedge's side. For a
        // half-angle below 90° the two half-planes meet in the wedge alone.
        let (fa1, fb1) = (s.rx * ay - s.ry * ax, s.rx * by - s.ry * bx);
        let (fa2, fb2) = (ax * s.ly - ay * s.lx, bx * s.ly - by * s.lx);
        if (fa1 < 0.0 && fb1 < 0.0) || (fa2 < 0.0 && fb2 < 0.0) {
            return f64::INFINITY;
        }
        // Clip the parameter range of a + t (b - a) to both half-planes.
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        if fa1 < 0.0 {
            t0 = fa1 / (fa1 - fb1);
        } else if fb1 < 0.0 {
            t1 = fa1 / (fa1 - fb1);
        }
        if fa2 < 0.0 {
            t0 = t0.max(fa2 / (fa2 - fb2));
        } else if fb2 < 0.0 {
            t1 = t1.min(fa2 / (fa2 - fb2));
        }
        if t0 > t1 {
            // The wall crosses both edges' lines behind the sensor.
            return f64::INFINITY;
        }
        let (dx, dy) = (bx - ax, by - ay);
        let dd = dx * dx + dy * dy;
        // The foot of the perpendicular from the sensor, as a parameter.
        let foot = if dd > 0.0 {
            -(ax * dx + ay * dy) / dd
        } else {
            0.0
        };
        let t = foot.max(t0).min(t1);
        let (qx, qy) = (ax + t * dx, ay + t * dy);
        let d2 = qx * qx + qy * qy;
        // Incidence is 0 at the foot; elsewhere cos(incidence) =
        // |d × q| / (|d| |q|). Compared squared, so no root, no atan2.
        let grazing = t != foot && {
            let cross = dx * qy - dy * qx;
            cross * cross < self.cos2_incidence * dd * d2
        };
        if grazing {
            let long = d2.sqrt() * self.specular_factor;
            if long < best { long } else { f64::INFINITY }
        } else if d2 < best * best {
            d2.sqrt()
        } else {
            f64::INFINITY
        }
    }
}

/// Errors unless every part of `pose` is finite.
fn check_finite(pose: &Pose2) -> Result<(), SimError> {
    if pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite() {
        Ok(())
    } else {
        Err(SimError::invalid("pose", "must be finite"))
    }
}

/// The nearest point of a wall inside a wedge, relative to the sensor.
#[derive(Debug, Clone, Copy)]
struct Nearest {
    /// The point, relative to the sensor, world frame.
    qx: f64,
    qy: f64,
    /// Its squared distance.
    d2: f64,
    /// The wall's direction and its squared length.
    dx: f64,
    dy: f64,
    dd: f64,
    /// Whether the point is the foot of the perpendicular from the sensor.
    at_foot: bool,
}

impl Nearest {
    /// Whether the point is struck past the critical incidence, given the
    /// cosine of that incidence squared.
    #[inline]
    fn grazing(&self, cos2_incidence: f64) -> bool {
        // Incidence is 0 at the foot; elsewhere cos(incidence) =
        // |d × q| / (|d| |q|). Compared squared, so no root, no atan2.
        !self.at_foot && {
            let cross = self.dx * self.qy - self.dy * self.qx;
            cross * cross < cos2_incidence * self.dd * self.d2
        }
    }
}

/// The nearest point of `wall` inside the wedge `s`, if any of the wall
/// lies inside it. Only the specular path uses it ([`occlusion`]).
#[inline]
fn nearest_in_wedge(s: &Wedge, wall: &Segment) -> Option<Nearest> {
    let (ax, ay) = (wall.a.x - s.x, wall.a.y - s.y);
    let (bx, by) = (wall.b.x - s.x, wall.b.y - s.y);
    // Signed sides of each edge: >= 0 is the wedge's side. For a
    // half-angle below 90° the two half-planes meet in the wedge alone.
    let (fa1, fb1) = (s.rx * ay - s.ry * ax, s.rx * by - s.ry * bx);
    let (fa2, fb2) = (ax * s.ly - ay * s.lx, bx * s.ly - by * s.lx);
    if (fa1 < 0.0 && fb1 < 0.0) || (fa2 < 0.0 && fb2 < 0.0) {
        return None;
    }
    // Clip the parameter range of a + t (b - a) to both half-planes.
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    if fa1 < 0.0 {
        t0 = fa1 / (fa1 - fb1);
    } else if fb1 < 0.0 {
        t1 = fa1 / (fa1 - fb1);
    }
    if fa2 < 0.0 {
        t0 = t0.max(fa2 / (fa2 - fb2));
    } else if fb2 < 0.0 {
        t1 = t1.min(fa2 / (fa2 - fb2));
    }
    if t0 > t1 {
        // The wall crosses both edges' lines behind the sensor.
        return None;
    }
    let (dx, dy) = (bx - ax, by - ay);
    let dd = dx * dx + dy * dy;
    // The foot of the perpendicular from the sensor, as a parameter.
    let foot = if dd > 0.0 {
        -(ax * dx + ay * dy) / dd
    } else {
        0.0
    };
    let t = foot.max(t0).min(t1);
    let (qx, qy) = (ax + t * dx, ay + t * dy);
    Some(Nearest {
        qx,
        qy,
        d2: qx * qx + qy * qy,
        dx,
        dy,
        dd,
        at_foot: t == foot,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A wall as its two ends' (x, y).
    type Ends = ((f64, f64), (f64, f64));

    fn index(walls: &[Ends]) -> SegmentIndex {
        SegmentIndex::new(
            walls
                .iter()
                .map(|&(a, b)| Segment::new(Point2::new(a.0, a.1), Point2::new(b.0, b.1)))
                .collect(),
        )
    }

    /// One sonar at the origin facing +x: its own frame.
    fn single(params: SonarParams) -> SonarRing {
        let ring = SensorRing::from_mounts(vec![Pose2::new(0.0, 0.0, 0.0)]).expect("one mount");
        SonarRing::new(ring, params).expect("valid params")
    }

    fn read(sonar: &SonarRing, idx: &SegmentIndex) -> f64 {
        let mut out = [0.0];
        sonar
            .true_ranges(idx, &Pose2::new(0.0, 0.0, 0.0), &mut out)
            .expect("valid input");
        out[0]
    }

    #[test]
    fn a_wall_behind_the_sensor_is_not_seen() {
        let s = single(SonarParams::exact());
        assert_eq!(
            read(&s, &index(&[((-2.0, -5.0), (-2.0, 5.0))])),
            s.params.max_range
        );
    }

    #[test]
    fn a_wall_crossing_behind_through_both_edge_lines_is_not_seen() {
        // Passes through the back of the wedge's double cone: each end is
        // inside one half-plane, never both at once.
        let s = single(SonarParams::exact());
        assert_eq!(
            read(&s, &index(&[((-1.0, 3.0), (-1.0, -3.0))])),
            s.params.max_range
        );
    }

    #[test]
    fn a_point_wall_inside_the_cone_is_seen() {
        let s = single(SonarParams::exact());
        let r = read(&s, &index(&[((2.0, 0.1), (2.0, 0.1))]));
        assert!((r - 2.0f64.hypot(0.1)).abs() < 1e-12, "{r}");
    }

    #[test]
    fn specular_long_multiplies_the_grazing_echo() {
        let params = SonarParams {
            specular: Specular::Long {
                max_incidence: 40f64.to_radians(),
                factor: 2.0,
            },
            ..SonarParams::exact()
        };
        let s = single(params);
        // A wall along the axis, 1 m to the left: the nearest point inside
        // the cone is where the left edge meets it, struck at 75° from
        // its normal, past 40°.
        let idx = index(&[((0.0, 1.0), (10.0, 1.0))]);
        let direct = 1.0 / 15f64.to_radians().sin();
        assert!((read(&s, &idx) - 2.0 * direct).abs() < 1e-9);
    }

    /// Every wall against every sonar, no index, no early stop: without
    /// specular loss each wall's echo, with it every ray of the fan against
    /// every wall inside the wedge.
    fn brute_force(sonar: &SonarRing, walls: &[Segment], pose: &Pose2) -> Vec<f64> {
        let wedges = sonar.wedges(pose);
        let max = sonar.params.max_range;
        (0..sonar.len())
            .map(|i| {
                let echo = if matches!(sonar.params.specular, Specular::Off) {
                    walls
                        .iter()
                        .map(|w| sonar.echo(&wedges[i], w, max))
                        .fold(max, f64::min)
                } else {
                    sonar.brute_force_occluded(&wedges[i], walls)
                };
                echo.clamp(sonar.params.min_range, max)
            })
            .collect()
    }

    #[test]
    fn the_indexed_frame_equals_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        // Offices: many short walls, some long ones, a few diagonal.
        let walls: Vec<Segment> = (0..400)
            .map(|_| {
                let a = Point2::new(rng.random_range(0.0..40.0), rng.random_range(0.0..30.0));
                let len = if rng.random_bool(0.1) { 15.0 } else { 1.5 };
                let b = match rng.random_range(0..3) {
                    0 => Point2::new(a.x + rng.random_range(-len..len), a.y),
                    1 => Point2::new(a.x, a.y + rng.random_range(-len..len)),
                    _ => Point2::new(
                        a.x + rng.random_range(-len..len),
                        a.y + rng.random_range(-len..len),
                    ),
                };
                Segment::new(a, b)
            })
            .collect();
        let idx = SegmentIndex::new(walls.clone());
        for specular in [
            Specular::Off,
            Specular::Lost { max_incidence: 0.5 },
            Specular::Long {
                max_incidence: 0.5,
                factor: 1.7,
            },
        ] {
            let params = SonarParams {
                specular,
                ..SonarParams::exact()
            };
            let sonar = SonarRing::new(SensorRing::scout(), params).expect("valid params");
            let mut out = [0.0; 16];
            for _ in 0..300 {
                let pose = Pose2::new(
                    rng.random_range(-5.0..45.0),
                    rng.random_range(-5.0..35.0),
                    rng.random_range(-4.0..4.0),
                );
                sonar
                    .true_ranges(&idx, &pose, &mut out)
                    .expect("valid input");
                let expected = brute_force(&sonar, &walls, &pose);
                assert_eq!(out.to_vec(), expected, "at {pose:?} with {specular:?}");
            }
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let s = SonarRing::scout();
        let idx = index(&[((1.0, -1.0), (1.0, 1.0))]);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut out = [0.0; 16];
        assert!(
            s.fire(&idx, &Pose2::new(f64::NAN, 0.0, 0.0), &mut rng, &mut out)
                .is_err()
        );
        assert!(
            s.fire(&idx, &Pose2::new(0.0, 0.0, 0.0), &mut rng, &mut out[..3])
                .is_err()
        );
        let bad = SonarParams {
            dropout_probability: f64::NAN,
            ..SonarParams::default()
        };
        assert!(SonarRing::new(SensorRing::scout(), bad).is_err());
        let too_many = SensorRing::uniform(65, 0.2).expect("a ring");
        assert!(SonarRing::new(too_many, SonarParams::default()).is_err());
        for crosstalk in [-0.1, 1.5, f64::NAN] {
            let bad = SonarParams {
                crosstalk_probability: crosstalk,
                ..SonarParams::default()
            };
            let err = SonarRing::new(SensorRing::scout(), bad).expect_err("out of range");
            assert!(err.to_string().contains("crosstalk_probability"), "{err}");
        }
        assert!(
            s.fire_posed(&idx, &[Pose2::default(); 3], &mut rng, &mut out)
                .is_err()
        );
        let mut poses = [Pose2::default(); 16];
        poses[5].theta = f64::INFINITY;
        assert!(s.fire_posed(&idx, &poses, &mut rng, &mut out).is_err());
        SonarParams::realistic()
            .validate()
            .expect("the preset is valid");
    }

    /// A robot at the origin of a 4 x 4 m room with a post near sonar 2's
    /// axis: its neighbours 1 and 3 have a much shorter neighbour echo.
    fn post_room() -> SegmentIndex {
        let post = 45f64.to_radians();
        index(&[
            ((-2.0, -2.0), (2.0, -2.0)),
            ((2.0, -2.0), (2.0, 2.0)),
            ((2.0, 2.0), (-2.0, 2.0)),
            ((-2.0, 2.0), (-2.0, -2.0)),
            (
                (0.6 * post.cos(), 0.6 * post.sin()),
                (0.6 * post.cos(), 0.6 * post.sin()),
            ),
        ])
    }

    #[test]
    fn with_certain_crosstalk_each_sonar_hears_the_nearest_of_itself_and_its_neighbours() {
        let params = SonarParams {
            crosstalk_probability: 1.0,
            ..SonarParams::exact()
        };
        let ring = SonarRing::new(SensorRing::scout(), params).expect("valid");
        let idx = post_room();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut own = [0.0; 16];
        SonarRing::new(SensorRing::scout(), SonarParams::exact())
            .expect("valid")
            .true_ranges(&idx, &pose, &mut own)
            .expect("fires");
        let mut heard = [0.0; 16];
        ring.fire(&idx, &pose, &mut ChaCha8Rng::seed_from_u64(3), &mut heard)
            .expect("fires");
        for i in 0..16 {
            let expected = own[i].min(own[(i + 15) % 16]).min(own[(i + 1) % 16]);
            assert_eq!(heard[i], expected, "sonar {i}");
        }
        // The ring closes: sonar 0 hears sonar 15.
        assert!(own[2] < own[1] && heard[1] == own[2] && heard[3] == own[2]);
    }

    #[test]
    fn crosstalk_happens_at_its_rate_and_never_lengthens_a_reading() {
        let params = SonarParams {
            crosstalk_probability: 0.1,
            ..SonarParams::exact()
        };
        let ring = SonarRing::new(SensorRing::scout(), params).expect("valid");
        let idx = post_room();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut own = [0.0; 16];
        ring.true_ranges(&idx, &pose, &mut own).expect("fires");
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut out = [0.0; 16];
        let (mut crossed, frames) = (0, 5000);
        for _ in 0..frames {
            ring.fire(&idx, &pose, &mut rng, &mut out).expect("fires");
            assert!(out.iter().zip(&own).all(|(a, b)| a <= b));
            crossed += usize::from(out[1] < own[1]);
        }
        let rate = crossed as f64 / f64::from(frames);
        // 5000 frames: the standard error is 0.0042.
        assert!((rate - 0.1).abs() < 0.02, "crosstalk rate {rate}");
    }

    #[test]
    fn fired_at_one_pose_each_a_posed_frame_is_the_frame() {
        let idx = post_room();
        for params in [SonarParams::default(), SonarParams::realistic()] {
            let ring = SonarRing::new(SensorRing::scout(), params).expect("valid");
            let pose = Pose2::new(0.3, -0.2, 1.1);
            let (mut a, mut b) = ([0.0; 16], [0.0; 16]);
            let (mut ra, mut rb) = (ChaCha8Rng::seed_from_u64(2), ChaCha8Rng::seed_from_u64(2));
            for _ in 0..50 {
                ring.fire(&idx, &pose, &mut ra, &mut a).expect("fires");
                ring.fire_posed(&idx, &[pose; 16], &mut rb, &mut b)
                    .expect("fires");
                assert_eq!(a, b);
            }
        }
    }
}
