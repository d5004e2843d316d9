//! Changes made through other servers sharing the store, relayed to the
//! watchers of this one: the store hears them (PostgreSQL's LISTEN), this
//! turns each into the event the writer would have sent for it. Where the
//! store cannot hear them, it asks for a poll once a second, and watchers
//! of what moved read it again.

use crate::events::{Events, FrameNote, MapEvent};
use crate::store::{Store, StoreChange};
use deog_proto::v1::PoseEstimate;
use prost::Message as _;
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

/// Relays `first`, then `feed`, into `events` until the feed ends or
/// `stop` is cancelled.
pub(crate) async fn relay<S: Store>(
    store: Arc<S>,
    events: Arc<Events>,
    mut first: Option<StoreChange>,
    mut feed: mpsc::Receiver<StoreChange>,
    stop: CancellationToken,
) {
    let mut looked = Looked::default();
    loop {
        let change = match first.take() {
            Some(change) => Some(change),
            None => tokio::select! {
                () = stop.cancelled() => break,
                change = feed.recv() => change,
            },
        };
        let Some(change) = change else {
            break;
        };
        match change {
            StoreChange::Map { map, event } => events.map_changed(&map, [event]),
            StoreChange::Frame { robot, sequence } => events.frame_stored(FrameNote {
                robot: Arc::from(robot.as_str()),
                sequence,
            }),
            StoreChange::Pose { robot, sequence } => {
                let store = store.clone();
                let read =
                    tokio::task::spawn_blocking(move || read_pose(&*store, &robot, sequence));
                if let Ok(Some(pose)) = read.await {
                    events.pose_stored(Arc::new(pose));
                }
            }
            StoreChange::Poll => {
                let store = store.clone();
                let watched = events.watched_maps();
                let read = tokio::task::spawn_blocking(move || {
                    let maps: Vec<(String, u64)> = watched
                        .into_iter()
                        .filter_map(|name| {
                            let version = store.map(&name).ok().flatten()?.version;
                            Some((name, version))
                        })
                        .collect();
                    (maps, store.robots().unwrap_or_default())
                })
                .await;
                let Ok((maps, robots)) = read else {
                    continue;
                };
                for (map, version) in maps {
                    if looked.map_moved(&map, version) {
                        events.map_changed(&map, [MapEvent::Resync]);
                    }
                }
                for (robot, summary) in robots {
                    if looked.robot_moved(&robot, summary.last_sequence) {
                        events.frame_stored(FrameNote {
                            robot: Arc::from(robot.as_str()),
                            sequence: summary.last_sequence,
                        });
                    }
                }
            }
            StoreChange::Resync => {
                for map in events.watched_maps() {
                    events.map_changed(&map, [MapEvent::Resync]);
                }
                // Frame subscribers catch up from the store on a note past
                // what they sent.
                let store = store.clone();
                let robots = tokio::task::spawn_blocking(move || store.robots()).await;
                if let Ok(Ok(robots)) = robots {
                    for (robot, summary) in robots {
                        events.frame_stored(FrameNote {
                            robot: Arc::from(robot.as_str()),
                            sequence: summary.last_sequence,
                        });
                    }
                }
            }
        }
    }
}

/// What the last polls found: each watched map's version and each
/// robot's last frame.
#[derive(Default)]
struct Looked {
    maps: HashMap<String, u64>,
    robots: HashMap<String, u64>,
}

impl Looked {
    /// Whether `map` moved since the last look (not on the first).
    fn map_moved(&mut self, map: &str, version: u64) -> bool {
        self.maps
            .insert(map.to_string(), version)
            .is_some_and(|before| before != version)
    }

    /// Whether `robot` has frames past those of the last look (every
    /// robot is new on the first).
    fn robot_moved(&mut self, robot: &str, last_sequence: u64) -> bool {
        self.robots
            .insert(robot.to_string(), last_sequence)
            .is_some_and(|before| before != last_sequence)
    }
}

fn read_pose<S: Store + ?Sized>(store: &S, robot: &str, sequence: u64) -> Option<PoseEstimate> {
    let mut pose = None;
    let read = store.read_poses(robot, sequence, sequence, &mut |_, bytes| {
        pose = PoseEstimate::decode(bytes).ok();
        false
    });
    if let Err(error) = read {
        tracing::warn!(%error, robot, sequence, "cannot read a pose estimate another server stored");
    }
    pose
}
