//! `deog teleport`: carries a simulated robot to another pose without
//! telling its odometry (the kidnapped-robot test).

use anyhow::{Context, Result};
use clap::Args;
use deog_grid::Pose2;
use deog_robot_client::SimClient;

use crate::connection::{ConnectTimeoutArgs, SimConnectionArgs};
use crate::pose_args::parse_pose;

/// Options of `deog teleport`.
#[derive(Debug, Args)]
pub struct TeleportArgs {
    /// The robot to carry off.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// Where to put it: x,y,theta (metres, radians).
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pub pose: Pose2,
    #[command(flatten)]
    pub sim: SimConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// Runs `deog teleport`.
pub fn run(args: TeleportArgs) -> Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let config = args.timeout.apply(args.sim.client_config()?)?;
    runtime.block_on(async {
        let sim = SimClient::connect(config).await?;
        let state = sim
            .teleport(&args.robot, args.pose)
            .await
            .with_context(|| format!("teleporting {}", args.robot))?;
        let pose = state.true_pose.unwrap_or_default();
        println!(
            "{} is now at ({:.3}, {:.3}, {:.3}); its odometry did not notice",
            args.robot, pose.x, pose.y, pose.theta
        );
        Ok(())
    })
}
