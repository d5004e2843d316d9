//! `deog bench`: the release benchmarks.
//!
//! `deog bench map-server` starts the real map server as a child process
//! (this same executable, `deog server`, on a free port and a fresh data
//! directory) and measures, in one run:
//!
//! 1. durable throughput: cell updates per second acknowledged by the server
//!    (acknowledged means flushed to disk), from 1 and from 4 concurrent
//!    clients each sending dense tile deltas over a shared region of tiles;
//! 2. the thesis baseline on the same store engine: the mapper of the
//!    thesis's Fig. 7.1 on sled, one key per cell (`(x << 16) + y`), a get,
//!    the Bayes update and an insert per cell update, a flush every 300
//!    updates, single-threaded, over the same cells;
//! 3. memory: the server's resident set while a map grows to `--cells`
//!    cells through 4 clients, with the map's cell count and the size of the
//!    data directory afterwards.

use std::fmt::Write as _;
use std::fs;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use clap::{Args, Subcommand};
use deog_grid::{LogOdds, TileDelta, TileKey, TileSize};
use deog_harness::proc_stats::{
    cpu_seconds as proc_cpu_seconds, own_cpu_seconds, status_kb as proc_status_kb,
};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use tokio::sync::Barrier;

/// The name the server's health service reports the map service under.
const MAP_SERVICE: &str = "deog.v1.MapService";
/// Cells per tile side of every benchmark map.
const TILE_SIDE: u32 = 64;
/// The thesis's mapper commits after this many writes.
const BASELINE_COMMIT_EVERY: u64 = 300;
/// Log-odds deltas (1/1000 nat) of the two kinds of evidence sent: a cell
/// gets them in turn on successive visits, so beliefs move both ways.
const EVIDENCE: (i16, i16) = (400, -300);

/// Options of `deog bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    target: BenchTarget,
}

#[derive(Debug, Subcommand)]
enum BenchTarget {
    /// Durable update throughput of the map server from concurrent clients
    /// against the thesis's mapper on the same store engine, and the
    /// server's memory while a map grows.
    MapServer(MapServerArgs),
    /// Localization accuracy over seeded runs per world, in one process:
    /// global convergence, error after convergence, kidnap recovery.
    Localize(crate::bench_localize::LocalizeBenchArgs),
    /// The localizer's memory against its cache setting, with the real
    /// processes, on a generated city map at least 100 times the cache.
    LocalizeMemory(crate::bench_memory::LocalizeMemoryArgs),
}

/// Options of `deog bench map-server`.
#[derive(Debug, Args)]
struct MapServerArgs {
    /// Seconds each throughput measurement (and the baseline) runs.
    #[arg(long, default_value_t = 10)]
    duration_s: u64,
    /// Numbers of concurrent clients to measure, comma-separated.
    #[arg(long, default_value = "1,4", value_delimiter = ',')]
    clients: Vec<usize>,
    /// Cells the memory test grows its map to (0 skips the memory test).
    #[arg(long, default_value_t = 100_000_000)]
    cells: u64,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Tiles per update batch.
    #[arg(long, default_value_t = 16)]
    batch_tiles: usize,
    /// Batches each client sends ahead of their acknowledgements.
    #[arg(long, default_value_t = 32)]
    window: usize,
    /// Side, in tiles, of the square region the throughput clients update.
    #[arg(long, default_value_t = 32)]
    region_tiles: i32,
    /// Page cache of the server's store, MiB.
    #[arg(long, default_value_t = 64)]
    cache_mb: u64,
}

/// Runs `deog bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    match args.target {
        BenchTarget::MapServer(args) => map_server(args),
        BenchTarget::Localize(args) => crate::bench_localize::run(args),
        BenchTarget::LocalizeMemory(args) => crate::bench_memory::run(args),
    }
}

