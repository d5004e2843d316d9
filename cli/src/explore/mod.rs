//! `deog explore`: drives one simulated robot to the frontiers of the
//! shared map (known-free cells beside unknown ones) as the map grows, and
//! publishes its frames as `deog wander` does, so a cartographer maps
//! them. Stops by itself, saying so, once no reachable frontier is left.
//!
//! Each plan reads the map's changed tiles from the server, inflates it by
//! the robot's radius, prices every cell from the robot at once and picks
//! the frontier whose length is worth most against the way there; a pure
//! pursuit follows the path, and the robot's own ranges slow and stop it
//! short of anything ahead, mapped or not. Plans are made in a task of
//! their own ([`planner`]), so that the steering never waits for one. What
//! to do with each robot state (follow, ask for a plan, bar a goal not
//! neared, look about, stop once explored) is `deog_explore::Steering`'s
//! to decide; this loop drives, publishes and logs as it says.

mod planner;
mod summary;

use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_explore::{Clearance, DeadReckoning, FollowParams, Steering, SteeringParams};
use deog_grid::Pose2;
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_or_origin;
use deog_robot_client::{MapClient, SimClient};
use deog_simulator::deog_rig::{Reading, Rig};

use crate::connection::{ConnectionArgs, SimConnectionArgs};
use crate::wander::{sim_rig, spawn_publisher, spawn_state_reader};
use planner::{Planner, spawn_planner};
use summary::Summary;

/// Options of `deog explore`.
#[derive(Debug, Args)]
pub struct ExploreArgs {
    /// The robot to drive.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    /// The shared map whose frontiers it drives to (the one its
    /// cartographer writes).
    #[arg(long)]
    pub map: String,
    #[command(flatten)]
    pub sim: SimConnectionArgs,
    /// Spawn the robot first (at the world's start pose).
    #[arg(long)]
    pub spawn: bool,
    /// Simulated seconds after which it stops even with frontiers left
    /// (0: none).
    #[arg(long, default_value_t = 0.0)]
    pub duration: f64,
    /// Forward speed in the open, m/s.
    #[arg(long, default_value_t = 0.5)]
    pub speed: f64,
    /// Simulated seconds between plans while following a path.
    #[arg(long, default_value_t = 3.0)]
    pub replan_s: f64,
    /// Cell size the paths are planned on, metres: the map's cells merged
    /// up to about this size (never finer than the map).
    #[arg(long, default_value_t = 0.1)]
    pub plan_resolution_m: f64,
    /// Frontiers shorter than this are ignored, metres.
    #[arg(long, default_value_t = 0.5)]
    pub min_frontier_m: f64,
    /// The pose it plans and steers from: the simulator's true pose, the
    /// robot's odometry, or a localizer's converged estimates carried
    /// forward by the odometry since their frames (`estimate`; until the
    /// first one the robot turns on the spot).
    #[arg(long, value_enum, default_value_t = DrivePose::True)]
    pub pose: DrivePose,
    /// With --pose estimate: the map the estimates are made on (default:
    /// --map).
    #[arg(long)]
    pub estimate_map: Option<String>,
    /// Drive without publishing frames.
    #[arg(long)]
    pub no_publish: bool,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// Which pose `deog explore` plans and steers from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DrivePose {
    /// The simulator's true pose.
    True,
    /// The robot's odometry.
    Odometry,
    /// A localizer's converged estimates, carried forward by odometry.
    Estimate,
}

/// Wall-clock time between two reads of the localizer's new estimates.
const ESTIMATE_POLL: Duration = Duration::from_millis(250);

/// The robot's own ends of the loop: its name, the map and server it
/// claims goals on, the rig its ranges come from.
struct Explorer {
    robot: String,
    map: String,
    client: MapClient,
    rig: Rig,
}

/// Follows the localizer's converged estimates of `robot` on `map`: the
/// newest one's frame and pose.
fn spawn_estimate_follower(
    client: MapClient,
    robot: &str,
    map: &str,
) -> tokio::sync::watch::Receiver<Option<(u64, Pose2)>> {
    let (newest, follow) = tokio::sync::watch::channel(None);
    let (robot, map) = (robot.to_string(), map.to_string());
    tokio::spawn(async move {
        let mut from = 0;
        loop {
            match client.read_poses(&robot, from, 0).await {
                Ok(poses) => {
                    if let Some(last) = poses.last() {
                        from = last.frame_sequence + 1;
                    }
                    let found = poses
                        .iter()
                        .rev()
                        .find(|p| p.map == map && p.converged)
                        .map(|p| (p.frame_sequence, pose_or_origin(p.pose)));
                    if found.is_some() && newest.send(found).is_err() {
                        break;
                    }
                }
                Err(error) => tracing::warn!(%error, "reading the estimates"),
            }
            tokio::time::sleep(ESTIMATE_POLL).await;
        }
    });
    follow
}

