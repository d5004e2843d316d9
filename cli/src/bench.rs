//! `deog bench`: the release benchmarks, each in deog-bench; this only
//! names the subcommands.

use anyhow::Result;
use clap::{Args, Subcommand};
use deog_bench::fuzz::FuzzOptions;
use deog_bench::laser_mapping::LaserMappingOptions;
use deog_bench::localize::LocalizeOptions;
use deog_bench::localize_memory::LocalizeMemoryOptions;
use deog_bench::localize_peers::LocalizePeersOptions;
use deog_bench::map_server::MapServerOptions;
use deog_bench::real::RealOptions;
use deog_bench::sonar_mapping::SonarMappingOptions;

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
    MapServer(MapServerOptions),
    /// Localization accuracy over seeded runs per world, in one process:
    /// global convergence, error after convergence, kidnap recovery.
    Localize(LocalizeOptions),
    /// deog's localizer beside nav2's amcl (a Python child process) on the
    /// same sonar frames and map: CPU per update, particle-beams/s,
    /// accuracy and time to settle.
    LocalizePeers(LocalizePeersOptions),
    /// The localizer's memory against its cache setting, with the real
    /// processes, on a generated city map at least 100 times the cache.
    LocalizeMemory(LocalizeMemoryOptions),
    /// deog's laser mapping beside OctoMap's (a Python child process) on
    /// the same scans of a real CARMEN log: scans/s, cell updates/s, their
    /// ratio and how alike the two maps come out.
    LaserMapping(LaserMappingOptions),
    /// The real-data recipe on one CARMEN log, with the real processes:
    /// the reference map, tracking over the whole log and seeded global
    /// starts, judged against the log's reference poses.
    Real(RealOptions),
    /// The sonar mapping methods side by side (the thesis's model, cones
    /// that stop at known walls, evidence by direction, and OctoMap as a
    /// Python child process, one ray per echo) on the same simulated
    /// readings: frames/s, cell updates/s, each map judged against the
    /// world.
    SonarMapping(SonarMappingOptions),
    /// Every decoder of outside input (tile cells, the servers' wire
    /// requests, rig, map, world, data and log files) fed seeded mutated
    /// bytes for a fixed time per target: execs, crashes, hangs. Fails if
    /// any input panicked; those inputs are saved.
    Fuzz(FuzzOptions),
    /// The live view under load in a headless Chromium: the page's frames
    /// per second idle and with robots driving, how soon a tile reaches
    /// the page after its acknowledgement, the view's memory and CPU.
    View(deog_bench::view::ViewBenchOptions),
    /// Wanderers and explorers on the same world, seeds and robot counts,
    /// side by side (each run a whole `deog demo` without localizers):
    /// simulated time to 95% and 99% of the reachable free space, the map
    /// right, bumps, and whether the robots stopped by themselves.
    Explore(deog_bench::explore::ExploreBenchOptions),
}

/// Runs `deog bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    match args.target {
        BenchTarget::MapServer(options) => deog_bench::map_server::run(options),
        BenchTarget::Localize(options) => deog_bench::localize::run(options),
        BenchTarget::LocalizePeers(options) => deog_bench::localize_peers::run(options),
        BenchTarget::LocalizeMemory(options) => deog_bench::localize_memory::run(options),
        BenchTarget::LaserMapping(options) => deog_bench::laser_mapping::run(options),
        BenchTarget::Real(options) => deog_bench::real::run(options),
        BenchTarget::SonarMapping(options) => deog_bench::sonar_mapping::run(options),
        BenchTarget::Fuzz(options) => deog_bench::fuzz::run(options),
        BenchTarget::View(options) => deog_bench::view::run(options),
        BenchTarget::Explore(options) => deog_bench::explore::run(options),
    }
}
