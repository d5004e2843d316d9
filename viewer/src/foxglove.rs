//! The view over the Foxglove WebSocket protocol (`deog view --foxglove`),
//! so Foxglove shows deog as it shows a ROS robot:
//!
//! | topic | type | what |
//! |---|---|---|
//! | `/map` | `foxglove.Grid` | the shown map, at most twice a second while its tiles change (all unknown once cleared) |
//! | `/tf` | `foxglove.FrameTransforms` | `map` → `<robot>/base_link`: the true pose, else the estimate |
//! | `/<robot>/true_pose` | `foxglove.PoseInFrame` | where the simulator says the robot is |
//! | `/<robot>/estimate` | `foxglove.PoseInFrame` | the localizer's estimate |
//! | `/<robot>/estimate_covariance` | `foxglove.SceneUpdate` | its 2σ position ellipse, the filter's state as metadata |
//! | `/<robot>/scan`, `/<robot>/scan_2`, … | `foxglove.LaserScan` | the newest frame's lasers, one topic each |
//! | `/<robot>/sonar` | `foxglove.SceneUpdate` | the newest frame's sonar cones |
//! | `/<robot>/true_path`, `/<robot>/estimate_path` | `foxglove.PosesInFrame` | the paths, once a second |
//! | `/<robot>/particles` | `foxglove.PosesInFrame` | the newest sample of the localizer's particles (a few a second) |
//! | `/<robot>/kidnaps` | `foxglove.SceneUpdate` | each kidnap seen: a red line from where the robot was to where it was put |
//!
//! One task follows the shared state's updates, as a page's connection
//! does: every 50 ms it builds what changed under the state's lock and
//! logs it after the lock is released. A client subscribing to a topic
//! is sent what that topic shows at once (the map for `/map`, every
//! robot for `/tf`, the robot for its own topics), so a still robot or a
//! finished map shows without waiting for a change.

use std::collections::{BTreeSet, HashMap};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ::foxglove::messages::{
    FrameTransforms, Grid, LaserScan, PoseInFrame, PosesInFrame, SceneUpdate, Timestamp,
};
use ::foxglove::websocket::{ChannelView, Client, ServerListener};
use ::foxglove::{Channel, Context, Encode, FoxgloveError, WebSocketServer, WebSocketServerHandle};
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::mpsc;

use crate::feeds::{Shared, Update};
use crate::foxglove_messages as messages;
use crate::state::{Change, RobotTrack};

/// How often what changed is sent.
const PUSH_PERIOD: Duration = Duration::from_millis(50);
/// The shortest time between two grids of the map.
const MAP_PERIOD: Duration = Duration::from_millis(500);
/// The shortest time between two paths of a robot.
const PATH_PERIOD: Duration = Duration::from_secs(1);
/// Messages queued per client before the oldest are dropped: some
/// seconds of one robot's data, so a stalled client holds few grids.
const CLIENT_BACKLOG: usize = 1_024;

/// The Foxglove WebSocket server of a view, listening, not yet sending.
pub struct FoxgloveServer {
    context: Arc<Context>,
    handle: WebSocketServerHandle,
    addr: SocketAddr,
    subscribed: mpsc::UnboundedReceiver<String>,
}

/// Hears clients subscribe (the topics), so they are sent what is already
/// held.
struct SubscribeListener(mpsc::UnboundedSender<String>);

impl ServerListener for SubscribeListener {
    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        // The task ends only at shutdown; a subscription then is moot.
        let _ = self.0.send(channel.topic().to_string());
    }
}

impl FoxgloveServer {
    /// Listens on `addr` (port 0 takes a free one).
    pub async fn start(addr: SocketAddr) -> Result<Self, FoxgloveError> {
        let context = Context::new();
        let (subscribed_tx, subscribed) = mpsc::unbounded_channel();
        // The SDK joins host and port with a colon, so IPv6 needs brackets.
        let host = match addr {
            SocketAddr::V4(v4) => v4.ip().to_string(),
            SocketAddr::V6(v6) => format!("[{}]", v6.ip()),
        };
        let handle = WebSocketServer::new()
            .name("deog view")
            .context(&context)
            .bind(host, addr.port())
            .message_backlog_size(CLIENT_BACKLOG)
            .listener(Arc::new(SubscribeListener(subscribed_tx)))
            .start()
            .await?;
        let addr = SocketAddr::new(addr.ip(), handle.port());
        Ok(Self {
            context,
            handle,
            addr,
            subscribed,
        })
    }

