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
//! their own ([`planner`]), so that the steering never waits for one. A
//! goal not neared for a while (by the way left along its path) is barred
//! for a minute, for an hour the second time; the frontier cells around a
//! goal reached are barred for an hour (if still a frontier once reached,
//! nothing more can be seen of it from there). With frontiers left but
//! none in reach, the robot keeps looking for half a minute, and until its
//! bars run out, before it calls the map explored.

mod planner;

use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_explore::{
    Blacklist, Clearance, DeadReckoning, FollowCommand, FollowParams, Goal, GoalParams,
    PathFollower,
};
use deog_grid::Pose2;
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_or_origin;
use deog_robot_client::{MapClient, SimClient};
use deog_simulator::deog_rig::{Reading, Rig};

use crate::connection::{ConnectionArgs, SimConnectionArgs};
use crate::wander::{sim_rig, spawn_publisher, spawn_state_reader};
use planner::{Plan, PlanRequest, Planner, spawn_planner};

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

/// Plans in a row that found nothing before the robot is done.
const EMPTY_PLANS_TO_STOP: u32 = 3;
/// Simulated seconds a robot keeps looking when frontiers remain but none
/// can be reached: the map changes under it (a wall thickened by a
/// sonar's cone thins as more frames come, other robots open the way).
const UNREACHABLE_PATIENCE_S: f64 = 30.0;
/// Simulated seconds a barred goal stays barred the first time; barred
/// again at the same place, it stays barred as long as a goal reached.
const BAR_S: f64 = 60.0;
/// Simulated seconds a goal reached stays barred: for the rest of any
/// run worth the name (a frontier still there once reached is one nothing
/// more can be seen from).
const ARRIVED_BAR_S: f64 = 3600.0;
/// A goal reached bars the cells of its frontier within this distance of
/// it, metres (a long frontier's far end may yet be seen from elsewhere)...
const ARRIVED_BAR_REACH_M: f64 = 2.5;
/// ...each within this radius, metres.
const ARRIVED_BAR_CELL_M: f64 = 0.15;
/// Blocked this near its goal, metres, the robot counts it reached.
const BLOCKED_REACHES_M: f64 = 1.0;
/// A place a frontier was looked at from is not used again within this
/// distance, metres.
const APPROACH_BAR_M: f64 = 0.5;
/// Simulated seconds without nearing its goal before it is barred.
const STALL_S: f64 = 12.0;
/// Simulated seconds turned in place to look about when the map has
/// nothing near the robot yet, or after being blocked.
const LOOK_ABOUT_S: f64 = 2.0;

