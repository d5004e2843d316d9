//! The embedded default store, on sled.
//!
//! Layout: one sled tree per map, `map/<name>`, holding the record under `m`,
//! client cursors under `c<client>` (encoded as `cursor.rs` says) and tiles
//! under `t<key>` (the key's 8 sortable bytes, so a range of x is a range of
//! keys). Frames live in the
//! tree `frames` under `f<robot>\0<sequence>` with a summary per robot under
//! `r<robot>`; poses in `poses` under `<robot>\0<sequence>`; rigs in `rigs`
//! under their name; explorers' goals in `goals` under `<map>\0<robot>`. Names never hold
//! a zero byte (the service checks), and sequences are big-endian, so a
//! robot's frames sort by sequence.

use super::{
    ClientCursor, Direct, FrameWrite, MapRecord, MapWrite, RobotSummary, Store, StoredTile,
    TileRange, Transaction,
};
use crate::error::StoreError;
use deog_grid::TileKey;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, RwLock, Weak};

const MAP_TREE_PREFIX: &str = "map/";
const RECORD_KEY: &[u8] = b"m";
const CURSOR_PREFIX: u8 = b'c';
const TILE_PREFIX: u8 = b't';
/// Written in the default tree by a recovery, to see that writes land.
const PROBE_KEY: &[u8] = b"deog/recovery-probe";

/// How to open the sled store.
#[derive(Debug, Clone)]
pub struct SledConfig {
    /// Data directory; created if missing.
    pub path: PathBuf,
    /// Bytes sled may keep in its page cache. The map lives on disk; this is
    /// what bounds the server's memory.
    pub cache_bytes: u64,
}

impl SledConfig {
    /// The defaults for `path`: a 64 MiB cache.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            cache_bytes: 64 << 20,
        }
    }
}

/// The sled-backed [`Store`].
///
/// The open database sits behind a lock so that [`Store::recover`] can let
/// go of it and open it again from disk: after a failed write sled refuses
/// every later one, and what it holds in memory may include writes that
/// never reached the disk.
pub struct SledStore {
    config: SledConfig,
    open: RwLock<Option<Arc<OpenStore>>>,
    /// The database let go of by the last recovery, while calls still read
    /// it: it cannot be opened again until they finish.
    released: Mutex<Option<Weak<OpenStore>>>,
    /// Why it is closed: the failed write, then the last attempt to open
    /// it again.
    closed_because: Mutex<String>,
}

/// One opening of the database.
struct OpenStore {
    db: sled::Db,
    frames: sled::Tree,
    poses: sled::Tree,
    rigs: sled::Tree,
    goals: sled::Tree,
    maps: RwLock<HashMap<String, sled::Tree>>,
}

impl std::fmt::Debug for SledStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SledStore")
            .field("path", &self.config.path)
            .finish_non_exhaustive()
    }
}

impl SledStore {
    /// Opens (or creates) the store.
    pub fn open(config: &SledConfig) -> Result<Self, StoreError> {
        Ok(Self {
            config: config.clone(),
            open: RwLock::new(Some(Arc::new(OpenStore::open(config)?))),
            released: Mutex::new(None),
            closed_because: Mutex::new(String::new()),
        })
    }

    /// The open database, or why there is none (a recovery is under way).
    fn current(&self) -> Result<Arc<OpenStore>, StoreError> {
        self.open
            .read()
            .map_err(|_| StoreError::Backend("store lock poisoned".into()))?
            .clone()
            .ok_or_else(|| {
                let why = self
                    .closed_because
                    .lock()
                    .map(|why| why.clone())
                    .unwrap_or_default();
                StoreError::Unavailable(format!(
                    "the store is being opened again after a failed write ({why})"
                ))
            })
    }

    #[cfg(test)]
    fn tree(&self, name: &str) -> Result<sled::Tree, StoreError> {
        self.current()?.tree(name)
    }
}

