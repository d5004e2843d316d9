//! `deog bench localize-memory`: whether the localizer's memory stays
//! within its cache setting on a map far larger than the cache.
//!
//! Every part is a real process of this binary, as in `deog demo`: a map
//! server on a fresh data folder, `deog import` putting a generated city
//! (`deog_world::city`: solid blocks 6 to 12 m a side between streets 2.5
//! to 3 m wide, inside an outer wall) on it, the simulator running the
//! same city, one wanderer driving a robot from a street crossing near
//! the middle, and `deog localize`
//! tracking that robot from its known start pose with a small
//! `--cache-mb`. The map is sized so that holding all of it in the
//! localizer (each tile's cells and its expected-range table, ~1 MB a
//! tile) would take at least `--min-ratio` times the cache; as the robot
//! drives on, the localizer keeps needing tiles it has not got, and the
//! cache must evict.
//!
//! Measured: the localizer's resident set every 100 ms and its `VmHWM`
//! (the peak, read until it exits); its baseline, the resident set once
//! it has started and built the tables of its first tiles; its resident
//! set less the cache size it logs every 100 frames (what it holds beyond
//! the cache); the tiles the robot's true path crossed; the range tables
//! built and the final cache size from the localizer's last line; and the
//! tracking error, estimate by estimate and as `deog eval localize`
//! judges it.
//!
//! Its parts: `plan` ([`CityPlan`]: the options checked, the city sized),
//! `processes` (the city written and the processes started), `run` (the
//! run watched and judged), `sampling` (the localizer's memory from
//! `/proc`, its baseline, its resident set beyond the cache), `log` (the
//! localizer's log read), `server_reads` (the filter's figures and the
//! robot's path from the server), `figures` (everything measured),
//! `table` and `record` (the figures printed, and as the JSON
//! `--out-json` writes).

mod figures;
mod log;
mod plan;
mod processes;
mod record;
mod run;
mod sampling;
mod server_reads;
mod table;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Args;

use crate::option_error::require_folder_of;

pub use plan::CityPlan;

/// The map's name on the server.
const MAP: &str = "bench";
/// The one robot.
const ROBOT: &str = "scout-1";
/// Cells per tile side: the server's default, which `deog import` uses.
const TILE_SIDE: u32 = 64;
/// How often the localizer's memory is read.
const SAMPLE_EVERY: Duration = Duration::from_millis(100);

/// Options of `deog bench localize-memory`.
#[derive(Debug, Clone, Args)]
pub struct LocalizeMemoryOptions {
    /// The localizer's cache budget, MiB (its --cache-mb; 16 or more).
    #[arg(long, default_value_t = 16)]
    pub cache_mb: usize,
    /// The localizer's most particles (its --max-particles). The filter's
    /// memory grows with it, apart from the cache: about 0.2 KiB a
    /// particle when a drop in the fit spreads them out.
    #[arg(long, default_value_t = 10_000)]
    pub max_particles: usize,
    /// Side of the square city, metres. Default: the smallest whole number
    /// of tiles a side whose map, held whole in the localizer, is
    /// --min-ratio times the cache budget.
    #[arg(long)]
    pub side_m: Option<f64>,
    /// Least ratio of the map's size in the localizer's representation
    /// (tiles × the bytes of a tile and its range table) to the cache
    /// budget; a smaller map is refused.
    #[arg(long, default_value_t = 100.0)]
    pub min_ratio: f64,
    /// Simulated seconds the robot drives.
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// Simulated seconds per wall-clock second. The localizer must keep
    /// up: every tile the robot reaches costs it a range-table build
    /// (about 0.25 s on one core), and a cache this small rebuilds the
    /// tables of tiles the robot comes back to.
    #[arg(long, default_value_t = 2.0)]
    pub speed: f64,
    /// The robot's cruising speed, m/s (the Scout tops out at 1).
    #[arg(long, default_value_t = 0.8)]
    pub robot_speed: f64,
    /// The robot's rig (the simulator's and the wanderer's --rig; the
    /// localizer reads it from the frames): a built-in name or a rig file.
    /// The city is sized by the beam model's tables all the same, so with a
    /// laser rig (a likelihood field, far smaller per tile) the map is even
    /// larger beside the budget than the ratio says.
    #[arg(long, default_value = "scout")]
    pub rig: String,
    /// Seed of the city's layout, the simulator, the wanderer and the
    /// localizer.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Work folder, kept: the city's map files, the server's data and the
    /// processes' logs (its earlier server data and logs are replaced).
    /// Default: a temporary folder, removed after a successful run.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub out_json: Option<PathBuf>,
}

impl LocalizeMemoryOptions {
    /// Checks the options a run cannot start with, the city they make
    /// included (see [`CityPlan::new`]).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        CityPlan::new(self).map(drop)
    }
}

/// Runs `deog bench localize-memory`: prints the figures as a table, and
/// writes them as JSON to `--out-json` if given.
pub fn run(options: LocalizeMemoryOptions) -> Result<()> {
    let plan = CityPlan::new(&options)?;
    // A JSON file that cannot be written fails now, not after the run.
    require_folder_of(options.out_json.as_deref(), "--out-json")?;
    let (work, temporary) = match &options.out {
        Some(dir) => {
            deog_harness::prepare_run_folder(dir)?;
            (dir.clone(), None)
        }
        None => {
            let dir = tempfile::Builder::new()
                .prefix("deog-localize-memory-")
                .tempdir()
                .context("creating a temporary work folder")?;
            (dir.path().to_path_buf(), Some(dir))
        }
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let result = runtime.block_on(run::bench(&options, &plan, &work));
    let figures = match result {
        Ok(figures) => figures,
        Err(error) => {
            // The logs say why: keep them.
            if let Some(dir) = temporary {
                let kept = dir.keep();
                deog_harness::eprintln_above_bars!(
                    "the work folder is kept for its logs: {}",
                    kept.display()
                );
            }
            return Err(error);
        }
    };
    deog_harness::print_above_bars!("{}", figures.table());
    if figures.gave_up.is_some()
        && let Some(dir) = temporary
    {
        let kept = dir.keep();
        deog_harness::eprintln_above_bars!(
            "the work folder is kept for the localizer's log and the server's data: {}",
            kept.display()
        );
    }
    if let Some(path) = &options.out_json {
        std::fs::write(path, figures.json()?)
            .with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
    }
    Ok(())
}
