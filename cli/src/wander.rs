//! `deog wander`: drives one robot about its world at random without
//! hitting anything, and publishes every frame to the map server, naming
//! the simulator's rig (stored on the map server first when it is not a
//! built-in one).

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::Pose2;
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_or_origin;
use deog_robot_client::{MapClient, SimClient};
use deog_simulator::data_file::{DataUnits, format_line};
use deog_simulator::deog_rig::{self, Rig};
use deog_simulator::{WanderParams, Wanderer};
use tokio::sync::mpsc;

use crate::connection::{ConnectionArgs, SimConnectionArgs};
use crate::pose_args::{PoseSource, parse_pose};

/// Options of `deog wander`.
#[derive(Debug, Args)]
pub struct WanderArgs {
    /// The robot to drive.
    #[arg(long, env = "DEOG_ROBOT")]
    pub robot: String,
    #[command(flatten)]
    pub sim: SimConnectionArgs,
    /// Place the robot first (at --start, or at a random free pose); without
    /// it the robot must exist.
    #[arg(long)]
    pub spawn: bool,
    /// Where to place it with --spawn: x,y,theta (metres, radians).
    #[arg(long, value_parser = parse_pose, requires = "spawn")]
    pub start: Option<Pose2>,
    /// Seed of the wandering's random turns.
    #[arg(long, env = "DEOG_SEED", default_value_t = 1)]
    pub seed: u64,
    /// Stop after this many simulated seconds (0: run until ctrl-c).
    #[arg(long, default_value_t = 0.0)]
    pub duration: f64,
    /// Cruising speed, m/s.
    #[arg(long, default_value_t = 0.5)]
    pub speed: f64,
    /// Do not publish frames to the map server.
    #[arg(long)]
    pub no_publish: bool,
    /// Also write the thesis's data file (`x y theta s1 ... s16` per line;
    /// Scout rig only).
    #[arg(long)]
    pub data_file: Option<PathBuf>,
    /// Units of the data file.
    #[arg(long, default_value = "si")]
    pub data_units: DataUnits,
    /// Which pose the data file holds.
    #[arg(long, value_enum, default_value_t = PoseSource::True)]
    pub data_pose: PoseSource,
    /// The rig the robot must carry (a built-in name or a rig file): the
    /// wanderer stops at once if the simulator's is another. Without it,
    /// the simulator's rig, whatever it is.
    #[arg(long)]
    pub rig: Option<String>,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// What the wanderer did.
#[derive(Debug, Default)]
struct Summary {
    frames: u64,
    published: u64,
    bumps: u64,
    distance_m: f64,
    sim_seconds: f64,
}

/// Runs the wanderer until its duration passes, ctrl-c or SIGTERM.
pub fn run(args: WanderArgs) -> Result<()> {
    if !(args.duration.is_finite() && args.duration >= 0.0) {
        bail!("--duration must be zero or positive, got {}", args.duration);
    }
    check_robot_name(&args.robot).context("--robot")?;
    let params = WanderParams {
        cruise_speed: args.speed,
        ..WanderParams::default()
    };
    let mut data_file = match &args.data_file {
        Some(path) => Some(std::io::BufWriter::new(
            std::fs::File::create(path)
                .with_context(|| format!("creating data file {}", path.display()))?,
        )),
        None => None,
    };
    let sim_config = args.sim.client_config()?.retrying_forever();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let summary = runtime.block_on(async {
        // Deaf to the signal no more while it connects and waits to start:
        // until the loop below listens, the signal ends the process.
        let until_running =
            deog_harness::ExitOnSignal::during("connecting", &tokio::runtime::Handle::current());
        let sim = SimClient::connect(sim_config).await?;
        let rig = sim_rig(&sim).await?;
        if let Some(spec) = &args.rig {
            let expected = crate::rig_args::load_rig(spec)?;
            if expected != rig {
                bail!(
                    "the simulator's robots carry rig {}, not {} (--rig)",
                    rig.name(),
                    expected.name()
                );
            }
        }
        tracing::info!(rig = %rig.name(), readings = rig.readings(), "the simulator's rig");
        if data_file.is_some() && rig.name() != deog_rig::DEFAULT_RIG {
            bail!(
                "--data-file writes the Scout's 16 sonar readings; the simulator's rig is {}",
                rig.name()
            );
        }
        let mut wanderer = Wanderer::for_rig(params, &rig, args.seed)?;
        if args.spawn {
            let state = sim.spawn(&args.robot, args.start).await?;
            let p = pose_or_origin(state.true_pose);
            tracing::info!(robot = %args.robot, x = p.x, y = p.y, theta = p.theta, "spawned");
        }
        let publisher = if args.no_publish {
            None
        } else {
            let config = args.connection.client_config()?.retrying_forever();
            let map = MapClient::connect(config).await?;
            // The map server knows the built-in rigs; any other must be
            // stored before a frame names it.
            if !deog_rig::is_built_in(rig.name()) {
                map.put_rig(&rig)
                    .await
                    .with_context(|| format!("storing rig {} on the map server", rig.name()))?;
            }
            Some(spawn_publisher(map))
        };
        let mut states = spawn_state_reader(sim.watch(&args.robot).await?);
        let shutdown = deog_harness::shutdown_signal();
        tokio::pin!(shutdown);
        drop(until_running);
        let mut summary = Summary::default();
        let (mut start_time, mut last_control, mut last_pose) = (None, None::<f64>, None::<Pose2>);
        let mut was_bumped = false;
        let mut backlog = Vec::new();
        'run: loop {
            // Everything that queued up while we were busy: each frame is
            // recorded, but only the newest steers, or a busy machine would
            // have the robot react to where it was.
            if !states.next_batch(shutdown.as_mut(), &mut backlog).await? {
                break;
            }
            let mut newest = None;
            for state in backlog.drain(..) {
                let true_pose = pose_or_origin(state.true_pose);
                let start = *start_time.get_or_insert(state.time_s);
                if let Some(previous) = last_pose {
                    summary.distance_m +=
                        (true_pose.x - previous.x).hypot(true_pose.y - previous.y);
                }
                last_pose = Some(true_pose);
                if state.bumper && !was_bumped {
                    summary.bumps += 1;
                }
                was_bumped = state.bumper;
                summary.frames += 1;
                summary.sim_seconds = state.time_s - start;
                if let Some(file) = data_file.as_mut() {
                    let pose = match args.data_pose {
                        PoseSource::True => true_pose,
                        PoseSource::Odometry => pose_or_origin(state.odometry),
                    };
                    file.write_all(format_line(&pose, &state.ranges, args.data_units).as_bytes())
                        .context("writing the data file")?;
                }
                let done = args.duration > 0.0 && summary.sim_seconds >= args.duration;
                if let Some((frames, _)) = &publisher {
                    let frame = pb::SonarFrame {
                        robot: args.robot.clone(),
                        sequence: state.sequence,
                        time_s: state.time_s,
                        odometry: state.odometry,
                        true_pose: state.true_pose,
                        ranges: state.ranges.clone(),
                        rig: rig.name().to_owned(),
                        reference_pose: None,
                    };
                    if frames.send(frame).await.is_err() {
                        break 'run;
                    }
                }
                if done {
                    break 'run;
                }
                newest = Some(state);
            }
            let Some(state) = newest else {
                continue;
            };
            let dt = last_control.map_or(0.1, |t| (state.time_s - t).max(1e-3));
            last_control = Some(state.time_s);
            let (linear, angular) = wanderer.command(&state.ranges, state.bumper, dt)?;
            sim.drive(&args.robot, linear, angular).await?;
        }
        // Leave the robot standing, not driving into the next wall.
        if let Err(error) = sim.drive(&args.robot, 0.0, 0.0).await {
            tracing::warn!(%error, "could not stop the robot");
        }
        if let Some((frames, task)) = publisher {
            drop(frames);
            summary.published = task.await.context("the frame publisher panicked")??;
        }
        anyhow::Ok(summary)
    })?;
    if let Some(mut file) = data_file {
        file.flush().context("writing the data file")?;
    }
    println!(
        "{}: {} frames over {:.1} simulated s, {:.1} m driven, {} bumps, {} frames published",
        args.robot,
        summary.frames,
        summary.sim_seconds,
        summary.distance_m,
        summary.bumps,
        summary.published
    );
    Ok(())
}

