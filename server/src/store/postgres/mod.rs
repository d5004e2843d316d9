//! The shared store, on PostgreSQL.
//!
//! Any number of map servers may open the same database. Each group commit
//! is one transaction that locks the rows of the maps and robots it writes,
//! maps before robots and each in name order, so that two servers never
//! wait on each other in a cycle; it reads the tiles and cursors it merges
//! inside that transaction, so no update is lost. A commit that returns is
//! durable as far as the database's `synchronous_commit` says.
//!
//! Tables (see [`schema`]): `maps` (name, encoded record), `tiles` (map, x,
//! y, version, dense cells), `cursors` (map, client, encoded cursor),
//! `robots` (name, encoded frame summary), `frames` (robot, sequence,
//! encoded frame), `poses` (robot, sequence, encoded estimate) and `rigs`
//! (name, encoded rig). Frame sequences are kept as `bigint` shifted
//! down by 2^63, so the whole `u64` range fits in order.
//!
//! The store is synchronous, as the [`Store`] contract is. Connections are
//! driven by a small runtime of its own; calls wait on the calling thread,
//! so they may come from the server's async handlers, as sled's do.

mod connection;
pub mod schema;

use super::change::{StoreChange, encode_changes};
use super::{
    ClientCursor, FrameWrite, MapRecord, MapWrite, RobotSummary, Store, StoredTile, TileRange,
    Transaction,
};
use crate::error::StoreError;
use crate::events::MapEvent;
use connection::{Conn, Pool};
use deog_grid::{Tile, TileKey};
use std::collections::BTreeMap;

/// Rows a long read takes per query. A connection is held only while a
/// page is read, never while the caller hands rows to a slow client, so a
/// reader never keeps one from the others for long.
const PAGE_ROWS: i64 = 256;

/// The channel servers tell each other their changes on.
const CHANGES_CHANNEL: &str = "deog_changes";

/// How to open the PostgreSQL store.
#[derive(Debug, Clone)]
pub struct PostgresConfig {
    /// A libpq-style connection string or `postgres://` URL. Several hosts
    /// (`host=a,b` or `postgres://a,b/db`) with
    /// `target_session_attrs=read-write` make the store follow a failover.
    pub url: String,
    /// Most idle connections kept for reuse.
    pub pool_size: usize,
    /// Most connections open at once for reads and one-off writes; a call
    /// past it waits for one. The writer's own connection comes on top.
    pub max_connections: usize,
    /// Hear other servers' changes by polling even where the database
    /// has `NOTIFY` (it is used when present otherwise).
    pub poll_changes: bool,
}

impl PostgresConfig {
    /// The defaults for `url`.
    pub fn new(url: impl Into<String>) -> Self {
        Self {
            url: url.into(),
            pool_size: 8,
            max_connections: 16,
            poll_changes: false,
        }
    }
}

/// Whether `location` names a PostgreSQL database rather than a folder.
pub fn is_postgres_url(location: &str) -> bool {
    location.starts_with("postgres://") || location.starts_with("postgresql://")
}

/// The PostgreSQL-backed [`Store`].
pub struct PostgresStore {
    pool: Pool,
}

impl std::fmt::Debug for PostgresStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PostgresStore")
            .field("database", &self.pool.describe())
            .finish_non_exhaustive()
    }
}

impl PostgresStore {
    /// Connects, and creates or migrates the schema.
    pub fn open(config: &PostgresConfig) -> Result<Self, StoreError> {
        let mut pool = Pool::new(config)?;
        let mut conn = pool.get()?;
        let opened = schema::migrate(&mut conn)
            .and_then(|()| pool.probe_notify(&mut conn, config.poll_changes));
        pool.put(conn);
        opened?;
        Ok(Self { pool })
    }

    /// The schema version the database holds.
    pub fn schema_version(&self) -> Result<i32, StoreError> {
        let mut conn = self.pool.get()?;
        let version = schema::version(&mut conn);
        self.pool.put(conn);
        version
    }

