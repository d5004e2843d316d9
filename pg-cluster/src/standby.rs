//! A streaming standby of a running server, and its promotion.
//!
//! The standby is a [`LocalCluster`] of its own (its own folder, port and
//! watchdog), made with `pg_basebackup -R` from the primary instead of
//! `initdb`, so it is stopped and cleaned up as any cluster is. The
//! primary needs nothing special: PostgreSQL's defaults (`wal_level =
//! replica`, ten WAL senders) and `initdb --auth=trust` (which trusts
//! replication connections from 127.0.0.1) already allow it.

use std::sync::atomic::{AtomicU32, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use crate::binaries::tool;
use crate::cluster::{POLL, READY_TIMEOUT, USER};
use crate::process;
use crate::{ClusterError, LocalCluster};

/// How long a promotion may take (`pg_promote`'s own wait).
const PROMOTE_TIMEOUT: Duration = Duration::from_secs(60);

/// Tells this process's standbys apart in `pg_stat_replication`.
static STANDBYS: AtomicU32 = AtomicU32::new(0);

/// Whether the primary waits for the standby before a commit returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replication {
    /// Commits return once the primary has flushed them; the standby
    /// follows a little behind, and a failover may lose the last commits.
    Asynchronous,
    /// The standby is the primary's synchronous standby: with the
    /// primary's `synchronous_commit` on (the default), a commit returns
    /// only once the standby has flushed it too, so a failover loses no
    /// commit that returned. While the standby is down, the primary's
    /// commits wait.
    Synchronous,
}

impl LocalCluster {
    /// Starts a streaming standby of this server: `pg_basebackup -R -X
    /// stream` into a fresh temporary folder, then `postgres` on a free
    /// port with this server's [`crate::ClusterOptions`] (but not its
    /// port); waits until the primary reports it `streaming` (and, for
    /// [`Replication::Synchronous`], `sync`, after making it the
    /// primary's `synchronous_standby_names` with `ALTER SYSTEM`).
    ///
    /// The standby takes read-only connections (hot standby) until
    /// [`LocalCluster::promote`]. Databases created on the primary, before
    /// or after, appear on it.
    pub fn start_standby(&self, replication: Replication) -> Result<LocalCluster, ClusterError> {
        let started = Instant::now();
        let name = format!(
            "deog_standby_{}_{}",
            std::process::id(),
            STANDBYS.fetch_add(1, Ordering::Relaxed)
        );
        let mut options = self.options.clone();
        options.port = None;
        let mut standby = LocalCluster::prepare(&options)?;
        standby.base_backup(self.port, &name)?;
        standby.launch(None)?;
        self.await_standby(&name, "streaming", &standby)?;
        if replication == Replication::Synchronous {
            self.psql(
                "postgres",
                &format!("ALTER SYSTEM SET synchronous_standby_names = '\"{name}\"'"),
            )?;
            self.psql("postgres", "SELECT pg_reload_conf()")?;
            self.await_standby(&name, "sync", &standby)?;
        }
        tracing::debug!(
            primary = self.port,
            port = standby.port,
            ?replication,
            elapsed_ms = started.elapsed().as_millis(),
            "PostgreSQL standby streaming"
        );
        Ok(standby)
    }

    /// Promotes this standby to a primary (`SELECT pg_promote()`) and
    /// waits until it takes writes. It keeps its port. The old primary, if
    /// it still runs, is not told: stop or kill it first, as a failover
    /// does. The promoted server has no synchronous standby of its own, so
    /// its commits do not wait.
    pub fn promote(&self) -> Result<(), ClusterError> {
        let promoted = self.psql(
            "postgres",
            &format!("SELECT pg_promote(true, {})", PROMOTE_TIMEOUT.as_secs()),
        )?;
        if promoted != "t" || self.psql("postgres", "SELECT pg_is_in_recovery()")? != "f" {
            return Err(ClusterError::NotReady {
                reason: format!("the standby on port {} was not promoted", self.port),
                log_tail: self.log_tail(),
            });
        }
        Ok(())
    }

    /// Whether this server is a standby (in recovery) rather than a
    /// primary.
    pub fn is_standby(&self) -> Result<bool, ClusterError> {
        Ok(self.psql("postgres", "SELECT pg_is_in_recovery()")? == "t")
    }

    /// Copies the primary on `primary_port` into the (not yet existing)
    /// data folder, with `standby.signal` and a `primary_conninfo` that
    /// names the standby `name`.
    fn base_backup(&self, primary_port: u16, name: &str) -> Result<(), ClusterError> {
        let mut command = self.runner.server(&tool(&self.bin_dir, "pg_basebackup"));
        command
            .arg("-d")
            .arg(format!(
                "host=127.0.0.1 port={primary_port} user={USER} application_name={name}"
            ))
            .arg("-D")
            .arg(&self.data_dir)
            .args(["-R", "-X", "stream", "--checkpoint=fast"])
            // The folder is thrown away, as initdb's is.
            .arg("--no-sync")
            .current_dir(&self.root);
        process::run(&mut command).map(drop)
    }

    /// Waits until `pg_stat_replication` on this server shows the standby
    /// `name` with `state` (`streaming`) or `sync_state` (`sync`).
    fn await_standby(
        &self,
        name: &str,
        wanted: &str,
        standby: &LocalCluster,
    ) -> Result<(), ClusterError> {
        let sql = format!(
            "SELECT state || ' ' || sync_state FROM pg_stat_replication \
             WHERE application_name = '{name}'"
        );
        let deadline = Instant::now() + READY_TIMEOUT;
        let mut seen = String::new();
        loop {
            seen = self.psql("postgres", &sql).unwrap_or(seen);
            if seen.split_whitespace().any(|word| word == wanted) {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(ClusterError::NotReady {
                    reason: format!(
                        "the standby on port {} is not {wanted} after {READY_TIMEOUT:?} \
                         (pg_stat_replication says {seen:?})",
                        standby.port
                    ),
                    log_tail: standby.log_tail(),
                });
            }
            thread::sleep(POLL);
        }
    }
}
