//! [`TileWatch`]: a map's tile events read as they come, for a process
//! that keeps its own copy of some tiles and wants to know which went
//! stale (the localizer's cache does; it fetches them again when it is
//! ready to).

use deog_grid::TileKey;
use deog_proto::v1 as pb;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::convert::tile_key_from_wire;

/// What a tile event means to a copy of the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TileChange {
    /// This tile changed.
    Tile(TileKey),
    /// Events were lost or the map was cleared: every tile held is stale.
    All,
}

impl TileChange {
    /// The change an event reports; `None` for an event that names none.
    pub fn of(event: &pb::TileEvent) -> Option<Self> {
        match &event.event {
            Some(pb::tile_event::Event::Changed(tile)) => {
                tile.key.map(|k| Self::Tile(tile_key_from_wire(k)))
            }
            Some(pb::tile_event::Event::Resync(_) | pb::tile_event::Event::Cleared(_)) => {
                Some(Self::All)
            }
            None => None,
        }
    }
}

/// A `WatchTiles` stream read by a task of its own into a queue of
/// changes; the task stops when the watch is dropped.
#[derive(Debug)]
pub struct TileWatch {
    changes: mpsc::UnboundedReceiver<TileChange>,
    reader: JoinHandle<()>,
}

impl TileWatch {
    /// Starts reading `stream` (from [`crate::MapClient::watch_tiles`]);
    /// must be called within a tokio runtime. A stream that ends or fails
    /// is logged: the copy is then no longer kept current.
    pub fn spawn(mut stream: tonic::Streaming<pb::TileEvent>) -> Self {
        // Unbounded, but one small value per event the server sends, and
        // the server drops a slow watcher's backlog for one resync.
        let (tx, changes) = mpsc::unbounded_channel();
        let reader = tokio::spawn(async move {
            loop {
                let change = match stream.message().await {
                    Ok(Some(event)) => match TileChange::of(&event) {
                        Some(change) => change,
                        None => continue,
                    },
                    Ok(None) => break,
                    Err(status) => {
                        tracing::warn!(%status, "the tile watch stream ended; the map is no longer kept current");
                        break;
                    }
                };
                if tx.send(change).is_err() {
                    break;
                }
            }
        });
        Self { changes, reader }
    }

    /// A change that has arrived, if any.
    pub fn try_next(&mut self) -> Option<TileChange> {
        self.changes.try_recv().ok()
    }
}

impl Drop for TileWatch {
    fn drop(&mut self) {
        self.reader.abort();
    }
}
