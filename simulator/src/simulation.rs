//! A world with robots in it, advanced in fixed physics steps; every robot
//! carries the simulation's rig, whose sensors fire on a fixed period.
//!
//! Each robot draws from its own random stream, seeded from the simulation's
//! seed and the robot's name, so a robot's run does not depend on which other
//! robots share the world. Robots do not see or bump into each other: each
//! senses the static world only, which is what the maps are built of.
//!
//! With [`SonarFiring::Sequential`] each sonar reads from the true pose the
//! robot had at the physics step its firing falls on
//! ([`steps_before_frame`]); a robot keeps its poses of the last sensor
//! period for that. A teleport starts that record afresh, so a frame never
//! mixes the places before and after a kidnapping.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use deog_grid::Pose2;
use deog_rig::Rig;
use deog_world::{Point2, SegmentIndex, World};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::SimError;
use crate::laser::LaserParams;
use crate::rig_sensors::RigSensors;
use crate::robot::{OdometryNoise, Robot, ScoutParams};
use crate::sonar::{SonarParams, Specular};
use crate::sonar_firing::{SonarFiring, steps_before_frame};

/// Figures of a simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Physics step, seconds.
    pub step_s: f64,
    /// Time between two firings of a robot's sensors, seconds (rounded
    /// to whole physics steps).
    pub sonar_period_s: f64,
    /// The sensors every robot carries, and its body radius; the Scout's
    /// by default.
    pub rig: Rig,
    /// The robots' speed limits. The body radius is the rig's
    /// ([`SimConfig::robot_params`]); `scout.radius` is not used.
    pub scout: ScoutParams,
    /// The sonars' noise, specular reflection, crosstalk, dropouts and
    /// firing order. Their range
    /// limits and half-angle are each sonar's in the rig (for the Scout,
    /// the same as these defaults).
    pub sonar: SonarParams,
    /// The lasers' noise.
    pub laser: LaserParams,
    /// Odometry error model.
    pub odometry: OdometryNoise,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            step_s: 0.01,
            sonar_period_s: 0.1,
            rig: deog_rig::scout(),
            scout: ScoutParams::default(),
            sonar: SonarParams::default(),
            laser: LaserParams::default(),
            odometry: OdometryNoise::default(),
        }
    }
}

impl SimConfig {
    /// When a frame's sonars fire, as a localizer or cartographer places
    /// their readings: in turn over the sensor period when the sonar fires
    /// sequentially (each firing falls on the physics step nearest its
    /// time, within half a step of this), together otherwise.
    pub fn ring_firing(&self) -> deog_grid::RingFiring {
        match self.sonar.firing {
            SonarFiring::Sequential => deog_grid::RingFiring::Sequential {
                period_s: self.sonar_period_s,
            },
            SonarFiring::Together => deog_grid::RingFiring::Together,
        }
    }

    /// A robot's body and drive figures: `scout`'s limits with the rig's
    /// body radius.
    pub fn robot_params(&self) -> ScoutParams {
        ScoutParams {
            radius: self.rig.body_radius(),
            ..self.scout
        }
    }
}

/// One robot as the outside sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSnapshot {
    /// The robot's name.
    pub name: String,
    /// Simulated time, seconds since the simulation started.
    pub time_s: f64,
    /// Where it really is.
    pub true_pose: Pose2,
    /// Where its odometry says it is.
    pub odometry: Pose2,
    /// The rig the ranges come from (its name).
    pub rig: Arc<str>,
    /// The latest ranges, metres, one per beam of the rig, in its order.
    pub ranges: Vec<f64>,
    /// Number of the firing these ranges came from, from 1 (0: none yet).
    pub sequence: u64,
    /// Velocity being executed (m/s, rad/s).
    pub velocity: (f64, f64),
    /// Whether it is pressed against an obstacle.
    pub bumper: bool,
    /// Times it has run into an obstacle (a press counts once).
    pub bumps: u64,
}

struct SimRobot {
    robot: Robot,
    rng: ChaCha8Rng,
    ranges: Vec<f64>,
    sequence: u64,
    /// With sequential firing: the true poses after each of the last
    /// physics steps (at most a sensor period's), oldest first; empty
    /// otherwise.
    trail: VecDeque<Pose2>,
    /// Scratch for each sonar's pose at its firing.
    sonar_poses: Vec<Pose2>,
}

