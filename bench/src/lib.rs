//! deog's release benchmarks, one module a benchmark, each the library
//! half of a `deog bench` subcommand: its options (clap-derived, so the
//! binary only parses them and calls [`map_server::run`],
//! [`localize::run`], [`localize_peers::run`], [`localize_memory::run`],
//! [`laser_mapping::run`] or [`real::run`]), their checks, the run, and the figures it prints and
//! writes. What each measures, and the figures of record, are in
//! BENCHMARKS.md.
//!
//! This is orchestration, used by the binary and by nothing else: like
//! deog-harness, whose processes and `/proc` sampling it uses, it reports
//! run errors as `anyhow` chains with the context a person at the
//! terminal needs. Bad options are an [`OptionError`] naming the flag.
//!
//! # Layout
//! - [`map_server`]: `deog bench map-server`, the map server as a child
//!   process: durable throughput from concurrent clients, the thesis's
//!   mapper on the same store engine as the baseline, and the server's
//!   memory while a map grows.
//! - [`localize`]: `deog bench localize`, localization accuracy over
//!   seeded runs per world, in one process: global convergence, error
//!   after convergence, kidnap recovery.
//! - [`localize_peers`]: `deog bench localize-peers`, deog's localizer
//!   beside nav2's amcl (`bench/localize_peers_amcl.py`, a child Python
//!   process) on the same sonar frames and sonar-built map: CPU per
//!   update, particle-beams per second, accuracy and time to settle.
//! - [`localize_memory`]: `deog bench localize-memory`, the localizer's
//!   memory against its cache setting, with the real processes, on a
//!   generated city far larger than the cache.
//! - [`laser_mapping`]: `deog bench laser-mapping`, deog's laser mapping
//!   beside OctoMap's on the same scans of a real CARMEN log: scans and
//!   cell updates per second on each side, their ratio, and how alike the
//!   two final maps are. OctoMap runs in `bench/octomap_insert.py`, a child
//!   Python process.
//! - [`sonar_mapping`]: `deog bench sonar-mapping`, deog's sonar mapping
//!   methods and OctoMap (one ray per echo, `bench/octomap_insert.py`) on
//!   the same simulated frames: frames and cell updates per second, each
//!   map judged against the world.
//! - [`real`]: `deog bench real`, the whole real-data recipe on one CARMEN
//!   log with the real processes: the reference map from the log's
//!   reference poses, tracking over the whole log and seeded global
//!   starts, judged against the reference poses.
//! - `octomap`: OctoMap as a peer (laser-mapping's and sonar-mapping's):
//!   `bench/octomap_insert.py` as a child process, the point-cloud file it
//!   reads and the cell file it writes.
//! - `python_script`: a peer's side as a child Python process (OctoMap's,
//!   amcl's): the built-in script written out, probed, run.
//! - [`fuzz`]: `deog bench fuzz`, every decoder of outside input (tile
//!   cells, the servers' wire requests, rig, map, world, data and log
//!   files) fed seeded mutated bytes for a fixed time: execs, crashes and
//!   hangs, crashing inputs saved.
//! - [`view`]: `deog bench view`, the live view under load in a real
//!   headless Chromium: frames per second idle (the baseline) and with
//!   robots driving, tile latency from acknowledgement to page, the view
//!   process's memory and CPU.
//! - [`explore`]: `deog bench explore`, wanderers and explorers side by
//!   side on the same world, seeds and robot counts, each run a whole
//!   `deog demo` child process read back from its report.json: time to
//!   95% and 99% coverage, the map right, bumps.
//! - [`option_error`]: [`OptionError`], an option out of its range or
//!   options that do not go together.

pub mod explore;
pub mod fuzz;
pub mod laser_mapping;
pub mod localize;
pub mod localize_memory;
pub mod localize_peers;
pub mod map_server;
mod octomap;

pub mod option_error;
mod python_script;
pub mod real;
pub mod sonar_mapping;
pub mod view;

pub use option_error::OptionError;
