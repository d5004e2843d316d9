//! `deog bench map-server`: starts the real map server as child processes
//! (this same executable, `deog server`, on free ports and a fresh store:
//! a sled data directory, a private PostgreSQL, or a PostgreSQL database
//! it is given) and measures, in one run:
//!
//! 1. durable throughput: cell updates per second acknowledged by the
//!    servers (acknowledged means committed to disk), for each `--servers`
//!    count of servers sharing the store and each `--clients` count of
//!    concurrent clients, spread round-robin over the servers, each
//!    sending dense tile deltas over a shared region of tiles;
//! 2. the thesis baseline on the same store engine: the mapper of the
//!    thesis's Fig. 7.1, one key (or row) per cell (`(x << 16) + y`), a
//!    read, the Bayes update and a write per cell update, a commit every
//!    300 updates, single-threaded, over the same cells;
//! 3. memory: the first server's resident set while a map grows to
//!    `--cells` cells through 4 clients, with the map's cell count and the
//!    size of the data directory (and, on PostgreSQL, of the database)
//!    afterwards.
//!
//! Its parts: `store` (the store the servers share), `workload` (the
//! region the clients update and the evidence they send), `baseline` (the
//! thesis's mapper on sled, and the cells it updates), `baseline_postgres`
//! (the same mapper on PostgreSQL), `throughput`, `memory`, `figures`
//! (everything measured, as the table printed) and `record` (the same as
//! the JSON `--out` writes).

mod baseline;
mod baseline_postgres;
mod figures;
mod memory;
mod record;
mod store;
mod throughput;
mod workload;

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::{TileKey, TileSize};
use deog_harness::{
    Progress, Role, Supervisor, connect, free_loopback_addr, log_tail, os, proc_stats,
};
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};

use figures::MapServerFigures;
use store::StoreUnderTest;

use crate::option_error::{OptionError, require};
pub use store::StoreChoice;
use workload::{TILE_SIDE, region_tiles};

/// Options of `deog bench map-server`.
#[derive(Debug, Clone, Args)]
pub struct MapServerOptions {
    /// Seconds each throughput measurement (and the baseline) runs.
    #[arg(long, default_value_t = 10)]
    pub duration_s: u64,
    /// Numbers of concurrent clients to measure, comma-separated.
    #[arg(long, default_value = "1,4", value_delimiter = ',')]
    pub clients: Vec<usize>,
    /// Cells the memory test grows its map to (0 skips the memory test).
    #[arg(long, default_value_t = 100_000_000)]
    pub cells: u64,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Tiles per update batch.
    #[arg(long, default_value_t = 16)]
    pub batch_tiles: usize,
    /// Batches each client sends ahead of their acknowledgements.
    #[arg(long, default_value_t = 32)]
    pub window: usize,
    /// Side, in tiles, of the square region the throughput clients update.
    #[arg(long, default_value_t = 32)]
    pub region_tiles: i32,
    /// Page cache of the server's store, MiB.
    #[arg(long, default_value_t = 64)]
    pub cache_mb: u64,
    /// The store the servers share: `sled` (a fresh data directory),
    /// `postgres` (a private PostgreSQL the bench starts, fsync and
    /// synchronous_commit on), or the `postgres://USER@HOST/DB` URL of a
    /// fresh database. The thesis baseline runs on the same engine.
    #[arg(long, default_value = "sled")]
    pub store: String,
    /// Numbers of servers sharing the store to measure, comma-separated;
    /// clients are spread over them round-robin. More than one needs
    /// PostgreSQL.
    #[arg(long, default_value = "1", value_delimiter = ',')]
    pub servers: Vec<usize>,
    /// Maps the throughput clients write, client `i` to map `i mod N`: one
    /// map's commits take turns (its version counts every batch), several
    /// maps' can overlap.
    #[arg(long, default_value_t = 1)]
    pub maps: usize,
}

impl MapServerOptions {
    /// Checks the options a run cannot start with.
    pub fn validate(&self) -> Result<(), OptionError> {
        require(self.duration_s > 0, "--duration-s", || {
            "--duration-s must be at least 1".into()
        })?;
        require(
            !self.clients.is_empty() && self.clients.iter().all(|&n| n > 0),
            "--clients",
            || "--clients needs one or more counts of at least 1".into(),
        )?;
        require(self.region_tiles > 0, "--region-tiles", || {
            "--region-tiles must be at least 1".into()
        })?;
        let store = self.store_choice()?;
        require(self.maps > 0, "--maps", || {
            "--maps must be at least 1".into()
        })?;
        require(
            !self.servers.is_empty() && self.servers.iter().all(|&n| n > 0),
            "--servers",
            || "--servers needs one or more counts of at least 1".into(),
        )?;
        require(
            store.is_shared() || self.servers.iter().all(|&n| n == 1),
            "--servers",
            || {
                "--servers: a sled store belongs to one server; several servers need \
                 --store postgres or a postgres:// URL"
                    .into()
            },
        )
    }