    /// Runs `work` on a pooled connection outside any transaction.
    fn with<T>(
        &self,
        work: impl FnOnce(&mut Conn) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let mut conn = self.pool.get()?;
        let result = work(&mut conn);
        self.pool.put(conn);
        result
    }

    /// Visits a robot's rows (frames or poses) with sequence in
    /// `from..=to` a page at a time; `sql` takes the robot, the page's
    /// first and last sequence (inclusive) and its size.
    fn read_sequenced(
        &self,
        sql: &'static str,
        robot: &str,
        (from, to): (u64, u64),
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        if from > to {
            return Ok(());
        }
        let (mut from, to) = (sql_sequence(from), sql_sequence(to));
        loop {
            let rows = self.with(|conn| conn.query(sql, &[&robot, &from, &to, &PAGE_ROWS]))?;
            let mut last = None;
            for row in &rows {
                let sequence: i64 = row.get(0);
                if !visit(stored_sequence(sequence), row.get(1)) {
                    return Ok(());
                }
                last = Some(sequence);
            }
            match last.filter(|_| rows.len() == PAGE_ROWS as usize) {
                Some(last) if last < to => from = last + 1,
                _ => return Ok(()),
            }
        }
    }

    /// Runs `work` in a transaction of its own and commits it.
    fn in_transaction(
        &self,
        work: impl FnOnce(&mut PostgresTransaction<'_>) -> Result<(), StoreError>,
    ) -> Result<(), StoreError> {
        let mut txn = PostgresTransaction::begin(&self.pool)?;
        work(&mut txn)?;
        Box::new(txn).commit()
    }
}

/// A sequence as the database keeps it: shifted down by 2^63 into
/// `bigint`, so the whole `u64` range fits and keeps its order.
fn sql_sequence(sequence: u64) -> i64 {
    (sequence ^ (1 << 63)) as i64
}

/// The sequence a stored `bigint` holds.
fn stored_sequence(value: i64) -> u64 {
    (value as u64) ^ (1 << 63)
}

/// A map version as the database keeps it (versions grow by one per
/// batch, far from 2^63).
fn sql_version(version: u64) -> i64 {
    i64::try_from(version).unwrap_or(i64::MAX)
}

/// A tile's cells as stored: the dense little-endian cells.
fn cells_bytes(tile: &Tile) -> Vec<u8> {
    let cells = tile.raw_cells();
    let mut out = Vec::with_capacity(cells.len() * 2);
    for c in cells {
        out.extend_from_slice(&c.to_le_bytes());
    }
    out
}

fn decode_tile(map: &MapRecord, version: i64, cells: &[u8]) -> Result<StoredTile, StoreError> {
    let tile =
        Tile::from_dense_bytes(map.settings.tile_size, cells).map_err(|e| StoreError::Corrupt {
            what: format!("tile of map {:?}", map.name),
            reason: e.to_string(),
        })?;
    Ok(StoredTile {
        version: u64::try_from(version).unwrap_or(0),
        tile,
    })
}

impl Store for PostgresStore {
    fn maps(&self) -> Result<Vec<MapRecord>, StoreError> {
        self.with(|conn| {
            let rows = conn.query("SELECT name, record FROM maps ORDER BY name", &[])?;
            rows.iter()
                .map(|row| MapRecord::decode(row.get(0), row.get(1)))
                .collect()
        })
    }

    fn map(&self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        self.with(|conn| read_map(conn, name, false))
    }

    fn create_map(&self, record: &MapRecord) -> Result<(), StoreError> {
        self.in_transaction(|txn| txn.create_map(record))
    }

    fn delete_map(&self, name: &str) -> Result<(), StoreError> {
        self.in_transaction(|txn| txn.delete_map(name))
    }

    fn write_map(&self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        self.in_transaction(|txn| {
            txn.lock_maps(&[name])?;
            txn.write_map(name, write)
        })
    }