impl OpenStore {
    /// The one place the database is opened.
    fn open(config: &SledConfig) -> Result<Self, StoreError> {
        remove_unfinished_snapshots(&config.path)?;
        let db = open_db(config)?;
        let frames = db.open_tree("frames")?;
        let poses = db.open_tree("poses")?;
        let rigs = db.open_tree("rigs")?;
        let goals = db.open_tree("goals")?;
        let mut maps = HashMap::new();
        for name in db.tree_names() {
            let Some(map) = std::str::from_utf8(&name)
                .ok()
                .and_then(|n| n.strip_prefix(MAP_TREE_PREFIX))
            else {
                continue;
            };
            let tree = db.open_tree(&name)?;
            if tree.contains_key(RECORD_KEY)? {
                maps.insert(map.to_string(), tree);
            } else {
                // A create that never finished: no record, so never acknowledged.
                drop(tree);
                db.drop_tree(&name)?;
            }
        }
        Ok(Self {
            db,
            frames,
            poses,
            rigs,
            goals,
            maps: RwLock::new(maps),
        })
    }

    fn tree(&self, name: &str) -> Result<sled::Tree, StoreError> {
        self.maps
            .read()
            .map_err(|_| StoreError::Backend("map catalog lock poisoned".into()))?
            .get(name)
            .cloned()
            .ok_or_else(|| StoreError::MapNotFound(name.to_string()))
    }
}

/// How long an opening waits for the directory lock an earlier opening in
/// this process still holds: sled lets go of it from its own threads, a
/// moment after the last handle is dropped.
const LOCK_WAIT: std::time::Duration = std::time::Duration::from_secs(3);

