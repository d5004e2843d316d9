//! The wanderer's policy: from one frame of ranges to a velocity command
//! that keeps a round robot moving about without touching anything.
//!
//! Any rig: each reading is first put in the terms the policy was made
//! for, the Scout's ring, whose sensors sit just inside the body's edge
//! ([`SENSOR_INSET_M`]) and face straight out. From the beam's mount and
//! direction the echo's point in the robot's frame is found; its bearing from the
//! robot's centre and its distance less the radius of such a ring are the
//! reading's bearing and range. A Scout's readings pass unchanged, bit for
//! bit; a Pioneer's off-centre sonars and a laser at the centre read as a
//! ring of their own would. A sector no beam looks into counts as blocked,
//! so a front-only laser never backs blindly.
//!
//! Pure and seeded: the `deog wander` process feeds it each frame and sends
//! the command it returns.

use deog_grid::{Pose2, SCOUT_BODY_RADIUS_M, SCOUT_RING_RADIUS_M, SensorRing, normalize_angle};
use deog_rig::{Beam, Reading, Rig};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::error::SimError;

/// How the wanderer drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WanderParams {
    /// Forward speed with open space ahead, m/s.
    pub cruise_speed: f64,
    /// Turning rate in place, rad/s.
    pub turn_rate: f64,
    /// Clearance ahead below which the robot stops and turns, metres
    /// (a range as the policy's ring reads it: see the module docs).
    pub stop_distance: f64,
    /// Clearance ahead below which it slows down, metres.
    pub slow_distance: f64,
    /// Clearance at the sides below which it steers away, metres.
    pub side_distance: f64,
    /// Mean number of spontaneous turns per second of cruising: the
    /// randomness that makes it explore rather than follow walls.
    pub random_turns_per_s: f64,
    /// Mean number of times per second of cruising beside a wall that it
    /// starts following that wall for a while: following a wall leads
    /// round corners and through doors, which random driving seldom finds.
    pub wall_follows_per_s: f64,
    /// Distance kept from a followed wall, metres (as the policy's ring
    /// reads it).
    pub follow_distance: f64,
}

impl Default for WanderParams {
    fn default() -> Self {
        Self {
            cruise_speed: 0.5,
            turn_rate: 1.0,
            stop_distance: 0.55,
            slow_distance: 1.2,
            side_distance: 0.45,
            random_turns_per_s: 0.15,
            wall_follows_per_s: 0.2,
            follow_distance: 0.6,
        }
    }
}

/// Speed while moving on to the middle of an opening, m/s.
const OPENING_SPEED: f64 = 0.25;
/// Time to move on from where the square sonar first sees through an
/// opening to about the middle of a door (0.6 m on at 0.25 m/s, less what
/// the sonar saw already).
const OPENING_CREEP_S: f64 = 1.8;

/// A reading this short from a front-diagonal sonar stops the robot. Such
/// an echo lies at least 30° off the heading (the cone's inner edge), so
/// anything farther passes beside the body; a larger margin here would
/// make every door look shut.
const NEAR_DIAGONAL_M: f64 = 0.25;

/// How far inside the body's edge the policy's sensors sit, metres: the
/// Scout's ring (0.2 m) inside its body (0.205 m).
pub const SENSOR_INSET_M: f64 = SCOUT_BODY_RADIUS_M - SCOUT_RING_RADIUS_M;

/// Two readings are neighbours, for judging an opening, within this angle
/// of each other: the Scout's sonar spacing, 22.5°, and a hair.
const NEIGHBOUR_RAD: f64 = std::f64::consts::PI / 8.0 + 1e-6;

/// One reading's geometry, robot frame.
#[derive(Debug, Clone, Copy)]
struct Sensor {
    mount: Pose2,
    /// For a sensor that faces straight away from the centre (or sits on
    /// it): its bearing and what its range is off the policy's ring, so
    /// its reading converts without rounding.
    radial: Option<(f64, f64)>,
    /// The beam, when the rig is known: what its readings mean.
    beam: Option<Beam>,
}

/// What the wanderer is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Cruise,
    /// Turning in place through the given angle (signed, radians; what is
    /// left of it).
    Turn {
        remaining_rad: f64,
    },
    /// Backing away after the bumper touched.
    Reverse {
        remaining_s: f64,
    },
    /// Following the wall on one side (+1 left, -1 right) for a while.
    Follow {
        side: f64,
        remaining_s: f64,
    },
    /// An opening beside a followed wall: on to its middle, then a quarter
    /// turn into it; squarely, as a slanted approach would meet a jamb.
    Opening {
        side: f64,
        remaining_s: f64,
    },
}

