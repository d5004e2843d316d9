//! Durable throughput: cell updates a second the servers acknowledge as
//! applied (committed to disk) from concurrent clients, spread round-robin
//! over the servers sharing the store, each sending dense tile deltas over
//! the shared region of one map.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use deog_grid::{TileDelta, TileKey, TileSize};
use deog_harness::proc_stats::own_cpu_seconds;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use tokio::sync::Barrier;

use super::ServerUnderTest;
use super::store::StoreUnderTest;
use super::workload::{create_map_request, evidence_pattern};

/// What one throughput client did.
struct ClientRun {
    cells: u64,
    batches: u64,
    applied: u64,
    finished: Instant,
}

/// Figures of one throughput measurement.
pub(super) struct ThroughputRun {
    /// Servers sharing the store.
    pub servers: usize,
    /// Concurrent clients.
    pub clients: usize,
    /// Maps they wrote.
    pub maps: usize,
    /// Cell updates acknowledged.
    pub cells: u64,
    /// Batches acknowledged as applied.
    pub batches: u64,
    /// From the clients' start to the last one's last acknowledgement.
    pub seconds: f64,
    /// CPU seconds the servers used meanwhile, together.
    pub server_cpu_s: f64,
    /// CPU seconds the private PostgreSQL used meanwhile; `None` on sled
    /// or a PostgreSQL the bench did not start.
    pub database_cpu_s: Option<f64>,
    /// CPU seconds this process (the clients) used meanwhile.
    pub bench_cpu_s: f64,
    /// The maps' versions afterwards, added: one per batch applied.
    pub map_version: u64,
}

impl ThroughputRun {
    /// Cell updates a second.
    pub fn cells_per_s(&self) -> f64 {
        self.cells as f64 / self.seconds
    }
}

/// `clients` clients, each on its own connection to a server (client `i`
/// to server `i mod N`), send the region's tiles of one of `maps` maps
/// (client `i` to map `i mod maps`) from their own starting points for
/// `duration`; counted once every batch is acknowledged.
#[allow(clippy::too_many_arguments)]
pub(super) async fn durable_throughput(
    servers: &[ServerUnderTest],
    store: &StoreUnderTest,
    clients: usize,
    maps: usize,
    duration: Duration,
    size: TileSize,
    region: &[TileKey],
    config: UpdateSenderConfig,
) -> Result<ThroughputRun> {
    let maps = maps.max(1);
    let names: Vec<String> = (0..maps)
        .map(|m| format!("bench-throughput-{}x{clients}-{m}", servers.len()))
        .collect();
    let first = servers.first().context("no server to measure")?;
    let admin = MapClient::connect(ClientConfig::new(first.url.clone())).await?;
    for map in &names {
        admin.ensure_map(create_map_request(map)).await?;
    }
    let region = Arc::new(region.to_vec());
    let barrier = Arc::new(Barrier::new(clients + 1));
    let mut tasks = Vec::with_capacity(clients);
    for i in 0..clients {
        let (url, map, region, barrier) = (
            servers[i % servers.len()].url.clone(),
            names[i % maps].clone(),
            region.clone(),
            barrier.clone(),
        );
        let start = i * region.len() / clients;
        tasks.push(tokio::spawn(async move {
            let client = MapClient::connect(ClientConfig::new(url)).await;
            let sender = match &client {
                Ok(client) => Some(
                    client
                        .updates(&map, &format!("bench-{clients}-{i}"), config)
                        .await,
                ),
                Err(_) => None,
            };
            // Everyone passes the barrier, ready or not, so none waits for ever.
            barrier.wait().await;
            let mut sender = sender.context("connecting")??;
            let deadline = Instant::now() + duration;
            let patterns = [evidence_pattern(size, 0), evidence_pattern(size, 1)];
            let (mut cells, mut visit) = (0u64, start);
            while Instant::now() < deadline {
                let key = region[visit % region.len()];
                let pattern = &patterns[(visit / region.len()) % 2];
                let delta = TileDelta::from_raw(key, size, pattern.clone())?;
                cells += delta.nonzero_count() as u64;
                sender.push(delta).await?;
                visit += 1;
            }
            // The deadline can pass with a batch part-filled: send it now,
            // as closing would, so that it counts among the batches sent
            // (its cells are counted already).
            sender.send_batch().await?;
            let batches = sender.next_sequence() - 1;
            let state = sender.close().await?;
            ensure!(
                state.last_acked == batches && state.failure.is_none(),
                "client {i}: {} of {batches} batches acknowledged",
                state.last_acked
            );
            anyhow::Ok(ClientRun {
                cells,
                batches,
                applied: state.applied,
                finished: Instant::now(),
            })
        }));
    }
    barrier.wait().await;
    let (start, server_cpu, database_cpu, bench_cpu) = (
        Instant::now(),
        servers_cpu_seconds(servers)?,
        store.database_cpu_seconds(),
        own_cpu_seconds()?,
    );
    let mut runs = Vec::with_capacity(clients);
    for task in tasks {
        runs.push(task.await.context("client task panicked")??);
    }
    let end = runs.iter().map(|r| r.finished).max().unwrap_or(start);
    let seconds = end.duration_since(start).as_secs_f64();
    let server_cpu_s = servers_cpu_seconds(servers)? - server_cpu;
    let database_cpu_s = store
        .database_cpu_seconds()
        .zip(database_cpu)
        .map(|(after, before)| after - before);
    let bench_cpu_s = own_cpu_seconds()? - bench_cpu;
    let mut map_version = 0;
    for map in &names {
        map_version += admin.map_info(map).await?.version;
    }
    let batches: u64 = runs.iter().map(|r| r.batches).sum();
    let applied: u64 = runs.iter().map(|r| r.applied).sum();
    ensure!(
        applied == batches && map_version == batches,
        "{batches} batches sent, {applied} acknowledged as applied, map versions add to {map_version}"
    );
    Ok(ThroughputRun {
        servers: servers.len(),
        clients,
        maps,
        cells: runs.iter().map(|r| r.cells).sum(),
        batches,
        seconds,
        server_cpu_s,
        database_cpu_s,
        bench_cpu_s,
        map_version,
    })
}

/// CPU seconds the servers have used, together.
fn servers_cpu_seconds(servers: &[ServerUnderTest]) -> Result<f64> {
    servers.iter().map(ServerUnderTest::cpu_seconds).sum()
}