fn follow_params(args: &ExploreArgs) -> Result<FollowParams> {
    let follow = FollowParams {
        cruise_speed: args.speed,
        ..FollowParams::default()
    };
    follow.validate()?;
    Ok(follow)
}

impl Explorer {
    /// Tells the other explorers where this one is heading; `active`
    /// false gives the goal up.
    async fn publish_goal(&self, x: f64, y: f64, time_s: f64, active: bool) -> Result<()> {
        self.client
            .publish_goal(pb::ExplorationGoal {
                robot: self.robot.clone(),
                map: self.map.clone(),
                x,
                y,
                time_s,
                active,
            })
            .await
            .context("publishing the goal")
    }

    /// What the robot's ranges see around it, metres from its body.
    fn clearance(&self, ranges: &[f64]) -> Clearance {
        let echoes = self
            .rig
            .beams()
            .iter()
            .zip(ranges)
            .filter_map(|(beam, &range)| match beam.classify(range) {
                Some(Reading::Echo(range)) => Some((
                    beam.mount.x + range * beam.mount.theta.cos(),
                    beam.mount.y + range * beam.mount.theta.sin(),
                )),
                _ => None,
            });
        Clearance::of_echoes(echoes, self.rig.body_radius())
    }
}

/// Runs the explorer until no reachable frontier is left, its duration
/// passes, ctrl-c or SIGTERM.
pub fn run(args: ExploreArgs) -> Result<()> {
    check_robot_name(&args.robot).context("--robot")?;
    deog_proto::names::check_map_name(&args.map).context("--map")?;
    if let Some(map) = &args.estimate_map {
        deog_proto::names::check_map_name(map).context("--estimate-map")?;
    }
    for (name, value, least) in [
        ("--duration", args.duration, 0.0),
        ("--replan-s", args.replan_s, 0.1),
        ("--min-frontier-m", args.min_frontier_m, 0.0),
        ("--plan-resolution-m", args.plan_resolution_m, 0.0),
    ] {
        if !(value.is_finite() && value >= least) {
            bail!("{name} must be at least {least}, got {value}");
        }
    }
    if args.plan_resolution_m > 0.5 {
        bail!(
            "--plan-resolution-m must be at most 0.5 (coarser cells close doors), got {}",
            args.plan_resolution_m
        );
    }
    if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 2.0) {
        bail!(
            "--speed must be above 0 and at most 2 m/s, got {}",
            args.speed
        );
    }
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let summary = runtime.block_on(explore(&args))?;
    let ending = if summary.finished {
        "no reachable frontier left: explored"
    } else {
        "stopped before the map was explored"
    };
    println!(
        "{}: {ending}; {} goals, {} barred, {:.1} m driven over {:.1} simulated s, {} bumps, {} frames ({} published)",
        args.robot,
        summary.goals,
        summary.barred,
        summary.distance_m,
        summary.sim_seconds,
        summary.bumps,
        summary.frames,
        summary.published
    );
    Ok(())
}