    /// `--store`, read.
    pub fn store_choice(&self) -> Result<StoreChoice, OptionError> {
        StoreChoice::parse(&self.store).ok_or_else(|| OptionError {
            flag: "--store",
            message: format!(
                "--store {}: takes sled, postgres or a postgres:// URL",
                self.store
            ),
        })
    }
}

/// One map server under test: where it serves, and its process for
/// `/proc`.
struct ServerUnderTest {
    url: String,
    pid: u32,
}

impl ServerUnderTest {
    /// A `kB` field of the server's `/proc/<pid>/status`.
    fn status_kb(&self, field: &str) -> Result<u64> {
        proc_stats::status_kb(self.pid, field)
    }

    /// User plus system CPU seconds the server has used.
    fn cpu_seconds(&self) -> Result<f64> {
        proc_stats::cpu_seconds(self.pid)
    }
}

/// Runs `deog bench map-server`: prints the figures as a table, and writes
/// them as JSON to `--out` if given.
pub fn run(options: MapServerOptions) -> Result<()> {
    options.validate()?;
    let choice = options.store_choice()?;
    let duration = Duration::from_secs(options.duration_s);
    let size = TileSize::new(TILE_SIDE)?;
    let region = region_tiles(options.region_tiles);
    let sender_config = UpdateSenderConfig {
        max_batch_tiles: options.batch_tiles.max(1),
        window: options.window.max(1),
    };

    let work = tempfile::tempdir().context("creating a temporary directory")?;
    if choice == StoreChoice::PrivatePostgres {
        deog_harness::eprintln_above_bars!(
            "starting a private PostgreSQL (fsync and synchronous_commit on) ..."
        );
    }
    let store = StoreUnderTest::open(&choice, work.path())?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(store.check_fresh())?;

    // The baseline, each (servers, clients) throughput run and the memory
    // test, each timed apart.
    let progress = Progress::new(
        "map server measurements",
        "steps",
        1 + (options.servers.len() * options.clients.len()) as u64 + u64::from(options.cells > 0),
    );
    let baseline = match store.postgres_url() {
        None => {
            deog_harness::eprintln_above_bars!(
                "thesis baseline: Fig. 7.1 mapper on sled for {} s ...",
                options.duration_s
            );
            baseline::thesis_baseline(duration, size, &region)?
        }
        Some(url) => {
            deog_harness::eprintln_above_bars!(
                "thesis baseline: Fig. 7.1 mapper on PostgreSQL for {} s ...",
                options.duration_s
            );
            baseline_postgres::thesis_baseline(url, duration, size, &region)?
        }
    };
    progress.inc(1);

    let result = runtime.block_on(async {
        // Started in their own process groups, the servers do not see a
        // ctrl-c at the terminal: this run ends on it, and the supervisor
        // stops them on the way out.
        let mut shutdown = std::pin::pin!(deog_harness::shutdown_signal());
        tokio::select! {
            () = &mut shutdown => bail!("interrupted: the map servers were stopped"),
            measured = measure(&options, &store, work.path(), size, &region, sender_config, &progress) => measured,
        }
    });
    let (throughput, memory) = result?;
    progress.finish();
    drop(store);

    let figures = MapServerFigures {
        options: &options,
        store: choice.label(),
        baseline,
        throughput,
        memory,
    };
    deog_harness::print_above_bars!("{}", figures.table());
    if let Some(path) = &options.out {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
    }
    Ok(())
}

