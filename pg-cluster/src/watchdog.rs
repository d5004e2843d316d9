//! The shell script that cleans up after a process that died.
//!
//! A destructor is not enough: statics are never dropped, and a process can
//! be killed. So each cluster has a watchdog: `sh` reading a pipe whose only
//! writer is this process (the write end is close-on-exec, so no other child
//! inherits it). The read returns end-of-file when this process drops the
//! cluster or dies in any way; the watchdog then stops whatever postmaster
//! `postmaster.pid` names at that moment and removes the cluster's folder.
//! Because it watches this process and not the postmaster, a
//! [`crate::LocalCluster::kill`] followed by a restart leaves it untouched.
//!
//! It runs as this process's user (root can signal and remove everything the
//! `postgres` user owns), in a process group of its own so a terminal's
//! Ctrl-C reaches this process, whose death the watchdog then handles,
//! instead of killing the watchdog first.

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use crate::ClusterError;

/// `$1` is the folder to remove, `$2` the data folder inside it. Before it
/// signals a pid from `postmaster.pid` it checks that the process works in
/// the data folder, since a stale file may name a pid now reused.
const SCRIPT: &str = r#"
while read -r _; do :; done
root=$1
data=$2
pid=
if [ -f "$data/postmaster.pid" ]; then
    read -r pid < "$data/postmaster.pid" || true
fi
if [ -n "$pid" ] && [ "$(readlink "/proc/$pid/cwd" 2>/dev/null)" = "$data" ]; then
    kill -INT "$pid" 2>/dev/null
    i=0
    while [ "$i" -lt 100 ] && kill -0 "$pid" 2>/dev/null; do
        sleep 0.1
        i=$((i + 1))
    done
    kill -KILL "$pid" 2>/dev/null
fi
rm -rf "$root"
"#;

/// A running watchdog.
#[derive(Debug)]
pub(crate) struct Watchdog {
    child: Child,
    /// Dropping this (or this process ending) sets the watchdog off.
    pipe: Option<ChildStdin>,
}

impl Watchdog {
    /// Starts a watchdog for the cluster in `root` with its data in `data`.
    pub(crate) fn spawn(root: &Path, data: &Path) -> Result<Self, ClusterError> {
        let mut child = Command::new("sh")
            .args(["-c", SCRIPT, "deog-pg-watchdog"])
            .arg(root)
            .arg(data)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .process_group(0)
            .spawn()
            .map_err(|e| ClusterError::io("starting the watchdog shell", e))?;
        let pipe = child.stdin.take();
        Ok(Self { child, pipe })
    }

    /// Sets the watchdog off and waits for it to finish its cleanup,
    /// at most `patience`.
    pub(crate) fn finish(&mut self, patience: Duration) {
        self.pipe = None;
        let deadline = Instant::now() + patience;
        loop {
            match self.child.try_wait() {
                Ok(Some(_)) => return,
                Ok(None) if Instant::now() < deadline => {
                    thread::sleep(Duration::from_millis(20));
                }
                Ok(None) | Err(_) => {
                    tracing::warn!("the cluster's watchdog did not finish in time; killing it");
                    let _ = self.child.kill();
                    let _ = self.child.wait();
                    return;
                }
            }
        }
    }
}
