//! A simulated Nomad Super Scout II: a round differential-drive body with a
//! bumper, driven by (linear, angular) velocity commands, and wheel
//! odometry with random and systematic error.
//!
//! Motion: each [`Robot::step`] is cut into sub-steps of at most 20 ms and
//! at most half a body radius of travel, so the body cannot jump through a
//! wall. In each, the velocities move towards the command within the
//! acceleration limits and the robot follows the exact circular arc of the
//! sub-step's mean velocities. A sub-step whose end would put the body
//! within its radius of a wall, or its centre outside free space, does not
//! translate: the robot only turns in place (a round body always can), its
//! linear velocity drops to 0 and its bumper is set, until a translation
//! succeeds.
//!
//! Odometry integrates the motion actually made. The wheels do not slip in
//! this model, so a blocked robot's odometry does not advance either; its
//! error comes from [`OdometryNoise`] alone.

use std::f64::consts::{FRAC_PI_2, TAU};

use deog_grid::{Pose2, SCOUT_BODY_RADIUS_M, normalize_angle};
use deog_world::{Point2, SegmentIndex, World};
use rand::Rng;

use crate::error::SimError;

/// The longest time one [`Robot::step`] may cover, seconds.
pub const MAX_STEP_S: f64 = 10.0;

/// The longest sub-step, seconds: 2 cm of travel at 1 m/s.
const SUB_STEP_S: f64 = 0.02;

/// The robot's body and drive limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoutParams {
    /// Body radius, metres.
    pub radius: f64,
    /// Top speed forwards or backwards, m/s.
    pub max_linear: f64,
    /// Top turn rate either way, rad/s.
    pub max_angular: f64,
    /// Linear acceleration and braking limit, m/s².
    pub max_linear_accel: f64,
    /// Angular acceleration and braking limit, rad/s².
    pub max_angular_accel: f64,
}

impl Default for ScoutParams {
    /// Scout-like figures, not measured ones: the Scout's body radius, 1 m/s,
    /// 90°/s, 1 m/s² and 3 rad/s², a brisk indoor robot's.
    fn default() -> Self {
        Self {
            radius: SCOUT_BODY_RADIUS_M,
            max_linear: 1.0,
            max_angular: FRAC_PI_2,
            max_linear_accel: 1.0,
            max_angular_accel: 3.0,
        }
    }
}

impl ScoutParams {
    /// Checks every figure is finite and positive (and not absurd).
    pub fn validate(&self) -> Result<Self, SimError> {
        within("radius", self.radius, 1e-3, 10.0)?;
        within("max_linear", self.max_linear, 1e-3, 10.0)?;
        within("max_angular", self.max_angular, 1e-3, 20.0)?;
        within("max_linear_accel", self.max_linear_accel, 1e-3, 100.0)?;
        within("max_angular_accel", self.max_angular_accel, 1e-3, 100.0)?;
        Ok(*self)
    }
}

/// How odometry errs. The random parts follow the standard odometry error
/// model (translation error from distance and turning, rotation error from
/// turning and distance), as standard deviations accumulated over one metre
/// or one radian: errors of successive motions are independent, so the
/// spread grows as the square root of the distance, however finely the
/// motion is stepped. The systematic parts bend and stretch every path the
/// same way, as unequal or mis-measured wheels do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryNoise {
    /// Distance error per metre travelled, metres (standard deviation).
    pub translation_per_m: f64,
    /// Heading error per radian turned, radians (standard deviation).
    pub rotation_per_rad: f64,
    /// Heading error per metre travelled, radians (standard deviation).
    pub rotation_per_m: f64,
    /// Distance error per radian turned, metres (standard deviation).
    pub translation_per_rad: f64,
    /// Systematic heading drift, radians per metre travelled (signed:
    /// counter-clockwise driving forwards, so clockwise driving backwards).
    pub drift_rad_per_m: f64,
    /// Systematic distance scale error: odometry reports `1 + scale_error`
    /// times the distance travelled.
    pub scale_error: f64,
}

impl Default for OdometryNoise {
    /// Small errors: about 1 cm and 0.3° of spread per metre, 1° per
    /// radian turned, 0.1°/m of drift and a 1 % scale error.
    fn default() -> Self {
        Self {
            translation_per_m: 0.01,
            rotation_per_rad: 0.02,
            rotation_per_m: 0.005,
            translation_per_rad: 0.002,
            drift_rad_per_m: 0.002,
            scale_error: 0.01,
        }
    }
}

