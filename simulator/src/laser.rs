//! Planar lasers: what each ray of a rig's scanning lasers reads in a world
//! of walls.
//!
//! A laser ray reports the distance along its own line to the first wall
//! it meets: exact ray–segment intersection, no beam width. Then Gaussian
//! noise (standard deviation [`LaserParams::noise_sigma`]) and clamping to
//! the beam's [min_range, max_range]. A ray that meets no wall within
//! max_range reads the beam's no-echo value ([`no_echo_reading`]), without
//! noise.
//!
//! Speed: one frame walks the walls near the robot once, nearest buckets
//! first ([`SegmentIndex::visit_outward`]). Each wall is turned into the
//! laser's own frame and the two angles of its ends (two `atan2`) give the
//! few rays that can meet it; only those are intersected with it, with
//! the rays' directions precomputed once per laser. A wall farther from the
//! laser than its longest unsettled ray is skipped without trigonometry,
//! and the walk stops once every unvisited wall is provably beyond every
//! ray's hit: a 180-ray laser in an office costs about as many
//! intersections as walls it sees, not rays times walls.

use std::f64::consts::{PI, TAU};
use std::ops::ControlFlow;

use deog_grid::Pose2;
use deog_rig::{NoEcho, Rig, SensorKind};
use deog_world::segment_index::{Visit, distance2};
use deog_world::{Point2, Segment, SegmentIndex};
use rand::Rng;

use crate::error::SimError;
use crate::robot::standard_normal;

/// The simulated lasers' figures besides the rig's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserParams {
    /// Standard deviation of the Gaussian range noise, metres, in [0, 1].
    pub noise_sigma: f64,
}

impl Default for LaserParams {
    /// 1 cm of noise, a SICK LMS 200's order of accuracy.
    fn default() -> Self {
        Self { noise_sigma: 0.01 }
    }
}

impl LaserParams {
    /// Without noise: readings are the true ranges, clamped.
    pub fn exact() -> Self {
        Self { noise_sigma: 0.0 }
    }

    /// Checks every figure is finite and within its documented range.
    pub fn validate(&self) -> Result<Self, SimError> {
        if self.noise_sigma.is_finite() && (0.0..=1.0).contains(&self.noise_sigma) {
            Ok(*self)
        } else {
            Err(SimError::invalid(
                "laser.noise_sigma",
                format!("must be within [0, 1] metres, got {}", self.noise_sigma),
            ))
        }
    }
}

/// The reading a beam gives when nothing echoes: its no-echo threshold
/// when finite (for the built-in rigs, the maximum range), else 0 when the
/// rig reads 0 as no echo, else infinity.
pub fn no_echo_reading(no_echo: &NoEcho) -> f64 {
    if no_echo.at_or_beyond.is_finite() {
        no_echo.at_or_beyond
    } else if no_echo.zero {
        0.0
    } else {
        f64::INFINITY
    }
}

/// One laser of the rig.
#[derive(Debug, Clone)]
struct Scan {
    /// Mount, robot frame.
    x: f64,
    y: f64,
    /// The mount's heading plus the first ray's angle: the frame in which
    /// ray `i` points at `i * step`.
    theta: f64,
    step: f64,
    /// Each ray's direction in that frame: (cos, sin) of `i * step`.
    dirs: Vec<(f64, f64)>,
    /// Distance of the mount from the robot's centre, metres.
    radius: f64,
    min_range: f64,
    max_range: f64,
    no_echo: f64,
    /// Where its first reading goes in the rig's frame.
    first_slot: usize,
}

/// Every laser of a rig: fires their rays for a robot pose.
#[derive(Debug, Clone)]
pub struct Lasers {
    scans: Vec<Scan>,
    params: LaserParams,
}