    /// The address clients connect to.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Sends the shared state's changes until the view shuts down, then
    /// stops the server.
    pub async fn run(self, shared: Arc<Shared>) {
        let Self {
            context,
            handle,
            mut subscribed,
            ..
        } = self;
        let mut publisher = Publisher::new(context);
        let mut updates = shared.subscribe();
        let mut tick = tokio::time::interval(PUSH_PERIOD);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                () = shared.shutdown.cancelled() => break,
                _ = tick.tick() => publisher.push(&shared),
                Some(topic) = subscribed.recv() => publisher.subscribed(&topic),
                update = updates.recv() => match update {
                    Ok(update) => publisher.note(update),
                    // Fell behind: send everything again.
                    Err(RecvError::Lagged(_)) => publisher.want_everything(),
                    Err(RecvError::Closed) => break,
                },
            }
        }
        handle.stop().wait().await;
    }
}

/// A robot's channels, made when the robot is first sent.
struct RobotChannels {
    true_pose: Arc<Channel<PoseInFrame>>,
    estimate: Arc<Channel<PoseInFrame>>,
    covariance: Arc<Channel<SceneUpdate>>,
    sonar: Arc<Channel<SceneUpdate>>,
    scans: Vec<Arc<Channel<LaserScan>>>,
    true_path: Arc<Channel<PosesInFrame>>,
    estimate_path: Arc<Channel<PosesInFrame>>,
    particles: Arc<Channel<PosesInFrame>>,
    kidnaps: Arc<Channel<SceneUpdate>>,
    /// The newest estimate sent: (map, frame sequence).
    estimate_sent: Option<(String, u64)>,
    /// The newest particle sample sent: (map, frame sequence).
    particles_sent: Option<(String, u64)>,
    /// Kidnaps sent: (how many, the newest one's time).
    kidnaps_sent: (usize, f64),
    had_cones: bool,
    path_sent: Option<Instant>,
}

impl RobotChannels {
    fn new(context: &Arc<Context>, robot: &str) -> Self {
        Self {
            true_pose: channel(context, &format!("/{robot}/true_pose")),
            estimate: channel(context, &format!("/{robot}/estimate")),
            covariance: channel(context, &format!("/{robot}/estimate_covariance")),
            sonar: channel(context, &format!("/{robot}/sonar")),
            scans: Vec::new(),
            true_path: channel(context, &format!("/{robot}/true_path")),
            estimate_path: channel(context, &format!("/{robot}/estimate_path")),
            particles: channel(context, &format!("/{robot}/particles")),
            kidnaps: channel(context, &format!("/{robot}/kidnaps")),
            estimate_sent: None,
            particles_sent: None,
            kidnaps_sent: (0, f64::NAN),
            had_cones: false,
            path_sent: None,
        }
    }
}

fn channel<T: Encode>(context: &Arc<Context>, topic: &str) -> Arc<Channel<T>> {
    Arc::new(context.channel_builder(topic).build::<T>())
}

/// The topic of a robot's `index`th laser: `/<robot>/scan`, then
/// `/<robot>/scan_2`, `/<robot>/scan_3`, ...
pub fn scan_topic(robot: &str, index: usize) -> String {
    match index {
        0 => format!("/{robot}/scan"),
        n => format!("/{robot}/scan_{}", n + 1),
    }
}

/// One message ready to log, built under the state's lock.
enum Outgoing {
    Grid(Grid),
    Transforms(FrameTransforms),
    Pose(Arc<Channel<PoseInFrame>>, PoseInFrame),
    Scene(Arc<Channel<SceneUpdate>>, SceneUpdate),
    Scan(Arc<Channel<LaserScan>>, LaserScan),
    Path(Arc<Channel<PosesInFrame>>, PosesInFrame),
}

/// What has changed since the last push, and the channels.
struct Publisher {
    context: Arc<Context>,
    map_channel: Arc<Channel<Grid>>,
    tf_channel: Arc<Channel<FrameTransforms>>,
    robots: HashMap<String, RobotChannels>,
    map: Option<String>,
    map_changed: bool,
    map_sent: Option<Instant>,
    changed_robots: BTreeSet<String>,
    /// The map is sent at the next push, however recently it was sent.
    map_wanted: bool,
    /// Every robot is sent whole at the next push.
    all_robots_wanted: bool,
    /// These robots are sent whole at the next push.
    robots_wanted: BTreeSet<String>,
}