impl OdometryNoise {
    /// Perfect odometry: it equals the true pose while nothing teleports
    /// the robot.
    pub fn none() -> Self {
        Self {
            translation_per_m: 0.0,
            rotation_per_rad: 0.0,
            rotation_per_m: 0.0,
            translation_per_rad: 0.0,
            drift_rad_per_m: 0.0,
            scale_error: 0.0,
        }
    }

    /// Every figure times `factor` (0 turns the noise off, 2 doubles it);
    /// errors when the result is out of range.
    pub fn scaled(&self, factor: f64) -> Result<Self, SimError> {
        if !(factor.is_finite() && factor >= 0.0) {
            return Err(SimError::invalid(
                "factor",
                format!("must be zero or positive, got {factor}"),
            ));
        }
        Self {
            translation_per_m: self.translation_per_m * factor,
            rotation_per_rad: self.rotation_per_rad * factor,
            rotation_per_m: self.rotation_per_m * factor,
            translation_per_rad: self.translation_per_rad * factor,
            drift_rad_per_m: self.drift_rad_per_m * factor,
            scale_error: self.scale_error * factor,
        }
        .validate()
    }

    /// Checks every figure is finite and within reason.
    pub fn validate(&self) -> Result<Self, SimError> {
        within("translation_per_m", self.translation_per_m, 0.0, 1.0)?;
        within("rotation_per_rad", self.rotation_per_rad, 0.0, 1.0)?;
        within("rotation_per_m", self.rotation_per_m, 0.0, 1.0)?;
        within("translation_per_rad", self.translation_per_rad, 0.0, 1.0)?;
        within("drift_rad_per_m", self.drift_rad_per_m, -1.0, 1.0)?;
        within("scale_error", self.scale_error, -0.5, 0.5)?;
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

/// Errors unless every component of `pose` is finite.
fn finite_pose(field: &str, pose: &Pose2) -> Result<Pose2, SimError> {
    if pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite() {
        Ok(Pose2::new(pose.x, pose.y, normalize_angle(pose.theta)))
    } else {
        Err(SimError::invalid(field, "must be finite"))
    }
}

/// One simulated Scout.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    params: ScoutParams,
    noise: OdometryNoise,
    true_pose: Pose2,
    odometry: Pose2,
    command: (f64, f64),
    velocity: (f64, f64),
    bumper: bool,
    bumps: u64,
    /// Metres moved unblocked since the last contact.
    clear_since_contact_m: f64,
}

/// Metres a robot must move unblocked after touching something for its
/// next contact to count as another bump: pressing on against a wall
/// creeps a hair's breadth now and then, and is still the one bump.
const BUMP_CLEARANCE_M: f64 = 0.05;

impl Robot {
    /// A robot standing still at `pose` (world frame), its odometry starting
    /// there too. Errors on a non-finite pose or bad figures.
    pub fn new(pose: Pose2, params: ScoutParams, noise: OdometryNoise) -> Result<Self, SimError> {
        let pose = finite_pose("pose", &pose)?;
        Ok(Self {
            params: params.validate()?,
            noise: noise.validate()?,
            true_pose: pose,
            odometry: pose,
            command: (0.0, 0.0),
            velocity: (0.0, 0.0),
            bumper: false,
            bumps: 0,
            clear_since_contact_m: f64::INFINITY,
        })
    }

    /// The body and drive figures.
    pub fn params(&self) -> &ScoutParams {
        &self.params
    }

    /// The odometry error figures.
    pub fn noise(&self) -> &OdometryNoise {
        &self.noise
    }

    /// Where the robot really is, world frame.
    pub fn true_pose(&self) -> Pose2 {
        self.true_pose
    }

    /// Where its odometry says it is, in the frame of its starting pose
    /// (the world frame until a teleport).
    pub fn odometry(&self) -> Pose2 {
        self.odometry
    }

    /// The commanded (linear m/s, angular rad/s) velocity.
    pub fn command(&self) -> (f64, f64) {
        self.command
    }

    /// The current (linear m/s, angular rad/s) velocity.
    pub fn velocity(&self) -> (f64, f64) {
        self.velocity
    }

    /// Whether the last attempted translation was blocked by a wall.
    pub fn bumper(&self) -> bool {
        self.bumper
    }

    /// How many times it has run into an obstacle: each press of the
    /// bumper counts once, however long it lasts (and a press counts anew
    /// only after the robot moved a few centimetres clear).
    pub fn bumps(&self) -> u64 {
        self.bumps
    }