fn open_db(config: &SledConfig) -> Result<sled::Db, StoreError> {
    let started = std::time::Instant::now();
    loop {
        let opened = sled::Config::new()
            .path(&config.path)
            .cache_capacity(config.cache_bytes)
            // Durability comes from the writer's explicit flush after each
            // group of writes; the periodic flush only bounds dirty memory.
            .flush_every_ms(Some(1000))
            .open();
        match opened {
            // sled words a held lock only in its message.
            Err(sled::Error::Io(error))
                if error.to_string().contains("could not acquire lock")
                    && started.elapsed() < LOCK_WAIT =>
            {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            other => return Ok(other?),
        }
    }
}

/// Removes the snapshot files sled left half written. sled writes a
/// snapshot as `snap.<lsn>.generating` and renames it when complete; one
/// cut short (a full disk, a kill) keeps that name, and sled 0.34 then
/// takes it for the newest snapshot and refuses to open ("corrupted
/// data"). The log it summarises is intact, so the snapshot is rebuilt.
fn remove_unfinished_snapshots(path: &std::path::Path) -> Result<(), StoreError> {
    let entries = match std::fs::read_dir(path) {
        Ok(entries) => entries,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(error) => {
            return Err(StoreError::Backend(format!(
                "reading the data directory {}: {error}",
                path.display()
            )));
        }
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("snap.") && name.ends_with(".generating") {
            tracing::warn!(file = %entry.path().display(), "removing a snapshot left half written");
            std::fs::remove_file(entry.path()).map_err(|error| {
                StoreError::Backend(format!(
                    "removing the half-written snapshot {}: {error}",
                    entry.path().display()
                ))
            })?;
        }
    }
    Ok(())
}

fn tile_key_bytes(key: TileKey) -> [u8; 9] {
    let mut out = [TILE_PREFIX; 9];
    out[1..].copy_from_slice(&key.to_store_bytes());
    out
}

fn cursor_key(client: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(client.len() + 1);
    out.push(CURSOR_PREFIX);
    out.extend_from_slice(client.as_bytes());
    out
}

fn frame_key(robot: &str, sequence: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(robot.len() + 10);
    out.push(b'f');
    out.extend_from_slice(robot.as_bytes());
    out.push(0);
    out.extend_from_slice(&sequence.to_be_bytes());
    out
}

fn summary_key(robot: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(robot.len() + 1);
    out.push(b'r');
    out.extend_from_slice(robot.as_bytes());
    out
}

fn pose_key(robot: &str, sequence: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(robot.len() + 9);
    out.extend_from_slice(robot.as_bytes());
    out.push(0);
    out.extend_from_slice(&sequence.to_be_bytes());
    out
}

fn sequence_of(key: &[u8]) -> u64 {
    key.last_chunk::<8>().map_or(0, |b| u64::from_be_bytes(*b))
}

fn visit_range(
    tree: &sled::Tree,
    from: Vec<u8>,
    to: Vec<u8>,
    visit: &mut dyn FnMut(u64, &[u8]) -> bool,
) -> Result<(), StoreError> {
    for entry in tree.range(from..=to) {
        let (key, value) = entry?;
        if !visit(sequence_of(&key), &value) {
            break;
        }
    }
    Ok(())
}

impl Store for SledStore {
    fn maps(&self) -> Result<Vec<MapRecord>, StoreError> {
        let open = self.current()?;
        let trees: Vec<(String, sled::Tree)> = open
            .maps
            .read()
            .map_err(|_| StoreError::Backend("map catalog lock poisoned".into()))?
            .iter()
            .map(|(n, t)| (n.clone(), t.clone()))
            .collect();
        let mut out = Vec::with_capacity(trees.len());
        for (name, tree) in trees {
            if let Some(bytes) = tree.get(RECORD_KEY)? {
                out.push(MapRecord::decode(&name, &bytes)?);
            }
        }
        out.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(out)
    }

    fn map(&self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        let tree = match self.current()?.tree(name) {
            Ok(tree) => tree,
            Err(StoreError::MapNotFound(_)) => return Ok(None),
            Err(e) => return Err(e),
        };
        tree.get(RECORD_KEY)?
            .map(|bytes| MapRecord::decode(name, &bytes))
            .transpose()
    }

    fn create_map(&self, record: &MapRecord) -> Result<(), StoreError> {
        let open = self.current()?;
        let mut maps = open
            .maps
            .write()
            .map_err(|_| StoreError::Backend("map catalog lock poisoned".into()))?;
        if maps.contains_key(&record.name) {
            return Err(StoreError::MapExists(record.name.clone()));
        }
        let tree = open
            .db
            .open_tree(format!("{MAP_TREE_PREFIX}{}", record.name))?;
        tree.insert(RECORD_KEY, record.encode())?;
        maps.insert(record.name.clone(), tree);
        Ok(())
    }

    fn delete_map(&self, name: &str) -> Result<(), StoreError> {
        let open = self.current()?;
        let mut maps = open
            .maps
            .write()
            .map_err(|_| StoreError::Backend("map catalog lock poisoned".into()))?;
        if maps.remove(name).is_none() {
            return Err(StoreError::MapNotFound(name.to_string()));
        }
        open.db.drop_tree(format!("{MAP_TREE_PREFIX}{name}"))?;
        Ok(())
    }

    fn write_map(&self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        let tree = self.current()?.tree(name)?;
        let mut batch = sled::Batch::default();
        if write.clear_tiles {
            for key in tree.scan_prefix([TILE_PREFIX]).keys() {
                batch.remove(key?);
            }
        }
        for (key, tile) in &write.tiles {
            batch.insert(&tile_key_bytes(*key)[..], tile.encode());
        }
        for (client, cursor) in &write.cursors {
            batch.insert(cursor_key(client), cursor.encode());
        }
        if let Some(record) = &write.record {
            batch.insert(RECORD_KEY, record.encode());
        }
        tree.apply_batch(batch)?;
        Ok(())
    }

    fn tile(&self, map: &MapRecord, key: TileKey) -> Result<Option<StoredTile>, StoreError> {
        let tree = self.current()?.tree(&map.name)?;
        tree.get(tile_key_bytes(key))?
            .map(|bytes| StoredTile::decode(map.settings.tile_size, &bytes))
            .transpose()
    }

    fn tiles_in(
        &self,
        map: &MapRecord,
        range: TileRange,
        visit: &mut dyn FnMut(TileKey, StoredTile) -> bool,
    ) -> Result<(), StoreError> {
        let tree = self.current()?.tree(&map.name)?;
        let from = tile_key_bytes(range.min);
        let to = tile_key_bytes(range.max);
        for entry in tree.range(from..=to) {
            let (key_bytes, value) = entry?;
            let key =
                TileKey::from_store_bytes(&key_bytes[1..]).map_err(|e| StoreError::Corrupt {
                    what: format!("tile key in map {:?}", map.name),
                    reason: e.to_string(),
                })?;
            // Keys sort by x, then y: the x band is contiguous, y is filtered.
            if !range.contains(key) {
                continue;
            }
            let tile = StoredTile::decode(map.settings.tile_size, &value)?;
            if !visit(key, tile) {
                break;
            }
        }
        Ok(())
    }

    fn cursor(&self, name: &str, client: &str) -> Result<ClientCursor, StoreError> {
        let tree = self.current()?.tree(name)?;
        match tree.get(cursor_key(client))? {
            Some(bytes) => ClientCursor::decode(client, &bytes),
            None => Ok(ClientCursor::new()),
        }
    }

    fn cursors(&self, name: &str) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        let tree = self.current()?.tree(name)?;
        let mut out = Vec::new();
        for entry in tree.scan_prefix([CURSOR_PREFIX]) {
            let (key, bytes) = entry?;
            let client = String::from_utf8_lossy(&key[1..]).into_owned();
            let cursor = ClientCursor::decode(&client, &bytes)?;
            out.push((client, cursor));
        }
        Ok(out)
    }

    fn write_frames(&self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        let open = self.current()?;
        for write in writes {
            let mut batch = sled::Batch::default();
            for (sequence, bytes) in write.frames {
                batch.insert(frame_key(&write.robot, sequence), bytes);
            }
            batch.insert(summary_key(&write.robot), &write.summary.encode()[..]);
            open.frames.apply_batch(batch)?;
        }
        Ok(())
    }

    fn has_frame(&self, robot: &str, sequence: u64) -> Result<bool, StoreError> {
        Ok(self
            .current()?
            .frames
            .contains_key(frame_key(robot, sequence))?)
    }

    fn robot(&self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.current()?
            .frames
            .get(summary_key(robot))?
            .map(|b| RobotSummary::decode(&b))
            .transpose()
    }

    fn robots(&self) -> Result<Vec<(String, RobotSummary)>, StoreError> {
        let mut out = Vec::new();
        for entry in self.current()?.frames.scan_prefix(b"r") {
            let (key, value) = entry?;
            let name = String::from_utf8_lossy(&key[1..]).into_owned();
            out.push((name, RobotSummary::decode(&value)?));
        }
        Ok(out)
    }

    fn read_frames(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        visit_range(
            &self.current()?.frames,
            frame_key(robot, from),
            frame_key(robot, to),
            visit,
        )
    }

    fn write_poses(&self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        let mut batch = sled::Batch::default();
        for (robot, sequence, bytes) in poses {
            batch.insert(pose_key(&robot, sequence), bytes);
        }
        self.current()?.poses.apply_batch(batch)?;
        Ok(())
    }

    fn read_poses(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        visit_range(
            &self.current()?.poses,
            pose_key(robot, from),
            pose_key(robot, to),
            visit,
        )
    }

    fn rigs(&self) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        let mut out = Vec::new();
        for entry in self.current()?.rigs.iter() {
            let (key, value) = entry?;
            out.push((String::from_utf8_lossy(&key).into_owned(), value.to_vec()));
        }
        Ok(out)
    }

    fn put_rig(&self, name: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.current()?.rigs.insert(name.as_bytes(), bytes)?;
        Ok(())
    }

    fn put_goal(&self, map: &str, robot: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.current()?.goals.insert(goal_key(map, robot), bytes)?;
        Ok(())
    }

    fn goals(&self, map: &str) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        let prefix = goal_key(map, "");
        let mut out = Vec::new();
        for entry in self.current()?.goals.scan_prefix(&prefix) {
            let (key, value) = entry?;
            let robot = String::from_utf8_lossy(&key[prefix.len()..]).into_owned();
            out.push((robot, value.to_vec()));
        }
        Ok(out)
    }

    fn flush(&self) -> Result<(), StoreError> {
        self.current()?.db.flush()?;
        Ok(())
    }

    fn begin(&self) -> Result<Box<dyn Transaction + '_>, StoreError> {
        // One process holds the directory and one writer thread writes it.
        Ok(Box::new(Direct(self)))
    }

    fn recover(&self, failure: &str) -> Result<(), StoreError> {
        let old = self
            .open
            .write()
            .map_err(|_| StoreError::Backend("store lock poisoned".into()))?
            .take();
        let mut released = self
            .released
            .lock()
            .map_err(|_| StoreError::Backend("store lock poisoned".into()))?;
        if let Some(old) = old {
            *released = Some(Arc::downgrade(&old));
            if let Ok(mut why) = self.closed_because.lock() {
                failure.clone_into(&mut why);
            }
        }
        // sled locks its directory: the old opening must be gone first.
        let readers = released.as_ref().map_or(0, Weak::strong_count);
        if readers > 0 {
            return Err(StoreError::Unavailable(format!(
                "{readers} calls still read the store as it was before the failed write"
            )));
        }
        *released = None;
        let opened = OpenStore::open(&self.config);
        if let (Err(error), Ok(mut why)) = (&opened, self.closed_because.lock()) {
            *why = error.to_string();
        }
        let fresh = Arc::new(opened?);
        *self
            .open
            .write()
            .map_err(|_| StoreError::Backend("store lock poisoned".into()))? = Some(fresh.clone());
        // Open is not enough: a small durable write shows the device takes
        // writes again.
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        fresh.db.insert(PROBE_KEY, &stamp.to_le_bytes()[..])?;
        fresh.db.flush()?;
        Ok(())
    }
}