    fn tile(&self, map: &MapRecord, key: TileKey) -> Result<Option<StoredTile>, StoreError> {
        self.with(|conn| {
            let rows = conn.query(
                "SELECT version, cells FROM tiles WHERE map = $1 AND x = $2 AND y = $3",
                &[&map.name, &key.x, &key.y],
            )?;
            rows.first()
                .map(|row| decode_tile(map, row.get(0), row.get(1)))
                .transpose()
        })
    }

    fn tiles_in(
        &self,
        map: &MapRecord,
        range: TileRange,
        visit: &mut dyn FnMut(TileKey, StoredTile) -> bool,
    ) -> Result<(), StoreError> {
        // Each page starts at a key, inclusive, given as the one lower
        // bound `(x, y) >= (…)`, so that even a generic plan starts its
        // index scan there (with a second lower bound, or "first page or
        // past the last key", it scans from the range's start every page).
        let mut from = (range.min.x, i32::MIN);
        loop {
            let rows = self.with(|conn| {
                conn.query(
                    "SELECT x, y, version, cells FROM tiles WHERE map = $1 \
                     AND x <= $2 AND y BETWEEN $3 AND $4 AND (x, y) >= ($5, $6) \
                     ORDER BY x, y LIMIT $7",
                    &[
                        &map.name,
                        &range.max.x,
                        &range.min.y,
                        &range.max.y,
                        &from.0,
                        &from.1,
                        &PAGE_ROWS,
                    ],
                )
            })?;
            let mut last = None;
            for row in &rows {
                let key = TileKey::new(row.get(0), row.get(1));
                if !visit(key, decode_tile(map, row.get(2), row.get(3))?) {
                    return Ok(());
                }
                last = Some(key);
            }
            let Some(last) = last.filter(|_| rows.len() == PAGE_ROWS as usize) else {
                return Ok(());
            };
            // The key after the last, in (x, y) order.
            from = match (last.y.checked_add(1), last.x.checked_add(1)) {
                (Some(y), _) => (last.x, y),
                (None, Some(x)) => (x, i32::MIN),
                (None, None) => return Ok(()),
            };
        }
    }

    fn cursor(&self, name: &str, client: &str) -> Result<ClientCursor, StoreError> {
        self.with(|conn| {
            let found = read_cursors(conn, name, &[client])?;
            Ok(found.into_iter().next().map(|(_, c)| c).unwrap_or_default())
        })
    }

    fn cursors(&self, name: &str) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        self.with(|conn| {
            let rows = conn.query(
                "SELECT client, cursor FROM cursors WHERE map = $1 ORDER BY client",
                &[&name],
            )?;
            rows.iter()
                .map(|row| {
                    let client: String = row.get(0);
                    let cursor = ClientCursor::decode(&client, row.get(1))?;
                    Ok((client, cursor))
                })
                .collect()
        })
    }

    fn write_frames(&self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        let mut robots: Vec<String> = writes.iter().map(|w| w.robot.clone()).collect();
        robots.sort_unstable();
        robots.dedup();
        let robots: Vec<&str> = robots.iter().map(String::as_str).collect();
        self.in_transaction(|txn| {
            txn.lock_robots(&robots)?;
            txn.write_frames(writes)
        })
    }

    fn has_frame(&self, robot: &str, sequence: u64) -> Result<bool, StoreError> {
        let sequence = sql_sequence(sequence);
        self.with(|conn| {
            let rows = conn.query(
                "SELECT 1 FROM frames WHERE robot = $1 AND sequence = $2",
                &[&robot, &sequence],
            )?;
            Ok(!rows.is_empty())
        })
    }

    fn robot(&self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.with(|conn| read_robot(conn, robot))
    }

    fn robots(&self) -> Result<Vec<(String, RobotSummary)>, StoreError> {
        self.with(|conn| {
            let rows = conn.query(
                "SELECT name, summary FROM robots WHERE summary IS NOT NULL ORDER BY name",
                &[],
            )?;
            rows.iter()
                .map(|row| Ok((row.get(0), RobotSummary::decode(row.get(1))?)))
                .collect()
        })
    }

