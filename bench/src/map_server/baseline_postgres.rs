//! The thesis baseline on PostgreSQL: the mapper of the thesis's Fig. 7.1
//! with its schema, one row per cell keyed `(x << 16) + y`, on the same
//! PostgreSQL the servers use, over the same cells as on sled.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::{TileKey, TileSize};
use tokio_postgres::types::ToSql;

use super::baseline::{BASELINE_COMMIT_EVERY, BaselineRun, ThesisCells, bayes};
use super::store::connect;

/// The baseline's table, created fresh in the bench's database and
/// dropped afterwards, so the servers' figures do not count it.
const TABLE: &str = "thesis_cells";

/// The thesis's Fig. 7.1 on the PostgreSQL database `url`: for each cell
/// update, a `SELECT` of the cell, the Bayes update (a missing cell
/// starts at 0.5), then an upsert (`INSERT … ON CONFLICT DO UPDATE`) if
/// the cell was missing or its value changed; a `COMMIT` after every 300
/// writes. One connection, one thread, each statement a round trip, as
/// the thesis's mapper did through its database driver.
pub(super) fn thesis_baseline(
    url: &str,
    duration: Duration,
    size: TileSize,
    region: &[TileKey],
) -> Result<BaselineRun> {
    // The bench is synchronous; this runtime drives the one connection.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the baseline's runtime")?;
    runtime.block_on(run(url, duration, size, region))
}

async fn run(
    url: &str,
    duration: Duration,
    size: TileSize,
    region: &[TileKey],
) -> Result<BaselineRun> {
    let client = connect(url).await?;
    client
        .batch_execute(&format!(
            "DROP TABLE IF EXISTS {TABLE}; \
             CREATE TABLE {TABLE} (cell integer PRIMARY KEY, p double precision NOT NULL)"
        ))
        .await
        .context("creating the baseline's table")?;
    let select = client
        .prepare(&format!("SELECT p FROM {TABLE} WHERE cell = $1"))
        .await
        .context("preparing the baseline's SELECT")?;
    let upsert = client
        .prepare(&format!(
            "INSERT INTO {TABLE} (cell, p) VALUES ($1, $2) \
             ON CONFLICT (cell) DO UPDATE SET p = excluded.p"
        ))
        .await
        .context("preparing the baseline's upsert")?;
    let (mut updates, mut inserts, mut rewrites, mut flushes, mut pending) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    let deadline = start + duration;
    client.batch_execute("BEGIN").await?;
    for (key, pemp) in ThesisCells::new(size, region) {
        // The thesis's key as a signed column: the same 32 bits.
        let cell = key as i32;
        let stored: Option<f64> = client
            .query_opt(&select, &[&cell])
            .await
            .context("the baseline's SELECT")?
            .map(|row| row.get(0));
        let old = stored.unwrap_or(0.5);
        let p = bayes(pemp, old);
        if stored.is_none() || p != old {
            client
                .execute(&upsert, &[&cell as &(dyn ToSql + Sync), &p])
                .await
                .context("the baseline's upsert")?;
            if stored.is_none() {
                inserts += 1;
            } else {
                rewrites += 1;
            }
            pending += 1;
        }
        updates += 1;
        if pending >= BASELINE_COMMIT_EVERY {
            client.batch_execute("COMMIT; BEGIN").await?;
            flushes += 1;
            pending = 0;
            if Instant::now() >= deadline {
                break;
            }
        }
    }
    client.batch_execute("COMMIT").await?;
    flushes += 1;
    let seconds = start.elapsed().as_secs_f64();
    client
        .batch_execute(&format!("DROP TABLE {TABLE}"))
        .await
        .context("dropping the baseline's table")?;
    Ok(BaselineRun {
        engine: "postgres",
        updates,
        inserts,
        rewrites,
        flushes,
        seconds,
    })
}