/// The wandering policy of one robot.
#[derive(Debug, Clone)]
pub struct Wanderer {
    params: WanderParams,
    sensors: Vec<Sensor>,
    /// The policy's ring radius: body radius less [`SENSOR_INSET_M`].
    ring_radius: f64,
    /// This frame's robot-frame bearing of each echo, radians.
    bearings: Vec<f64>,
    /// This frame's ranges, as the policy's ring reads them.
    ranges: Vec<f64>,
    mode: Mode,
    rng: ChaCha8Rng,
}

impl Wanderer {
    /// A wanderer for a robot of the Scout's body with sensors at `ring`'s
    /// mounts, taking readings as they are (no no-echo convention), seeded.
    pub fn new(params: WanderParams, ring: &SensorRing, seed: u64) -> Result<Self, SimError> {
        let sensors = ring.mounts().iter().map(|&m| (m, None)).collect();
        Self::build(params, sensors, SCOUT_BODY_RADIUS_M, seed)
    }

    /// A wanderer for a robot carrying `rig`, seeded: readings are judged
    /// by their beams (a no-echo reading counts as the beam's max range).
    pub fn for_rig(params: WanderParams, rig: &Rig, seed: u64) -> Result<Self, SimError> {
        let sensors = rig.beams().iter().map(|b| (b.mount, Some(*b))).collect();
        Self::build(params, sensors, rig.body_radius(), seed)
    }