/// A goal's key: the map, a zero byte, the robot.
fn goal_key(map: &str, robot: &str) -> Vec<u8> {
    let mut key = Vec::with_capacity(map.len() + robot.len() + 1);
    key.extend_from_slice(map.as_bytes());
    key.push(0);
    key.extend_from_slice(robot.as_bytes());
    key
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{MapSettings, SequenceCheck};
    use deog_grid::{Resolution, TileSize};

    /// A store in a fresh directory (kept while the guard lives) holding an
    /// empty map "m".
    fn store_with_map_m() -> (tempfile::TempDir, SledStore) {
        let dir = tempfile::tempdir().unwrap();
        let store = SledStore::open(&SledConfig::new(dir.path())).unwrap();
        let settings =
            MapSettings::new(Resolution::DEFAULT, TileSize::DEFAULT, (0.1, 0.9)).unwrap();
        store
            .create_map(&MapRecord::new("m".into(), settings))
            .unwrap();
        (dir, store)
    }

    #[test]
    fn a_cursor_written_before_the_applied_list_still_loads() {
        let (_dir, store) = store_with_map_m();
        // The highest sequence alone, as servers before the list wrote it.
        store
            .tree("m")
            .unwrap()
            .insert(cursor_key("old"), &41u64.to_le_bytes()[..])
            .unwrap();
        let cursor = store.cursor("m", "old").unwrap();
        assert_eq!((cursor.last, cursor.recent.len()), (41, 0));
        assert_eq!(cursor.check(40), SequenceCheck::Unknown);
        assert_eq!(store.cursor("m", "new").unwrap(), ClientCursor::new());
    }

    #[test]
    fn a_recovery_opens_the_store_again_once_no_call_holds_the_old_one() {
        let (_dir, store) = store_with_map_m();
        store.flush().unwrap();
        let reader = store.current().unwrap();
        let error = store.recover("disk full").unwrap_err();
        assert!(matches!(error, StoreError::Unavailable(_)), "{error}");
        // Meanwhile calls are refused, saying why.
        let refused = store.maps().unwrap_err().to_string();
        assert!(refused.contains("disk full"), "{refused}");
        drop(reader);
        store.recover("disk full").unwrap();
        assert_eq!(store.maps().unwrap().len(), 1);
    }

    #[test]
    fn a_snapshot_left_half_written_does_not_stop_the_store_opening() {
        let dir = tempfile::tempdir().unwrap();
        let settings =
            MapSettings::new(Resolution::DEFAULT, TileSize::DEFAULT, (0.1, 0.9)).unwrap();
        {
            let store = SledStore::open(&SledConfig::new(dir.path())).unwrap();
            store
                .create_map(&MapRecord::new("m".into(), settings))
                .unwrap();
            store.flush().unwrap();
        }
        // What a snapshot cut short by a full disk leaves, sorting after
        // every complete one.
        std::fs::write(dir.path().join("snap.FFFFFFFFFFFFFFFF.generating"), b"").unwrap();
        let store = SledStore::open(&SledConfig::new(dir.path())).unwrap();
        assert_eq!(store.maps().unwrap().len(), 1);
    }
}
