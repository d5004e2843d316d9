//! The kidnapped-robot test: the simulator carries a robot to a random
//! free pose at least 2 m away, with another heading, and its odometry
//! does not notice.

use anyhow::{Context, Result};
use deog_grid::Pose2;
use deog_proto::v1 as pb;
use deog_robot_client::SimClient;
use deog_robot_client::convert::pose_from_wire;
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_world::World;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The least distance a kidnap carries the robot, metres: less could pass
/// for a slip the localizer tracks through.
const LEAST_JUMP_M: f64 = 2.0;
/// Random poses tried for one at least [`LEAST_JUMP_M`] away; a world too
/// small for one gets the last pose tried.
const ATTEMPTS: usize = 1000;
/// Mixed into the demo's seed, so the kidnap's draws differ from the
/// simulator's own.
const SEED_SALT: u64 = 0x6b69_646e_6170;

/// The kidnap as it happened.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct KidnapDone {
    /// The robot carried off.
    pub robot: String,
    /// Simulated second the simulator carried it, as it reported.
    pub time_s: f64,
    /// Where it was, true pose.
    pub from: Pose2,
    /// Where it was put.
    pub to: Pose2,
}

/// Carries `state`'s robot to a random free pose of `world` at least 2 m
/// away; the pose is drawn from `seed`.
pub(crate) async fn kidnap_robot(
    sim: &SimClient,
    world: &World,
    state: &pb::RobotState,
    seed: u64,
) -> Result<KidnapDone> {
    let from = state
        .true_pose
        .map(pose_from_wire)
        .context("the simulator gave no true pose")?;
    let sampler = Simulation::new(world.clone(), SimConfig::default(), seed)
        .context("setting up the kidnap")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ SEED_SALT);
    let mut to = sampler.random_free_pose(&mut rng)?;
    for _ in 0..ATTEMPTS {
        if (to.x - from.x).hypot(to.y - from.y) >= LEAST_JUMP_M {
            break;
        }
        to = sampler.random_free_pose(&mut rng)?;
    }
    let after = sim
        .teleport(&state.name, to)
        .await
        .with_context(|| format!("kidnapping {}", state.name))?;
    Ok(KidnapDone {
        robot: state.name.clone(),
        time_s: after.time_s,
        from,
        to,
    })
}
