//! One server's life: init, start, stop, kill, restart, and its `psql`
//! helpers.

use std::fs::{self, File, OpenOptions};
use std::io::{Read, Seek, SeekFrom};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use tempfile::TempDir;

use crate::binaries::tool;
use crate::error::tail;
use crate::port::free_port;
use crate::process::{self, Runner};
use crate::template;
use crate::watchdog::Watchdog;
use crate::{ClusterError, ClusterOptions, binaries};

/// The role `initdb` creates; it owns everything and needs no password.
pub const USER: &str = "deog";

/// How long a start may take before the server counts as not ready.
pub(crate) const READY_TIMEOUT: Duration = Duration::from_secs(30);
/// How long a fast shutdown may take before the server is killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(30);
/// How long killed processes may take to disappear.
const KILL_TIMEOUT: Duration = Duration::from_secs(10);
/// Between two readiness probes.
pub(crate) const POLL: Duration = Duration::from_millis(50);
/// Starts that fail because a port or shared memory is still taken.
const START_ATTEMPTS: u32 = 3;
/// The server's log, inside the data folder, appended to by every start.
const LOG_FILE: &str = "deog-postgres.log";

/// A private PostgreSQL server in a temporary folder, listening on
/// 127.0.0.1 only, with trust authentication for the user [`USER`].
///
/// Dropping it stops the server and removes the folder; if this process
/// dies first, a watchdog does the same (see the crate documentation).
#[derive(Debug)]
pub struct LocalCluster {
    pub(crate) bin_dir: PathBuf,
    pub(crate) runner: Runner,
    pub(crate) options: ClusterOptions,
    /// The folder holding the data folder and the sockets; canonical, since
    /// the server's working folder is compared with it.
    pub(crate) root: PathBuf,
    pub(crate) data_dir: PathBuf,
    pub(crate) port: u16,
    /// Whether the data folder is a copy of the template, not `initdb`'s.
    from_template: bool,
    /// The running server: the postmaster, or `runuser` above it when root.
    server: Option<Child>,
    watchdog: Watchdog,
    /// Removes the folder if the watchdog did not; dropped last.
    _temp: TempDir,
}

impl LocalCluster {
    /// Finds the binaries, runs `initdb` into a fresh temporary folder,
    /// starts `postgres` on a free 127.0.0.1 port and waits until it
    /// accepts connections; with the default [`ClusterOptions`].
    pub fn start() -> Result<Self, ClusterError> {
        Self::start_with(&ClusterOptions::default())
    }

    /// [`LocalCluster::start`] with the given options.
    pub fn start_with(options: &ClusterOptions) -> Result<Self, ClusterError> {
        let started = Instant::now();
        let mut cluster = Self::prepare(options)?;
        cluster.from_template = cluster.init()?;
        cluster.launch(options.port)?;
        tracing::debug!(
            port = cluster.port,
            from_template = cluster.from_template,
            data_dir = %cluster.data_dir.display(),
            elapsed_ms = started.elapsed().as_millis(),
            "PostgreSQL cluster started"
        );
        Ok(cluster)
    }

    /// A cluster not yet initialised: its temporary folder (given to the
    /// server's user) and its watchdog, but no data folder and no server.
    pub(crate) fn prepare(options: &ClusterOptions) -> Result<Self, ClusterError> {
        let bin_dir = binaries()?;
        let runner = Runner::for_this_process();
        // The server's user must be able to reach the folder, and a root's
        // TMPDIR may not allow that; /tmp always does.
        let mut builder = tempfile::Builder::new();
        builder.prefix("deog-pg-");
        let temp = if runner.as_server_user {
            builder.tempdir_in("/tmp")
        } else {
            builder.tempdir()
        }
        .map_err(|e| ClusterError::io("creating a temporary folder for the cluster", e))?;
        let root = fs::canonicalize(temp.path())
            .map_err(|e| ClusterError::io(format!("resolving {}", temp.path().display()), e))?;
        let data_dir = root.join("data");
        runner.hand_over(&root)?;
        let watchdog = Watchdog::spawn(&root, &data_dir)?;
        // From here on, Drop (or the watchdog) cleans up after a failure.
        Ok(Self {
            bin_dir,
            runner,
            options: options.clone(),
            root,
            data_dir,
            port: 0,
            from_template: false,
            server: None,
            watchdog,
            _temp: temp,
        })
    }