    /// Commands a linear (m/s, forwards positive) and angular (rad/s,
    /// counter-clockwise positive) velocity, clamped to the limits; returns
    /// the command as clamped. Errors on a non-finite value.
    pub fn set_command(&mut self, linear: f64, angular: f64) -> Result<(f64, f64), SimError> {
        if !linear.is_finite() {
            return Err(SimError::invalid("linear", "must be finite"));
        }
        if !angular.is_finite() {
            return Err(SimError::invalid("angular", "must be finite"));
        }
        let p = &self.params;
        self.command = (
            linear.clamp(-p.max_linear, p.max_linear),
            angular.clamp(-p.max_angular, p.max_angular),
        );
        Ok(self.command)
    }

    /// Moves the robot for `dt` seconds (0 to [`MAX_STEP_S`]) among the walls
    /// of `index` and the free space of `world`, drawing odometry noise from
    /// `rng` (nothing is drawn with [`OdometryNoise::none`]).
    pub fn step<R: Rng + ?Sized>(
        &mut self,
        dt: f64,
        index: &SegmentIndex,
        world: &World,
        rng: &mut R,
    ) -> Result<(), SimError> {
        within("dt", dt, 0.0, MAX_STEP_S)?;
        if dt == 0.0 {
            return Ok(());
        }
        // Half a radius per sub-step at most: a body that ends a sub-step
        // clear of a wall cannot have crossed it.
        let longest = SUB_STEP_S.min(0.5 * self.params.radius / self.params.max_linear);
        // longest >= min(0.02, 0.5 * 0.001 / 10) = 5e-5 s (validated figures), so
        // count <= 10 / 5e-5 = 200 000.
        let count = (dt / longest).ceil().max(1.0) as usize;
        let h = dt / count as f64;
        for _ in 0..count {
            self.sub_step(h, index, world, rng);
        }
        Ok(())
    }

    /// Puts the robot at `pose` (world frame) without telling its odometry:
    /// a kidnapping. Velocities and command are kept. It does not check free
    /// space: callers that must not place a robot in a wall check
    /// [`fits`](Self::fits) first. Errors on a non-finite pose.
    pub fn teleport(&mut self, pose: Pose2) -> Result<(), SimError> {
        self.true_pose = finite_pose("pose", &pose)?;
        // Wherever it lands, touching there is a new contact.
        self.clear_since_contact_m = f64::INFINITY;
        Ok(())
    }

    /// Whether the body, centred at `p`, is in free space and at least its
    /// radius from every wall.
    pub fn fits(&self, p: Point2, index: &SegmentIndex, world: &World) -> bool {
        index.min_distance(p, self.params.radius) >= self.params.radius && world.is_free(p)
    }

    fn sub_step<R: Rng + ?Sized>(
        &mut self,
        h: f64,
        index: &SegmentIndex,
        world: &World,
        rng: &mut R,
    ) {
        let (v0, w0) = self.velocity;
        let mut v1 = approach(v0, self.command.0, self.params.max_linear_accel * h);
        let w1 = approach(w0, self.command.1, self.params.max_angular_accel * h);
        // The arc of the mean velocities: exact at constant speed, second
        // order while accelerating.
        let (v, w) = (0.5 * (v0 + v1), 0.5 * (w0 + w1));
        let half_turn = 0.5 * w * h;
        let mut chord = v * h * sinc(half_turn);
        if chord != 0.0 {
            let next = advance(self.true_pose, chord, half_turn, half_turn);
            let from = Point2::new(self.true_pose.x, self.true_pose.y);
            if self.may_move(from, Point2::new(next.x, next.y), index, world) {
                self.bumper = false;
                self.clear_since_contact_m += chord.abs();
            } else {
                chord = 0.0;
                v1 = 0.0;
                if self.clear_since_contact_m >= BUMP_CLEARANCE_M {
                    self.bumps += 1;
                }
                self.clear_since_contact_m = 0.0;
                self.bumper = true;
            }
        }
        self.true_pose = advance(self.true_pose, chord, half_turn, half_turn);
        self.velocity = (v1, w1);
        self.integrate_odometry(chord, 2.0 * half_turn, rng);
    }

    /// Whether the body may go from `from` to `to`: it ends clear of walls in
    /// free space, or it was already touching (after a teleport) and moves
    /// away, so that a robot put against a wall can still leave it.
    fn may_move(&self, from: Point2, to: Point2, index: &SegmentIndex, world: &World) -> bool {
        let r = self.params.radius;
        let clear_to = index.min_distance(to, r);
        let free_to = world.is_free(to);
        if clear_to >= r && free_to {
            return true;
        }
        let clear_from = index.min_distance(from, r);
        clear_from < r && clear_to > clear_from && (free_to || !world.is_free(from))
    }

