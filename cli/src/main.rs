//! `deog`: every process of the system as a subcommand.

mod bench;
mod completions;
mod connection;
mod copy;
mod demo;
mod eval;
mod explore;
mod export;
mod frame_queue;
mod frames;
mod import;
mod localize;
mod map;
mod pose_args;
mod record;
mod refit;
mod rig_args;
mod server;
mod sim;
mod status;
mod store_location;
mod teleport;
mod view;
mod wander;

use std::io::IsTerminal;

use anyhow::Result;
use clap::{CommandFactory, Parser, Subcommand};
use tracing_subscriber::EnvFilter;

/// deog: a shared, dynamically expanding occupancy-grid map for robots with
/// sonars or lasers.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    /// Show no progress bars or progress log lines for long work (import,
    /// export, copy, replays, benchmarks).
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The whole system at once, each part its own process: a map server, the
    /// simulator, and per robot a wanderer, a cartographer and a localizer
    /// that starts knowing nothing; one robot is kidnapped half-way. Writes
    /// the map, path plots and a report to demo-out/.
    Demo(demo::DemoOptions),
    /// Runs the map server: maps, frames and poses in an embedded store,
    /// served over gRPC.
    Server(server::ServerArgs),
    /// Runs the simulator: a world and its robots (Scouts, or any rig),
    /// driven over gRPC.
    Sim(sim::SimArgs),
    /// Drives one simulated robot about at random and publishes its frames
    /// to the map server.
    Wander(wander::WanderArgs),
    /// Drives one simulated robot to the frontiers of the shared map (the
    /// edge of what has been seen) as it grows, publishing its frames;
    /// stops by itself once no reachable frontier is left.
    Explore(explore::ExploreArgs),
    /// Lists the robots whose frames the map server holds, or prints one
    /// robot's frames (--follow: as they arrive).
    Frames(frames::FramesArgs),
    /// The cartographer: follows a robot's frames and builds a map on the
    /// server from them.
    Map(map::MapArgs),
    /// The localizer: follows a robot's frames and estimates its pose on a
    /// map held by the server (Monte Carlo Localization), publishing each
    /// estimate.
    Localize(localize::LocalizeArgs),
    /// Carries a simulated robot to another pose without telling its
    /// odometry: the kidnapped-robot test.
    Teleport(teleport::TeleportArgs),
    /// Imports recorded data into the map server: a wanderer data file, a
    /// CARMEN log (--carmen) or a ROS 2 recording (--mcap) as a robot's
    /// frames (--robot), or a map_server map as a map (--map).
    Import(import::ImportArgs),
    /// Records a robot's frames, odometry, true and reference poses, its
    /// localizer's estimates and optionally a map (--map) as a ROS 2
    /// recording in MCAP (--mcap FILE), for ROS 2 and Foxglove tools.
    Record(record::RecordArgs),
    /// Copies maps (tiles, cursors), frames, pose estimates and rigs from
    /// one store to another, resumably, checking each map at the end
    Copy(copy::CopyArgs),
    /// Exports a map, even one still being built, to map_server files
    /// (PGM + YAML) and a PNG.
    Export(export::ExportArgs),
    /// Refits a map to every sonar frame that built it at once, through
    /// the specular sonar's forward model, and writes the result as
    /// map_server files (PGM + YAML) and a PNG; the map on the server
    /// stays as it is.
    Refit(refit::RefitArgs),
    /// Evaluation reports: `eval map` judges a map on the server against
    /// a world's ground truth.
    Eval(eval::EvalArgs),
    /// Runs the release benchmarks: the map server, localization accuracy,
    /// the localizer's memory.
    Bench(bench::BenchArgs),
    /// What a running system is doing: the map server's health, its maps,
    /// the robots' frames and the localizers' estimates, with rates over
    /// an interval (--watch: redrawn until ctrl-c).
    Status(status::StatusArgs),
    /// Serves a live web page of the running system: the map as it grows,
    /// each robot's true pose, frame and path, each localizer's estimate
    /// with its covariance, and kidnaps as they happen.
    View(view::ViewArgs),
    /// Prints the shell completion script for bash, zsh or fish (and
    /// elvish, powershell).
    Completions(completions::CompletionsArgs),
    /// Writes man pages for deog and every subcommand into a folder.
    Man(completions::ManArgs),
}

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_writer(deog_harness::progress::stderr_writer)
        // Colour only on a terminal: logs written to files stay plain text.
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    let cli = Cli::parse();
    deog_harness::progress::set_quiet(cli.quiet);
    match run(cli.command) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            // The chain of causes on one line, without a backtrace: this is
            // for the person at the terminal.
            let text = format!("{error:#}");
            match connection::hint_for(&text) {
                Some(hint) => eprintln!("error: {text} ({hint})"),
                None => eprintln!("error: {text}"),
            }
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Demo(options) => demo::run(options),
        Command::Server(args) => server::run(args),
        Command::Sim(args) => sim::run(args),
        Command::Wander(args) => wander::run(args),
        Command::Import(args) => import::run(args),
        Command::Record(args) => record::run(args),
        Command::Copy(args) => copy::run(args),
        Command::Export(args) => export::run(args),
        Command::Refit(args) => refit::run(args),
        Command::Map(args) => map::run(args),
        Command::Localize(args) => localize::run(args),
        Command::Teleport(args) => teleport::run(args),
        Command::Frames(args) => frames::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Status(args) => status::run(args),
        Command::Explore(args) => explore::run(args),
        Command::View(args) => view::run(args),
        Command::Completions(args) => completions::print_completions(args, Cli::command()),
        Command::Man(args) => completions::write_man_pages(args, Cli::command()),
    }
}