/// The measurements: for each `--servers` count, that many servers
/// started on the store and throughput for each client count; then, on
/// the last set of servers and unless `--cells` is 0, the memory test on
/// the first of them.
async fn measure(
    options: &MapServerOptions,
    store: &StoreUnderTest,
    work: &Path,
    size: TileSize,
    region: &[TileKey],
    sender_config: UpdateSenderConfig,
    progress: &Progress,
) -> Result<(Vec<throughput::ThroughputRun>, Option<memory::MemoryRun>)> {
    let duration = Duration::from_secs(options.duration_s);
    let mut runs = Vec::new();
    let mut memory = None;
    for (index, &count) in options.servers.iter().enumerate() {
        // Each set logs into a folder of its own, `servers-N/server-I.log`.
        let logs = work.join(format!("servers-{count}"));
        let mut children = Supervisor::new(&logs)?;
        let measured = async {
            let servers = start_servers(&mut children, store, count, options.cache_mb).await?;
            for &clients in &options.clients {
                deog_harness::eprintln_above_bars!(
                    "durable throughput: {count} server(s), {clients} client(s) for {} s ...",
                    options.duration_s
                );
                let run = throughput::durable_throughput(
                    &servers,
                    store,
                    clients,
                    options.maps,
                    duration,
                    size,
                    region,
                    sender_config,
                )
                .await?;
                runs.push(run);
                progress.inc(1);
            }
            if index + 1 == options.servers.len() && options.cells > 0 {
                deog_harness::eprintln_above_bars!(
                    "memory: growing a map to {} cells through 4 clients of the first server ...",
                    options.cells
                );
                memory = Some(
                    memory::memory_growth(&servers[0], store, options.cells, size, sender_config)
                        .await?,
                );
                progress.inc(1);
            }
            anyhow::Ok(())
        }
        .await;
        if measured.is_err() {
            for i in 1..=count {
                let log = logs.join(format!("server-{i}.log"));
                deog_harness::eprintln_above_bars!(
                    "last lines of server {i}'s log ({}):",
                    log.display()
                );
                deog_harness::eprint_above_bars!("{}", log_tail(&log, 20));
            }
        }
        // Stops this set before the next starts.
        drop(children);
        measured?;
    }
    Ok((runs, memory))
}

/// Starts `count` servers on `store`, `server-1` … `server-N`, and waits
/// until each answers.
async fn start_servers(
    children: &mut Supervisor,
    store: &StoreUnderTest,
    count: usize,
    cache_mb: u64,
) -> Result<Vec<ServerUnderTest>> {
    let mut servers = Vec::with_capacity(count);
    for i in 1..=count {
        let name = format!("server-{i}");
        let addr = free_loopback_addr()?;
        let args: Vec<_> = os(&["server", "--listen", &addr.to_string()])
            .into_iter()
            .chain(store.server_args(cache_mb))
            .collect();
        children.start_with_env(&name, Role::Service, &args, &store.server_env())?;
        let server = ServerUnderTest {
            url: format!("http://{addr}"),
            pid: children
                .pid(&name)
                .with_context(|| format!("map server {i} has no process id"))?,
        };
        connect(children, "map server", || {
            MapClient::connect(ClientConfig::new(server.url.clone()))
        })
        .await?;
        deog_harness::eprintln_above_bars!("map server {i}: pid {}, {}", server.pid, server.url);
        servers.push(server);
    }
    Ok(servers)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: MapServerOptions,
    }

    fn parse(args: &[&str]) -> MapServerOptions {
        Cli::try_parse_from(std::iter::once("map-server").chain(args.iter().copied()))
            .expect("options parse")
            .options
    }

    #[test]
    fn the_defaults_are_valid() {
        let options = parse(&[]);
        assert_eq!(options.clients, [1, 4]);
        assert_eq!(options.store, "sled");
        assert_eq!(options.servers, [1]);
        assert_eq!(options.validate(), Ok(()));
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        for (flag, args) in [
            ("--duration-s", &["--duration-s", "0"][..]),
            ("--clients", &["--clients", "1,0"][..]),
            ("--region-tiles", &["--region-tiles", "0"][..]),
            ("--store", &["--store", "mysql://db/maps"][..]),
            ("--servers", &["--servers", "0"][..]),
        ] {
            let err = parse(args).validate().expect_err(flag);
            assert_eq!(err.flag, flag);
            assert!(err.to_string().starts_with(flag), "{err}");
        }
    }

    #[test]
    fn several_servers_on_sled_are_refused() {
        let err = parse(&["--servers", "1,2"])
            .validate()
            .expect_err("sled, 2 servers");
        assert_eq!(err.flag, "--servers");
        assert!(err.to_string().contains("sled"), "{err}");
        let options = parse(&["--store", "postgres", "--servers", "1,2"]);
        assert_eq!(options.servers, [1, 2]);
        assert_eq!(options.validate(), Ok(()));
        let options = parse(&["--store", "postgres://deog@db/maps", "--servers", "2"]);
        assert_eq!(options.validate(), Ok(()));
    }
}
