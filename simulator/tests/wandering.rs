//! The wanderer, run against the simulation in-process for simulated
//! minutes in each world: it keeps moving, explores, and hits nothing,
//! with the Scout's sonar ring, the Pioneer's sonar arrays or a laser.

use deog_grid::SensorRing;
use deog_rig::{Rig, load_rig_spec};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{WanderParams, Wanderer};
use deog_world::load_world;
use std::collections::HashSet;

fn world(name: &str) -> deog_world::World {
    let path = format!("{}/../worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    load_world(std::path::Path::new(&path)).expect("world loads")
}

/// What a wandering run did.
#[derive(Debug)]
struct Run {
    /// Times the bumper went on.
    bumps: u32,
    /// Firings with the bumper on.
    bumped_frames: u32,
    /// Firings in all.
    frames: u32,
    /// Metres driven.
    distance: f64,
    /// Distinct 1 m squares visited.
    squares: usize,
}

/// Wanders a Scout for `seconds` of simulated time; returns (bumps,
/// distance m, distinct 1 m squares visited).
fn wander(world_name: &str, seed: u64, seconds: f64) -> (u32, f64, usize) {
    let wanderer =
        Wanderer::new(WanderParams::default(), &SensorRing::scout(), seed).expect("wanderer");
    let run = wander_with(world_name, deog_rig::scout(), wanderer, seed, seconds);
    (run.bumps, run.distance, run.squares)
}

/// Wanders a robot carrying `rig` for `seconds` of simulated time.
fn wander_rig(world_name: &str, rig: Rig, seed: u64, seconds: f64) -> Run {
    let wanderer = Wanderer::for_rig(WanderParams::default(), &rig, seed).expect("wanderer");
    wander_with(world_name, rig, wanderer, seed, seconds)
}

fn wander_with(world_name: &str, rig: Rig, mut wanderer: Wanderer, seed: u64, seconds: f64) -> Run {
    let config = SimConfig {
        rig,
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(world(world_name), config, seed).expect("sim");
    let first = sim.spawn("w", None).expect("spawn");
    let (mut bumps, mut distance, mut last) = (0, 0.0, first.true_pose);
    let (mut frames, mut bumped_frames) = (0, 0);
    let mut squares = HashSet::new();
    let mut was_bumped = false;
    let mut fired = Vec::new();
    let period = sim.config().sonar_period_s;
    let mut state = first;
    while sim.time_s() < seconds {
        let (v, w) = wanderer
            .command(&state.ranges, state.bumper, period)
            .expect("command");
        sim.drive("w", v, w).expect("drive");
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired).expect("advance");
        }
        state = fired.pop().expect("a firing");
        if state.bumper && !was_bumped {
            bumps += 1;
        }
        frames += 1;
        bumped_frames += u32::from(state.bumper);
        was_bumped = state.bumper;
        let p = state.true_pose;
        distance += (p.x - last.x).hypot(p.y - last.y);
        last = p;
        squares.insert((p.x.floor() as i64, p.y.floor() as i64));
    }
    Run {
        bumps,
        bumped_frames,
        frames,
        distance,
        squares: squares.len(),
    }
}

#[test]
fn ten_minutes_in_map2_without_a_bump() {
    for seed in 1..=4 {
        let (bumps, distance, squares) = wander("map2", seed, 600.0);
        assert_eq!(bumps, 0, "seed {seed}");
        assert!(distance > 100.0, "seed {seed}: drove only {distance:.1} m");
        assert!(squares > 30, "seed {seed}: visited only {squares} squares");
    }
}

#[test]
fn ten_minutes_in_map1_and_the_office_without_a_bump() {
    for name in ["map1", "office"] {
        let (bumps, distance, squares) = wander(name, 11, 600.0);
        assert_eq!(bumps, 0, "{name}");
        assert!(distance > 100.0, "{name}: drove only {distance:.1} m");
        assert!(squares > 30, "{name}: visited only {squares} squares");
    }
}

#[test]
fn the_scouts_wandering_is_unchanged() {
    // Recorded before the wanderer learned other rigs: the Scout's runs
    // (and so the seeded benchmarks built on them) stay the same.
    let (bumps, distance, squares) = wander("office", 5, 120.0);
    assert_eq!(
        (bumps, distance.to_bits(), squares),
        (0, 4629756235604547707, 28),
        "{distance}"
    );
}

#[test]
fn a_pioneer_and_a_laser_robot_wander_the_office_without_sticking_to_walls() {
    for name in ["pioneer3dx", "laser180"] {
        for seed in [1, 2] {
            let rig = load_rig_spec(name).expect("built in");
            let run = wander_rig("office", rig, seed, 300.0);
            eprintln!("{name} seed {seed}: {run:?}");
            assert_eq!(run.bumps, 0, "{name} seed {seed}: {run:?}");
            assert!(
                run.bumped_frames * 100 <= run.frames,
                "{name} seed {seed}: bumper on too often: {run:?}"
            );
            assert!(run.distance > 50.0, "{name} seed {seed}: {run:?}");
            assert!(run.squares > 20, "{name} seed {seed}: {run:?}");
        }
    }
}
