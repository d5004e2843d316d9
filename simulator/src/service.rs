//! `RobotService` over a shared [`Simulation`], and the clock that advances
//! it in real time (times `speed`).
//!
//! Watch policy: a watched robot has a bounded broadcast of its states, one
//! per firing of its sensors. A watcher that falls behind skips to the newest
//! states (a warning is logged); `GetState` is always current. Only robots in
//! the world can be watched, and a robot's channel goes when its last watcher
//! does, so watch calls cannot grow the server's memory.
//!
//! Limits: at most [`SimServeConfig::max_robots`] robots and
//! [`SimServeConfig::max_watchers`] open watch streams; past either the call
//! is `RESOURCE_EXHAUSTED`.

use std::collections::HashMap;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_server::RobotService;
use deog_rig::SensorKind;
use tokio::sync::{broadcast, mpsc};
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status};

use crate::convert;
use crate::error::SimError;
use crate::serve::SimServeConfig;
use crate::simulation::{RobotSnapshot, Simulation};

/// States buffered per robot before a watcher counts as lagging.
const WATCH_BUFFER: usize = 256;

struct Shared {
    sim: Mutex<Simulation>,
    /// One channel per watched robot; none for robots nobody watches.
    channels: Mutex<HashMap<String, broadcast::Sender<Arc<pb::RobotState>>>>,
    /// Watch streams open now; shared with their slots, which need nothing
    /// else of the server.
    watchers: Arc<AtomicUsize>,
    config: SimServeConfig,
    shutdown: CancellationToken,
}

/// Holds one of the [`SimServeConfig::max_watchers`] places while a watch
/// stream is open.
struct WatcherSlot(Arc<AtomicUsize>);

impl WatcherSlot {
    fn take(shared: &Shared) -> Result<Self, Status> {
        let max = shared.config.max_watchers;
        shared
            .watchers
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            })
            .map_err(|_| {
                Status::from(SimError::Limit(format!(
                    "the simulator already serves {max} watch streams (--max-watchers); \
                     close one first"
                )))
            })?;
        Ok(Self(Arc::clone(&shared.watchers)))
    }
}

impl Drop for WatcherSlot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

/// The `RobotService` implementation; cheap to clone.
#[derive(Clone)]
pub struct SimServer {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for SimServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimServer")
            .field("speed", &self.shared.config.speed)
            .finish_non_exhaustive()
    }
}

impl SimServer {
    /// Serves `sim` as `config` says (checked here); cancelling `shutdown`
    /// ends the clock and the watch streams.
    pub fn new(
        sim: Simulation,
        config: SimServeConfig,
        shutdown: CancellationToken,
    ) -> Result<Self, SimError> {
        config.validate()?;
        Ok(Self {
            shared: Arc::new(Shared {
                sim: Mutex::new(sim),
                channels: Mutex::new(HashMap::new()),
                watchers: Arc::new(AtomicUsize::new(0)),
                config,
                shutdown,
            }),
        })
    }

    /// How it serves.
    pub fn config(&self) -> &SimServeConfig {
        &self.shared.config
    }

    /// Watch streams open now.
    pub fn watcher_count(&self) -> usize {
        self.shared.watchers.load(Ordering::Acquire)
    }

    /// Robots with a state channel now: those somebody watches (a channel
    /// outlives its last watcher until the next firing of the sensors).
    pub fn watch_channel_count(&self) -> usize {
        self.channels().len()
    }

    fn channels(&self) -> MutexGuard<'_, HashMap<String, broadcast::Sender<Arc<pb::RobotState>>>> {
        // A panic while holding the lock would be a bug; the map is still
        // usable, so keep serving it.
        self.shared
            .channels
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn sim(&self) -> MutexGuard<'_, Simulation> {
        // A panic while holding the lock would be a bug; the state is still
        // the last consistent one, so keep serving it.
        self.shared
            .sim
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn check_size(&self, what: &str, message: &impl prost::Message) -> Result<(), Status> {
        Ok(convert::check_size(
            what,
            message,
            self.shared.config.max_message_bytes,
        )?)
    }

