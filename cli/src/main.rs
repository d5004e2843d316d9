//! `deog`: every process of the system as a subcommand.

mod bench;
mod demo;
mod server;
mod signal;

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

/// deog: a shared, dynamically expanding occupancy-grid map for sonar robots.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Maps the embedded default room in-process with the grid core and
    /// writes the map and a quality summary.
    Demo(demo::DemoArgs),
    /// Runs the map server: maps, frames and poses in an embedded store,
    /// served over gRPC.
    Server(server::ServerArgs),
    /// Runs the release benchmarks of the map server.
    Bench(bench::BenchArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Demo(args) => demo::run(args),
        Command::Server(args) => server::run(args),
        Command::Bench(args) => bench::run(args),
    }
}
