//! `deog bench map-server`: starts the real map server as a child process
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
//!
//! Its parts: `workload` (the region the clients update and the evidence
//! they send), `baseline` (the thesis's mapper on sled), `throughput`,
//! `memory`, `figures` (everything measured, as the table printed) and
//! `record` (the same as the JSON `--out` writes).

mod baseline;
mod figures;
mod memory;
mod record;
mod throughput;
mod workload;

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::{TileKey, TileSize};
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, log_tail, os, proc_stats};
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};

use figures::MapServerFigures;

use crate::option_error::{OptionError, require};
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
        })
    }
}

/// The map server under test: where it serves, and its process for
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
    let duration = Duration::from_secs(options.duration_s);
    let size = TileSize::new(TILE_SIDE)?;
    let region = region_tiles(options.region_tiles);
    let sender_config = UpdateSenderConfig {
        max_batch_tiles: options.batch_tiles.max(1),
        window: options.window.max(1),
    };

    eprintln!(
        "thesis baseline: Fig. 7.1 mapper on sled for {} s ...",
        options.duration_s
    );
    let baseline = baseline::thesis_baseline(duration, size, &region)?;

    let work = tempfile::tempdir().context("creating a temporary directory")?;
    let data = work.path().join("data");
    // The server's log is `server.log` in the work directory.
    let mut children = Supervisor::new(work.path())?;
    let addr = free_loopback_addr()?;
    children.start(
        "server",
        Role::Service,
        &os(&["server", "--listen", &addr.to_string(), "--data"])
            .into_iter()
            .chain([data.clone().into_os_string()])
            .chain(os(&["--cache-mb", &options.cache_mb.to_string()]))
            .collect::<Vec<_>>(),
    )?;
    let server = ServerUnderTest {
        url: format!("http://{addr}"),
        pid: children
            .pid("server")
            .context("the map server has no process id")?,
    };
    eprintln!("map server: pid {}, {}", server.pid, server.url);

    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(async {
        // Started in its own process group, the server does not see a
        // ctrl-c at the terminal: this run ends on it, and the supervisor
        // stops the server on the way out.
        let mut shutdown = std::pin::pin!(deog_harness::shutdown_signal());
        tokio::select! {
            () = &mut shutdown => bail!("interrupted: the map server was stopped"),
            connected = connect(&mut children, "map server", || {
                MapClient::connect(ClientConfig::new(server.url.clone()))
            }) => { connected?; }
        }
        let measured = tokio::select! {
            () = &mut shutdown => bail!("interrupted: the map server was stopped"),
            measured = measure(&options, &server, &data, size, &region, sender_config) => measured,
        };
        if measured.is_err() {
            let log = work.path().join("server.log");
            eprintln!("last lines of the server's log ({}):", log.display());
            eprint!("{}", log_tail(&log, 20));
        }
        measured
    });
    drop(children);
    let (throughput, memory) = result?;

    let figures = MapServerFigures {
        options: &options,
        baseline,
        throughput,
        memory,
    };
    print!("{}", figures.table());
    if let Some(path) = &options.out {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("figures written to {}", path.display());
    }
    Ok(())
}

/// The measurements against the running server: throughput for each
/// client count, then, unless `--cells` is 0, the memory test.
async fn measure(
    options: &MapServerOptions,
    server: &ServerUnderTest,
    data: &Path,
    size: TileSize,
    region: &[TileKey],
    sender_config: UpdateSenderConfig,
) -> Result<(Vec<throughput::ThroughputRun>, Option<memory::MemoryRun>)> {
    let duration = Duration::from_secs(options.duration_s);
    let mut runs = Vec::new();
    for &clients in &options.clients {
        eprintln!(
            "durable throughput: {clients} client(s) for {} s ...",
            options.duration_s
        );
        let run =
            throughput::durable_throughput(server, clients, duration, size, region, sender_config)
                .await?;
        runs.push(run);
    }
    let memory = if options.cells > 0 {
        eprintln!(
            "memory: growing a map to {} cells through 4 clients ...",
            options.cells
        );
        Some(memory::memory_growth(server, data, options.cells, size, sender_config).await?)
    } else {
        None
    };
    Ok((runs, memory))
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
        assert_eq!(options.validate(), Ok(()));
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        for (flag, args) in [
            ("--duration-s", &["--duration-s", "0"][..]),
            ("--clients", &["--clients", "1,0"][..]),
            ("--region-tiles", &["--region-tiles", "0"][..]),
        ] {
            let err = parse(args).validate().expect_err(flag);
            assert_eq!(err.flag, flag);
            assert!(err.to_string().starts_with(flag), "{err}");
        }
    }
}