    /// The current state of robot `name` and a subscription to its next
    /// ones, taken together under the simulation's lock so that no firing
    /// falls between the two. NOT_FOUND, and no channel made, when there is
    /// no such robot.
    fn subscribe(
        &self,
        name: &str,
    ) -> Result<(RobotSnapshot, broadcast::Receiver<Arc<pb::RobotState>>), SimError> {
        let sim = self.sim();
        let current = sim.snapshot(name)?;
        let states = self
            .channels()
            .entry(name.to_string())
            .or_insert_with(|| broadcast::channel(WATCH_BUFFER).0)
            .subscribe();
        drop(sim);
        Ok((current, states))
    }

    /// Advances the simulation in real time until shutdown, every `tick` of
    /// wall-clock time, and hands each firing to the robot's watchers.
    /// A tick never advances more than `max_step` of simulated time, so a
    /// stalled process slows the world rather than letting it jump.
    pub async fn run_clock(self, tick: Duration, max_step: Duration) {
        let mut interval = tokio::time::interval(tick);
        interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut last = Instant::now();
        let mut fired = Vec::new();
        loop {
            tokio::select! {
                () = self.shared.shutdown.cancelled() => break,
                _ = interval.tick() => {}
            }
            let now = Instant::now();
            let dt = (now - last).as_secs_f64() * self.shared.config.speed;
            last = now;
            let result = self
                .sim()
                .advance(dt.min(max_step.as_secs_f64()), &mut fired);
            if let Err(error) = result {
                tracing::error!(%error, "simulation step failed");
            }
            if fired.is_empty() {
                continue;
            }
            let mut channels = self.channels();
            // A channel nobody listens to any more goes; a new watcher makes
            // a new one.
            channels.retain(|_, sender| sender.receiver_count() > 0);
            for state in fired.drain(..) {
                if let Some(sender) = channels.get(&state.name) {
                    let _ = sender.send(Arc::new(convert::robot_state(&state)));
                }
            }
        }
    }

    /// The world's description on the wire.
    pub fn world_info(&self) -> pb::WorldInfo {
        let sim = self.sim();
        let (min, max) = sim.world().bounds();
        let rig = sim.rig();
        // The sonar_* fields predate rigs: they describe the first sonar.
        let sonars: Vec<_> = rig
            .sensors()
            .iter()
            .filter(|s| matches!(s.kind, SensorKind::Sonar { .. }))
            .collect();
        let first = sonars.first().copied();
        pb::WorldInfo {
            name: sim.world().name().to_string(),
            bounds: Some(pb::WorldBox {
                min_x: min.x,
                min_y: min.y,
                max_x: max.x,
                max_y: max.y,
            }),
            sonar_count: sonars.len() as u32,
            sonar_min_range_m: first.map_or(0.0, |s| s.min_range),
            sonar_max_range_m: first.map_or(0.0, |s| s.max_range),
            sonar_cone_rad: first.map_or(0.0, |s| match s.kind {
                SensorKind::Sonar { half_angle } => 2.0 * half_angle,
                SensorKind::Laser { .. } => 0.0,
            }),
            sonar_ring_radius_m: first.map_or(0.0, |s| s.mount.x.hypot(s.mount.y)),
            robot_radius_m: rig.body_radius(),
            speed: self.shared.config.speed,
            rig: Some(deog_proto::rig::rig_to_wire(rig)),
        }
    }
}

type StateStream = Pin<Box<dyn Stream<Item = Result<pb::RobotState, Status>> + Send>>;

fn reply(state: RobotSnapshot) -> Response<pb::RobotState> {
    Response::new(convert::robot_state(&state))
}