    /// Adds the motion made (a chord of `chord` metres along the mean
    /// heading, a turn of `turn` radians) to the odometry, with its errors.
    fn integrate_odometry<R: Rng + ?Sized>(&mut self, chord: f64, turn: f64, rng: &mut R) {
        let n = &self.noise;
        let (dist, angle) = (chord.abs(), turn.abs());
        let mut trans = chord * (1.0 + n.scale_error);
        let (mut rot1, mut rot2) = (0.5 * turn, 0.5 * turn);
        let var_trans = n.translation_per_m.powi(2) * dist + n.translation_per_rad.powi(2) * angle;
        if var_trans > 0.0 {
            trans += var_trans.sqrt() * standard_normal(rng);
        }
        // The heading's variance is split between the turn before and the
        // turn after the translation.
        let var_rot = 0.5 * (n.rotation_per_rad.powi(2) * angle + n.rotation_per_m.powi(2) * dist);
        if var_rot > 0.0 {
            let sd = var_rot.sqrt();
            rot1 += sd * standard_normal(rng);
            rot2 += sd * standard_normal(rng);
        }
        rot2 += n.drift_rad_per_m * chord;
        self.odometry = advance(self.odometry, trans, rot1, rot2);
    }
}

/// `from` moved towards `to` by at most `step`.
fn approach(from: f64, to: f64, step: f64) -> f64 {
    from + (to - from).clamp(-step, step)
}

/// sin(x) / x, continuous at 0.
fn sinc(x: f64) -> f64 {
    // Below 1e-4 the series' next term (x⁴/120) is under 1e-18.
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// `pose` after turning `rot1`, going `trans` straight, and turning `rot2`:
/// an arc of turn `2a` is exactly `rot1 = rot2 = a` around its chord. The
/// true pose and the odometry both move through here, so perfect odometry
/// equals the true pose to the last bit.
fn advance(pose: Pose2, trans: f64, rot1: f64, rot2: f64) -> Pose2 {
    let heading = pose.theta + rot1;
    let (sin, cos) = heading.sin_cos();
    Pose2::new(
        pose.x + trans * cos,
        pose.y + trans * sin,
        normalize_angle(heading + rot2),
    )
}

/// A standard normal deviate by Box–Muller: rand 0.9 itself has no normal
/// distribution (rand_distr does), and two lines do not justify a crate.
pub(crate) fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    // 1 - [0, 1) is (0, 1]: the logarithm stays finite.
    let u1 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_world::Polygon;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A 10 x 6 m room, no obstacles.
    fn room() -> (World, SegmentIndex) {
        let world = World::new(
            "room",
            Some(Polygon::rectangle(
                Point2::new(0.0, 0.0),
                Point2::new(10.0, 6.0),
            )),
            vec![],
        )
        .expect("a world");
        let index = SegmentIndex::new(world.walls());
        (world, index)
    }

    #[test]
    fn sinc_is_smooth_through_zero() {
        assert_eq!(sinc(0.0), 1.0);
        assert!((sinc(0.99e-4) - (0.99e-4f64).sin() / 0.99e-4).abs() < 1e-15);
        assert!((sinc(FRAC_PI_2) - 2.0 / std::f64::consts::PI).abs() < 1e-15);
    }

    #[test]
    fn a_full_circle_at_constant_speed_comes_back() {
        let (world, index) = room();
        let params = ScoutParams {
            max_linear_accel: 100.0,
            max_angular_accel: 100.0,
            ..ScoutParams::default()
        };
        let start = Pose2::new(5.0, 2.0, 0.0);
        let mut robot = Robot::new(start, params, OdometryNoise::none()).expect("a robot");
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        // Reach speed within a few ms, then a circle of radius 0.5 / 1 = 0.5 m.
        robot.set_command(0.5, 1.0).expect("finite");
        robot
            .step(0.01, &index, &world, &mut rng)
            .expect("valid dt");
        let after_ramp = robot.true_pose();
        robot.step(TAU, &index, &world, &mut rng).expect("valid dt");
        let end = robot.true_pose();
        assert!(
            (end.x - after_ramp.x).abs() < 1e-9,
            "{end:?} vs {after_ramp:?}"
        );
        assert!((end.y - after_ramp.y).abs() < 1e-9);
        assert!(normalize_angle(end.theta - after_ramp.theta).abs() < 1e-9);
    }

    #[test]
    fn acceleration_is_limited() {
        let (world, index) = room();
        let mut robot = Robot::new(
            Pose2::new(2.0, 3.0, 0.0),
            ScoutParams::default(),
            OdometryNoise::none(),
        )
        .expect("a robot");
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        robot.set_command(1.0, 1.5).expect("finite");
        robot.step(0.1, &index, &world, &mut rng).expect("valid dt");
        let (v, w) = robot.velocity();
        assert!((v - 0.1).abs() < 1e-12, "{v}");
        assert!((w - 0.3).abs() < 1e-12, "{w}");
        // From rest at 1 m/s² for 0.1 s: 5 mm.
        assert!((robot.true_pose().x - 2.005).abs() < 1e-6);
    }

    #[test]
    fn bad_input_is_an_error_and_changes_nothing() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = Robot::new(
            Pose2::new(2.0, 3.0, 0.0),
            ScoutParams::default(),
            OdometryNoise::default(),
        )
        .expect("a robot");
        let before = robot.clone();
        for dt in [f64::NAN, -0.1, f64::INFINITY, MAX_STEP_S + 1.0] {
            assert!(robot.step(dt, &index, &world, &mut rng).is_err(), "dt {dt}");
        }
        assert!(robot.set_command(f64::NAN, 0.0).is_err());
        assert!(robot.set_command(0.0, f64::INFINITY).is_err());
        assert!(robot.teleport(Pose2::new(0.0, f64::NAN, 0.0)).is_err());
        assert_eq!(robot, before);
        assert!(
            Robot::new(
                Pose2::new(f64::NAN, 0.0, 0.0),
                ScoutParams::default(),
                OdometryNoise::none()
            )
            .is_err()
        );
        let bad = ScoutParams {
            max_linear: -1.0,
            ..ScoutParams::default()
        };
        assert!(Robot::new(Pose2::default(), bad, OdometryNoise::none()).is_err());
        let bad = OdometryNoise {
            scale_error: f64::NAN,
            ..OdometryNoise::none()
        };
        assert!(Robot::new(Pose2::default(), ScoutParams::default(), bad).is_err());
    }

