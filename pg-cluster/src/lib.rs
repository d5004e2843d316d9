//! A private, throwaway PostgreSQL server for tests, benchmarks and demos.
//!
//! [`LocalCluster::start`] finds the server binaries, runs `initdb` into a
//! fresh temporary folder, starts `postgres` on a free loopback port with
//! trust authentication for the user `deog`, and waits until it accepts
//! connections. Nothing depends on a server that is already running.
//!
//! The server never outlives the process that started it: a small shell
//! watchdog holds the read end of a pipe whose only writer is this process.
//! When the process ends, however it ends (a destructor that never runs, a
//! `SIGKILL`), the pipe closes and the watchdog stops the server and removes
//! its folder.
//!
//! PostgreSQL refuses to run as root; when this process is root, the server
//! binaries run as the `postgres` user through `runuser`.
//!
//! # Layout
//! - [`cluster`]: [`LocalCluster`], one server's life: init, start, stop,
//!   kill, restart, and its `psql` helpers.
//! - [`options`]: [`ClusterOptions`], the settings a server starts with.
//! - [`mod@binaries`]: where the server binaries are ([`binaries()`]).
//! - `process` (private): running a binary, as `postgres` when root, and
//!   finding and signalling the processes of a data folder.
//! - `watchdog` (private): the shell script that cleans up after a process
//!   that died.
//! - `port` (private): picking a free loopback port.
//! - [`error`]: the crate's one error type.
//!
//! # Example
//! ```
//! use deog_pg_cluster::LocalCluster;
//!
//! let cluster = LocalCluster::start()?;
//! let url = cluster.create_database("maps")?;
//! assert!(url.ends_with("/maps"));
//! assert_eq!(cluster.psql("maps", "SELECT 1")?, "1");
//! # Ok::<(), deog_pg_cluster::ClusterError>(())
//! ```

pub mod binaries;
pub mod cluster;
pub mod error;
pub mod options;
mod port;
mod process;
mod watchdog;

pub use binaries::binaries;
pub use cluster::LocalCluster;
pub use error::ClusterError;
pub use options::ClusterOptions;