impl Lasers {
    /// The lasers of `rig` (none if it has none) with `params`.
    ///
    /// ```
    /// use deog_grid::Pose2;
    /// use deog_simulator::{LaserParams, Lasers};
    /// use deog_world::{Point2, Segment, SegmentIndex};
    /// use rand::SeedableRng;
    ///
    /// // laser180: 180 rays from the robot's centre, -90° to +89°.
    /// let rig = deog_rig::load_rig_spec("laser180")?;
    /// let lasers = Lasers::new(&rig, LaserParams::exact())?;
    /// // A wall 3 m ahead, across the robot's path.
    /// let wall = Segment::new(Point2::new(3.0, -50.0), Point2::new(3.0, 50.0));
    /// let index = SegmentIndex::new(vec![wall]);
    /// let mut ranges = vec![0.0; rig.readings()];
    /// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    /// lasers.fire(&index, &Pose2::new(0.0, 0.0, 0.0), &mut rng, &mut ranges)?;
    /// assert!((ranges[90] - 3.0).abs() < 1e-9); // straight ahead
    /// assert!((ranges[30] - 6.0).abs() < 1e-9); // 60° right: 3 / cos 60°
    /// assert_eq!(ranges[0], 50.0); // along the wall: no echo
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn new(rig: &Rig, params: LaserParams) -> Result<Self, SimError> {
        let params = params.validate()?;
        let mut scans = Vec::new();
        let mut slot = 0;
        for sensor in rig.sensors() {
            if let SensorKind::Laser {
                first_angle,
                angle_step,
                beam_count,
            } = sensor.kind
            {
                let dirs = (0..beam_count)
                    .map(|i| {
                        let (sin, cos) = (angle_step * f64::from(i)).sin_cos();
                        (cos, sin)
                    })
                    .collect();
                scans.push(Scan {
                    x: sensor.mount.x,
                    y: sensor.mount.y,
                    theta: sensor.mount.theta + first_angle,
                    step: angle_step,
                    dirs,
                    radius: sensor.mount.x.hypot(sensor.mount.y),
                    min_range: sensor.min_range,
                    max_range: sensor.max_range,
                    no_echo: no_echo_reading(&sensor.no_echo),
                    first_slot: slot,
                });
            }
            slot += sensor.readings();
        }
        Ok(Self { scans, params })
    }

    /// The figures in use.
    pub fn params(&self) -> &LaserParams {
        &self.params
    }

    /// Number of lasers.
    pub fn len(&self) -> usize {
        self.scans.len()
    }

    /// Whether the rig has no laser.
    pub fn is_empty(&self) -> bool {
        self.scans.is_empty()
    }

    /// One frame: writes every laser reading into its slot of `out` (the
    /// whole rig's frame, in beam order; other slots are left alone) for a
    /// robot at `pose` (world frame) among the walls of `index`, with noise
    /// drawn from `rng` (one normal deviate per echo, in beam order, when
    /// there is noise). Errors on a non-finite pose or an `out` too short
    /// for the rig.
    pub fn fire<R: Rng + ?Sized>(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        rng: &mut R,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.hits(index, pose, out)?;
        let sigma = self.params.noise_sigma;
        for scan in &self.scans {
            for range in &mut out[scan.first_slot..scan.first_slot + scan.dirs.len()] {
                if *range <= scan.max_range {
                    if sigma > 0.0 {
                        *range += sigma * standard_normal(rng);
                    }
                    *range = range.clamp(scan.min_range, scan.max_range);
                } else {
                    *range = scan.no_echo;
                }
            }
        }
        Ok(())
    }

    /// The readings without noise: each ray's hit clamped to its range
    /// limits, or the no-echo value.
    pub fn true_ranges(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.hits(index, pose, out)?;
        for scan in &self.scans {
            for range in &mut out[scan.first_slot..scan.first_slot + scan.dirs.len()] {
                *range = if *range <= scan.max_range {
                    range.clamp(scan.min_range, scan.max_range)
                } else {
                    scan.no_echo
                };
            }
        }
        Ok(())
    }

