//! The view's reading side: tasks that follow the map server (its maps and
//! robots, each followed map's tile events, each robot's frames, every
//! localizer's estimates) and, when one is given, the simulator's true
//! poses, and feed what they read into the shared [`ViewState`].
//!
//! Every follower reconnects on its own after a lost stream, a second
//! later, until the view shuts down.

use std::collections::HashSet;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use deog_grid::{CellBox, CellIndex, Pose2, TileSize};
use deog_proto::v1 as pb;
use deog_rig::Rig;
use deog_robot_client::convert::{decode_tile, pose_from_wire, pose_or_origin};
use deog_robot_client::{ClientError, MapClient, SimClient};
use tokio::sync::broadcast;
use tokio_util::sync::CancellationToken;
use tracing::{debug, warn};

use crate::protocol::MapEntry;
use crate::state::{Change, EstimateView, FrameView, ViewState};

/// How often the lists of maps and robots are read again.
const CATALOGUE_PERIOD: Duration = Duration::from_secs(1);
/// How long a lost stream waits before it is opened again.
const RECONNECT_DELAY: Duration = Duration::from_secs(1);
/// Frames read back when a robot is first seen, so its recent path shows.
const HISTORY_FRAMES: u64 = 3_000;
/// Cells in every direction a tile watch covers: all of any map.
const WHOLE_MAP: i32 = 1 << 28;

/// What the page connections hear.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Update {
    /// The state changed.
    State(Change),
    /// The list of maps changed.
    Maps,
}

/// What the followers and the page connections share.
#[derive(Debug)]
pub struct Shared {
    state: Mutex<ViewState>,
    maps: Mutex<Vec<MapEntry>>,
    followed_maps: Mutex<HashSet<String>>,
    updates: broadcast::Sender<Update>,
    client: MapClient,
    /// The map shown when a page names none.
    pub default_map: Option<String>,
    /// The simulator's world, when one is followed.
    pub world: Mutex<Option<String>>,
    /// Stops every follower.
    pub shutdown: CancellationToken,
}

impl Shared {
    /// Shared parts over a connected map-server client.
    pub fn new(
        client: MapClient,
        state: ViewState,
        default_map: Option<String>,
        shutdown: CancellationToken,
    ) -> Arc<Self> {
        let (updates, _) = broadcast::channel(4_096);
        Arc::new(Self {
            state: Mutex::new(state),
            maps: Mutex::new(Vec::new()),
            followed_maps: Mutex::new(HashSet::new()),
            updates,
            client,
            default_map,
            world: Mutex::new(None),
            shutdown,
        })
    }

    /// The state, locked; a poisoned lock still holds a usable state.
    pub fn state(&self) -> MutexGuard<'_, ViewState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The maps the server held at the last look.
    pub fn maps(&self) -> Vec<MapEntry> {
        self.maps.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Hears every update from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Update> {
        self.updates.subscribe()
    }

    /// The map a page shows when it names none: the one given, else the
    /// first the server holds.
    pub fn map_to_show(&self) -> Option<String> {
        self.default_map
            .clone()
            .or_else(|| self.maps().first().map(|m| m.name.clone()))
    }

    fn publish(&self, changes: impl IntoIterator<Item = Change>) {
        for change in changes {
            // No page listening is fine.
            let _ = self.updates.send(Update::State(change));
        }
    }

    /// Starts following `map`'s tiles, once.
    pub fn follow_map(self: &Arc<Self>, map: &str) {
        let first = self
            .followed_maps
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(map.to_string());
        if first {
            tokio::spawn(follow_tiles(Arc::clone(self), map.to_string()));
        }
    }
}

/// Starts the followers of the map server, and of the simulator when one
/// is given.
pub fn start(shared: &Arc<Shared>, simulator: Option<SimClient>) {
    tokio::spawn(follow_catalogue(Arc::clone(shared)));
    tokio::spawn(follow_estimates(Arc::clone(shared)));
    if let Some(map) = &shared.default_map {
        shared.follow_map(map);
    }
    if let Some(sim) = simulator {
        tokio::spawn(follow_simulator(Arc::clone(shared), sim));
    }
}

/// Reads the maps and robots every second: a new robot gets a frame
/// follower, a changed list of maps is told to the pages.
async fn follow_catalogue(shared: Arc<Shared>) {
    let mut robots_followed = HashSet::new();
    let mut tick = tokio::time::interval(CATALOGUE_PERIOD);
    loop {
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            _ = tick.tick() => {}
        }
        match shared.client.maps().await {
            Ok(infos) => {
                let entries: Vec<MapEntry> = infos
                    .iter()
                    .map(|m| MapEntry {
                        name: m.name.clone(),
                        cells: m.cell_count,
                        tiles: m.tile_count,
                        version: m.version,
                    })
                    .collect();
                let changed = {
                    let mut held = shared.maps.lock().unwrap_or_else(|e| e.into_inner());
                    let changed = *held != entries;
                    *held = entries;
                    changed
                };
                if changed {
                    let _ = shared.updates.send(Update::Maps);
                }
            }
            Err(error) => debug!(%error, "listing the maps"),
        }
        let followed: Vec<String> = shared
            .followed_maps
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .cloned()
            .collect();
        for map in followed {
            match shared.client.goals(&map).await {
                Ok(goals) => {
                    let mut state = shared.state();
                    let changes: Vec<Change> = goals
                        .into_iter()
                        .filter_map(|g| {
                            let at = g.active.then(|| (g.map.clone(), g.x, g.y));
                            state.on_goal(&g.robot, at)
                        })
                        .collect();
                    drop(state);
                    shared.publish(changes);
                }
                Err(error) => debug!(%map, %error, "reading the explorers' goals"),
            }
        }
        match shared.client.robots().await {
            Ok(robots) => {
                for robot in robots {
                    if robots_followed.insert(robot.robot.clone()) {
                        let from = robot.last_sequence.saturating_sub(HISTORY_FRAMES).max(1);
                        tokio::spawn(follow_frames(Arc::clone(&shared), robot.robot, from));
                    }
                }
            }
            Err(error) => debug!(%error, "listing the robots"),
        }
    }
}