/// The steering half's own state: what it needs besides the plans.
struct Explorer {
    robot: String,
    map: String,
    client: MapClient,
    rig: Rig,
    follow: FollowParams,
    goals: GoalParams,
    blacklist: Blacklist,
    /// When the last bar for a while runs out, simulated seconds.
    bars_lapse_s: f64,
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
    /// Bars a goal not neared: for a while the first time, as long as a
    /// goal reached when the robot failed there before.
    fn bar_stalled(&mut self, x: f64, y: f64, now_s: f64) {
        let first = self.blacklist.bar_failure(
            (x, y),
            now_s,
            (BAR_S, ARRIVED_BAR_S),
            self.goals.blacklist_radius_m,
        );
        if first {
            self.bars_lapse_s = self.bars_lapse_s.max(now_s + BAR_S);
        }
    }

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

/// The goal being driven to, and how it is going.
struct Pursuit {
    goal: Goal,
    follower: PathFollower,
    planned_at_s: f64,
    /// The shortest way left along the path so far, metres, and when.
    best_distance: f64,
    best_at_s: f64,
}

#[derive(Debug, Default)]
struct Summary {
    frames: u64,
    published: u64,
    goals: u64,
    barred: u64,
    bumps: u64,
    distance_m: f64,
    sim_seconds: f64,
    finished: bool,
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
    let mut explorer = Explorer {
        robot: args.robot.clone(),
        map: args.map.clone(),
        client: client.clone(),
        rig: rig.clone(),
        follow: planner.follow,
        goals: planner.goals,
        blacklist: Blacklist::default(),
        bars_lapse_s: f64::NEG_INFINITY,
    };
    let (plan_requests, mut plans) = spawn_planner(planner);
    let mut reckoning = DeadReckoning::new();
    let mut estimates = (args.pose == DrivePose::Estimate).then(|| {
        spawn_estimate_follower(
            client.clone(),
            &args.robot,
            args.estimate_map.as_deref().unwrap_or(&args.map),
        )
    });
    let mut planning = false;
    // The last goal driven to: where, the nearest the robot came, when.
    let mut last_goal: Option<(f64, f64, f64, f64)> = None;
    let mut states = spawn_state_reader(sim.watch(&args.robot).await?);
    let shutdown = deog_harness::shutdown_signal();
    tokio::pin!(shutdown);
    let mut summary = Summary::default();
    let mut pursuit: Option<Pursuit> = None;
    let mut look_about_until: Option<f64> = None;
    let mut empty_plans = 0;
    // When the plans began to find frontiers but none in reach.
    let mut out_of_reach_since: Option<f64> = None;
    let mut backlog = Vec::new();
    let mut start_time = None;
    let mut last_pose: Option<Pose2> = None;
    let mut last_time_s = 0.0;
    let mut was_bumped = false;
    let mut next_plan_s = f64::NEG_INFINITY;
    'run: loop {
        if !states.next_batch(shutdown.as_mut(), &mut backlog).await? {
            break;
        }
        let mut newest = None;
        for state in backlog.drain(..) {
            let truth = pose_or_origin(state.true_pose);
            let start = *start_time.get_or_insert(state.time_s);
            if let Some(previous) = last_pose {
                summary.distance_m += (truth.x - previous.x).hypot(truth.y - previous.y);
            }
            last_pose = Some(truth);
            if state.bumper && !was_bumped {
                summary.bumps += 1;
                tracing::warn!(
                    x = truth.x,
                    y = truth.y,
                    heading_deg = truth.theta.to_degrees(),
                    "bumped into something"
                );
            }
            was_bumped = state.bumper;
            summary.frames += 1;
            summary.sim_seconds = state.time_s - start;
            last_time_s = state.time_s;
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
                    sim.drive(&args.robot, 0.0, 0.5 * explorer.follow.max_turn_rate)
                        .await?;
                    continue;
                }
            },
        };

        if look_about_until.is_some_and(|until| now < until) {
            let turn = if clearance.left >= clearance.right {
                1.0
            } else {
                -1.0
            };
            sim.drive(&args.robot, 0.0, turn * explorer.follow.max_turn_rate)
                .await?;
            continue;
        }
        look_about_until = None;
        // A plan that came back since the last state.
        match plans.try_recv() {
            Ok(answer) => {
                planning = false;
                let (request, plan) = answer?;
                match plan {
                    Plan::Go { ref goal, .. }
                        if explorer.blacklist.bars(
                            goal.x,
                            goal.y,
                            explorer.goals.blacklist_radius_m,
                        ) =>
                    {
                        // Planned before its goal was barred: plan again
                        // with the blacklist as it is now.
                        pursuit = None;
                    }
                    Plan::Go {
                        goal,
                        follower,
                        tight,
                    } => {
                        empty_plans = 0;
                        out_of_reach_since = None;
                        // The same goal as the last one, even if the pursuit
                        // was dropped in between (blocked, looking about):
                        // its progress carries over, so a goal the robot
                        // keeps being turned back from is still barred.
                        let same = last_goal.is_some_and(|(x, y, _, _)| {
                            (x - goal.x).hypot(y - goal.y) <= explorer.goals.current_radius_m
                        });
                        let distance = follower.remaining_length_m(pose);
                        let (best_distance, best_at_s) = match last_goal {
                            Some((_, _, best, at)) if same => (best, at),
                            _ => {
                                summary.goals += 1;
                                tracing::info!(
                                    x = goal.x,
                                    y = goal.y,
                                    frontier_m = goal.frontier_m,
                                    travel_m = goal.travel_m,
                                    tight,
                                    approach = goal.approach,
                                    "new goal"
                                );
                                (distance, now)
                            }
                        };
                        // Each plan refreshes the claim, so that it stays fresh.
                        explorer.publish_goal(goal.x, goal.y, now, true).await?;
                        pursuit = Some(Pursuit {
                            goal,
                            follower,
                            planned_at_s: request.now_s,
                            best_distance,
                            best_at_s,
                        });
                    }
                    Plan::LookAbout => {
                        look_about_until = Some(now + LOOK_ABOUT_S);
                        continue;
                    }
                    Plan::Nothing { frontiers } => {
                        pursuit = None;
                        empty_plans += 1;
                        let since = *out_of_reach_since.get_or_insert(now);
                        tracing::info!(frontiers, empty_plans, "no reachable frontier");
                        // Frontiers left out of reach: not done while the
                        // map may yet open a way or a bar run out.
                        let hoping = frontiers > 0
                            && (now - since < UNREACHABLE_PATIENCE_S
                                || now < explorer.bars_lapse_s);
                        if empty_plans >= EMPTY_PLANS_TO_STOP && !hoping {
                            summary.finished = true;
                            break 'run;
                        }
                        // Let the cartographer catch up before looking
                        // again; turn meanwhile, so that the sonars sweep
                        // what the map holds around the robot.
                        next_plan_s = now + 1.0;
                        if frontiers > 0 {
                            look_about_until = Some(now + LOOK_ABOUT_S);
                        }
                        sim.drive(&args.robot, 0.0, 0.0).await?;
                        continue;
                    }
                }
            }
            Err(tokio::sync::mpsc::error::TryRecvError::Empty) => {}
            Err(tokio::sync::mpsc::error::TryRecvError::Disconnected) => {
                bail!("the planner stopped")
            }
        }
        let replan = pursuit
            .as_ref()
            .is_none_or(|p| now - p.planned_at_s >= args.replan_s);
        if replan && !planning && now >= next_plan_s {
            explorer.blacklist.expire(now);
            let request = PlanRequest {
                pose,
                now_s: now,
                current: pursuit.as_ref().map(|p| (p.goal.x, p.goal.y)),
                blacklist: explorer.blacklist.clone(),
            };
            plan_requests
                .send(request)
                .await
                .context("the planner stopped")?;
            planning = true;
        }
        let Some(p) = pursuit.as_mut() else {
            sim.drive(&args.robot, 0.0, 0.0).await?;
            continue;
        };
        let distance = (p.goal.x - pose.x).hypot(p.goal.y - pose.y);
        // Progress is the way left along the path, which falls as the
        // robot goes round a pillar while the straight distance may not.
        let way_left = p.follower.remaining_length_m(pose);
        if way_left < p.best_distance - 0.1 {
            p.best_distance = way_left;
            p.best_at_s = now;
        }
        last_goal = Some((p.goal.x, p.goal.y, p.best_distance, p.best_at_s));
        let stalled = now - p.best_at_s > STALL_S;
        let command = p.follower.command(pose, clearance);
        tracing::trace!(
            x = pose.x,
            y = pose.y,
            theta = pose.theta,
            front = clearance.front(),
            ?command,
            "steering"
        );
        // Stopped by something just short of the goal is as near as the
        // robot gets: as good as there.
        let reached = command == FollowCommand::Arrived
            || (command == FollowCommand::Blocked && distance <= BLOCKED_REACHES_M);
        let (linear, angular) = match command {
            _ if reached => {
                // A frontier looked at from near: not from here again;
                // turn, so that the sonars sweep it, then plan (the way
                // there may have opened).
                if p.goal.approach {
                    explorer.blacklist.add_within(
                        p.goal.x,
                        p.goal.y,
                        APPROACH_BAR_M,
                        now + ARRIVED_BAR_S,
                    );
                    look_about_until = Some(now + LOOK_ABOUT_S);
                    pursuit = None;
                    sim.drive(&args.robot, 0.0, 0.0).await?;
                    continue;
                }
                // A frontier the robot stands at and still sees as one (a
                // gap in a wall's line, the far side of furniture) cannot
                // be seen better from there: bar its cells around the
                // goal, or the robot would come back to it for ever.
                for &(x, y) in &p.goal.frontier_cells {
                    if (x - p.goal.x).hypot(y - p.goal.y) <= ARRIVED_BAR_REACH_M {
                        explorer.blacklist.add_within(
                            x,
                            y,
                            ARRIVED_BAR_CELL_M,
                            now + ARRIVED_BAR_S,
                        );
                    }
                }
                if command == FollowCommand::Blocked {
                    look_about_until = Some(now + LOOK_ABOUT_S);
                }
                pursuit = None;
                (0.0, 0.0)
            }
            FollowCommand::Drive { linear, angular } if !stalled => (linear, angular),
            _ => {
                if stalled {
                    explorer.bar_stalled(p.goal.x, p.goal.y, now);
                    last_goal = None;
                    summary.barred += 1;
                    tracing::info!(
                        x = p.goal.x,
                        y = p.goal.y,
                        "goal not neared: barred for a while"
                    );
                }
                pursuit = None;
                look_about_until = Some(now + LOOK_ABOUT_S);
                (0.0, 0.0)
            }
        };
        sim.drive(&args.robot, linear, angular).await?;
    }
    if let Err(error) = sim.drive(&args.robot, 0.0, 0.0).await {
        tracing::warn!(%error, "could not stop the robot");
    }
    // Give the goal up, so the others need not avoid it.
    let at = last_pose.unwrap_or_default();
    if let Err(error) = explorer.publish_goal(at.x, at.y, last_time_s, false).await {
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