    /// Each ray's distance to its first wall, or infinity for none within
    /// its maximum range, written to its slot.
    fn hits(&self, index: &SegmentIndex, pose: &Pose2, out: &mut [f64]) -> Result<(), SimError> {
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return Err(SimError::invalid("pose", "must be finite"));
        }
        let Some(need) = self.scans.last().map(|s| s.first_slot + s.dirs.len()) else {
            return Ok(());
        };
        if out.len() < need {
            return Err(SimError::invalid(
                "ranges",
                format!("expected at least {need} slots, got {}", out.len()),
            ));
        }
        let (sin, cos) = pose.theta.sin_cos();
        // Each laser's origin and frame in the world, and the farthest any
        // of its unsettled rays may still hit (max_range until settled).
        let mut frames: Vec<Frame> = self
            .scans
            .iter()
            .map(|s| {
                let (fs, fc) = (pose.theta + s.theta).sin_cos();
                Frame {
                    ox: pose.x + cos * s.x - sin * s.y,
                    oy: pose.y + sin * s.x + cos * s.y,
                    cos: fc,
                    sin: fs,
                    reach: s.max_range,
                    done: false,
                }
            })
            .collect();
        for s in &self.scans {
            out[s.first_slot..s.first_slot + s.dirs.len()].fill(f64::INFINITY);
        }
        let center = Point2::new(pose.x, pose.y);
        let radius = self
            .scans
            .iter()
            .map(|s| s.max_range + s.radius)
            .fold(0.0, f64::max);
        index.visit_outward(center, radius, |visit| match visit {
            Visit::Wall(wall) => {
                for (scan, frame) in self.scans.iter().zip(&frames) {
                    if !frame.done {
                        let slots = &mut out[scan.first_slot..scan.first_slot + scan.dirs.len()];
                        cast(scan, frame, wall, slots);
                    }
                }
                ControlFlow::Continue(())
            }
            Visit::Cleared(cleared) => {
                let mut all_done = true;
                for (scan, frame) in self.scans.iter().zip(frames.iter_mut()) {
                    if frame.done {
                        continue;
                    }
                    // The longest ray still unsettled; a ray with no hit
                    // yet may still meet a wall out to its max range.
                    let slots = &out[scan.first_slot..scan.first_slot + scan.dirs.len()];
                    frame.reach = slots
                        .iter()
                        .fold(0.0, |m: f64, &r| m.max(r.min(scan.max_range)));
                    // Every unvisited wall is farther than `cleared` from
                    // the centre, so farther than cleared - radius from
                    // the laser.
                    frame.done = frame.reach + scan.radius <= cleared;
                    all_done &= frame.done;
                }
                if all_done {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            }
        });
        Ok(())
    }
}

/// One laser in the world for one frame.
#[derive(Debug, Clone, Copy)]
struct Frame {
    ox: f64,
    oy: f64,
    /// Of the angle of ray 0, world frame.
    cos: f64,
    sin: f64,
    /// No unsettled ray can hit anything farther, metres.
    reach: f64,
    /// Every ray has its nearest wall.
    done: bool,
}

/// Slack on the segment parameter, so that a ray through the common corner
/// of two walls meets at least one of them despite rounding.
const END_SLACK: f64 = 1e-12;