/// One robot's frames, from `from` on, then live.
async fn follow_frames(shared: Arc<Shared>, robot: String, mut from: u64) {
    let mut rigs: Vec<(String, Arc<Rig>)> = Vec::new();
    loop {
        let outcome = async {
            let mut stream = shared.client.subscribe_frames(&robot, from).await?;
            while let Some(frame) = stream.message().await? {
                from = frame.sequence.saturating_add(1);
                let rig = rig_of(&shared.client, &mut rigs, &frame.rig).await;
                let view = FrameView {
                    sequence: frame.sequence,
                    time_s: frame.time_s,
                    odometry: pose_or_origin(frame.odometry),
                    true_pose: frame.true_pose.map(pose_from_wire),
                    ranges: &frame.ranges,
                    rig: rig.as_deref(),
                };
                let changes = shared.state().on_frame(&robot, &view);
                shared.publish(changes);
            }
            Ok::<(), ClientError>(())
        };
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            result = outcome => if let Err(error) = result {
                debug!(%robot, %error, "following frames");
            },
        }
        if pause(&shared).await {
            return;
        }
    }
}

/// The rig a frame names, read once per name; `None` while it cannot be
/// read (the frame then shows its pose without its beams).
async fn rig_of(
    client: &MapClient,
    held: &mut Vec<(String, Arc<Rig>)>,
    name: &str,
) -> Option<Arc<Rig>> {
    if let Some((_, rig)) = held.iter().find(|(n, _)| n == name) {
        return Some(Arc::clone(rig));
    }
    match client.rig(name).await {
        Ok(rig) => {
            let rig = Arc::new(rig);
            held.push((name.to_string(), Arc::clone(&rig)));
            Some(rig)
        }
        Err(error) => {
            warn!(rig = name, %error, "reading a frame's rig");
            None
        }
    }
}

/// Every localizer's estimates, as they are published.
async fn follow_estimates(shared: Arc<Shared>) {
    loop {
        let outcome = async {
            let mut stream = shared
                .client
                .raw()
                .watch_poses(pb::WatchPosesRequest {
                    robot: String::new(),
                })
                .await?
                .into_inner();
            while let Some(estimate) = stream.message().await? {
                let view = estimate_view(&estimate);
                let change = shared.state().on_estimate(&estimate.robot, view);
                shared.publish(change);
            }
            Ok::<(), tonic::Status>(())
        };
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            result = outcome => if let Err(error) = result {
                debug!(%error, "following the estimates");
            },
        }
        if pause(&shared).await {
            return;
        }
    }
}

