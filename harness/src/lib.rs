//! Running deog's processes from outside, as `deog demo` and the
//! benchmarks do, and reading a run back from the map server to judge it,
//! as they and `deog eval` do.
//!
//! This is orchestration, used by the binary's subcommands and by nothing
//! else: like the binary, it reports errors as `anyhow` chains with the
//! context a person at the terminal needs.
//!
//! # Layout
//! - [`supervisor`]: [`Supervisor`], child processes of the `deog`
//!   executable, each in its own process group with its own log, watched
//!   for failure and stopped on any exit; [`connect`] waits for a child's
//!   service.
//! - [`browser`]: [`browser::Browser`], a headless Chromium driven
//!   through ChromeDriver (open a page, run a script, screenshot), for the
//!   view's test and benchmark.
//! - [`proc_stats`]: a process's memory and CPU time from `/proc`.
//! - [`run_reads`]: a map, the robots' start poses, and a robot's true
//!   poses and estimates read from the map server, as the evaluation takes
//!   them.
//! - [`status`]: what a running system is doing, from two samples of
//!   the map server: the rows and table `deog status` prints.
//! - [`progress`]: [`Progress`], long work shown as a bar with its rate
//!   and time left on a terminal, as log lines every few seconds
//!   elsewhere, as nothing under `--quiet`.
//! - [`shutdown`]: [`shutdown_signal`], ctrl-c or SIGTERM, on which a run
//!   stops its children and a long-running subcommand ends.

pub mod browser;
pub mod proc_stats;
pub mod progress;
pub mod redact;
pub mod run_reads;
pub mod shutdown;
pub mod status;
pub mod supervisor;

pub use progress::Progress;
pub use shutdown::{ExitOnSignal, shutdown_signal};
pub use supervisor::{
    Role, Supervisor, connect, free_loopback_addr, log_tail, os, prepare_run_folder,
};