    fn read_frames(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        self.read_sequenced(
            "SELECT sequence, frame FROM frames WHERE robot = $1 AND sequence BETWEEN $2 AND $3 \
             ORDER BY sequence LIMIT $4",
            robot,
            (from, to),
            visit,
        )
    }

    fn write_poses(&self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        self.in_transaction(|txn| txn.write_poses(poses))
    }

    fn read_poses(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        self.read_sequenced(
            "SELECT sequence, pose FROM poses WHERE robot = $1 AND sequence BETWEEN $2 AND $3 \
             ORDER BY sequence LIMIT $4",
            robot,
            (from, to),
            visit,
        )
    }

    fn rigs(&self) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        self.with(|conn| {
            let rows = conn.query("SELECT name, rig FROM rigs ORDER BY name", &[])?;
            Ok(rows.iter().map(|row| (row.get(0), row.get(1))).collect())
        })
    }

    fn put_rig(&self, name: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.with(|conn| {
            conn.execute(
                "INSERT INTO rigs (name, rig) VALUES ($1, $2) \
                 ON CONFLICT (name) DO UPDATE SET rig = excluded.rig",
                &[&name, &bytes],
            )?;
            Ok(())
        })
    }

    fn put_goal(&self, map: &str, robot: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.with(|conn| {
            conn.execute(
                "INSERT INTO goals (map, robot, goal) VALUES ($1, $2, $3) \
                 ON CONFLICT (map, robot) DO UPDATE SET goal = excluded.goal",
                &[&map, &robot, &bytes],
            )?;
            Ok(())
        })
    }

    fn goals(&self, map: &str) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        self.with(|conn| {
            let rows = conn.query(
                "SELECT robot, goal FROM goals WHERE map = $1 ORDER BY robot",
                &[&map],
            )?;
            Ok(rows.iter().map(|row| (row.get(0), row.get(1))).collect())
        })
    }

    fn flush(&self) -> Result<(), StoreError> {
        // Every write is committed before it returns.
        Ok(())
    }

    fn begin(&self) -> Result<Box<dyn Transaction + '_>, StoreError> {
        let conn = self.pool.get_for_writer()?;
        Ok(Box::new(PostgresTransaction::begin_on(&self.pool, conn)?))
    }

    fn foreign_changes(&self) -> Option<tokio::sync::mpsc::Receiver<StoreChange>> {
        Some(self.pool.listen(CHANGES_CHANNEL))
    }

    fn check_writable(&self) -> Result<(), StoreError> {
        self.with(probe)
    }

    fn recover(&self, _failure: &str) -> Result<(), StoreError> {
        // Connections the failure broke are dropped as they are found;
        // recovered once a write lands on a fresh one.
        self.pool.clear();
        self.with(probe)
    }
}

/// A small write, to see that writes land.
fn probe(conn: &mut Conn) -> Result<(), StoreError> {
    conn.execute(
        "INSERT INTO deog_probe (id, at) VALUES (1, now()) \
         ON CONFLICT (id) DO UPDATE SET at = excluded.at",
        &[],
    )?;
    Ok(())
}

fn read_map(conn: &mut Conn, name: &str, lock: bool) -> Result<Option<MapRecord>, StoreError> {
    let sql = if lock {
        "SELECT record FROM maps WHERE name = $1 FOR UPDATE"
    } else {
        "SELECT record FROM maps WHERE name = $1"
    };
    let rows = conn.query(sql, &[&name])?;
    rows.first()
        .map(|row| MapRecord::decode(name, row.get(0)))
        .transpose()
}

fn read_cursors(
    conn: &mut Conn,
    name: &str,
    clients: &[&str],
) -> Result<Vec<(String, ClientCursor)>, StoreError> {
    let rows = conn.query(
        "SELECT client, cursor FROM cursors WHERE map = $1 AND client = ANY($2)",
        &[&name, &clients],
    )?;
    rows.iter()
        .map(|row| {
            let client: String = row.get(0);
            let cursor = ClientCursor::decode(&client, row.get(1))?;
            Ok((client, cursor))
        })
        .collect()
}