/// The rig the simulator's robots carry; the Scout's from a simulator too
/// old to say.
pub(crate) async fn sim_rig(sim: &SimClient) -> Result<Rig> {
    let world = sim
        .world()
        .await
        .context("asking the simulator for its world")?;
    match world.rig {
        Some(wire) => {
            deog_proto::rig::rig_from_wire(&wire).context("the simulator's rig (WorldInfo.rig)")
        }
        None => Ok(deog_rig::scout()),
    }
}

/// The simulator's state stream of one robot, read into a queue as fast
/// as it comes ([`spawn_state_reader`]), so that a driving loop can take
/// everything that arrived at once.
pub(crate) struct StateReader {
    queue: mpsc::Receiver<pb::RobotState>,
    task: tokio::task::JoinHandle<Result<()>>,
    /// The newest state handed out.
    last_sequence: u64,
}

impl StateReader {
    /// Waits for the next state, then takes it and every state queued
    /// behind it into `batch` (cleared first), oldest first, leaving out
    /// any not newer than those handed out before (or without a
    /// sequence): a busy loop records every frame but steers by the
    /// newest. `false` once `shutdown` completes; an error when the stream
    /// fails or ends.
    pub(crate) async fn next_batch(
        &mut self,
        shutdown: std::pin::Pin<&mut impl std::future::Future<Output = ()>>,
        batch: &mut Vec<pb::RobotState>,
    ) -> Result<bool> {
        let first = tokio::select! {
            () = shutdown => return Ok(false),
            state = self.queue.recv() => match state {
                Some(state) => state,
                None => {
                    (&mut self.task).await.context("the state reader panicked")??;
                    bail!("the simulator ended the state stream");
                }
            },
        };
        batch.clear();
        batch.push(first);
        while let Ok(state) = self.queue.try_recv() {
            batch.push(state);
        }
        let last = &mut self.last_sequence;
        batch.retain(|state| {
            let fresh = state.sequence != 0 && state.sequence > *last;
            if fresh {
                *last = state.sequence;
            }
            fresh
        });
        Ok(true)
    }
}