    fn build(
        params: WanderParams,
        mounts: Vec<(Pose2, Option<Beam>)>,
        body_radius: f64,
        seed: u64,
    ) -> Result<Self, SimError> {
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SimError::invalid(
                    field,
                    format!("must be positive, got {v}"),
                ))
            }
        };
        positive("cruise_speed", params.cruise_speed)?;
        positive("turn_rate", params.turn_rate)?;
        positive("stop_distance", params.stop_distance)?;
        positive("side_distance", params.side_distance)?;
        positive("follow_distance", params.follow_distance)?;
        if !(params.wall_follows_per_s.is_finite() && params.wall_follows_per_s >= 0.0) {
            return Err(SimError::invalid(
                "wall_follows_per_s",
                format!(
                    "must be zero or positive, got {}",
                    params.wall_follows_per_s
                ),
            ));
        }
        if !(params.slow_distance.is_finite() && params.slow_distance > params.stop_distance) {
            return Err(SimError::invalid(
                "slow_distance",
                format!(
                    "must exceed stop_distance ({}), got {}",
                    params.stop_distance, params.slow_distance
                ),
            ));
        }
        if !(params.random_turns_per_s.is_finite() && params.random_turns_per_s >= 0.0) {
            return Err(SimError::invalid(
                "random_turns_per_s",
                format!(
                    "must be zero or positive, got {}",
                    params.random_turns_per_s
                ),
            ));
        }
        let ring_radius = body_radius - SENSOR_INSET_M;
        let sensors: Vec<Sensor> = mounts
            .into_iter()
            .map(|(mount, beam)| {
                let distance = mount.x.hypot(mount.y);
                let facing_out = distance < 1e-9
                    || normalize_angle(mount.y.atan2(mount.x) - mount.theta).abs() < 1e-9;
                let radial = facing_out.then(|| {
                    let offset = distance - ring_radius;
                    // On the ring to rounding: exactly on it.
                    let offset = if offset.abs() < 1e-9 { 0.0 } else { offset };
                    (normalize_angle(mount.theta), offset)
                });
                Sensor {
                    mount,
                    radial,
                    beam,
                }
            })
            .collect();
        let n = sensors.len();
        Ok(Self {
            params,
            sensors,
            ring_radius,
            bearings: vec![0.0; n],
            ranges: vec![0.0; n],
            mode: Mode::Cruise,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// The command (linear m/s, angular rad/s) for the next `dt` seconds,
    /// given this frame's ranges (one per beam, in the rig's order) and the
    /// bumper.
    pub fn command(
        &mut self,
        ranges: &[f64],
        bumper: bool,
        dt: f64,
    ) -> Result<(f64, f64), SimError> {
        if ranges.len() != self.sensors.len() {
            return Err(SimError::invalid(
                "ranges",
                format!(
                    "expected {} readings, got {}",
                    self.sensors.len(),
                    ranges.len()
                ),
            ));
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(SimError::invalid(
                "dt",
                format!("must be positive, got {dt}"),
            ));
        }
        self.convert(ranges)?;
        let ranges = std::mem::take(&mut self.ranges);
        let result = self.decide(&ranges, bumper, dt);
        self.ranges = ranges;
        result
    }

    /// Puts this frame's readings in the policy's terms: `self.bearings`
    /// and `self.ranges`.
    fn convert(&mut self, ranges: &[f64]) -> Result<(), SimError> {
        for (i, (sensor, &range)) in self.sensors.iter().zip(ranges).enumerate() {
            let bad = || {
                SimError::invalid(
                    format!("ranges[{i}]"),
                    format!("must be a range, got {range}"),
                )
            };
            let range = match &sensor.beam {
                None if range.is_finite() && range >= 0.0 => range,
                None => return Err(bad()),
                Some(beam) => match beam.classify(range).ok_or_else(bad)? {
                    Reading::Echo(r) => r,
                    Reading::NoEcho => beam.max_range,
                },
            };
            let (bearing, reading) = match sensor.radial {
                Some((bearing, offset)) => (bearing, range + offset),
                None => {
                    let m = &sensor.mount;
                    let (sin, cos) = m.theta.sin_cos();
                    let (x, y) = (m.x + range * cos, m.y + range * sin);
                    (y.atan2(x), x.hypot(y) - self.ring_radius)
                }
            };
            self.bearings[i] = bearing;
            self.ranges[i] = reading.max(0.0);
        }
        Ok(())
    }

    fn decide(&mut self, ranges: &[f64], bumper: bool, dt: f64) -> Result<(f64, f64), SimError> {
        let p = self.params;
        // Clearance within a sector: the shortest reading of the beams
        // whose bearing lies in [from, to] (radians, robot frame); 0 when
        // no beam looks there.
        let clearance = |from: f64, to: f64| {
            let seen = self
                .bearings
                .iter()
                .zip(ranges)
                .filter(|(b, _)| **b >= from - 1e-9 && **b <= to + 1e-9)
                .map(|(_, r)| *r)
                .fold(f64::INFINITY, f64::min);
            if seen == f64::INFINITY { 0.0 } else { seen }
        };
        let ahead = clearance(-0.45, 0.45);
        let front_wide = clearance(-0.8, 0.8);
        let left = clearance(0.7, 1.7);
        let right = clearance(-1.7, -0.7);
        let behind = clearance(2.6, 3.2).min(clearance(-3.2, -2.6));
        // Distance to the wall on each side, from the sonars facing it.
        let side_wall = |side: f64| {
            self.bearings
                .iter()
                .zip(ranges)
                .filter(|(b, _)| {
                    let b = **b * side;
                    (0.7..=2.4).contains(&b)
                })
                .map(|(b, r)| r * b.sin().abs())
                .fold(f64::INFINITY, f64::min)
        };
        let (wall_left, wall_right) = (side_wall(1.0), side_wall(-1.0));

        if bumper && !matches!(self.mode, Mode::Reverse { .. }) {
            self.mode = Mode::Reverse { remaining_s: 0.6 };
        }
        loop {
            match self.mode {
                Mode::Reverse { remaining_s } => {
                    if remaining_s <= 0.0 || behind < 0.3 {
                        self.mode = Mode::Turn {
                            remaining_rad: self.open_bearing(ranges),
                        };
                        continue;
                    }
                    self.mode = Mode::Reverse {
                        remaining_s: remaining_s - dt,
                    };
                    return Ok((-0.15, 0.0));
                }
                Mode::Turn { remaining_rad } => {
                    if remaining_rad.abs() < 0.05 {
                        if ahead < p.stop_distance {
                            // Still facing a wall (the opening was too narrow
                            // to judge from afar): look again.
                            let bearing = self.open_bearing(ranges);
                            if bearing.abs() >= 0.05 {
                                self.mode = Mode::Turn {
                                    remaining_rad: bearing,
                                };
                                continue;
                            }
                            // Nowhere better: creep on, the bumper guards.
                            self.mode = Mode::Cruise;
                            return Ok((0.05, 0.0));
                        }
                        self.mode = Mode::Cruise;
                        continue;
                    }
                    let step = (p.turn_rate * dt).min(remaining_rad.abs());
                    let direction = remaining_rad.signum();
                    self.mode = Mode::Turn {
                        remaining_rad: remaining_rad - direction * step,
                    };
                    return Ok((0.0, direction * p.turn_rate));
                }
                Mode::Opening { side, remaining_s } => {
                    if remaining_s <= 0.0 {
                        self.mode = Mode::Turn {
                            remaining_rad: side * std::f64::consts::FRAC_PI_2,
                        };
                        continue;
                    }
                    if ahead < p.stop_distance {
                        self.mode = Mode::Cruise;
                        continue;
                    }
                    self.mode = Mode::Opening {
                        side,
                        remaining_s: remaining_s - dt,
                    };
                    return Ok((OPENING_SPEED, 0.0));
                }
                Mode::Follow { side, remaining_s } => {
                    if remaining_s <= 0.0 {
                        self.mode = Mode::Cruise;
                        continue;
                    }
                    self.mode = Mode::Follow {
                        side,
                        remaining_s: remaining_s - dt,
                    };
                    if ahead < p.stop_distance || front_wide < NEAR_DIAGONAL_M {
                        // A wall ahead: turn away from the followed one.
                        return Ok((0.0, -side * p.turn_rate));
                    }
                    let wall = if side > 0.0 { wall_left } else { wall_right };
                    // The sonar square to the wall looks through a door
                    // that its neighbours, seeing the jambs, would hide.
                    let abeam = self.abeam(ranges, side);
                    if wall > 1.5 || abeam > 1.5 {
                        // The wall ended (a corner or a door).
                        self.mode = Mode::Opening {
                            side,
                            remaining_s: OPENING_CREEP_S,
                        };
                        continue;
                    }
                    let slow = ((ahead - p.stop_distance) / (p.slow_distance - p.stop_distance))
                        .clamp(0.3, 1.0);
                    let w = (side * 1.5 * (wall - p.follow_distance)).clamp(-0.6, 0.6);
                    return Ok((p.cruise_speed * slow, w));
                }
                Mode::Cruise => {
                    if ahead < p.stop_distance || front_wide < NEAR_DIAGONAL_M {
                        let bearing = self.open_bearing(ranges);
                        if bearing.abs() >= 0.05 {
                            self.mode = Mode::Turn {
                                remaining_rad: bearing,
                            };
                            continue;
                        }
                        return Ok((0.05, 0.0));
                    }
                    let near_wall = wall_left.min(wall_right) < 1.5;
                    if near_wall
                        && self
                            .rng
                            .random_bool((p.wall_follows_per_s * dt).clamp(0.0, 1.0))
                    {
                        self.mode = Mode::Follow {
                            side: if wall_left <= wall_right { 1.0 } else { -1.0 },
                            remaining_s: self.rng.random_range(30.0..90.0),
                        };
                        continue;
                    }
                    let turn_chance = p.random_turns_per_s * dt;
                    if self.rng.random_bool(turn_chance.clamp(0.0, 1.0)) {
                        let angle = self.rng.random_range(0.8..std::f64::consts::PI);
                        let direction = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
                        self.mode = Mode::Turn {
                            remaining_rad: direction * angle,
                        };
                        continue;
                    }
                    let slow = ((ahead - p.stop_distance) / (p.slow_distance - p.stop_distance))
                        .clamp(0.3, 1.0);
                    // Steer away from a close side; drift a little at random
                    // so that straight corridors are not followed forever.
                    let mut w: f64 = self.rng.random_range(-0.15..0.15);
                    if left < p.side_distance {
                        w -= 0.6;
                    }
                    if right < p.side_distance {
                        w += 0.6;
                    }
                    return Ok((p.cruise_speed * slow, w.clamp(-p.turn_rate, p.turn_rate)));
                }
            }
        }
    }

    /// The reading of the beam pointing most nearly square to `side` (+1
    /// left, -1 right).
    fn abeam(&self, ranges: &[f64], side: f64) -> f64 {
        let target = side * std::f64::consts::FRAC_PI_2;
        self.bearings
            .iter()
            .zip(ranges)
            .min_by(|a, b| (a.0 - target).abs().total_cmp(&(b.0 - target).abs()))
            .map_or(0.0, |(_, r)| *r)
    }

    /// The bearing (robot frame, radians) of an opening to turn toward:
    /// each beam scores the shortest reading of itself and its neighbours
    /// within [`NEIGHBOUR_RAD`] (on the Scout, the sonars either side: an
    /// opening as wide as the robot shows in all three); one of the
    /// directions scoring within 80% of the best is picked at random, so
    /// the robot does not always leave a place the same way.
    fn open_bearing(&mut self, ranges: &[f64]) -> f64 {
        let n = ranges.len();
        let bearings = &self.bearings;
        let score = |i: usize| {
            (0..n)
                .filter(|&j| normalize_angle(bearings[j] - bearings[i]).abs() <= NEIGHBOUR_RAD)
                .map(|j| ranges[j])
                .fold(f64::INFINITY, f64::min)
        };
        let scores: Vec<f64> = (0..n).map(score).collect();
        let best = scores.iter().copied().fold(0.0, f64::max);
        let candidates: Vec<usize> = (0..n).filter(|&i| scores[i] >= 0.8 * best).collect();
        let pick = candidates[self.rng.random_range(0..candidates.len())];
        self.bearings[pick]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wanderer(seed: u64) -> Wanderer {
        Wanderer::new(WanderParams::default(), &SensorRing::scout(), seed).expect("wanderer")
    }

    #[test]
    fn open_space_means_forward() {
        let mut w = wanderer(1);
        let mut forward = 0;
        for _ in 0..100 {
            let (v, _) = w.command(&[5.0; 16], false, 0.1).expect("command");
            if v > 0.0 {
                forward += 1;
            }
        }
        assert!(forward > 70, "{forward}");
    }

    #[test]
    fn a_wall_ahead_stops_and_turns_in_place() {
        let mut w = wanderer(2);
        let mut ranges = [3.0; 16];
        // Wall ahead; the right side (sonars 12..15) is close too.
        for i in [0, 1, 15] {
            ranges[i] = 0.4;
        }
        ranges[12..15].fill(0.8);
        let (v, omega) = w.command(&ranges, false, 0.1).expect("command");
        assert_eq!(v, 0.0);
        assert!(omega != 0.0, "turns in place: {omega}");
    }

    #[test]
    fn the_bumper_backs_off_first() {
        let mut w = wanderer(3);
        let (v, omega) = w.command(&[0.2; 16], true, 0.1).expect("command");
        // Everything is close behind too, so it turns rather than reverses.
        assert!(v <= 0.0 && (v < 0.0 || omega != 0.0));
        let mut w = wanderer(3);
        let mut ranges = [2.0; 16];
        ranges[0] = 0.2;
        let (v, _) = w.command(&ranges, true, 0.1).expect("command");
        assert!(v < 0.0);
    }

    #[test]
    fn the_same_seed_gives_the_same_commands() {
        let (mut a, mut b) = (wanderer(9), wanderer(9));
        for i in 0..200 {
            let ranges: Vec<f64> = (0..16)
                .map(|s| 0.5 + ((i * 7 + s * 3) % 30) as f64 * 0.1)
                .collect();
            assert_eq!(
                a.command(&ranges, i % 50 == 0, 0.1).expect("a"),
                b.command(&ranges, i % 50 == 0, 0.1).expect("b")
            );
        }
    }

    #[test]
    fn the_scouts_rig_drives_as_its_bare_ring() {
        let rig = deog_rig::scout();
        let mut a = wanderer(9);
        let mut b = Wanderer::for_rig(WanderParams::default(), &rig, 9).expect("wanderer");
        for i in 0..300 {
            let ranges: Vec<f64> = (0..16)
                .map(|s| 0.2 + ((i * 7 + s * 3) % 40) as f64 * 0.27)
                .collect();
            assert_eq!(
                a.command(&ranges, i % 60 == 0, 0.1).expect("a"),
                b.command(&ranges, i % 60 == 0, 0.1).expect("b")
            );
        }
    }

    #[test]
    fn a_laser_at_the_centre_reads_from_the_body_not_the_centre() {
        let rig = deog_rig::load_rig_spec("laser180").expect("built in");
        let mut w = Wanderer::for_rig(WanderParams::default(), &rig, 1).expect("wanderer");
        // A wall 0.7 m ahead of the centre is 0.45 m ahead of the body:
        // closer than the stop distance, so it stops and turns.
        let ranges: Vec<f64> = rig
            .beams()
            .iter()
            .map(|b| {
                let c = b.mount.theta.cos();
                if c > 0.01 { (0.7 / c).min(50.0) } else { 50.0 }
            })
            .collect();
        let (v, omega) = w.command(&ranges, false, 0.1).expect("command");
        assert_eq!(v, 0.0);
        assert!(omega != 0.0);
        // Nothing in range anywhere (every ray reads no echo): forward.
        let mut w = Wanderer::for_rig(WanderParams::default(), &rig, 1).expect("wanderer");
        let (v, _) = w.command(&[50.0; 180], false, 0.1).expect("command");
        assert!(v > 0.0);
        // Not a range for this rig.
        assert!(w.command(&[-1.0; 180], false, 0.1).is_err());
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut w = wanderer(4);
        assert!(w.command(&[1.0; 15], false, 0.1).is_err());
        assert!(w.command(&[f64::NAN; 16], false, 0.1).is_err());
        assert!(w.command(&[1.0; 16], false, 0.0).is_err());
        let bad = WanderParams {
            slow_distance: 0.1,
            ..WanderParams::default()
        };
        assert!(Wanderer::new(bad, &SensorRing::scout(), 0).is_err());
    }
}
