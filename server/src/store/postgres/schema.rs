//! The database schema, created and migrated by the server itself.
//!
//! `deog_schema` holds the version the database is at. Each migration
//! runs in one transaction under an advisory lock, so servers starting
//! together migrate once; a database at a later version than this build
//! knows is refused rather than written in a layout it does not know.

use super::connection::Conn;
use crate::error::StoreError;

/// The migrations, in order: migration `i` takes the schema from version
/// `i` to `i + 1`.
const MIGRATIONS: &[&str] = &[
    // 1: the first layout.
    "CREATE TABLE maps (
         name text PRIMARY KEY,
         record bytea NOT NULL
     );
     CREATE TABLE tiles (
         map text NOT NULL,
         x integer NOT NULL,
         y integer NOT NULL,
         version bigint NOT NULL,
         cells bytea NOT NULL,
         PRIMARY KEY (map, x, y)
     );
     CREATE TABLE cursors (
         map text NOT NULL,
         client text NOT NULL,
         cursor bytea NOT NULL,
         PRIMARY KEY (map, client)
     );
     CREATE TABLE robots (
         name text PRIMARY KEY,
         summary bytea
     );
     CREATE TABLE frames (
         robot text NOT NULL,
         sequence bigint NOT NULL,
         frame bytea NOT NULL,
         PRIMARY KEY (robot, sequence)
     );
     CREATE TABLE poses (
         robot text NOT NULL,
         sequence bigint NOT NULL,
         pose bytea NOT NULL,
         PRIMARY KEY (robot, sequence)
     );
     CREATE TABLE rigs (
         name text PRIMARY KEY,
         rig bytea NOT NULL
     );
     CREATE TABLE deog_probe (
         id integer PRIMARY KEY,
         at timestamptz NOT NULL
     );",
    // 2: explorers' goals, one per map and robot.
    "CREATE TABLE goals (
         map text NOT NULL,
         robot text NOT NULL,
         goal bytea NOT NULL,
         PRIMARY KEY (map, robot)
     );",
];

/// The schema version this build writes.
pub const CURRENT: i32 = MIGRATIONS.len() as i32;

/// An arbitrary key for the advisory lock migrations take.
const MIGRATION_LOCK: i64 = 0x6465_6f67_7363_6d61;

/// The version the database is at (0 for an empty one).
pub(super) fn version(conn: &mut Conn) -> Result<i32, StoreError> {
    let rows = conn.query("SELECT to_regclass('deog_schema') IS NOT NULL", &[])?;
    if !rows.first().is_some_and(|row| row.get::<_, bool>(0)) {
        return Ok(0);
    }
    recorded_version(conn)
}

fn recorded_version(conn: &mut Conn) -> Result<i32, StoreError> {
    let rows = conn.query("SELECT max(version) FROM deog_schema", &[])?;
    Ok(rows
        .first()
        .and_then(|row| row.get::<_, Option<i32>>(0))
        .unwrap_or(0))
}

/// Brings the schema to [`CURRENT`]. Servers starting together on an
/// empty database take turns: everything, the first table included, is
/// created under the lock.
pub(super) fn migrate(conn: &mut Conn) -> Result<(), StoreError> {
    let found = version(conn)?;
    if found > CURRENT {
        return Err(refuse_newer(found));
    }
    if found == CURRENT {
        return Ok(());
    }
    conn.batch("BEGIN")?;
    let migrated = run_migrations(conn);
    match migrated {
        Ok(()) => conn.batch("COMMIT"),
        Err(error) => {
            let _ = conn.batch("ROLLBACK");
            Err(error)
        }
    }
}

fn run_migrations(conn: &mut Conn) -> Result<(), StoreError> {
    conn.query("SELECT pg_advisory_xact_lock($1)", &[&MIGRATION_LOCK])?;
    conn.batch("CREATE TABLE IF NOT EXISTS deog_schema (version integer NOT NULL)")?;
    // Another server may have migrated while this one waited.
    let found = recorded_version(conn)?;
    if found > CURRENT {
        return Err(refuse_newer(found));
    }
    for (index, migration) in MIGRATIONS.iter().enumerate().skip(found as usize) {
        conn.batch(migration)?;
        let reached = index as i32 + 1;
        conn.execute("INSERT INTO deog_schema (version) VALUES ($1)", &[&reached])?;
        tracing::info!(version = reached, "database schema migrated");
    }
    Ok(())
}

fn refuse_newer(found: i32) -> StoreError {
    StoreError::Backend(format!(
        "the database holds deog schema version {found}, newer than this build knows \
         ({CURRENT}): upgrade deog rather than let it write an older layout"
    ))
}