/// Reads the simulator's state stream into a queue as fast as it comes.
pub(crate) fn spawn_state_reader(mut stream: tonic::Streaming<pb::RobotState>) -> StateReader {
    let (tx, queue) = mpsc::channel(4096);
    let task = tokio::spawn(async move {
        while let Some(state) = stream
            .message()
            .await
            .context("the simulator's state stream failed")?
        {
            if tx.send(state).await.is_err() {
                break;
            }
        }
        Ok(())
    });
    StateReader {
        queue,
        task,
        last_sequence: 0,
    }
}

pub(crate) type Publisher = (
    mpsc::Sender<pb::SonarFrame>,
    tokio::task::JoinHandle<Result<u64>>,
);

/// Publishes frames in batches of whatever has queued up, so the driving
/// loop never waits on the map server's disk.
pub(crate) fn spawn_publisher(map: MapClient) -> Publisher {
    let (tx, mut rx) = mpsc::channel::<pb::SonarFrame>(4096);
    let task = tokio::spawn(async move {
        let mut published = 0u64;
        let mut batch = Vec::new();
        while rx.recv_many(&mut batch, 256).await > 0 {
            let (stored, duplicates) = map
                .publish_frames(std::mem::take(&mut batch))
                .await
                .context("publishing frames")?;
            if duplicates > 0 {
                tracing::debug!(duplicates, "frames already stored");
            }
            published += u64::from(stored);
        }
        Ok(published)
    });
    (tx, task)
}