    /// The TCP port on 127.0.0.1.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Whether the data folder was copied from the template an earlier
    /// start kept, rather than made by `initdb`.
    pub fn from_template(&self) -> bool {
        self.from_template
    }

    /// `postgres://deog@127.0.0.1:PORT/DATABASE`, the database name
    /// percent-encoded. No password: loopback connections are trusted.
    pub fn url(&self, database: &str) -> String {
        format!(
            "postgres://{USER}@127.0.0.1:{}/{}",
            self.port,
            percent_encode(database)
        )
    }

    /// Creates the database `name` and returns its URL; an error if it
    /// exists.
    pub fn create_database(&self, name: &str) -> Result<String, ClusterError> {
        self.psql(
            "postgres",
            &format!("CREATE DATABASE {}", quote_ident(name)),
        )?;
        Ok(self.url(name))
    }

    /// Runs `sql` through `psql` against `database` and returns what it
    /// printed: unaligned rows without headers or command tags
    /// (`psql -X -A -t -q`), columns separated by `|`, rows by newlines,
    /// without the final newline. An SQL error is a
    /// [`ClusterError::Command`] carrying psql's message.
    pub fn psql(&self, database: &str, sql: &str) -> Result<String, ClusterError> {
        let mut command = process::client(&tool(&self.bin_dir, "psql"));
        command
            .args(["-X", "-A", "-t", "-q", "-v", "ON_ERROR_STOP=1", "-d"])
            .arg(self.url(database))
            .arg("-c")
            .arg(sql);
        let out = process::run(&mut command)?;
        Ok(out.strip_suffix('\n').unwrap_or(&out).to_owned())
    }

    /// The data folder (`PGDATA`). The server's log, `deog-postgres.log`, is
    /// in it.
    pub fn data_dir(&self) -> &Path {
        &self.data_dir
    }

    /// Stops the server with a fast shutdown (`SIGINT` to the postmaster:
    /// sessions are ended, a checkpoint is written) and waits for it; does
    /// nothing if it is not running. A server that has not stopped after
    /// 30 s is killed.
    pub fn stop(&mut self) -> Result<(), ClusterError> {
        let Some(mut server) = self.server.take() else {
            return Ok(());
        };
        if !matches!(server.try_wait(), Ok(Some(_))) {
            match process::postmaster_pid(&self.data_dir) {
                Some(pid) => process::signal("INT", &[pid]),
                // Without the pid file the child itself is the best guess;
                // when root it is `runuser`, which then ends the server.
                None => process::signal("INT", &[server.id()]),
            }
            if !wait_for_exit(&mut server, STOP_TIMEOUT) {
                tracing::warn!(
                    data_dir = %self.data_dir.display(),
                    "PostgreSQL did not stop within {STOP_TIMEOUT:?}; killing it"
                );
                self.kill_all(&mut server);
            }
        }
        self.wait_until_gone()
    }

    /// Kills the postmaster and all its processes with `SIGKILL`, as a crash
    /// would, and waits until they are gone. The data folder stays as it is,
    /// for [`LocalCluster::restart`] and its crash recovery. Does nothing if
    /// the server is not running.
    pub fn kill(&mut self) -> Result<(), ClusterError> {
        let Some(mut server) = self.server.take() else {
            return Ok(());
        };
        self.kill_all(&mut server);
        self.wait_until_gone()
    }

    /// Starts the server again on the same data folder and port, after
    /// [`LocalCluster::stop`] or [`LocalCluster::kill`]; a running server is
    /// stopped first. After a kill, the server recovers from its WAL.
    pub fn restart(&mut self) -> Result<(), ClusterError> {
        self.stop()?;
        self.launch(Some(self.port))
    }

    /// The last lines of the server's log, for error messages.
    pub(crate) fn log_tail(&self) -> String {
        tail(&read_from(&self.data_dir.join(LOG_FILE), 0), 20)
    }

    /// Initialises the data folder: a copy of the template an earlier
    /// `initdb` of the same binaries left, or else `initdb`, whose folder
    /// then becomes the template. True if it was a copy.
    fn init(&self) -> Result<bool, ClusterError> {
        let template = template::dir(&self.bin_dir, &self.runner);
        if template::copy_into(&template, &self.data_dir, &self.runner) {
            return Ok(true);
        }
        self.initdb()?;
        template::keep(&self.data_dir, &template, &self.runner);
        Ok(false)
    }