impl Publisher {
    fn new(context: Arc<Context>) -> Self {
        Self {
            map_channel: channel(&context, "/map"),
            tf_channel: channel(&context, "/tf"),
            context,
            robots: HashMap::new(),
            map: None,
            map_changed: true,
            map_sent: None,
            changed_robots: BTreeSet::new(),
            map_wanted: false,
            all_robots_wanted: false,
            robots_wanted: BTreeSet::new(),
        }
    }

    fn want_everything(&mut self) {
        self.map_wanted = true;
        self.all_robots_wanted = true;
    }

    /// A client subscribed to `topic`: what it shows is sent whole.
    fn subscribed(&mut self, topic: &str) {
        match topic {
            "/map" => self.map_wanted = true,
            "/tf" => self.all_robots_wanted = true,
            _ => {
                if let Some(robot) = robot_of_topic(topic) {
                    self.robots_wanted.insert(robot.to_string());
                }
            }
        }
    }

    fn note(&mut self, update: Update) {
        match update {
            Update::State(Change::Tile { map, .. } | Change::Cleared { map }) => {
                if self.map.as_deref() == Some(map.as_str()) {
                    self.map_changed = true;
                }
            }
            Update::State(
                Change::Robot(robot) | Change::Kidnap(robot) | Change::Particles(robot),
            ) => {
                self.changed_robots.insert(robot);
            }
            Update::Maps => {}
        }
    }

    /// Builds what changed under the state's lock, then logs it.
    fn push(&mut self, shared: &Arc<Shared>) {
        if self.map.is_none() {
            self.map = shared.map_to_show();
            if let Some(map) = &self.map {
                shared.follow_map(map);
                self.map_changed = true;
            }
        }
        let now = Instant::now();
        let stamp = Timestamp::now();
        let map_wanted = std::mem::take(&mut self.map_wanted);
        let all_robots = std::mem::take(&mut self.all_robots_wanted);
        let wanted = std::mem::take(&mut self.robots_wanted);
        let mut out = Vec::new();
        {
            let state = shared.state();
            let map_due = self
                .map_sent
                .is_none_or(|sent| now.duration_since(sent) >= MAP_PERIOD);
            if (map_wanted || self.map_changed && map_due)
                && let Some(layer) = self.map.as_deref().and_then(|m| state.map(m))
            {
                self.map_changed = false;
                self.map_sent = Some(now);
                out.push(Outgoing::Grid(messages::occupancy_grid(layer, stamp)));
            }
            let mut names = std::mem::take(&mut self.changed_robots);
            if all_robots {
                names.extend(state.robots().keys().cloned());
            } else {
                names.extend(wanted.iter().cloned());
            }
            let mut transforms = Vec::new();
            for name in names {
                let Some(track) = state.robots().get(&name) else {
                    continue;
                };
                let channels = self
                    .robots
                    .entry(name.clone())
                    .or_insert_with(|| RobotChannels::new(&self.context, &name));
                let body = track
                    .true_pose
                    .or_else(|| track.estimate.as_ref().map(|e| e.pose));
                if let Some(pose) = body {
                    transforms.push(messages::body_transform(&name, pose, stamp));
                }
                let round = Round {
                    everything: all_robots || wanted.contains(&name),
                    now,
                    stamp,
                };
                channels.messages(&self.context, &name, track, &round, &mut out);
            }
            if !transforms.is_empty() {
                out.push(Outgoing::Transforms(FrameTransforms { transforms }));
            }
        }
        for message in out {
            match message {
                Outgoing::Grid(grid) => self.map_channel.log(&grid),
                Outgoing::Transforms(tf) => self.tf_channel.log(&tf),
                Outgoing::Pose(channel, pose) => channel.log(&pose),
                Outgoing::Scene(channel, scene) => channel.log(&scene),
                Outgoing::Scan(channel, scan) => channel.log(&scan),
                Outgoing::Path(channel, path) => channel.log(&path),
            }
        }
    }
}

/// The robot a robot's topic (`/<robot>/...`) names.
fn robot_of_topic(topic: &str) -> Option<&str> {
    let (robot, rest) = topic.strip_prefix('/')?.split_once('/')?;
    (!robot.is_empty() && !rest.is_empty()).then_some(robot)
}