fn map_server(args: MapServerArgs) -> Result<()> {
    ensure!(args.duration_s > 0, "--duration-s must be at least 1");
    ensure!(
        !args.clients.is_empty() && args.clients.iter().all(|&n| n > 0),
        "--clients needs one or more counts of at least 1"
    );
    ensure!(args.region_tiles > 0, "--region-tiles must be at least 1");
    let duration = Duration::from_secs(args.duration_s);
    let size = TileSize::new(TILE_SIDE)?;
    let region = region_tiles(args.region_tiles);
    let sender_config = UpdateSenderConfig {
        max_batch_tiles: args.batch_tiles.max(1),
        window: args.window.max(1),
    };

    eprintln!(
        "thesis baseline: Fig. 7.1 mapper on sled for {} s ...",
        args.duration_s
    );
    let baseline = thesis_baseline(duration, size, &region)?;

    let work = tempfile::tempdir().context("creating a temporary directory")?;
    let data = work.path().join("data");
    let mut server = ServerProcess::start(&data, &work.path().join("server.log"), args.cache_mb)?;
    eprintln!("map server: pid {}, {}", server.pid, server.url);

    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async {
        server.wait_until_serving().await?;
        let mut throughput = Vec::new();
        for &clients in &args.clients {
            eprintln!(
                "durable throughput: {clients} client(s) for {} s ...",
                args.duration_s
            );
            let run = durable_throughput(&server, clients, duration, size, &region, sender_config)
                .await?;
            throughput.push(run);
        }
        let memory = if args.cells > 0 {
            eprintln!(
                "memory: growing a map to {} cells through 4 clients ...",
                args.cells
            );
            Some(memory_growth(&server, &data, args.cells, size, sender_config).await?)
        } else {
            None
        };
        anyhow::Ok((throughput, memory))
    });
    let (throughput, memory) = match result {
        Ok(figures) => figures,
        Err(error) => {
            server.print_log_tail();
            return Err(error);
        }
    };
    drop(server);

    let report = Report {
        args: &args,
        baseline,
        throughput,
        memory,
    };
    print!("{}", report.table());
    if let Some(path) = &args.out {
        fs::write(path, report.json()).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("figures written to {}", path.display());
    }
    Ok(())
}

/// The tiles of a `side` × `side` square from tile (0, 0), row by row.
fn region_tiles(side: i32) -> Vec<TileKey> {
    (0..side)
        .flat_map(|y| (0..side).map(move |x| TileKey::new(x, y)))
        .collect()
}

/// The deltas a tile gets on its `visit`-th visit: every cell nonzero,
/// alternating between the two kinds of evidence along a row and from one
/// visit to the next.
fn evidence_pattern(size: TileSize, visit: usize) -> Vec<i16> {
    (0..size.area())
        .map(|i| {
            if (i + visit) % 2 == 0 {
                EVIDENCE.0
            } else {
                EVIDENCE.1
            }
        })
        .collect()
}

/// The map server, run as a child process; killed when dropped.
struct ServerProcess {
    child: Child,
    pid: u32,
    url: String,
    log: PathBuf,
}

impl ServerProcess {
    fn start(data: &Path, log: &Path, cache_mb: u64) -> Result<Self> {
        let port = {
            let listener =
                std::net::TcpListener::bind("127.0.0.1:0").context("finding a free port")?;
            listener.local_addr()?.port()
        };
        let exe = std::env::current_exe().context("locating the deog executable")?;
        let log_file =
            fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
        let child = Command::new(&exe)
            .arg("server")
            .arg("--listen")
            .arg(format!("127.0.0.1:{port}"))
            .arg("--data")
            .arg(data)
            .arg("--cache-mb")
            .arg(cache_mb.to_string())
            .stdin(Stdio::null())
            .stdout(log_file.try_clone()?)
            .stderr(log_file)
            .spawn()
            .with_context(|| format!("starting {} server", exe.display()))?;
        Ok(Self {
            pid: child.id(),
            child,
            url: format!("http://127.0.0.1:{port}"),
            log: log.to_path_buf(),
        })
    }