    /// Runs `initdb` into the data folder.
    fn initdb(&self) -> Result<(), ClusterError> {
        let mut command = self.runner.server(&self.bin_dir.join("initdb"));
        command
            .arg("-D")
            .arg(&self.data_dir)
            .args(["-U", USER, "--auth=trust", "-E", "UTF8", "--locale=C"])
            // The folder is thrown away; waiting for the disk buys nothing.
            .arg("--no-sync")
            .current_dir(&self.root);
        process::run(&mut command).map(drop)
    }

    /// Starts the server on `port` (or on a free one) and waits until it is
    /// ready, trying again while a port or shared memory is still taken.
    pub(crate) fn launch(&mut self, port: Option<u16>) -> Result<(), ClusterError> {
        let mut attempt = 1;
        loop {
            let candidate = match port {
                Some(port) => port,
                None => free_port()?,
            };
            match self.launch_once(candidate) {
                Ok(()) => {
                    self.port = candidate;
                    return Ok(());
                }
                Err(ClusterError::NotReady { log_tail, .. })
                    if attempt < START_ATTEMPTS && is_transient(&log_tail) =>
                {
                    tracing::debug!(port = candidate, attempt, %log_tail, "PostgreSQL start failed; trying again");
                    attempt += 1;
                    if port.is_some() {
                        thread::sleep(Duration::from_millis(200));
                    }
                }
                Err(error) => return Err(error),
            }
        }
    }

    /// One start on `port`: spawn, then wait until ready, the server exits,
    /// or [`READY_TIMEOUT`] passes.
    fn launch_once(&mut self, port: u16) -> Result<(), ClusterError> {
        let log_path = self.data_dir.join(LOG_FILE);
        let log = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .map_err(|e| ClusterError::io(format!("opening {}", log_path.display()), e))?;
        let log_start = log.metadata().map(|m| m.len()).unwrap_or(0);
        let stderr = log
            .try_clone()
            .map_err(|e| ClusterError::io(format!("duplicating {}", log_path.display()), e))?;

        let mut command = self.runner.server(&self.bin_dir.join("postgres"));
        command
            .arg("-D")
            .arg(&self.data_dir)
            .arg("-p")
            .arg(port.to_string())
            .arg("-k")
            .arg(&self.root)
            .args(["-c", "listen_addresses=127.0.0.1"])
            .args(["-c", &format!("fsync={}", on_off(self.options.fsync))])
            .args([
                "-c",
                &format!(
                    "synchronous_commit={}",
                    on_off(self.options.synchronous_commit)
                ),
            ]);
        for (name, value) in &self.options.extra_settings {
            command.arg("-c").arg(format!("{name}={value}"));
        }
        command
            .current_dir(&self.root)
            .stdin(Stdio::null())
            .stdout(log)
            .stderr(stderr)
            // Away from the terminal's Ctrl-C; this process decides.
            .process_group(0);
        let shown = process::show(&command);
        let mut server = command
            .spawn()
            .map_err(|e| ClusterError::io(format!("starting `{shown}`"), e))?;

        let deadline = Instant::now() + READY_TIMEOUT;
        let failure = loop {
            if let Ok(Some(status)) = server.try_wait() {
                break format!("the server exited ({status})");
            }
            if self.accepts_connections(port) {
                self.server = Some(server);
                return Ok(());
            }
            if Instant::now() >= deadline {
                self.kill_all(&mut server);
                break format!("not accepting connections after {READY_TIMEOUT:?}");
            }
            thread::sleep(POLL);
        };
        // Leave nothing behind for the next attempt.
        self.wait_until_gone()?;
        Err(ClusterError::NotReady {
            reason: format!("{failure} on port {port}"),
            log_tail: tail(&read_from(&log_path, log_start), 20),
        })
    }