/// Intersects `wall` with the rays of `scan` that can meet it, lowering
/// their entries of `best`.
#[inline]
fn cast(scan: &Scan, frame: &Frame, wall: &Segment, best: &mut [f64]) {
    let origin = Point2::new(frame.ox, frame.oy);
    if distance2(wall, origin) >= frame.reach * frame.reach {
        return;
    }
    // The wall's ends in the laser's frame, where ray i points at i * step.
    let to_frame = |p: Point2| {
        let (dx, dy) = (p.x - frame.ox, p.y - frame.oy);
        (
            frame.cos * dx + frame.sin * dy,
            frame.cos * dy - frame.sin * dx,
        )
    };
    let (p, q) = (to_frame(wall.a), to_frame(wall.b));
    let (ex, ey) = (q.0 - p.0, q.1 - p.1);
    // The wall's angular extent seen from the laser: the shorter arc
    // between its ends' directions (a wall not through the laser spans
    // less than a half turn).
    let (angle_p, angle_q) = (p.1.atan2(p.0), q.1.atan2(q.0));
    let mut lo = angle_p.min(angle_q);
    let mut span = angle_p.max(angle_q) - lo;
    if span > PI {
        lo = angle_p.max(angle_q);
        span = TAU - span;
    }
    // Rays at i * step within [lo, lo + span] modulo a turn; a ray or two
    // of margin each side, since the intersection below is exact anyway.
    let n = scan.dirs.len() as i64;
    let lo = lo.rem_euclid(TAU);
    for shift in [0.0, -TAU] {
        let from = ((lo + shift) / scan.step).floor() as i64 - 1;
        let to = ((lo + shift + span) / scan.step).ceil() as i64 + 1;
        let (from, to) = (from.max(0), to.min(n - 1));
        for i in from..=to {
            let i = i as usize;
            let (dx, dy) = scan.dirs[i];
            if let Some(t) = ray_hits(dx, dy, p, ex, ey) {
                if t < best[i] {
                    best[i] = t;
                }
            }
        }
    }
}