/// The simulation: a world, its robots and the clock.
pub struct Simulation {
    world: World,
    index: SegmentIndex,
    /// The walls the sensors fire at: the world's faces
    /// ([`SegmentIndex::of_world`]) when the sonar loses grazed echoes,
    /// since it must tell a face seen from its solid side; otherwise the
    /// walls as given, so the default sonar's frames stay the same to the
    /// last bit.
    sensed: SegmentIndex,
    sensors: RigSensors,
    rig_name: Arc<str>,
    robot_params: ScoutParams,
    config: SimConfig,
    seed: u64,
    robots: BTreeMap<String, SimRobot>,
    /// Physics steps so far: time is counted in steps so it does not drift.
    steps: u64,
    /// Physics steps between two firings of the sensors.
    fire_every: u64,
    /// Whether the sonars fire one after another over the period.
    sequential: bool,
    /// Time left over from the last advance, less than one physics step.
    carry_s: f64,
}

impl std::fmt::Debug for Simulation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulation")
            .field("world", &self.world.name())
            .field("robots", &self.robots.len())
            .field("time_s", &self.time_s())
            .finish_non_exhaustive()
    }
}

/// FNV-1a: a hash of a robot's name that is the same on every platform and
/// every build, so seeded runs repeat.
fn stable_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl Simulation {
    /// A simulation of `world` with no robots yet.
    pub fn new(world: World, config: SimConfig, seed: u64) -> Result<Self, SimError> {
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
        positive("step_s", config.step_s)?;
        positive("sonar_period_s", config.sonar_period_s)?;
        if config.sonar_period_s < config.step_s {
            return Err(SimError::invalid(
                "sonar_period_s",
                format!(
                    "must be at least one physics step ({} s), got {}",
                    config.step_s, config.sonar_period_s
                ),
            ));
        }
        config.sonar.validate()?;
        let sensors = RigSensors::new(config.rig.clone(), config.sonar, config.laser)?;
        let robot_params = config.robot_params().validate()?;
        let index = SegmentIndex::new(world.walls());
        let sensed = if matches!(config.sonar.specular, Specular::Off) {
            index.clone()
        } else {
            SegmentIndex::of_world(&world)
        };
        Ok(Self {
            index,
            sensed,
            world,
            sensors,
            rig_name: Arc::from(config.rig.name()),
            robot_params,
            config: config.clone(),
            seed,
            robots: BTreeMap::new(),
            steps: 0,
            fire_every: (config.sonar_period_s / config.step_s).round().max(1.0) as u64,
            sequential: config.sonar.firing == SonarFiring::Sequential,
            carry_s: 0.0,
        })
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The figures it runs with.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The sensors every robot carries.
    pub fn sensors(&self) -> &RigSensors {
        &self.sensors
    }

    /// The rig every robot carries.
    pub fn rig(&self) -> &Rig {
        self.sensors.rig()
    }

    /// Simulated seconds since the start.
    pub fn time_s(&self) -> f64 {
        self.steps as f64 * self.config.step_s
    }

    /// Whether a robot's body fits at `p`: in free space and at least its
    /// radius (plus a hair) from every wall.
    pub fn fits(&self, p: Point2) -> bool {
        let radius = self.robot_params.radius;
        self.world.is_free(p) && self.index.min_distance(p, radius + 0.05) > radius + 0.01
    }

    /// Places a robot named `name` at `pose`, or at a random free pose
    /// (drawn from its own random stream) when `None`; its sensors fire at
    /// once so its first state has ranges.
    pub fn spawn(&mut self, name: &str, pose: Option<Pose2>) -> Result<RobotSnapshot, SimError> {
        if self.robots.contains_key(name) {
            return Err(SimError::RobotExists(name.to_string()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ stable_hash(name));
        let pose = match pose {
            Some(pose) => {
                check_pose("pose", &pose)?;
                if !self.fits(Point2::new(pose.x, pose.y)) {
                    return Err(SimError::Blocked(format!(
                        "a robot does not fit at ({:.3}, {:.3}): too close to or inside an obstacle",
                        pose.x, pose.y
                    )));
                }
                pose
            }
            None => self.random_free_pose(&mut rng)?,
        };
        let robot = Robot::new(pose, self.robot_params, self.config.odometry)?;
        let mut entry = SimRobot {
            robot,
            rng,
            ranges: vec![0.0; self.sensors.readings()],
            sequence: 0,
            trail: VecDeque::new(),
            sonar_poses: Vec::new(),
        };
        if self.sequential {
            entry.trail.push_back(pose);
        }
        self.fire(&mut entry)?;
        self.robots.insert(name.to_string(), entry);
        self.snapshot(name)
    }

    /// Sets a robot's velocity command (clamped to the Scout's limits).
    pub fn drive(
        &mut self,
        name: &str,
        linear: f64,
        angular: f64,
    ) -> Result<RobotSnapshot, SimError> {
        let entry = self
            .robots
            .get_mut(name)
            .ok_or_else(|| SimError::UnknownRobot(name.to_string()))?;
        entry.robot.set_command(linear, angular)?;
        self.snapshot(name)
    }

    /// Moves a robot to `pose` without telling its odometry (a kidnapping).
    pub fn teleport(&mut self, name: &str, pose: Pose2) -> Result<RobotSnapshot, SimError> {
        check_pose("pose", &pose)?;
        if !self.robots.contains_key(name) {
            return Err(SimError::UnknownRobot(name.to_string()));
        }
        if !self.fits(Point2::new(pose.x, pose.y)) {
            return Err(SimError::Blocked(format!(
                "a robot does not fit at ({:.3}, {:.3}): too close to or inside an obstacle",
                pose.x, pose.y
            )));
        }
        if let Some(entry) = self.robots.get_mut(name) {
            entry.robot.teleport(pose)?;
            if self.sequential {
                entry.trail.clear();
                entry.trail.push_back(pose);
            }
        }
        self.snapshot(name)
    }

    /// A robot's current state.
    pub fn snapshot(&self, name: &str) -> Result<RobotSnapshot, SimError> {
        let entry = self
            .robots
            .get(name)
            .ok_or_else(|| SimError::UnknownRobot(name.to_string()))?;
        Ok(snapshot_of(name, entry, &self.rig_name, self.time_s()))
    }

    /// Every robot's state, by name.
    pub fn snapshots(&self) -> Vec<RobotSnapshot> {
        self.robots
            .iter()
            .map(|(name, entry)| snapshot_of(name, entry, &self.rig_name, self.time_s()))
            .collect()
    }

    /// Number of robots.
    pub fn robot_count(&self) -> usize {
        self.robots.len()
    }

    /// Advances the clock by `dt` seconds in physics steps (a remainder
    /// shorter than a step waits for the next call); each time the sensors
    /// fire, pushes every robot's new state onto `fired`.
    pub fn advance(&mut self, dt: f64, fired: &mut Vec<RobotSnapshot>) -> Result<(), SimError> {
        if !(dt.is_finite() && dt >= 0.0) {
            return Err(SimError::invalid(
                "dt",
                format!("must be zero or positive, got {dt}"),
            ));
        }
        let step = self.config.step_s;
        self.carry_s += dt;
        // Whole steps, with a hair of tolerance so that 20 s of 10 ms steps
        // is 2000 steps despite rounding.
        let whole = (self.carry_s / step + 1e-9).floor();
        self.carry_s = (self.carry_s - whole * step).max(0.0);
        for _ in 0..whole as u64 {
            self.steps += 1;
            let fire = self.steps % self.fire_every == 0;
            let now = self.time_s();
            let names: Vec<String> = self.robots.keys().cloned().collect();
            for name in names {
                let Some(mut entry) = self.robots.remove(&name) else {
                    continue;
                };
                let mut result = entry
                    .robot
                    .step(step, &self.index, &self.world, &mut entry.rng);
                if self.sequential {
                    entry.trail.push_back(entry.robot.true_pose());
                    if entry.trail.len() as u64 > self.fire_every {
                        entry.trail.pop_front();
                    }
                }
                if fire && result.is_ok() {
                    result = self.fire(&mut entry);
                    fired.push(snapshot_of(&name, &entry, &self.rig_name, now));
                }
                self.robots.insert(name, entry);
                result?;
            }
        }
        Ok(())
    }

    fn fire(&self, entry: &mut SimRobot) -> Result<(), SimError> {
        let pose = entry.robot.true_pose();
        if self.sequential {
            // Each sonar at the pose of the step its firing falls on, or
            // the oldest pose kept (just spawned or teleported).
            let n = self.sensors.sonar_count();
            let kept = entry.trail.len() as u64;
            entry.sonar_poses.clear();
            entry.sonar_poses.extend((0..n).map(|k| {
                let back = steps_before_frame(k, n, self.fire_every).min(kept.saturating_sub(1));
                kept.checked_sub(1 + back)
                    .and_then(|at| entry.trail.get(at as usize))
                    .copied()
                    .unwrap_or(pose)
            }));
            self.sensors.fire_sequential(
                &self.sensed,
                &pose,
                &entry.sonar_poses,
                &mut entry.rng,
                &mut entry.ranges,
            )?;
        } else {
            self.sensors
                .fire(&self.sensed, &pose, &mut entry.rng, &mut entry.ranges)?;
        }
        entry.sequence += 1;
        Ok(())
    }

    /// A pose drawn at random where a robot fits with room to move, any heading.
    pub fn random_free_pose(&self, rng: &mut ChaCha8Rng) -> Result<Pose2, SimError> {
        let (min, max) = self.world.bounds();
        for _ in 0..100_000 {
            let p = Point2::new(
                rng.random_range(min.x..=max.x),
                rng.random_range(min.y..=max.y),
            );
            // A little more room than the body needs, so the first moves
            // are free.
            if self.fits(p) && self.index.min_distance(p, 1.0) > self.robot_params.radius + 0.2 {
                let theta = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
                return Ok(Pose2::new(p.x, p.y, theta));
            }
        }
        Err(SimError::Blocked(format!(
            "found no free place for a robot in world {:?}",
            self.world.name()
        )))
    }
}

fn snapshot_of(name: &str, entry: &SimRobot, rig: &Arc<str>, time_s: f64) -> RobotSnapshot {
    RobotSnapshot {
        name: name.to_string(),
        time_s,
        rig: Arc::clone(rig),
        true_pose: entry.robot.true_pose(),
        odometry: entry.robot.odometry(),
        ranges: entry.ranges.clone(),
        sequence: entry.sequence,
        velocity: entry.robot.velocity(),
        bumper: entry.robot.bumper(),
        bumps: entry.robot.bumps(),
    }
}

fn check_pose(field: &str, pose: &Pose2) -> Result<(), SimError> {
    for (part, v) in [("x", pose.x), ("y", pose.y), ("theta", pose.theta)] {
        if !v.is_finite() {
            return Err(SimError::invalid(
                format!("{field}.{part}"),
                format!("must be a finite number, got {v}"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_world::Polygon;

    fn room() -> World {
        World::new(
            "room",
            Some(Polygon::rectangle(
                Point2::new(0.0, 0.0),
                Point2::new(10.0, 8.0),
            )),
            vec![Polygon::rectangle(
                Point2::new(4.0, 4.0),
                Point2::new(5.0, 5.0),
            )],
        )
        .expect("world")
    }

    /// Drives `names` in circles for 20 simulated seconds; returns the
    /// firings of robot "a".
    fn run(seed: u64, names: &[&str]) -> Vec<RobotSnapshot> {
        let mut sim = Simulation::new(room(), SimConfig::default(), seed).expect("sim");
        for name in names {
            sim.spawn(name, None).expect("spawn");
            sim.drive(name, 0.4, 0.3).expect("drive");
        }
        let mut fired = Vec::new();
        sim.advance(20.0, &mut fired).expect("advance");
        fired.into_iter().filter(|s| s.name == "a").collect()
    }

    #[test]
    fn a_seed_repeats_a_run_and_other_robots_do_not_change_it() {
        let alone = run(3, &["a"]);
        assert_eq!(alone.len(), 200, "20 s at 10 firings per second");
        assert_eq!(alone, run(3, &["a"]));
        assert_eq!(alone, run(3, &["a", "b", "c"]));
        assert_ne!(alone, run(4, &["a"]));
        let sequences: Vec<u64> = alone.iter().map(|s| s.sequence).collect();
        assert_eq!(sequences, (2..=201).collect::<Vec<_>>());
    }

    /// FNV-1a over the bits of every range and pose of a run.
    fn fingerprint(run: &[RobotSnapshot]) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        for s in run {
            let p = s.true_pose;
            for v in s.ranges.iter().chain([p.x, p.y, p.theta].iter()) {
                for b in v.to_bits().to_le_bytes() {
                    h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
                }
            }
        }
        h
    }

    #[test]
    fn the_scouts_readings_for_a_seed_are_unchanged() {
        // Recorded before rigs came to the simulator: the Scout's frames
        // must stay the same to the last bit.
        let run = run(3, &["a"]);
        assert_eq!(
            fingerprint(&run),
            16961497543682628086,
            "{:?}",
            run[57].ranges
        );
    }

    #[test]
    fn sequential_sonars_read_from_the_pose_at_their_firing() {
        use crate::sonar::SonarRing;
        let config = SimConfig {
            sonar: SonarParams {
                firing: SonarFiring::Sequential,
                ..SonarParams::exact()
            },
            ..SimConfig::default()
        };
        let mut sim = Simulation::new(room(), config, 1).expect("sim");
        sim.spawn("a", Some(Pose2::new(2.0, 2.0, 0.0)))
            .expect("spawn");
        sim.drive("a", 0.3, 0.8).expect("drive");
        let ring =
            SonarRing::new(deog_grid::SensorRing::scout(), SonarParams::exact()).expect("valid");
        let index = SegmentIndex::new(room().walls());
        let mut poses = Vec::new();
        let mut fired = Vec::new();
        let mut frames = 0;
        for _ in 0..100 {
            sim.advance(0.01, &mut fired).expect("advance");
            poses.push(sim.snapshot("a").expect("a robot").true_pose);
            let Some(frame) = fired.pop() else {
                continue;
            };
            frames += 1;
            let mut together = [0.0; 16];
            ring.true_ranges(&index, &frame.true_pose, &mut together)
                .expect("fires");
            for k in 0..16 {
                let back = steps_before_frame(k, 16, 10) as usize;
                let at = poses[poses.len() - 1 - back];
                let mut own = [0.0; 16];
                ring.true_ranges(&index, &at, &mut own).expect("fires");
                assert_eq!(frame.ranges[k], own[k], "sonar {k}");
            }
            assert_ne!(frame.ranges.to_vec(), together.to_vec(), "the motion shows");
            assert_eq!(
                frame.ranges[15], together[15],
                "the last fires with the frame"
            );
        }
        assert_eq!(frames, 10);
    }

    #[test]
    fn a_teleport_starts_the_sequential_record_afresh() {
        let config = SimConfig {
            sonar: SonarParams {
                firing: SonarFiring::Sequential,
                ..SonarParams::exact()
            },
            ..SimConfig::default()
        };
        let mut sim = Simulation::new(room(), config, 1).expect("sim");
        sim.spawn("a", Some(Pose2::new(2.0, 2.0, 0.0)))
            .expect("spawn");
        let mut fired = Vec::new();
        sim.advance(0.05, &mut fired).expect("advance");
        let there = Pose2::new(7.0, 6.0, 1.0);
        sim.teleport("a", there).expect("teleport");
        sim.advance(0.05, &mut fired).expect("advance");
        let frame = fired.pop().expect("a firing");
        let mut expected = vec![0.0; 16];
        sim.sensors()
            .true_ranges(&sim.index, &there, &mut expected)
            .expect("fires");
        assert_eq!(frame.ranges, expected);
    }

    #[test]
    fn time_is_counted_in_steps_and_remainders_carry_over() {
        let mut sim = Simulation::new(room(), SimConfig::default(), 1).expect("sim");
        sim.spawn("a", Some(Pose2::new(1.0, 1.0, 0.0)))
            .expect("spawn");
        let mut fired = Vec::new();
        for _ in 0..1000 {
            sim.advance(0.0037, &mut fired).expect("advance");
        }
        // 3.7 s: 370 steps, 37 firings.
        assert!((sim.time_s() - 3.7).abs() < 1e-9, "{}", sim.time_s());
        assert_eq!(fired.len(), 37);
        assert!(sim.advance(f64::NAN, &mut fired).is_err());
        assert!(sim.advance(-1.0, &mut fired).is_err());
    }

    #[test]
    fn spawning_checks_names_and_room() {
        let mut sim = Simulation::new(room(), SimConfig::default(), 1).expect("sim");
        sim.spawn("a", None).expect("spawn");
        assert!(matches!(
            sim.spawn("a", None),
            Err(SimError::RobotExists(_))
        ));
        assert!(matches!(
            sim.spawn("b", Some(Pose2::new(4.5, 4.5, 0.0))),
            Err(SimError::Blocked(_))
        ));
        assert!(matches!(
            sim.spawn("b", Some(Pose2::new(f64::NAN, 1.0, 0.0))),
            Err(SimError::Invalid { .. })
        ));
        assert!(matches!(
            sim.drive("nobody", 0.1, 0.0),
            Err(SimError::UnknownRobot(_))
        ));
        assert_eq!(sim.robot_count(), 1);
    }
}
