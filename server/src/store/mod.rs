//! The storage contract of the map server, and its embedded default.
//!
//! A [`Store`] keeps maps (a record and its tiles and client cursors),
//! robots' frames, localizers' poses and the rigs frames name. It knows nothing of gRPC: frames and
//! poses arrive as opaque encoded bytes. Atomicity is per call: one
//! [`MapWrite`] lands whole or not at all, and [`Store::flush`] makes every
//! earlier write durable. The group-commit writer builds on exactly that.

mod change;
mod copy;
mod cursor;
pub mod postgres;
mod record;
mod sled_store;
mod transaction;

pub use change::{StoreChange, decode_changes, encode_changes};
pub use copy::{CopyError, CopyProgress, CopyReport, MapCopied, copy_store};
pub use cursor::{ClientCursor, RECENT_SEQUENCES, SequenceCheck};
pub use postgres::{PostgresConfig, PostgresStore, is_postgres_url};
pub use record::{MapRecord, MapSettings, RobotSummary, StoredTile};
pub use sled_store::{SledConfig, SledStore};
pub use transaction::{Direct, Transaction};

use crate::error::StoreError;
use deog_grid::TileKey;

/// Everything one commit changes in one map, applied atomically.
#[derive(Debug, Default)]
pub struct MapWrite {
    /// The map's record after the write.
    pub record: Option<MapRecord>,
    /// Remove every tile before writing `tiles` (a clear).
    pub clear_tiles: bool,
    /// Tiles to store, replacing what was there.
    pub tiles: Vec<(TileKey, StoredTile)>,
    /// Per-client applied batch sequences, replacing what was there.
    pub cursors: Vec<(String, ClientCursor)>,
}

/// One robot's frames to add, with the robot's summary after them.
#[derive(Debug)]
pub struct FrameWrite {
    /// Robot name.
    pub robot: String,
    /// Summary once these frames are stored.
    pub summary: RobotSummary,
    /// (sequence, encoded frame) pairs.
    pub frames: Vec<(u64, Vec<u8>)>,
}

/// An inclusive range of tile keys: x in `min.x..=max.x`, y in `min.y..=max.y`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileRange {
    /// Lowest key on both axes.
    pub min: TileKey,
    /// Highest key on both axes.
    pub max: TileKey,
}

impl TileRange {
    /// Whether `key` lies in the range.
    pub fn contains(&self, key: TileKey) -> bool {
        (self.min.x..=self.max.x).contains(&key.x) && (self.min.y..=self.max.y).contains(&key.y)
    }
}

/// The storage backend of the map server. Implementations must be safe to
/// read from many threads while one writer thread writes.
pub trait Store: Send + Sync + 'static {
    /// Every map's record, by name.
    fn maps(&self) -> Result<Vec<MapRecord>, StoreError>;
    /// One map's record, if it exists.
    fn map(&self, name: &str) -> Result<Option<MapRecord>, StoreError>;
    /// Creates a map; [`StoreError::MapExists`] if the name is taken.
    fn create_map(&self, record: &MapRecord) -> Result<(), StoreError>;
    /// Removes a map with its tiles and cursors; [`StoreError::MapNotFound`]
    /// if there is none.
    fn delete_map(&self, name: &str) -> Result<(), StoreError>;
    /// Applies `write` to map `name` atomically.
    fn write_map(&self, name: &str, write: MapWrite) -> Result<(), StoreError>;
    /// One stored tile.
    fn tile(&self, map: &MapRecord, key: TileKey) -> Result<Option<StoredTile>, StoreError>;
    /// Visits the stored tiles in `range`, in key order, until `visit`
    /// returns false.
    fn tiles_in(
        &self,
        map: &MapRecord,
        range: TileRange,
        visit: &mut dyn FnMut(TileKey, StoredTile) -> bool,
    ) -> Result<(), StoreError>;
    /// The batch sequences applied for `client` on map `name`
    /// ([`ClientCursor::new`] if none).
    fn cursor(&self, name: &str, client: &str) -> Result<ClientCursor, StoreError>;
    /// Every client with applied batches on map `name`, by client id, with
    /// its cursor.
    fn cursors(&self, name: &str) -> Result<Vec<(String, ClientCursor)>, StoreError>;

    /// Stores frames (atomically per robot).
    fn write_frames(&self, writes: Vec<FrameWrite>) -> Result<(), StoreError>;
    /// Whether a frame with this sequence is stored.
    fn has_frame(&self, robot: &str, sequence: u64) -> Result<bool, StoreError>;
    /// A robot's summary, if it published anything.
    fn robot(&self, robot: &str) -> Result<Option<RobotSummary>, StoreError>;
    /// Every robot's summary, by name.
    fn robots(&self) -> Result<Vec<(String, RobotSummary)>, StoreError>;
    /// Visits a robot's encoded frames with sequence in `from..=to`, in order,
    /// until `visit` returns false.
    fn read_frames(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError>;

    /// Stores encoded pose estimates by (robot, frame sequence), replacing any
    /// earlier one for the same pair.
    fn write_poses(&self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError>;
    /// Visits a robot's encoded poses with frame sequence in `from..=to`.
    fn read_poses(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError>;

    /// Stores an explorer's encoded goal on `map`, replacing its earlier
    /// one. Called from any thread.
    fn put_goal(&self, map: &str, robot: &str, bytes: Vec<u8>) -> Result<(), StoreError>;
    /// Every explorer's latest encoded goal on `map`, by robot name.
    fn goals(&self, map: &str) -> Result<Vec<(String, Vec<u8>)>, StoreError>;

    /// Every stored rig, encoded, by name.
    fn rigs(&self) -> Result<Vec<(String, Vec<u8>)>, StoreError>;
    /// Stores an encoded rig under `name`, replacing any earlier one; the
    /// service decides whether that is allowed. Called from any thread.
    fn put_rig(&self, name: &str, bytes: Vec<u8>) -> Result<(), StoreError>;

    /// Makes every earlier write durable.
    fn flush(&self) -> Result<(), StoreError>;

    /// Begins one group commit. A store whose writes come from one writer
    /// alone (sled: one process holds it) may return [`Direct`], which
    /// writes through and flushes at commit; a store shared by several
    /// servers returns a real transaction.
    fn begin(&self) -> Result<Box<dyn Transaction + '_>, StoreError>;

    /// After a failed write: lets go of whatever the store holds in memory
    /// (it may include writes that never became durable), opens it again
    /// from what is durable, and checks that a write lands. Until it
    /// succeeds, calls may fail with [`StoreError::Unavailable`]. Called by
    /// the writer, which tries again while it fails; what was acknowledged
    /// was flushed, so nothing acknowledged is lost. `failure` says why the
    /// commit failed, for the errors calls get meanwhile.
    fn recover(&self, failure: &str) -> Result<(), StoreError>;

    /// Whether a write would land now, asked when a read found the store
    /// unavailable while no write was under way. A store that a failed
    /// read cannot mean unwritable (sled: reads fail only while it is
    /// being opened again) answers yes.
    fn check_writable(&self) -> Result<(), StoreError> {
        Ok(())
    }

    /// Changes committed through other servers sharing this store, as they
    /// arrive, so that watchers here hear of them; `None` (the default)
    /// for a store no other server writes. Called once, by the server.
    fn foreign_changes(&self) -> Option<tokio::sync::mpsc::Receiver<StoreChange>> {
        None
    }
}