/// Where the ray from the origin along (dx, dy) (a unit vector) meets the
/// segment from `p` along (ex, ey): its distance, if it does.
#[inline]
pub(crate) fn ray_hits(dx: f64, dy: f64, p: (f64, f64), ex: f64, ey: f64) -> Option<f64> {
    let denom = dx * ey - dy * ex;
    let cross_pd = p.0 * dy - p.1 * dx;
    if denom == 0.0 {
        // Parallel: a hit only when the ray runs along the wall itself,
        // at the nearer end in front of the laser.
        if cross_pd != 0.0 {
            return None;
        }
        let (tp, tq) = (p.0 * dx + p.1 * dy, (p.0 + ex) * dx + (p.1 + ey) * dy);
        return match (tp >= 0.0, tq >= 0.0) {
            (true, true) => Some(tp.min(tq)),
            (false, false) => None,
            // The laser sits on the wall.
            _ => Some(0.0),
        };
    }
    let t = (p.0 * ey - p.1 * ex) / denom;
    let u = cross_pd / denom;
    (t >= 0.0 && (-END_SLACK..=1.0 + END_SLACK).contains(&u)).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use deog_rig::{RangeSensor, load_rig_spec};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
        Segment::new(Point2::new(ax, ay), Point2::new(bx, by))
    }

    fn laser180() -> (Rig, Lasers) {
        let rig = load_rig_spec("laser180").expect("built in");
        let lasers = Lasers::new(&rig, LaserParams::exact()).expect("valid");
        (rig, lasers)
    }

    fn read(lasers: &Lasers, n: usize, walls: Vec<Segment>, pose: Pose2) -> Vec<f64> {
        let mut out = vec![0.0; n];
        lasers
            .true_ranges(&SegmentIndex::new(walls), &pose, &mut out)
            .expect("valid input");
        out
    }

    #[test]
    fn a_wall_ahead_reads_its_distance_along_each_ray() {
        let (rig, lasers) = laser180();
        let r = read(
            &lasers,
            rig.readings(),
            vec![seg(2.0, -30.0, 2.0, 30.0)],
            Pose2::new(0.0, 0.0, 0.0),
        );
        for (i, beam) in rig.beams().iter().enumerate() {
            let angle = beam.mount.theta;
            if angle.cos() * 30.0 > 2.0 * angle.sin().abs() {
                assert_abs_diff_eq!(r[i], 2.0 / angle.cos(), epsilon = 1e-9);
            }
        }
        // Ray 0 (-90°) runs parallel to the wall: nothing.
        assert_eq!(r[0], 50.0);
        // The same wall for a robot elsewhere, turned to face it.
        let r = read(
            &lasers,
            rig.readings(),
            vec![seg(-30.0, 7.5, 30.0, 7.5)],
            Pose2::new(1.0, 5.0, std::f64::consts::FRAC_PI_2),
        );
        assert_abs_diff_eq!(r[90], 2.5, epsilon = 1e-9);
        assert_abs_diff_eq!(r[135], 2.5 / 45f64.to_radians().cos(), epsilon = 1e-9);
    }

    #[test]
    fn a_ray_through_a_corner_reads_the_corner() {
        let (rig, lasers) = laser180();
        // A box corner at (2, 2): ray 135 (+45°) goes through it exactly.
        let walls = vec![seg(2.0, 2.0, 2.0, 6.0), seg(2.0, 2.0, 6.0, 2.0)];
        let r = read(&lasers, rig.readings(), walls, Pose2::new(0.0, 0.0, 0.0));
        assert_abs_diff_eq!(r[135], 8f64.sqrt(), epsilon = 1e-9);
        // Its neighbours meet one wall each, beyond the corner.
        assert!(r[134] > 8f64.sqrt() && r[136] > 8f64.sqrt());
        // The rays that miss the corner's walls read no echo.
        assert_eq!(r[90], 50.0);
        assert_eq!(r[179], 50.0);
    }

    #[test]
    fn a_wall_alongside_the_ray_and_no_wall_read_no_echo() {
        let (rig, lasers) = laser180();
        // A wall along the robot's path 1 m to its left: ray 90 (ahead)
        // runs parallel to it, ray 179 (+89°) meets it just ahead.
        let r = read(
            &lasers,
            rig.readings(),
            vec![seg(-5.0, 1.0, 40.0, 1.0)],
            Pose2::new(0.0, 0.0, 0.0),
        );
        assert_eq!(r[90], 50.0);
        assert_abs_diff_eq!(r[179], 1.0 / 89f64.to_radians().sin(), epsilon = 1e-9);
        // A ray exactly along a wall's own line reads its nearer end.
        assert_eq!(ray_hits(1.0, 0.0, (3.0, 0.0), 4.0, 0.0), Some(3.0));
        assert_eq!(ray_hits(1.0, 0.0, (3.0, 0.5), 4.0, 0.0), None);
        // No wall at all, or every wall out of range: the no-echo value.
        let r = read(&lasers, rig.readings(), vec![], Pose2::new(0.0, 0.0, 0.0));
        assert!(r.iter().all(|&x| x == 50.0));
        let r = read(
            &lasers,
            rig.readings(),
            vec![seg(60.0, -5.0, 60.0, 5.0)],
            Pose2::new(0.0, 0.0, 0.0),
        );
        assert!(r.iter().all(|&x| x == 50.0));
    }

    #[test]
    fn ranges_are_clamped_and_a_custom_no_echo_is_kept() {
        let sensor = RangeSensor {
            mount: Pose2::new(0.1, 0.0, 0.0),
            kind: SensorKind::Laser {
                first_angle: -0.1,
                angle_step: 0.1,
                beam_count: 3,
            },
            min_range: 0.5,
            max_range: 4.0,
            no_echo: NoEcho {
                at_or_beyond: f64::INFINITY,
                zero: true,
            },
        };
        let rig = Rig::new("short", 0.2, vec![sensor]).expect("valid");
        let lasers = Lasers::new(&rig, LaserParams::exact()).expect("valid");
        let r = read(&lasers, 3, vec![seg(0.3, -1.0, 0.3, 1.0)], Pose2::default());
        assert_eq!(r, vec![0.5; 3]);
        let r = read(&lasers, 3, vec![seg(9.0, -1.0, 9.0, 1.0)], Pose2::default());
        assert_eq!(r, vec![0.0; 3]);
    }

    #[test]
    fn noise_is_gaussian_with_the_given_sigma() {
        let (rig, _) = laser180();
        let lasers = Lasers::new(&rig, LaserParams { noise_sigma: 0.05 }).expect("valid");
        let index = SegmentIndex::new(vec![seg(2.0, -30.0, 2.0, 30.0)]);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut out = vec![0.0; rig.readings()];
        let mut errors = Vec::new();
        for _ in 0..200 {
            lasers
                .fire(&index, &Pose2::default(), &mut rng, &mut out)
                .expect("valid input");
            errors.push(out[90] - 2.0);
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let sd = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / 199.0).sqrt();
        assert!(mean.abs() < 0.012, "mean {mean}");
        assert!((sd - 0.05).abs() < 0.01, "sd {sd}");
        assert_eq!(out[0], 50.0, "no echo is not noisy");
    }

    /// Every wall against every ray.
    fn brute_force(rig: &Rig, walls: &[Segment], pose: &Pose2) -> Vec<f64> {
        rig.beams()
            .iter()
            .map(|b| {
                let m = pose.compose(&b.mount);
                let (dy, dx) = m.theta.sin_cos();
                let hit = walls
                    .iter()
                    .filter_map(|w| {
                        let p = (w.a.x - m.x, w.a.y - m.y);
                        ray_hits(dx, dy, p, w.b.x - w.a.x, w.b.y - w.a.y)
                    })
                    .fold(f64::INFINITY, f64::min);
                if hit <= b.max_range {
                    hit.clamp(b.min_range, b.max_range)
                } else {
                    b.no_echo.at_or_beyond
                }
            })
            .collect()
    }

    #[test]
    fn the_indexed_frame_equals_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let walls: Vec<Segment> = (0..300)
            .map(|_| {
                let a = Point2::new(rng.random_range(0.0..40.0), rng.random_range(0.0..30.0));
                let b = Point2::new(
                    a.x + rng.random_range(-3.0..3.0),
                    a.y + rng.random_range(-3.0..3.0),
                );
                Segment::new(a, b)
            })
            .collect();
        let index = SegmentIndex::new(walls.clone());
        // A full-turn laser off centre, so rays wrap past ±180°.
        let full = RangeSensor {
            mount: Pose2::new(0.15, -0.05, 0.4),
            kind: SensorKind::Laser {
                first_angle: -3.0,
                angle_step: 0.5f64.to_radians(),
                beam_count: 720,
            },
            min_range: 0.05,
            max_range: 12.0,
            no_echo: NoEcho {
                at_or_beyond: 12.0,
                zero: false,
            },
        };
        for rig in [
            load_rig_spec("laser180").expect("built in"),
            Rig::new("full", 0.2, vec![full]).expect("valid"),
        ] {
            let lasers = Lasers::new(&rig, LaserParams::exact()).expect("valid");
            let mut out = vec![0.0; rig.readings()];
            for _ in 0..100 {
                let pose = Pose2::new(
                    rng.random_range(-5.0..45.0),
                    rng.random_range(-5.0..35.0),
                    rng.random_range(-4.0..4.0),
                );
                lasers
                    .true_ranges(&index, &pose, &mut out)
                    .expect("valid input");
                let expected = brute_force(&rig, &walls, &pose);
                for (i, (a, b)) in out.iter().zip(&expected).enumerate() {
                    assert!((a - b).abs() < 1e-9, "ray {i} at {pose:?}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let (rig, lasers) = laser180();
        let index = SegmentIndex::new(vec![]);
        let mut out = vec![0.0; rig.readings()];
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        assert!(lasers.true_ranges(&index, &nan, &mut out).is_err());
        assert!(
            lasers
                .true_ranges(&index, &Pose2::default(), &mut out[..10])
                .is_err()
        );
        assert!(Lasers::new(&rig, LaserParams { noise_sigma: -1.0 }).is_err());
    }
}
