//! The frames both localizers read: one run of the wanderer in a world,
//! each frame's time, odometry, true pose and sonar ranges.

use anyhow::{Context, Result};
use deog_grid::Pose2;
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{WanderParams, Wanderer};

/// The robot's name in the simulator (it seeds the robot's draws).
const ROBOT: &str = "scout";

/// One recorded frame.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Frame {
    /// Simulated seconds since the run started.
    pub time_s: f64,
    /// Where the odometry says the robot is.
    pub odometry: Pose2,
    /// Where it is.
    pub true_pose: Pose2,
    /// The sonar ranges, metres, in the ring's order (at or past the
    /// maximum: no echo).
    pub ranges: Vec<f64>,
}

/// `count` frames of the wanderer in `world` with the simulator of
/// `config`, the robot placed at a random free pose by `seed`.
pub(super) fn record_frames(
    world: deog_world::World,
    config: &SimConfig,
    seed: u64,
    count: usize,
) -> Result<Vec<Frame>> {
    let mut sim = Simulation::new(world, config.clone(), seed)?;
    let mut state = sim.spawn(ROBOT, None)?;
    let mut wanderer = Wanderer::for_rig(WanderParams::default(), &config.rig, seed)?;
    let period = sim.config().sonar_period_s;
    let mut fired = Vec::new();
    let mut frames = Vec::with_capacity(count);
    while frames.len() < count {
        let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
        sim.drive(ROBOT, v, w)?;
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired)?;
        }
        state = fired.pop().context("a firing")?;
        frames.push(Frame {
            time_s: state.time_s,
            odometry: state.odometry,
            true_pose: state.true_pose,
            ranges: state.ranges.clone(),
        });
    }
    Ok(frames)
}
