//! The server's memory while a map grows to a target cell count through
//! four clients, each tile visited once, with the resident set sampled
//! every 100 ms from `/proc`; then the size of the store.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use deog_grid::{TileDelta, TileKey, TileSize};
use deog_harness::proc_stats;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};

use super::ServerUnderTest;
use super::store::StoreUnderTest;
use super::workload::{create_map_request, evidence_pattern};

/// Clients growing the map.
const CLIENTS: usize = 4;

/// Figures of the memory test.
pub(super) struct MemoryRun {
    /// Cells the map was grown to (`--cells`).
    pub target_cells: u64,
    /// Tiles those cells fill.
    pub tiles: u64,
    /// The map's cell count afterwards, as the server reports it.
    pub cell_count: u64,
    /// The map's tile count afterwards, as the server reports it.
    pub tile_count: u64,
    /// Wall-clock seconds the growth took.
    pub seconds: f64,
    /// The server's `VmRSS` before, kB.
    pub rss_before_kb: u64,
    /// The largest `VmRSS` sampled during the growth, kB.
    pub peak_rss_sampled_kb: u64,
    /// Samples taken.
    pub samples: u64,
    /// The server's `VmHWM` afterwards (its peak over the whole run), kB.
    pub hwm_kb: u64,
    /// The server's `VmRSS` afterwards, kB.
    pub rss_after_kb: u64,
    /// Bytes of the files in the data directory (sled's, or the private
    /// PostgreSQL's with its WAL); `None` when the bench does not know the
    /// folder (a PostgreSQL it was given).
    pub data_apparent_bytes: Option<u64>,
    /// Bytes the data directory's files take on disk.
    pub data_allocated_bytes: Option<u64>,
    /// `pg_database_size` of the database, on PostgreSQL.
    pub database_bytes: Option<u64>,
}

/// Grows map `bench-memory` to `target_cells` cells through `server` and
/// reads its memory around it, and the size of `store` afterwards.
pub(super) async fn memory_growth(
    server: &ServerUnderTest,
    store: &StoreUnderTest,
    target_cells: u64,
    size: TileSize,
    config: UpdateSenderConfig,
) -> Result<MemoryRun> {
    let map = "bench-memory";
    let admin = MapClient::connect(ClientConfig::new(server.url.clone())).await?;
    admin.ensure_map(create_map_request(map)).await?;
    let area = size.area() as u64;
    let tiles = target_cells.div_ceil(area);
    // Tiles laid out in a square, each visited once; the last holds only
    // what is left of the target so the map ends with exactly that many cells.
    let columns = (tiles as f64).sqrt().ceil() as u64;
    let rss_before_kb = server.status_kb("VmRSS")?;

    let stop = Arc::new(AtomicBool::new(false));
    let sampler = {
        let (stop, pid) = (stop.clone(), server.pid);
        std::thread::spawn(move || {
            let (mut peak, mut samples) = (0u64, 0u64);
            while !stop.load(Ordering::Relaxed) {
                if let Ok(rss) = proc_stats::status_kb(pid, "VmRSS") {
                    peak = peak.max(rss);
                    samples += 1;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            (peak, samples)
        })
    };

    let start = Instant::now();
    let mut tasks = Vec::with_capacity(CLIENTS);
    for i in 0..CLIENTS {
        let url = server.url.clone();
        tasks.push(tokio::spawn(async move {
            let client = MapClient::connect(ClientConfig::new(url)).await?;
            let mut sender = client
                .updates(map, &format!("bench-memory-{i}"), config)
                .await?;
            let full = evidence_pattern(size, 0);
            let mut cells = 0u64;
            for t in (i as u64..tiles).step_by(CLIENTS) {
                let key = TileKey::new((t % columns) as i32, (t / columns) as i32);
                let left = target_cells - t * area;
                let delta = if left >= area {
                    TileDelta::from_raw(key, size, full.clone())?
                } else {
                    let mut partial = full.clone();
                    partial[left as usize..].fill(0);
                    TileDelta::from_raw(key, size, partial)?
                };
                cells += delta.nonzero_count() as u64;
                sender.push(delta).await?;
            }
            let state = sender.close().await?;
            ensure!(state.failure.is_none(), "client {i}: {:?}", state.failure);
            anyhow::Ok(cells)
        }));
    }
    let mut sent = 0u64;
    let mut failure = None;
    for task in tasks {
        match task.await.context("client task panicked").and_then(|r| r) {
            Ok(cells) => sent += cells,
            Err(error) => {
                failure.get_or_insert(error);
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    // Let the sampler see the settled state once more.
    tokio::time::sleep(Duration::from_millis(200)).await;
    stop.store(true, Ordering::Relaxed);
    let (peak_rss_sampled_kb, samples) = sampler
        .join()
        .map_err(|_| anyhow::anyhow!("the RSS sampler panicked"))?;
    if let Some(error) = failure {
        return Err(error);
    }
    ensure!(
        sent == target_cells,
        "sent {sent} cells, meant {target_cells}"
    );
    let info = admin.map_info(map).await?;
    let hwm_kb = server.status_kb("VmHWM")?;
    let rss_after_kb = server.status_kb("VmRSS")?;
    let (data_apparent_bytes, data_allocated_bytes) = match store.data_dir() {
        Some(data) => {
            let (apparent, allocated) = dir_size(data)?;
            (Some(apparent), Some(allocated))
        }
        None => (None, None),
    };
    let database_bytes = store.database_bytes().await?;
    Ok(MemoryRun {
        target_cells,
        tiles,
        cell_count: info.cell_count,
        tile_count: info.tile_count,
        seconds,
        rss_before_kb,
        peak_rss_sampled_kb,
        samples,
        hwm_kb,
        rss_after_kb,
        data_apparent_bytes,
        data_allocated_bytes,
        database_bytes,
    })
}

/// Apparent and allocated bytes of every file under `path`.
fn dir_size(path: &Path) -> Result<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let (mut apparent, mut allocated) = (0u64, 0u64);
    for entry in std::fs::read_dir(path).with_context(|| format!("reading {}", path.display()))? {
        let entry = entry?;
        // PostgreSQL may remove a file (a recycled WAL segment) meanwhile.
        let Ok(meta) = entry.metadata() else {
            continue;
        };
        if meta.is_dir() {
            let (a, b) = dir_size(&entry.path())?;
            apparent += a;
            allocated += b;
        } else {
            apparent += meta.len();
            allocated += meta.blocks() * 512;
        }
    }
    Ok((apparent, allocated))
}
