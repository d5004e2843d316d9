//! Live notifications: what changed, for watchers and subscribers.
//!
//! Every channel is a bounded `tokio::sync::broadcast`: the writer never
//! waits for a reader, and a reader that falls more than the capacity behind
//! is told so (`Lagged`) instead of making the buffer grow. What a lagging
//! reader does then is the service's policy (see `service.rs`).

use deog_grid::TileKey;
use deog_proto::v1::{ExplorationGoal, PoseEstimate};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tokio::sync::broadcast;

/// A change to one map.
#[derive(Debug, Clone, PartialEq)]
pub enum MapEvent {
    /// A tile changed; `version` is the map version of its last change.
    TileChanged {
        /// The tile.
        key: TileKey,
        /// Map version of the change.
        version: u64,
    },
    /// Every tile was removed.
    Cleared {
        /// Map version after the clear.
        version: u64,
    },
    /// The map itself was deleted.
    Deleted,
    /// Changes made through another server may have been missed: a
    /// watcher reads again what it follows.
    Resync,
}

/// A newly stored frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameNote {
    /// Robot name.
    pub robot: Arc<str>,
    /// Its sequence.
    pub sequence: u64,
}

/// The broadcast channels of one server.
#[derive(Debug)]
pub struct Events {
    capacity: usize,
    maps: Mutex<HashMap<String, broadcast::Sender<MapEvent>>>,
    frames: broadcast::Sender<FrameNote>,
    poses: broadcast::Sender<Arc<PoseEstimate>>,
    goals: broadcast::Sender<Arc<ExplorationGoal>>,
}

impl Events {
    /// Channels holding at most `capacity` undelivered events each.
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            capacity,
            maps: Mutex::new(HashMap::new()),
            frames: broadcast::channel(capacity).0,
            poses: broadcast::channel(capacity).0,
            goals: broadcast::channel(capacity).0,
        }
    }

    /// Follows changes of map `name`.
    pub fn watch_map(&self, name: &str) -> broadcast::Receiver<MapEvent> {
        let mut maps = self.maps.lock().unwrap_or_else(|p| p.into_inner());
        maps.entry(name.to_string())
            .or_insert_with(|| broadcast::channel(self.capacity).0)
            .subscribe()
    }

    /// Tells the watchers of map `name`.
    pub fn map_changed(&self, name: &str, events: impl IntoIterator<Item = MapEvent>) {
        let mut maps = self.maps.lock().unwrap_or_else(|p| p.into_inner());
        let Some(sender) = maps.get(name) else {
            return;
        };
        if sender.receiver_count() == 0 {
            maps.remove(name);
            return;
        }
        for event in events {
            // No receiver left is not an error: nobody is watching.
            let _ = sender.send(event);
        }
    }

    /// The maps someone is watching.
    pub fn watched_maps(&self) -> Vec<String> {
        let maps = self.maps.lock().unwrap_or_else(|p| p.into_inner());
        maps.iter()
            .filter(|(_, sender)| sender.receiver_count() > 0)
            .map(|(name, _)| name.clone())
            .collect()
    }

    /// Follows newly stored frames of every robot.
    pub fn watch_frames(&self) -> broadcast::Receiver<FrameNote> {
        self.frames.subscribe()
    }

    /// Tells frame subscribers.
    pub fn frame_stored(&self, note: FrameNote) {
        let _ = self.frames.send(note);
    }

    /// Follows newly stored pose estimates.
    pub fn watch_poses(&self) -> broadcast::Receiver<Arc<PoseEstimate>> {
        self.poses.subscribe()
    }

    /// Tells pose watchers.
    pub fn pose_stored(&self, pose: Arc<PoseEstimate>) {
        let _ = self.poses.send(pose);
    }

    /// Hears every goal stored from now on.
    pub fn watch_goals(&self) -> broadcast::Receiver<Arc<ExplorationGoal>> {
        self.goals.subscribe()
    }

    /// Tells the goal watchers of a stored goal.
    pub fn goal_stored(&self, goal: Arc<ExplorationGoal>) {
        let _ = self.goals.send(goal);
    }
}