    /// Whether the server on `port` accepts connections: its pid file says
    /// so, and then `pg_isready` (if installed, else `SELECT 1` through
    /// `psql`) connects over TCP. The pid file comes first: a client probe
    /// of a port that another program holds would hang for seconds, and
    /// would take that program for our server.
    fn accepts_connections(&self, port: u16) -> bool {
        if !process::postmaster_ready(&self.data_dir) {
            return false;
        }
        let pg_isready = self.bin_dir.join("pg_isready");
        let mut command = if pg_isready.is_file() {
            let mut command = process::client(&pg_isready);
            command
                .args(["-q", "-h", "127.0.0.1", "-U", USER, "-d", "postgres", "-p"])
                .arg(port.to_string());
            command
        } else {
            let mut command = process::client(&tool(&self.bin_dir, "psql"));
            command
                .args([
                    "-X",
                    "-q",
                    "-h",
                    "127.0.0.1",
                    "-U",
                    USER,
                    "-d",
                    "postgres",
                    "-p",
                ])
                .arg(port.to_string())
                .args(["-c", "SELECT 1"]);
            command
        };
        command
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|status| status.success())
    }

    /// `SIGKILL` to the postmaster first (so it starts no new children),
    /// then to every other process in the data folder; then waits for
    /// `server` and for the postmaster to be reaped, since a new postmaster
    /// refuses to start while the pid in `postmaster.pid` names any process,
    /// even a zombie.
    fn kill_all(&self, server: &mut Child) {
        let postmaster = process::postmaster_pid(&self.data_dir);
        if let Some(pid) = postmaster {
            process::signal("KILL", &[pid]);
        }
        process::signal("KILL", &process::processes_in(&self.data_dir));
        // When root, `server` is `runuser`, which reaps the postmaster and
        // then exits; killing it first would leave that to init.
        if !wait_for_exit(server, KILL_TIMEOUT) {
            let _ = server.kill();
            let _ = server.wait();
        }
        if let Some(pid) = postmaster {
            let proc_dir = PathBuf::from(format!("/proc/{pid}"));
            let deadline = Instant::now() + KILL_TIMEOUT;
            while proc_dir.exists() && Instant::now() < deadline {
                thread::sleep(Duration::from_millis(20));
            }
        }
    }

    /// Waits until no process works in the data folder, killing stragglers
    /// (children of a killed postmaster exit on their own, but a restart
    /// must not find them holding shared memory).
    fn wait_until_gone(&self) -> Result<(), ClusterError> {
        let deadline = Instant::now() + KILL_TIMEOUT;
        loop {
            let left = process::processes_in(&self.data_dir);
            if left.is_empty() {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(ClusterError::io(
                    format!("waiting for the server's processes {left:?} to end"),
                    std::io::Error::from(std::io::ErrorKind::TimedOut),
                ));
            }
            process::signal("KILL", &left);
            thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for LocalCluster {
    fn drop(&mut self) {
        if let Err(error) = self.stop() {
            tracing::warn!(%error, "stopping the PostgreSQL cluster");
        }
        // The watchdog removes the folder (it may be owned by `postgres`);
        // the TempDir then finds it gone.
        self.watchdog.finish(Duration::from_secs(15));
    }
}

/// Whether a failed start's log shows something that may clear up: the
/// port taken ("Address already in use"), or, just after a kill, shared
/// memory or the lock file still held by the old server.
fn is_transient(log: &str) -> bool {
    log.contains("already in use") || log.contains("postmaster.pid\" already exists")
}

/// Waits for `child` to exit, at most `patience`; whether it did.
fn wait_for_exit(child: &mut Child, patience: Duration) -> bool {
    let deadline = Instant::now() + patience;
    loop {
        match child.try_wait() {
            Ok(Some(_)) => return true,
            Ok(None) if Instant::now() < deadline => thread::sleep(Duration::from_millis(20)),
            Ok(None) | Err(_) => return false,
        }
    }
}

/// The text of `path` from byte `start` on; empty if unreadable.
fn read_from(path: &Path, start: u64) -> String {
    let mut text = Vec::new();
    if let Ok(mut file) = File::open(path) {
        if file.seek(SeekFrom::Start(start)).is_ok() {
            let _ = file.read_to_end(&mut text);
        }
    }
    String::from_utf8_lossy(&text).into_owned()
}

fn on_off(on: bool) -> &'static str {
    if on { "on" } else { "off" }
}

/// `name` as an SQL identifier: in double quotes, inner quotes doubled.
fn quote_ident(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

/// Every byte outside RFC 3986's unreserved set as `%XX`.
fn percent_encode(text: &str) -> String {
    text.bytes()
        .map(|byte| match byte {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                char::from(byte).to_string()
            }
            _ => format!("%{byte:02X}"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_are_quoted() {
        assert_eq!(quote_ident("maps"), "\"maps\"");
        assert_eq!(quote_ident("a\"b"), "\"a\"\"b\"");
    }

    #[test]
    fn database_names_are_percent_encoded() {
        assert_eq!(percent_encode("maps_1"), "maps_1");
        assert_eq!(percent_encode("a b/é"), "a%20b%2F%C3%A9");
    }
}