    /// Polls the health service until it reports the map service serving.
    async fn wait_until_serving(&mut self) -> Result<()> {
        use tonic_health::pb::health_check_response::ServingStatus;
        use tonic_health::pb::health_client::HealthClient;
        let endpoint = tonic::transport::Endpoint::from_shared(self.url.clone())?
            .connect_timeout(Duration::from_secs(1));
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut last = String::from("not reached yet");
        while Instant::now() < deadline {
            if let Some(status) = self.child.try_wait()? {
                bail!("the map server exited at start ({status}): {last}");
            }
            match endpoint.connect().await {
                Ok(channel) => {
                    let request = tonic_health::pb::HealthCheckRequest {
                        service: MAP_SERVICE.into(),
                    };
                    match HealthClient::new(channel).check(request).await {
                        Ok(reply) if reply.get_ref().status == ServingStatus::Serving as i32 => {
                            return Ok(());
                        }
                        Ok(reply) => last = format!("health status {}", reply.get_ref().status),
                        Err(status) => last = status.to_string(),
                    }
                }
                Err(error) => last = error.to_string(),
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        bail!("the map server did not report {MAP_SERVICE} serving within 30 s: {last}")
    }

    fn status_kb(&self, field: &str) -> Result<u64> {
        proc_status_kb(self.pid, field)
    }

    /// User plus system CPU seconds the server has used.
    fn cpu_seconds(&self) -> Result<f64> {
        proc_cpu_seconds(self.pid)
    }

    fn print_log_tail(&self) {
        if let Ok(file) = fs::File::open(&self.log) {
            let lines: Vec<String> = BufReader::new(file).lines().map_while(Result::ok).collect();
            eprintln!("last lines of the server's log ({}):", self.log.display());
            for line in &lines[lines.len().saturating_sub(20)..] {
                eprintln!("  {line}");
            }
        }
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn create_map_request(name: &str) -> pb::CreateMapRequest {
    pb::CreateMapRequest {
        name: name.into(),
        tile_size: TILE_SIDE,
        ..Default::default()
    }
}

/// What one throughput client did.
struct ClientRun {
    cells: u64,
    batches: u64,
    applied: u64,
    finished: Instant,
}

/// Figures of one throughput measurement.
struct ThroughputRun {
    clients: usize,
    cells: u64,
    batches: u64,
    seconds: f64,
    server_cpu_s: f64,
    bench_cpu_s: f64,
    map_version: u64,
}

impl ThroughputRun {
    fn cells_per_s(&self) -> f64 {
        self.cells as f64 / self.seconds
    }
}

async fn durable_throughput(
    server: &ServerProcess,
    clients: usize,
    duration: Duration,
    size: TileSize,
    region: &[TileKey],
    config: UpdateSenderConfig,
) -> Result<ThroughputRun> {
    let map = format!("bench-throughput-{clients}");
    let admin = MapClient::connect(ClientConfig::new(server.url.clone())).await?;
    admin.ensure_map(create_map_request(&map)).await?;
    let region = Arc::new(region.to_vec());
    let barrier = Arc::new(Barrier::new(clients + 1));
    let mut tasks = Vec::with_capacity(clients);
    for i in 0..clients {
        let (url, map, region, barrier) = (
            server.url.clone(),
            map.clone(),
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
    let (start, server_cpu, bench_cpu) =
        (Instant::now(), server.cpu_seconds()?, own_cpu_seconds()?);
    let mut runs = Vec::with_capacity(clients);
    for task in tasks {
        runs.push(task.await.context("client task panicked")??);
    }
    let end = runs.iter().map(|r| r.finished).max().unwrap_or(start);
    let seconds = end.duration_since(start).as_secs_f64();
    let server_cpu_s = server.cpu_seconds()? - server_cpu;
    let bench_cpu_s = own_cpu_seconds()? - bench_cpu;
    let info = admin.map_info(&map).await?;
    let batches: u64 = runs.iter().map(|r| r.batches).sum();
    let applied: u64 = runs.iter().map(|r| r.applied).sum();
    ensure!(
        applied == batches && info.version == batches,
        "{batches} batches sent, {applied} acknowledged as applied, map version {}",
        info.version
    );
    Ok(ThroughputRun {
        clients,
        cells: runs.iter().map(|r| r.cells).sum(),
        batches,
        seconds,
        server_cpu_s,
        bench_cpu_s,
        map_version: info.version,
    })
}

/// Figures of the thesis's mapper on sled.
struct BaselineRun {
    updates: u64,
    inserts: u64,
    rewrites: u64,
    flushes: u64,
    seconds: f64,
}

impl BaselineRun {
    fn cells_per_s(&self) -> f64 {
        self.updates as f64 / self.seconds
    }
}

/// The thesis's Fig. 7.1 on sled: for each cell update, `getdata`, the
/// Bayes update with the sensor's probability (a missing cell starts at
/// 0.5), then `addrows` or `updatedb` (only if the value changed); a commit
/// (flush) after every 300 writes. The cells are the throughput clients':
/// the region's tiles in order, every cell of each, with the same evidence.
fn thesis_baseline(duration: Duration, size: TileSize, region: &[TileKey]) -> Result<BaselineRun> {
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let db = sled::Config::new()
        .path(dir.path())
        .cache_capacity(64 << 20)
        .open()
        .context("opening the baseline's sled database")?;
    let side = size.cells() as i32;
    // The sensor's probability for each cell of each pattern, P(s) = the
    // logistic of the log-odds delta the server gets for that cell.
    let sensor = |delta: i16| LogOdds::from_raw(delta).map_or(0.5, LogOdds::probability);
    let patterns: [Vec<f64>; 2] = [0, 1].map(|visit| {
        evidence_pattern(size, visit)
            .into_iter()
            .map(sensor)
            .collect()
    });
    let (mut updates, mut inserts, mut rewrites, mut flushes, mut pending) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    let deadline = start + duration;
    let mut visit = 0usize;
    'run: loop {
        let key = region[visit % region.len()];
        let pattern = &patterns[(visit / region.len()) % 2];
        for (i, &pemp) in pattern.iter().enumerate() {
            let x = key.x * side + (i as i32 % side);
            let y = key.y * side + (i as i32 / side);
            let cell_key = (((x as u32) << 16).wrapping_add(y as u32)).to_be_bytes();
            let stored = db.get(cell_key)?;
            let old = match &stored {
                Some(bytes) => f64::from_be_bytes(
                    bytes
                        .as_ref()
                        .try_into()
                        .context("baseline value is not 8 bytes")?,
                ),
                None => 0.5,
            };
            let both = pemp * old;
            let p = both / ((1.0 - pemp) * (1.0 - old) + both);
            if stored.is_none() {
                db.insert(cell_key, &p.to_be_bytes())?;
                inserts += 1;
                pending += 1;
            } else if p != old {
                db.insert(cell_key, &p.to_be_bytes())?;
                rewrites += 1;
                pending += 1;
            }
            updates += 1;
            if pending >= BASELINE_COMMIT_EVERY {
                db.flush()?;
                flushes += 1;
                pending = 0;
                if Instant::now() >= deadline {
                    break 'run;
                }
            }
        }
        visit += 1;
    }
    db.flush()?;
    flushes += 1;
    Ok(BaselineRun {
        updates,
        inserts,
        rewrites,
        flushes,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Figures of the memory test.
struct MemoryRun {
    target_cells: u64,
    tiles: u64,
    cell_count: u64,
    tile_count: u64,
    seconds: f64,
    rss_before_kb: u64,
    peak_rss_sampled_kb: u64,
    samples: u64,
    hwm_kb: u64,
    rss_after_kb: u64,
    data_apparent_bytes: u64,
    data_allocated_bytes: u64,
}

async fn memory_growth(
    server: &ServerProcess,
    data: &Path,
    target_cells: u64,
    size: TileSize,
    config: UpdateSenderConfig,
) -> Result<MemoryRun> {
    const CLIENTS: usize = 4;
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
                if let Ok(rss) = proc_status_kb(pid, "VmRSS") {
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
    let (data_apparent_bytes, data_allocated_bytes) = dir_size(data)?;
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
    })
}

/// Apparent and allocated bytes of every file under `path`.
fn dir_size(path: &Path) -> Result<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let (mut apparent, mut allocated) = (0u64, 0u64);
    for entry in fs::read_dir(path).with_context(|| format!("reading {}", path.display()))? {
        let entry = entry?;
        let meta = entry.metadata()?;
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

struct Report<'a> {
    args: &'a MapServerArgs,
    baseline: BaselineRun,
    throughput: Vec<ThroughputRun>,
    memory: Option<MemoryRun>,
}

fn millions(x: f64) -> String {
    format!("{:.2} M", x / 1e6)
}

fn mb(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

impl Report<'_> {
    fn table(&self) -> String {
        let b = &self.baseline;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "\nmap server bench: {} s per measurement, batches of {} tiles of {TILE_SIDE}x{TILE_SIDE}, window {}, region {}x{} tiles",
            self.args.duration_s,
            self.args.batch_tiles,
            self.args.window,
            self.args.region_tiles,
            self.args.region_tiles
        );
        let _ = writeln!(
            out,
            "\n| measure | cell updates/s | vs baseline | cells | seconds | server CPU s | bench CPU s |"
        );
        let _ = writeln!(out, "|---|---|---|---|---|---|---|");
        let _ = writeln!(
            out,
            "| thesis Fig. 7.1 on sled, 1 thread (baseline) | {} | 1.0x | {} | {:.2} | - | - |",
            millions(b.cells_per_s()),
            b.updates,
            b.seconds
        );
        for t in &self.throughput {
            let _ = writeln!(
                out,
                "| map server, {} client(s), durable | {} | {:.1}x | {} | {:.2} | {:.2} | {:.2} |",
                t.clients,
                millions(t.cells_per_s()),
                t.cells_per_s() / b.cells_per_s(),
                t.cells,
                t.seconds,
                t.server_cpu_s,
                t.bench_cpu_s
            );
        }
        let _ = writeln!(
            out,
            "\nbaseline: {} inserts, {} rewrites, {} flushes",
            b.inserts, b.rewrites, b.flushes
        );
        for t in &self.throughput {
            let _ = writeln!(
                out,
                "{} client(s): {} batches acknowledged as applied, map version {}",
                t.clients, t.batches, t.map_version
            );
        }
        if let Some(m) = &self.memory {
            let _ = writeln!(out, "\n| memory | value |");
            let _ = writeln!(out, "|---|---|");
            let _ = writeln!(
                out,
                "| target cells | {} ({} tiles) |",
                m.target_cells, m.tiles
            );
            let _ = writeln!(
                out,
                "| map cell_count / tile_count | {} / {} |",
                m.cell_count, m.tile_count
            );
            let _ = writeln!(
                out,
                "| growth time | {:.1} s ({} new cells/s) |",
                m.seconds,
                millions(m.target_cells as f64 / m.seconds)
            );
            let _ = writeln!(
                out,
                "| server VmRSS before | {:.1} MB |",
                mb(m.rss_before_kb)
            );
            let _ = writeln!(
                out,
                "| server peak VmRSS sampled (100 ms, {} samples) | {:.1} MB |",
                m.samples,
                mb(m.peak_rss_sampled_kb)
            );
            let _ = writeln!(
                out,
                "| server VmHWM at the end (whole run) | {:.1} MB |",
                mb(m.hwm_kb)
            );
            let _ = writeln!(out, "| server VmRSS after | {:.1} MB |", mb(m.rss_after_kb));
            let _ = writeln!(
                out,
                "| data directory (apparent / allocated) | {:.1} MB / {:.1} MB |",
                m.data_apparent_bytes as f64 / 1e6,
                m.data_allocated_bytes as f64 / 1e6
            );
        }
        out
    }

    fn json(&self) -> String {
        let b = &self.baseline;
        let mut out = String::from("{\n");
        let _ = writeln!(
            out,
            "  \"config\": {{\"duration_s\": {}, \"batch_tiles\": {}, \"window\": {}, \"region_tiles\": {}, \"tile_side\": {TILE_SIDE}, \"cache_mb\": {}}},",
            self.args.duration_s,
            self.args.batch_tiles,
            self.args.window,
            self.args.region_tiles,
            self.args.cache_mb
        );
        let _ = writeln!(
            out,
            "  \"baseline\": {{\"cell_updates\": {}, \"inserts\": {}, \"rewrites\": {}, \"flushes\": {}, \"seconds\": {:.3}, \"cell_updates_per_s\": {:.1}}},",
            b.updates,
            b.inserts,
            b.rewrites,
            b.flushes,
            b.seconds,
            b.cells_per_s()
        );
        let runs: Vec<String> = self
            .throughput
            .iter()
            .map(|t| {
                format!(
                    "    {{\"clients\": {}, \"cell_updates\": {}, \"batches\": {}, \"seconds\": {:.3}, \"cell_updates_per_s\": {:.1}, \"ratio_to_baseline\": {:.2}, \"server_cpu_s\": {:.2}, \"bench_cpu_s\": {:.2}}}",
                    t.clients,
                    t.cells,
                    t.batches,
                    t.seconds,
                    t.cells_per_s(),
                    t.cells_per_s() / b.cells_per_s(),
                    t.server_cpu_s,
                    t.bench_cpu_s
                )
            })
            .collect();
        let _ = write!(out, "  \"throughput\": [\n{}\n  ]", runs.join(",\n"));
        match &self.memory {
            Some(m) => {
                let _ = write!(
                    out,
                    ",\n  \"memory\": {{\"target_cells\": {}, \"tiles\": {}, \"cell_count\": {}, \"tile_count\": {}, \"seconds\": {:.3}, \"rss_before_mb\": {:.1}, \"peak_rss_sampled_mb\": {:.1}, \"samples\": {}, \"vm_hwm_mb\": {:.1}, \"rss_after_mb\": {:.1}, \"data_apparent_bytes\": {}, \"data_allocated_bytes\": {}}}\n",
                    m.target_cells,
                    m.tiles,
                    m.cell_count,
                    m.tile_count,
                    m.seconds,
                    mb(m.rss_before_kb),
                    mb(m.peak_rss_sampled_kb),
                    m.samples,
                    mb(m.hwm_kb),
                    mb(m.rss_after_kb),
                    m.data_apparent_bytes,
                    m.data_allocated_bytes
                );
            }
            None => out.push('\n'),
        }
        out.push_str("}\n");
        out
    }
}
