//! `RobotService` over a shared [`Simulation`], and the clock that advances
//! it in real time (times `speed`).
//!
//! Watch policy: each robot has a bounded broadcast of its states, one per
//! firing of its sensors. A watcher that falls behind skips to the newest states
//! (a warning is logged); `GetState` is always current.

use std::collections::HashMap;
use std::pin::Pin;
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
use crate::simulation::{RobotSnapshot, Simulation};

/// States buffered per robot before a watcher counts as lagging.
const WATCH_BUFFER: usize = 256;

struct Shared {
    sim: Mutex<Simulation>,
    watchers: Mutex<HashMap<String, broadcast::Sender<Arc<pb::RobotState>>>>,
    speed: f64,
    stream_buffer: usize,
    max_message_bytes: usize,
    shutdown: CancellationToken,
}

/// The `RobotService` implementation; cheap to clone.
#[derive(Clone)]
pub struct SimServer {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for SimServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimServer")
            .field("speed", &self.shared.speed)
            .finish_non_exhaustive()
    }
}

impl SimServer {
    /// Serves `sim`, run at `speed` simulated seconds per wall-clock second,
    /// refusing requests over `max_message_bytes`; `shutdown` ends the clock
    /// and the watch streams.
    pub fn new(
        sim: Simulation,
        speed: f64,
        stream_buffer: usize,
        max_message_bytes: usize,
        shutdown: CancellationToken,
    ) -> Self {
        Self {
            shared: Arc::new(Shared {
                sim: Mutex::new(sim),
                watchers: Mutex::new(HashMap::new()),
                speed,
                stream_buffer: stream_buffer.max(1),
                max_message_bytes,
                shutdown,
            }),
        }
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
            self.shared.max_message_bytes,
        )?)
    }

    fn sender(&self, robot: &str) -> broadcast::Sender<Arc<pb::RobotState>> {
        let mut watchers = self
            .shared
            .watchers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        watchers
            .entry(robot.to_string())
            .or_insert_with(|| broadcast::channel(WATCH_BUFFER).0)
            .clone()
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
            let dt = (now - last).as_secs_f64() * self.shared.speed;
            last = now;
            let result = self
                .sim()
                .advance(dt.min(max_step.as_secs_f64()), &mut fired);
            if let Err(error) = result {
                tracing::error!(%error, "simulation step failed");
            }
            for state in fired.drain(..) {
                let _ = self
                    .sender(&state.name)
                    .send(Arc::new(convert::robot_state(&state)));
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
            speed: self.shared.speed,
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
        let state = self.sim().spawn(&name, pose)?;
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
        // Subscribe before reading the current state, so no firing falls
        // between the two.
        let mut states = self.sender(&name).subscribe();
        let current = self.sim().snapshot(&name)?;
        let (tx, rx) = mpsc::channel(self.shared.stream_buffer);
        let shutdown = self.shared.shutdown.clone();
        tokio::spawn(async move {
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
