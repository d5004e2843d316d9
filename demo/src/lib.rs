//! `deog demo`: the whole system, each part its own OS process started
//! from the `deog` executable. A map server on a fresh sled folder, the
//! simulator, and per robot a wanderer and a cartographer building one
//! shared map; once the map has a head start, a localizer per robot that
//! knows nothing of where its robot is; half-way through, the first robot
//! is kidnapped. When the wanderers end, the demo waits for the
//! cartographers and localizers to drain their frames, judges the map and
//! the estimates with the same code as `deog eval` (deog-evaluation), and
//! writes everything to `--out`.
//!
//! This is orchestration, used by the binary's `demo` subcommand and by
//! nothing else: like the binary and deog-harness, it reports errors as
//! `anyhow` chains with the context a person at the terminal needs.
//!
//! # Layout
//! - `options`: [`DemoOptions`], the command-line flags, and the checks of
//!   the times they give.
//! - `plan`: what will run, decided before anything starts: the world, the
//!   robots and their seeds, the times, the output folder.
//! - `commands`: the `deog` command line of each process, and the name of
//!   the shared map.
//! - `run`: [`run`], the processes started through
//!   `deog_harness::Supervisor`, the driving and draining loops, then the
//!   judging and the reports.
//! - `pacer`: the loops' quarter-second tick and the ctrl-c/SIGTERM that
//!   ends them.
//! - `coverage`: the share of the world's reachable free space the map
//!   has seen, sampled every 10 simulated seconds, and the times to 95%
//!   and 99%.
//! - `kidnap`: carrying the first robot off without its odometry noticing.
//! - `status_line`: the line on stderr rewritten in place, and notes above
//!   it.
//! - `progress`: what that line says: time, frames, cells, each robot's
//!   error.
//! - `judge`: the run read back with `deog_harness::run_reads` and judged
//!   with `deog_evaluation`; the map files and the pictures written.
//! - `report`: report.json from [`DemoReport`], and the writing of both
//!   reports.
//! - `markdown`: report.md and the summary printed at the end.
//! - `fixtures` (tests only): options, a plan and a judged run made
//!   without any process.

mod commands;
mod coverage;
#[cfg(test)]
mod fixtures;
mod judge;
mod kidnap;
mod markdown;
mod options;
mod pacer;
mod plan;
mod progress;
mod report;
mod run;
mod status_line;

pub use coverage::CoverageSample;
pub use options::{DemoOptions, ExplorePose};
pub use report::{DemoKidnapRecord, DemoReport};
pub use run::run;
