//! The wanderer, run against the simulation in-process for simulated
//! minutes in each world: it keeps moving, explores, and hits nothing.

use deog_grid::SensorRing;
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{WanderParams, Wanderer};
use deog_world::load_world;
use std::collections::HashSet;

fn world(name: &str) -> deog_world::World {
    let path = format!("{}/../worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    load_world(std::path::Path::new(&path)).expect("world loads")
}

/// Wanders for `seconds` of simulated time; returns (bumps, distance m,
/// distinct 1 m squares visited).
fn wander(world_name: &str, seed: u64, seconds: f64) -> (u32, f64, usize) {
    let mut sim = Simulation::new(world(world_name), SimConfig::default(), seed).expect("sim");
    let first = sim.spawn("w", None).expect("spawn");
    let mut wanderer =
        Wanderer::new(WanderParams::default(), &SensorRing::scout(), seed).expect("wanderer");
    let (mut bumps, mut distance, mut last) = (0, 0.0, first.true_pose);
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
        was_bumped = state.bumper;
        let p = state.true_pose;
        distance += (p.x - last.x).hypot(p.y - last.y);
        last = p;
        squares.insert((p.x.floor() as i64, p.y.floor() as i64));
    }
    (bumps, distance, squares.len())
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
