//! One group commit's view of a store.
//!
//! The writer reads what a group of writes needs (map records, tiles,
//! cursors, robot summaries), merges in memory and writes the result, all
//! through one [`Transaction`]. On a store shared by several servers the
//! transaction holds row locks, taken in name order so that two servers
//! never wait on each other in a cycle, and nothing it wrote is visible or
//! durable before [`Transaction::commit`].

use super::{ClientCursor, FrameWrite, MapRecord, MapWrite, RobotSummary, Store, StoredTile};
use crate::error::StoreError;
use deog_grid::TileKey;

/// A group commit in progress. Reads see the transaction's own writes.
/// Dropping it without [`Transaction::commit`] abandons what the store
/// allows to be abandoned (all of it, on a transactional store).
pub trait Transaction {
    /// Holds the named maps against writes by anyone else until the end of
    /// the transaction. `names` is sorted and free of duplicates; names of
    /// maps that do not exist are ignored.
    fn lock_maps(&mut self, names: &[&str]) -> Result<(), StoreError>;
    /// The same for robots' frame summaries.
    fn lock_robots(&mut self, names: &[&str]) -> Result<(), StoreError>;
    /// One map's record, if it exists.
    fn map(&mut self, name: &str) -> Result<Option<MapRecord>, StoreError>;
    /// Creates a map; [`StoreError::MapExists`] if the name is taken.
    fn create_map(&mut self, record: &MapRecord) -> Result<(), StoreError>;
    /// Removes a map with its tiles and cursors; [`StoreError::MapNotFound`]
    /// if there is none.
    fn delete_map(&mut self, name: &str) -> Result<(), StoreError>;
    /// Applies `write` to map `name`.
    fn write_map(&mut self, name: &str, write: MapWrite) -> Result<(), StoreError>;
    /// The stored tiles among `keys` (absent ones are left out).
    fn tiles(
        &mut self,
        map: &MapRecord,
        keys: &[TileKey],
    ) -> Result<Vec<(TileKey, StoredTile)>, StoreError>;
    /// The cursors of `clients` on map `name` (clients without one are
    /// left out).
    fn cursors(
        &mut self,
        name: &str,
        clients: &[&str],
    ) -> Result<Vec<(String, ClientCursor)>, StoreError>;
    /// A robot's frame summary, if it published anything.
    fn robot(&mut self, robot: &str) -> Result<Option<RobotSummary>, StoreError>;
    /// Which of `sequences` a robot has stored.
    fn stored_frames(&mut self, robot: &str, sequences: &[u64]) -> Result<Vec<u64>, StoreError>;
    /// Stores frames.
    fn write_frames(&mut self, writes: Vec<FrameWrite>) -> Result<(), StoreError>;
    /// Stores pose estimates, replacing earlier ones for the same pair.
    fn write_poses(&mut self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError>;
    /// Makes everything written durable and visible, or fails and keeps
    /// none of it that the store could hold back.
    fn commit(self: Box<Self>) -> Result<(), StoreError>;
}

/// The transaction of a store written by one writer alone: each call goes
/// straight to the store, locks are not needed, and commit flushes.
#[derive(Debug)]
pub struct Direct<'s, S: ?Sized>(pub &'s S);

impl<S: Store + ?Sized> Transaction for Direct<'_, S> {
    fn lock_maps(&mut self, _names: &[&str]) -> Result<(), StoreError> {
        Ok(())
    }

    fn lock_robots(&mut self, _names: &[&str]) -> Result<(), StoreError> {
        Ok(())
    }

    fn map(&mut self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        self.0.map(name)
    }

    fn create_map(&mut self, record: &MapRecord) -> Result<(), StoreError> {
        self.0.create_map(record)
    }

    fn delete_map(&mut self, name: &str) -> Result<(), StoreError> {
        self.0.delete_map(name)
    }

    fn write_map(&mut self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        self.0.write_map(name, write)
    }

    fn tiles(
        &mut self,
        map: &MapRecord,
        keys: &[TileKey],
    ) -> Result<Vec<(TileKey, StoredTile)>, StoreError> {
        let mut found = Vec::new();
        for &key in keys {
            if let Some(tile) = self.0.tile(map, key)? {
                found.push((key, tile));
            }
        }
        Ok(found)
    }

    fn cursors(
        &mut self,
        name: &str,
        clients: &[&str],
    ) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        let mut found = Vec::new();
        for &client in clients {
            let cursor = self.0.cursor(name, client)?;
            if cursor != ClientCursor::new() {
                found.push((client.to_string(), cursor));
            }
        }
        Ok(found)
    }

    fn robot(&mut self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.0.robot(robot)
    }

    fn stored_frames(&mut self, robot: &str, sequences: &[u64]) -> Result<Vec<u64>, StoreError> {
        let mut found = Vec::new();
        for &sequence in sequences {
            if self.0.has_frame(robot, sequence)? {
                found.push(sequence);
            }
        }
        Ok(found)
    }

    fn write_frames(&mut self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        self.0.write_frames(writes)
    }

    fn write_poses(&mut self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        self.0.write_poses(poses)
    }

    fn commit(self: Box<Self>) -> Result<(), StoreError> {
        self.0.flush()
    }
}