fn estimate_view(estimate: &pb::PoseEstimate) -> EstimateView {
    let mut covariance = [0.0; 9];
    for (slot, value) in covariance.iter_mut().zip(&estimate.covariance) {
        *slot = *value;
    }
    EstimateView {
        map: estimate.map.clone(),
        sequence: estimate.frame_sequence,
        time_s: estimate.time_s,
        pose: pose_or_origin(estimate.pose),
        covariance,
        converged: estimate.converged,
        lost_score: estimate.lost_score,
        particles: estimate.particle_count,
        particle_sample: estimate
            .particle_sample
            .chunks_exact(3)
            .map(|p| Pose2::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
            .filter(|p| p.x.is_finite() && p.y.is_finite() && p.theta.is_finite())
            .collect(),
    }
}

/// One map's tiles: all of them once, then each change as it is heard.
/// The watch opens before the read, so no change in between is missed.
async fn follow_tiles(shared: Arc<Shared>, map: String) {
    loop {
        let outcome = async {
            let info = shared.client.map_info(&map).await?;
            let tile_size = TileSize::new(info.tile_size)
                .map_err(|e| ClientError::wire("tile_size", e.to_string()))?;
            shared
                .state()
                .follow_map(&map, info.resolution_m, tile_size);
            let whole = CellBox::new(
                CellIndex::new(-WHOLE_MAP, -WHOLE_MAP),
                CellIndex::new(WHOLE_MAP, WHOLE_MAP),
            )
            .expect("a box of positive size");
            let mut events = shared.client.watch_tiles(&map, whole, true).await?;
            read_all_tiles(&shared, &map, tile_size).await?;
            while let Some(event) = events.message().await? {
                match event.event {
                    Some(pb::tile_event::Event::Changed(tile)) if !tile.cells.is_empty() => {
                        let (key, version, cells) = decode_tile(&tile, tile_size)?;
                        let change = shared.state().on_tile(&map, key, version, &cells);
                        shared.publish(change);
                    }
                    Some(pb::tile_event::Event::Changed(_) | pb::tile_event::Event::Resync(_)) => {
                        read_all_tiles(&shared, &map, tile_size).await?;
                    }
                    Some(pb::tile_event::Event::Cleared(_)) => {
                        let change = shared.state().on_cleared(&map);
                        shared.publish(change);
                    }
                    None => {}
                }
            }
            Ok::<(), ClientError>(())
        };
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            result = outcome => if let Err(error) = result {
                debug!(%map, %error, "following tiles");
            },
        }
        if pause(&shared).await {
            return;
        }
    }
}

/// Reads every tile of `map` within its bounds.
async fn read_all_tiles(
    shared: &Shared,
    map: &str,
    tile_size: TileSize,
) -> Result<(), ClientError> {
    let info = shared.client.map_info(map).await?;
    let Some(bounds) = info.bounds_cells else {
        return Ok(());
    };
    let Some(region) = CellBox::new(
        CellIndex::new(bounds.min_x, bounds.min_y),
        CellIndex::new(bounds.max_x, bounds.max_y),
    ) else {
        return Ok(());
    };
    for (key, version, tile) in shared
        .client
        .tiles_in_region(map, tile_size, region)
        .await?
    {
        let change = shared.state().on_tile(map, key, version, &tile);
        shared.publish(change);
    }
    Ok(())
}

/// The simulator's robots: their true poses as the simulator steps.
async fn follow_simulator(shared: Arc<Shared>, sim: SimClient) {
    if let Ok(world) = sim.world().await {
        *shared.world.lock().unwrap_or_else(|e| e.into_inner()) = Some(world.name);
    }
    let mut watched = HashSet::new();
    let mut tick = tokio::time::interval(CATALOGUE_PERIOD);
    loop {
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            _ = tick.tick() => {}
        }
        let Ok(robots) = sim.robots().await else {
            continue;
        };
        for robot in robots {
            if watched.insert(robot.name.clone()) {
                tokio::spawn(watch_robot(Arc::clone(&shared), sim.clone(), robot.name));
            }
        }
    }
}

async fn watch_robot(shared: Arc<Shared>, sim: SimClient, robot: String) {
    loop {
        let outcome = async {
            let mut stream = sim.watch(&robot).await?;
            while let Some(state) = stream.message().await? {
                let truth: Pose2 = pose_or_origin(state.true_pose);
                let changes = shared.state().on_true_pose(&robot, state.time_s, truth);
                shared.publish(changes);
            }
            Ok::<(), ClientError>(())
        };
        tokio::select! {
            () = shared.shutdown.cancelled() => return,
            result = outcome => if let Err(error) = result {
                debug!(%robot, %error, "watching a simulated robot");
            },
        }
        if pause(&shared).await {
            return;
        }
    }
}

/// Waits before a reconnect; says whether the view is shutting down.
async fn pause(shared: &Shared) -> bool {
    tokio::select! {
        () = shared.shutdown.cancelled() => true,
        () = tokio::time::sleep(RECONNECT_DELAY) => false,
    }
}