async fn explore(args: &ExploreArgs) -> Result<Summary> {
    // Deaf to the signal no more while it connects and waits to start:
    // until the loop below listens, the signal ends the process.
    let until_running =
        deog_harness::ExitOnSignal::during("connecting", &tokio::runtime::Handle::current());
    let sim = SimClient::connect(args.sim.client_config()?.retrying_forever()).await?;
    let rig = sim_rig(&sim).await?;
    let client = MapClient::connect(args.connection.client_config()?.retrying_forever()).await?;
    if args.spawn {
        let state = sim.spawn(&args.robot, None).await?;
        let p = pose_or_origin(state.true_pose);
        tracing::info!(robot = %args.robot, x = p.x, y = p.y, "spawned");
    }
    let publisher = if args.no_publish {
        None
    } else {
        if !deog_simulator::deog_rig::is_built_in(rig.name()) {
            client.put_rig(&rig).await.context("storing the rig")?;
        }
        Some(spawn_publisher(client.clone()))
    };
    // The cartographer makes the map from the first frames: wait for it.
    let planner = loop {
        match Planner::new(client.clone(), &args.map, &rig, args).await {
            Ok(planner) => break planner,
            Err(error) if publisher.is_some() => {
                tracing::debug!(%error, "waiting for the map");
                tokio::time::sleep(Duration::from_millis(200)).await;
                // Frames must flow for the map to appear: publish while waiting.
                let state = sim.state(&args.robot).await?;
                if let Some((frames, _)) = &publisher {
                    let _ = frames.send(frame_of(&args.robot, &state, &rig)).await;
                }
            }
            Err(error) => return Err(error),
        }
    };
    let explorer = Explorer {
        robot: args.robot.clone(),
        map: args.map.clone(),
        client: client.clone(),
        rig: rig.clone(),
    };
    let mut steering = Steering::new(SteeringParams {
        max_turn_rate: planner.settings.follow.max_turn_rate,
        replan_s: args.replan_s,
        goals: planner.settings.goals,
    });
    let max_turn_rate = planner.settings.follow.max_turn_rate;
    let (plan_requests, mut plans) = spawn_planner(planner);
    let mut reckoning = DeadReckoning::new();
    let mut estimates = (args.pose == DrivePose::Estimate).then(|| {
        spawn_estimate_follower(
            client.clone(),
            &args.robot,
            args.estimate_map.as_deref().unwrap_or(&args.map),
        )
    });
    let mut states = spawn_state_reader(sim.watch(&args.robot).await?);
    let shutdown = deog_harness::shutdown_signal();
    tokio::pin!(shutdown);
    drop(until_running);
    let mut summary = Summary::default();
    let mut backlog = Vec::new();
    'run: loop {
        if !states.next_batch(shutdown.as_mut(), &mut backlog).await? {
            break;
        }
        let mut newest = None;
        for state in backlog.drain(..) {
            summary.observe(&state);
            if let Some((frames, _)) = &publisher
                && frames
                    .send(frame_of(&args.robot, &state, &rig))
                    .await
                    .is_err()
            {
                break 'run;
            }
            if args.duration > 0.0 && summary.sim_seconds >= args.duration {
                break 'run;
            }
            newest = Some(state);
        }
        let Some(state) = newest else { continue };
        let now = state.time_s;
        let clearance = explorer.clearance(&state.ranges);
        reckoning.odometry(state.sequence, pose_or_origin(state.odometry));
        if let Some(estimates) = &mut estimates
            && estimates.has_changed().unwrap_or(false)
            && let Some((sequence, estimate)) = *estimates.borrow_and_update()
        {
            reckoning.estimate(sequence, estimate);
        }
        let pose = match args.pose {
            DrivePose::True => pose_or_origin(state.true_pose),
            DrivePose::Odometry => pose_or_origin(state.odometry),
            DrivePose::Estimate => match reckoning.pose() {
                Some(pose) => pose,
                None => {
                    // Nowhere to plan from yet: turn, so the localizer
                    // sees the walls all around.
                    sim.drive(&args.robot, 0.0, 0.5 * max_turn_rate).await?;
                    continue;
                }
            },
        };
        if let Some((linear, angular)) = steering.looking_about(now, clearance) {
            sim.drive(&args.robot, linear, angular).await?;
            continue;
        }
        // A plan that came back since the last state.
        let plan = match plans.try_recv() {
            Ok(answer) => {
                let (request, plan) = answer?;
                Some((request.now_s, plan))
            }
            Err(tokio::sync::mpsc::error::TryRecvError::Empty) => None,
            Err(tokio::sync::mpsc::error::TryRecvError::Disconnected) => {
                bail!("the planner stopped")
            }
        };
        let decision = steering.step(now, pose, clearance, plan);
        summary.note(&decision.events);
        if decision.finished {
            summary.finished = true;
            break 'run;
        }
        if let Some((x, y)) = decision.claim {
            explorer.publish_goal(x, y, now, true).await?;
        }
        if let Some(request) = decision.request {
            plan_requests
                .send(request)
                .await
                .context("the planner stopped")?;
        }
        if let Some(command) = decision.followed {
            tracing::trace!(
                x = pose.x,
                y = pose.y,
                theta = pose.theta,
                front = clearance.front(),
                ?command,
                "steering"
            );
        }
        if let Some((linear, angular)) = decision.drive {
            sim.drive(&args.robot, linear, angular).await?;
        }
    }
    if let Err(error) = sim.drive(&args.robot, 0.0, 0.0).await {
        tracing::warn!(%error, "could not stop the robot");
    }
    // Give the goal up, so the others need not avoid it.
    let at = summary.last_pose.unwrap_or_default();
    let time_s = summary.last_time_s;
    if let Err(error) = explorer.publish_goal(at.x, at.y, time_s, false).await {
        tracing::warn!(%error, "could not give the goal up");
    }
    if let Some((frames, task)) = publisher {
        drop(frames);
        summary.published = task.await.context("the frame publisher panicked")??;
    }
    Ok(summary)
}

fn frame_of(robot: &str, state: &pb::RobotState, rig: &Rig) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: robot.to_string(),
        sequence: state.sequence,
        time_s: state.time_s,
        odometry: state.odometry,
        true_pose: state.true_pose,
        ranges: state.ranges.clone(),
        rig: rig.name().to_owned(),
        reference_pose: None,
    }
}