/// One push for one robot: whether all of it is sent again, and the
/// push's times.
struct Round {
    everything: bool,
    now: Instant,
    stamp: Timestamp,
}

impl RobotChannels {
    /// A robot's messages: its true pose, its estimate when new, its beams,
    /// and its paths when due.
    fn messages(
        &mut self,
        context: &Arc<Context>,
        robot: &str,
        track: &RobotTrack,
        round: &Round,
        out: &mut Vec<Outgoing>,
    ) {
        let Round {
            everything,
            now,
            stamp,
        } = *round;
        if let Some(truth) = track.true_pose {
            out.push(Outgoing::Pose(
                Arc::clone(&self.true_pose),
                messages::pose_in_map(truth, stamp),
            ));
        }
        if let Some(estimate) = &track.estimate {
            let key = (estimate.map.clone(), estimate.sequence);
            if everything || self.estimate_sent.as_ref() != Some(&key) {
                self.estimate_sent = Some(key);
                out.push(Outgoing::Pose(
                    Arc::clone(&self.estimate),
                    messages::pose_in_map(estimate.pose, stamp),
                ));
                out.push(Outgoing::Scene(
                    Arc::clone(&self.covariance),
                    messages::covariance_ellipse(robot, estimate, stamp),
                ));
            }
        }
        if let Some(sample) = &track.particles {
            let key = (sample.map.clone(), sample.sequence);
            if everything || self.particles_sent.as_ref() != Some(&key) {
                self.particles_sent = Some(key);
                out.push(Outgoing::Path(
                    Arc::clone(&self.particles),
                    messages::particle_poses(sample, stamp),
                ));
            }
        }
        let kidnaps = (
            track.kidnaps.len(),
            track.kidnaps.back().map_or(f64::NAN, |k| k.time_s),
        );
        let kidnaps_changed = kidnaps.0 != self.kidnaps_sent.0
            || kidnaps.1.to_bits() != self.kidnaps_sent.1.to_bits();
        if !track.kidnaps.is_empty() && (everything || kidnaps_changed) {
            self.kidnaps_sent = kidnaps;
            out.push(Outgoing::Scene(
                Arc::clone(&self.kidnaps),
                messages::kidnap_marks(robot, &track.kidnaps, stamp),
            ));
        }
        let has_cones = track.beams.iter().any(|b| b.half_angle > 0.0);
        if has_cones || self.had_cones {
            self.had_cones = has_cones;
            out.push(Outgoing::Scene(
                Arc::clone(&self.sonar),
                messages::sonar_cones(robot, &track.beams, stamp),
            ));
        }
        for (index, scan) in messages::laser_scans(&track.beams, stamp)
            .into_iter()
            .enumerate()
        {
            while self.scans.len() <= index {
                let topic = scan_topic(robot, self.scans.len());
                self.scans.push(channel(context, &topic));
            }
            out.push(Outgoing::Scan(Arc::clone(&self.scans[index]), scan));
        }
        let path_due = self
            .path_sent
            .is_none_or(|sent| now.duration_since(sent) >= PATH_PERIOD);
        if everything || path_due {
            self.path_sent = Some(now);
            if !track.true_path.is_empty() {
                out.push(Outgoing::Path(
                    Arc::clone(&self.true_path),
                    messages::path_in_map(track.true_path.iter().copied(), stamp),
                ));
            }
            if !track.estimate_path.is_empty() {
                out.push(Outgoing::Path(
                    Arc::clone(&self.estimate_path),
                    messages::path_in_map(track.estimate_path.iter().map(|p| [p.x, p.y]), stamp),
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{robot_of_topic, scan_topic};

    #[test]
    fn the_first_laser_is_the_scan_topic() {
        assert_eq!(scan_topic("r1", 0), "/r1/scan");
        assert_eq!(scan_topic("r1", 1), "/r1/scan_2");
    }

    #[test]
    fn a_robots_topics_name_it() {
        assert_eq!(robot_of_topic("/r1/scan_2"), Some("r1"));
        assert_eq!(robot_of_topic("/scout-1.a/true_pose"), Some("scout-1.a"));
        assert_eq!(robot_of_topic("/map"), None);
        assert_eq!(robot_of_topic("//x"), None);
        assert_eq!(robot_of_topic("/r1/"), None);
    }
}