fn read_robot(conn: &mut Conn, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
    let rows = conn.query("SELECT summary FROM robots WHERE name = $1", &[&robot])?;
    match rows.first().and_then(|row| row.get::<_, Option<&[u8]>>(0)) {
        Some(bytes) => Ok(Some(RobotSummary::decode(bytes)?)),
        None => Ok(None),
    }
}

/// One transaction on one connection. Its first error is kept: the
/// database refuses every later statement of a failed transaction, and
/// its commit then reports that error rather than success.
pub struct PostgresTransaction<'p> {
    pool: &'p Pool,
    conn: Option<Conn>,
    failed: Option<StoreError>,
    /// What it changed, told to the other servers when it commits.
    changes: Vec<StoreChange>,
}

impl<'p> PostgresTransaction<'p> {
    fn begin(pool: &'p Pool) -> Result<Self, StoreError> {
        Self::begin_on(pool, pool.get()?)
    }

    fn begin_on(pool: &'p Pool, mut conn: Conn) -> Result<Self, StoreError> {
        conn.batch("BEGIN")?;
        Ok(Self {
            pool,
            conn: Some(conn),
            failed: None,
            changes: Vec::new(),
        })
    }

    /// Runs `work` unless an earlier statement failed, keeping the first
    /// failure.
    fn run<T>(
        &mut self,
        work: impl FnOnce(&mut Conn) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        if let Some(failed) = &self.failed {
            return Err(failed.again());
        }
        let Some(conn) = self.conn.as_mut() else {
            return Err(StoreError::Backend("the transaction has ended".into()));
        };
        let result = work(conn);
        if let Err(error) = &result
            && error.is_backend()
        {
            self.failed = Some(error.again());
        }
        result
    }
}

impl Drop for PostgresTransaction<'_> {
    fn drop(&mut self) {
        if let Some(mut conn) = self.conn.take() {
            // Abandoned: roll back, and keep the connection only if that
            // worked.
            if conn.batch("ROLLBACK").is_ok() {
                self.pool.put(conn);
            }
        }
    }
}