#[tonic::async_trait]
impl RobotService for SimServer {
    async fn spawn(
        &self,
        request: Request<pb::SpawnRequest>,
    ) -> Result<Response<pb::RobotState>, Status> {
        let request = request.into_inner();
        self.check_size("SpawnRequest", &request)?;
        let name = convert::robot_name("name", &request.name)?;
        let pose = match &request.pose {
            Some(p) => Some(convert::pose("pose", Some(p))?),
            None => None,
        };
        let state = {
            let mut sim = self.sim();
            let max = self.shared.config.max_robots;
            if sim.robot_count() >= max {
                return Err(SimError::Limit(format!(
                    "the world already holds {max} robots, the most this simulator \
                     takes (--max-robots)"
                ))
                .into());
            }
            sim.spawn(&name, pose)?
        };
        tracing::info!(robot = %name, x = state.true_pose.x, y = state.true_pose.y, "robot spawned");
        Ok(reply(state))
    }

    async fn drive(
        &self,
        request: Request<pb::DriveRequest>,
    ) -> Result<Response<pb::RobotState>, Status> {
        let request = request.into_inner();
        self.check_size("DriveRequest", &request)?;
        let name = convert::robot_name("name", &request.name)?;
        let (linear, angular) = convert::twist("command", request.command.as_ref())?;
        let state = self.sim().drive(&name, linear, angular)?;
        Ok(reply(state))
    }

    async fn get_state(
        &self,
        request: Request<pb::RobotRef>,
    ) -> Result<Response<pb::RobotState>, Status> {
        self.check_size("RobotRef", request.get_ref())?;
        let name = convert::robot_name("name", &request.get_ref().name)?;
        let state = self.sim().snapshot(&name)?;
        Ok(reply(state))
    }

    async fn teleport(
        &self,
        request: Request<pb::TeleportRequest>,
    ) -> Result<Response<pb::RobotState>, Status> {
        let request = request.into_inner();
        self.check_size("TeleportRequest", &request)?;
        let name = convert::robot_name("name", &request.name)?;
        let pose = convert::pose("pose", request.pose.as_ref())?;
        let state = self.sim().teleport(&name, pose)?;
        tracing::info!(robot = %name, x = pose.x, y = pose.y, "robot teleported");
        Ok(reply(state))
    }

    async fn list_robots(
        &self,
        _request: Request<pb::ListSimRobotsRequest>,
    ) -> Result<Response<pb::ListSimRobotsResponse>, Status> {
        let robots = self
            .sim()
            .snapshots()
            .iter()
            .map(convert::robot_state)
            .collect();
        Ok(Response::new(pb::ListSimRobotsResponse { robots }))
    }

    type WatchStateStream = StateStream;

    async fn watch_state(
        &self,
        request: Request<pb::RobotRef>,
    ) -> Result<Response<Self::WatchStateStream>, Status> {
        self.check_size("RobotRef", request.get_ref())?;
        let name = convert::robot_name("name", &request.get_ref().name)?;
        let (current, mut states) = self.subscribe(&name)?;
        let slot = WatcherSlot::take(&self.shared)?;
        let (tx, rx) = mpsc::channel(self.shared.config.stream_buffer.max(1));
        let shutdown = self.shared.shutdown.clone();
        tokio::spawn(async move {
            // Held until the stream ends.
            let _slot = slot;
            let mut last = current.sequence;
            if tx.send(Ok(convert::robot_state(&current))).await.is_err() {
                return;
            }
            loop {
                let state = tokio::select! {
                    () = shutdown.cancelled() => {
                        let _ = tx.send(Err(Status::unavailable("the simulator is shutting down"))).await;
                        break;
                    }
                    () = tx.closed() => break,
                    state = states.recv() => state,
                };
                match state {
                    Ok(state) if state.sequence > last => {
                        last = state.sequence;
                        if tx.send(Ok((*state).clone())).await.is_err() {
                            break;
                        }
                    }
                    Ok(_) => {}
                    Err(broadcast::error::RecvError::Lagged(missed)) => {
                        tracing::warn!(robot = %name, missed, "a state watcher fell behind; skipping to the newest");
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                }
            }
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    async fn get_world(
        &self,
        _request: Request<pb::GetWorldRequest>,
    ) -> Result<Response<pb::WorldInfo>, Status> {
        Ok(Response::new(self.world_info()))
    }
}