    fn scout(pose: Pose2, noise: OdometryNoise) -> Robot {
        Robot::new(pose, ScoutParams::default(), noise).expect("a robot")
    }

    #[test]
    fn driving_into_a_wall_stops_clear_of_it_and_reversing_clears_the_bumper() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = scout(Pose2::new(5.0, 3.0, 0.0), OdometryNoise::none());
        robot.set_command(1.0, 0.0).expect("finite");
        robot
            .step(10.0, &index, &world, &mut rng)
            .expect("valid dt");
        let p = robot.true_pose();
        let radius = robot.params().radius;
        assert!(robot.bumper());
        assert_eq!(robot.velocity().0, 0.0);
        let clearance = index.min_distance(Point2::new(p.x, p.y), 1.0);
        assert!(clearance >= radius, "{clearance}");
        assert!(
            clearance < radius + 0.02,
            "stopped {clearance} from the wall"
        );
        // Wheels do not slip: the odometry stopped where the robot did.
        assert_eq!(robot.odometry(), p);

        // Pressing on is still the one bump.
        assert_eq!(robot.bumps(), 1);

        robot.set_command(-0.5, 0.0).expect("finite");
        robot.step(0.5, &index, &world, &mut rng).expect("valid dt");
        assert!(!robot.bumper());
        assert!(robot.true_pose().x < p.x);
        robot.set_command(1.0, 0.0).expect("finite");
        robot.step(3.0, &index, &world, &mut rng).expect("valid dt");
        assert!(robot.bumper());
        assert_eq!(robot.bumps(), 2);
    }

    #[test]
    fn a_blocked_robot_can_still_turn_in_place() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = scout(Pose2::new(9.0, 3.0, 0.0), OdometryNoise::none());
        robot.set_command(1.0, 0.0).expect("finite");
        robot.step(3.0, &index, &world, &mut rng).expect("valid dt");
        assert!(robot.bumper());
        let stuck = robot.true_pose();
        robot.set_command(0.2, 1.0).expect("finite");
        robot.step(0.5, &index, &world, &mut rng).expect("valid dt");
        assert!(robot.true_pose().theta > stuck.theta + 0.2);
        assert!(robot.true_pose().x <= stuck.x + 1e-12);
    }

    #[test]
    fn commands_are_clamped_to_the_limits() {
        let mut robot = scout(Pose2::default(), OdometryNoise::none());
        assert_eq!(
            robot.set_command(5.0, -10.0).expect("finite"),
            (1.0, -FRAC_PI_2)
        );
        assert_eq!(
            robot.set_command(-5.0, 10.0).expect("finite"),
            (-1.0, FRAC_PI_2)
        );
        assert_eq!(robot.set_command(0.3, 0.2).expect("finite"), (0.3, 0.2));
        assert_eq!(robot.command(), (0.3, 0.2));
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = scout(Pose2::new(1.0, 3.0, 0.0), OdometryNoise::none());
        robot.set_command(9.0, 0.0).expect("finite");
        robot.step(3.0, &index, &world, &mut rng).expect("valid dt");
        assert!(robot.velocity().0 <= 1.0);
    }

    /// A wiggly path through the room's middle, never near a wall.
    fn wiggle<R: Rng>(robot: &mut Robot, world: &World, index: &SegmentIndex, rng: &mut R) {
        for (v, w) in [
            (0.5, 0.3),
            (0.8, -0.6),
            (-0.3, 1.0),
            (0.6, 0.0),
            (0.2, -1.5),
        ] {
            robot.set_command(v, w).expect("finite");
            robot.step(2.0, index, world, rng).expect("valid dt");
            assert!(!robot.bumper());
        }
    }

    #[test]
    fn perfect_odometry_follows_the_true_pose() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = scout(Pose2::new(3.0, 3.0, 0.2), OdometryNoise::none());
        wiggle(&mut robot, &world, &index, &mut rng);
        let (t, o) = (robot.true_pose(), robot.odometry());
        assert!(
            (t.x - 3.0).abs() + (t.y - 3.0).abs() > 1.0,
            "it moved: {t:?}"
        );
        assert!((t.x - o.x).abs() < 1e-9 && (t.y - o.y).abs() < 1e-9);
        assert!(normalize_angle(t.theta - o.theta).abs() < 1e-9);
    }

    #[test]
    fn noisy_odometry_drifts_by_a_plausible_amount() {
        let (world, index) = room();
        let mut errors = Vec::new();
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut robot = scout(Pose2::new(3.0, 3.0, 0.2), OdometryNoise::default());
            wiggle(&mut robot, &world, &index, &mut rng);
            let (t, o) = (robot.true_pose(), robot.odometry());
            errors.push((t.x - o.x).hypot(t.y - o.y));
        }
        // About 5 m of path: the 1 % scale error alone is 5 cm.
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!(mean > 0.01 && mean < 0.5, "mean odometry error {mean} m");
        assert!(errors.windows(2).any(|w| w[0] != w[1]), "no randomness");
    }

    #[test]
    fn teleport_moves_the_robot_but_not_its_odometry() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = scout(Pose2::new(3.0, 3.0, 0.0), OdometryNoise::none());
        robot.set_command(0.5, 0.0).expect("finite");
        robot.step(1.0, &index, &world, &mut rng).expect("valid dt");
        let odometry = robot.odometry();
        let target = Pose2::new(7.0, 2.0, 1.0);
        assert!(robot.fits(Point2::new(target.x, target.y), &index, &world));
        robot.teleport(target).expect("finite");
        assert_eq!(robot.true_pose(), target);
        assert_eq!(robot.odometry(), odometry);
        assert!(!robot.fits(Point2::new(9.9, 3.0), &index, &world));
        assert!(!robot.fits(Point2::new(11.0, 3.0), &index, &world));
    }

    #[test]
    fn a_robot_teleported_against_a_wall_can_back_away_but_not_push_in() {
        let (world, index) = room();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut robot = Robot::new(
            Pose2::new(5.0, 3.0, 0.0),
            ScoutParams::default(),
            OdometryNoise::none(),
        )
        .expect("a robot");
        // 10 cm from the right wall, facing it.
        robot.teleport(Pose2::new(9.9, 3.0, 0.0)).expect("finite");
        robot.set_command(0.3, 0.0).expect("finite");
        robot.step(0.5, &index, &world, &mut rng).expect("valid dt");
        assert!(robot.bumper());
        assert_eq!(robot.true_pose().x, 9.9);
        robot.set_command(-0.3, 0.0).expect("finite");
        robot.step(1.0, &index, &world, &mut rng).expect("valid dt");
        assert!(!robot.bumper());
        assert!(robot.true_pose().x < 9.9);
    }
}