impl Transaction for PostgresTransaction<'_> {
    fn lock_maps(&mut self, names: &[&str]) -> Result<(), StoreError> {
        if names.is_empty() {
            return Ok(());
        }
        self.run(|conn| {
            conn.query(
                "SELECT name FROM maps WHERE name = ANY($1) ORDER BY name FOR UPDATE",
                &[&names],
            )?;
            Ok(())
        })
    }

    fn lock_robots(&mut self, names: &[&str]) -> Result<(), StoreError> {
        if names.is_empty() {
            return Ok(());
        }
        self.run(|conn| {
            // A robot's first frames: its row must exist to be locked.
            conn.execute(
                "INSERT INTO robots (name) SELECT n FROM unnest($1::text[]) AS n ORDER BY n \
                 ON CONFLICT (name) DO NOTHING",
                &[&names],
            )?;
            conn.query(
                "SELECT name FROM robots WHERE name = ANY($1) ORDER BY name FOR UPDATE",
                &[&names],
            )?;
            Ok(())
        })
    }

    fn map(&mut self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        self.run(|conn| read_map(conn, name, false))
    }

    fn create_map(&mut self, record: &MapRecord) -> Result<(), StoreError> {
        self.run(|conn| {
            let created = conn.execute(
                "INSERT INTO maps (name, record) VALUES ($1, $2) ON CONFLICT (name) DO NOTHING",
                &[&record.name, &record.encode()],
            )?;
            if created == 0 {
                return Err(StoreError::MapExists(record.name.clone()));
            }
            Ok(())
        })
    }

    fn delete_map(&mut self, name: &str) -> Result<(), StoreError> {
        self.run(|conn| {
            let deleted = conn.execute("DELETE FROM maps WHERE name = $1", &[&name])?;
            if deleted == 0 {
                return Err(StoreError::MapNotFound(name.to_string()));
            }
            conn.execute("DELETE FROM tiles WHERE map = $1", &[&name])?;
            conn.execute("DELETE FROM cursors WHERE map = $1", &[&name])?;
            Ok(())
        })?;
        self.changes.push(StoreChange::Map {
            map: name.to_string(),
            event: MapEvent::Deleted,
        });
        Ok(())
    }

    fn write_map(&mut self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        if write.clear_tiles
            && let Some(record) = &write.record
        {
            self.changes.push(StoreChange::Map {
                map: name.to_string(),
                event: MapEvent::Cleared {
                    version: record.version,
                },
            });
        }
        let changes = &mut self.changes;
        for (key, tile) in &write.tiles {
            changes.push(StoreChange::Map {
                map: name.to_string(),
                event: MapEvent::TileChanged {
                    key: *key,
                    version: tile.version,
                },
            });
        }
        self.run(|conn| {
            if let Some(record) = &write.record {
                let updated = conn.execute(
                    "UPDATE maps SET record = $2 WHERE name = $1",
                    &[&name, &record.encode()],
                )?;
                if updated == 0 {
                    return Err(StoreError::MapNotFound(name.to_string()));
                }
            }
            if write.clear_tiles {
                conn.execute("DELETE FROM tiles WHERE map = $1", &[&name])?;
            }
            if !write.tiles.is_empty() {
                let mut xs = Vec::with_capacity(write.tiles.len());
                let mut ys = Vec::with_capacity(write.tiles.len());
                let mut versions = Vec::with_capacity(write.tiles.len());
                let mut cells = Vec::with_capacity(write.tiles.len());
                // Key order, and one row per key (an upsert may not touch
                // a row twice).
                let tiles: BTreeMap<TileKey, StoredTile> = write.tiles.into_iter().collect();
                for (key, tile) in &tiles {
                    xs.push(key.x);
                    ys.push(key.y);
                    versions.push(sql_version(tile.version));
                    cells.push(cells_bytes(&tile.tile));
                }
                conn.execute(
                    "INSERT INTO tiles (map, x, y, version, cells) \
                     SELECT $1, * FROM unnest($2::int4[], $3::int4[], $4::int8[], $5::bytea[]) \
                     ON CONFLICT (map, x, y) DO UPDATE \
                     SET version = excluded.version, cells = excluded.cells",
                    &[&name, &xs, &ys, &versions, &cells],
                )?;
            }
            if !write.cursors.is_empty() {
                let cursors: BTreeMap<String, ClientCursor> = write.cursors.into_iter().collect();
                let clients: Vec<&str> = cursors.keys().map(String::as_str).collect();
                let encoded: Vec<Vec<u8>> = cursors.values().map(ClientCursor::encode).collect();
                conn.execute(
                    "INSERT INTO cursors (map, client, cursor) \
                     SELECT $1, * FROM unnest($2::text[], $3::bytea[]) \
                     ON CONFLICT (map, client) DO UPDATE SET cursor = excluded.cursor",
                    &[&name, &clients, &encoded],
                )?;
            }
            Ok(())
        })
    }

    fn tiles(
        &mut self,
        map: &MapRecord,
        keys: &[TileKey],
    ) -> Result<Vec<(TileKey, StoredTile)>, StoreError> {
        if keys.is_empty() {
            return Ok(Vec::new());
        }
        let xs: Vec<i32> = keys.iter().map(|k| k.x).collect();
        let ys: Vec<i32> = keys.iter().map(|k| k.y).collect();
        self.run(|conn| {
            let rows = conn.query(
                "SELECT t.x, t.y, t.version, t.cells FROM tiles t \
                 JOIN unnest($2::int4[], $3::int4[]) AS k(x, y) ON t.x = k.x AND t.y = k.y \
                 WHERE t.map = $1",
                &[&map.name, &xs, &ys],
            )?;
            rows.iter()
                .map(|row| {
                    let key = TileKey::new(row.get(0), row.get(1));
                    Ok((key, decode_tile(map, row.get(2), row.get(3))?))
                })
                .collect()
        })
    }

    fn cursors(
        &mut self,
        name: &str,
        clients: &[&str],
    ) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        if clients.is_empty() {
            return Ok(Vec::new());
        }
        self.run(|conn| read_cursors(conn, name, clients))
    }

    fn robot(&mut self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.run(|conn| read_robot(conn, robot))
    }

    fn stored_frames(&mut self, robot: &str, sequences: &[u64]) -> Result<Vec<u64>, StoreError> {
        let sequences: Vec<i64> = sequences.iter().map(|&s| sql_sequence(s)).collect();
        if sequences.is_empty() {
            return Ok(Vec::new());
        }
        self.run(|conn| {
            let rows = conn.query(
                "SELECT sequence FROM frames WHERE robot = $1 AND sequence = ANY($2)",
                &[&robot, &sequences],
            )?;
            Ok(rows.iter().map(|row| stored_sequence(row.get(0))).collect())
        })
    }

    fn write_frames(&mut self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        for write in &writes {
            for (sequence, _) in &write.frames {
                self.changes.push(StoreChange::Frame {
                    robot: write.robot.clone(),
                    sequence: *sequence,
                });
            }
        }
        self.run(|conn| {
            for write in writes {
                let mut sequences = Vec::with_capacity(write.frames.len());
                let mut frames = Vec::with_capacity(write.frames.len());
                for (sequence, frame) in write.frames {
                    sequences.push(sql_sequence(sequence));
                    frames.push(frame);
                }
                conn.execute(
                    "INSERT INTO robots (name, summary) VALUES ($1, $2) \
                     ON CONFLICT (name) DO UPDATE SET summary = excluded.summary",
                    &[&write.robot, &write.summary.encode().as_slice()],
                )?;
                conn.execute(
                    "INSERT INTO frames (robot, sequence, frame) \
                     SELECT $1, * FROM unnest($2::int8[], $3::bytea[]) \
                     ON CONFLICT (robot, sequence) DO NOTHING",
                    &[&write.robot, &sequences, &frames],
                )?;
            }
            Ok(())
        })
    }

    fn write_poses(&mut self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        // Key order, the last of each key: one row each, locked in one order.
        let mut latest: BTreeMap<(String, u64), Vec<u8>> = BTreeMap::new();
        for (robot, sequence, bytes) in poses {
            latest.insert((robot, sequence), bytes);
        }
        let mut robots = Vec::with_capacity(latest.len());
        let mut sequences = Vec::with_capacity(latest.len());
        let mut bytes = Vec::with_capacity(latest.len());
        for ((robot, sequence), pose) in latest {
            self.changes.push(StoreChange::Pose {
                robot: robot.clone(),
                sequence,
            });
            robots.push(robot);
            sequences.push(sql_sequence(sequence));
            bytes.push(pose);
        }
        if robots.is_empty() {
            return Ok(());
        }
        self.run(|conn| {
            conn.execute(
                "INSERT INTO poses (robot, sequence, pose) \
                 SELECT * FROM unnest($1::text[], $2::int8[], $3::bytea[]) \
                 ON CONFLICT (robot, sequence) DO UPDATE SET pose = excluded.pose",
                &[&robots, &sequences, &bytes],
            )?;
            Ok(())
        })
    }

    fn commit(mut self: Box<Self>) -> Result<(), StoreError> {
        if let Some(failed) = self.failed.take() {
            return Err(failed);
        }
        let Some(mut conn) = self.conn.take() else {
            return Err(StoreError::Backend("the transaction has ended".into()));
        };
        // Delivered to listeners when, and only if, the transaction commits.
        let changes = if self.pool.notifies() {
            encode_changes(self.pool.origin(), &self.changes)
        } else {
            Vec::new()
        };
        for payload in changes {
            if let Err(error) =
                conn.query("SELECT pg_notify($1, $2)", &[&CHANGES_CHANNEL, &payload])
            {
                let _ = conn.batch("ROLLBACK");
                self.pool.put(conn);
                return Err(error);
            }
        }
        // A failed COMMIT leaves its fate unknown to us; the connection is
        // not reused.
        conn.batch("COMMIT")?;
        self.pool.put(conn);
        Ok(())
    }
}
