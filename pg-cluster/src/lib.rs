//! A private, throwaway PostgreSQL server for tests, benchmarks and demos.
//!
//! [`LocalCluster::start`] finds the server binaries, runs `initdb` into a
//! fresh temporary folder (or copies the data folder a first `initdb` of
//! the same binaries left in the system's temporary folder as
//! `deog-pg-template-...`), starts `postgres` on a free loopback port with
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
//! # Standbys and failover
//! [`LocalCluster::start_standby`] makes a streaming standby of a running
//! server (`pg_basebackup -R -X stream`, then `postgres` on a port of its
//! own) and waits until the primary reports it streaming. The standby is a
//! [`LocalCluster`] like any other, with its own folder and watchdog, so it
//! is cleaned up the same way. With [`Replication::Synchronous`] it becomes
//! the primary's synchronous standby: a commit returns only once the
//! standby has it, so killing the primary ([`LocalCluster::kill`]) and
//! promoting the standby ([`LocalCluster::promote`]) loses no commit that
//! returned. Clients that list both ports
//! (`postgres://deog@127.0.0.1:P1,127.0.0.1:P2/db?target_session_attrs=read-write`)
//! find the writable one.
//!
//! ```
//! use deog_pg_cluster::{LocalCluster, Replication};
//!
//! let mut primary = LocalCluster::start()?;
//! let standby = primary.start_standby(Replication::Synchronous)?;
//! primary.create_database("maps")?;
//! primary.kill()?;
//! standby.promote()?;
//! assert!(!standby.is_standby()?);
//! # Ok::<(), deog_pg_cluster::ClusterError>(())
//! ```
//!
//! # Layout
//! - [`cluster`]: [`LocalCluster`], one server's life: init, start, stop,
//!   kill, restart, and its `psql` helpers.
//! - [`options`]: [`ClusterOptions`], the settings a server starts with.
//! - [`standby`]: a streaming standby of a server ([`Replication`]), and
//!   its promotion.
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
pub mod standby;
mod template;
mod watchdog;

pub use binaries::binaries;
pub use cluster::LocalCluster;
pub use error::ClusterError;
pub use options::ClusterOptions;
pub use standby::Replication;
