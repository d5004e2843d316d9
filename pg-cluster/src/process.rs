//! Running a binary (as `postgres` when root) and finding and signalling the
//! processes of a data folder.

use std::ffi::OsStr;
use std::fs;
use std::path::Path;
use std::process::{Command, Stdio};

use crate::ClusterError;
use crate::error::tail;

/// The user the server runs as when this process is root.
pub(crate) const SERVER_USER: &str = "postgres";

/// How binaries are run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Runner {
    /// This process is root, so the server binaries (which refuse root) run
    /// as [`SERVER_USER`] through `runuser`.
    pub(crate) as_server_user: bool,
}

impl Runner {
    /// The runner for this process.
    pub(crate) fn for_this_process() -> Self {
        Self {
            as_server_user: effective_uid() == Some(0),
        }
    }

    /// A command for a server binary (`initdb`, `postgres`): through
    /// `runuser -u postgres --` when root.
    pub(crate) fn server(&self, program: &Path) -> Command {
        let mut command = if self.as_server_user {
            let mut command = Command::new("runuser");
            command.args(["-u", SERVER_USER, "--"]).arg(program);
            command
        } else {
            Command::new(program)
        };
        clean_env(&mut command);
        command
    }

    /// Gives `dir` and everything in it to the server's user, when root.
    pub(crate) fn hand_over(&self, dir: &Path) -> Result<(), ClusterError> {
        if !self.as_server_user {
            return Ok(());
        }
        let mut command = Command::new("chown");
        command
            .arg("-R")
            .arg(format!("{SERVER_USER}:{SERVER_USER}"))
            .arg(dir);
        run(&mut command).map(drop)
    }
}

/// A command for a client binary (`psql`, `pg_isready`). Clients do not
/// refuse root, and they talk TCP to 127.0.0.1, so they run as this process.
pub(crate) fn client(program: &Path) -> Command {
    let mut command = Command::new(program);
    clean_env(&mut command);
    command
}

/// Removes `PG*` variables (`PGHOST`, `PGOPTIONS`, `PGDATA`, ...) so no
/// setting of the caller's reaches this private server, and makes messages
/// English so the log can be read for known failures.
fn clean_env(command: &mut Command) {
    for (name, _) in std::env::vars_os() {
        if name.to_string_lossy().starts_with("PG") {
            command.env_remove(name);
        }
    }
    command.env("LC_ALL", "C");
}

/// Runs `command` to completion and returns its standard output, or a
/// [`ClusterError::Command`] with the tail of its standard error.
pub(crate) fn run(command: &mut Command) -> Result<String, ClusterError> {
    let shown = show(command);
    let output = command
        .stdin(Stdio::null())
        .output()
        .map_err(|e| ClusterError::io(format!("running `{shown}`"), e))?;
    if output.status.success() {
        Ok(String::from_utf8_lossy(&output.stdout).into_owned())
    } else {
        Err(ClusterError::Command {
            command: shown,
            status: output.status.to_string(),
            stderr: tail(&String::from_utf8_lossy(&output.stderr), 20),
        })
    }
}

/// A command line for messages.
pub(crate) fn show(command: &Command) -> String {
    std::iter::once(command.get_program())
        .chain(command.get_args())
        .map(OsStr::to_string_lossy)
        .collect::<Vec<_>>()
        .join(" ")
}

/// This process's effective user id, from `/proc/self/status`, else `id -u`.
pub(crate) fn effective_uid() -> Option<u32> {
    let from_proc = fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            // "Uid:\treal\teffective\tsaved\tfilesystem"
            let line = status.lines().find(|line| line.starts_with("Uid:"))?;
            line.split_whitespace().nth(2)?.parse().ok()
        });
    from_proc.or_else(|| {
        let output = Command::new("id").arg("-u").output().ok()?;
        String::from_utf8_lossy(&output.stdout).trim().parse().ok()
    })
}

/// The postmaster's pid, from the first line of `postmaster.pid`.
pub(crate) fn postmaster_pid(data_dir: &Path) -> Option<u32> {
    fs::read_to_string(data_dir.join("postmaster.pid"))
        .ok()?
        .lines()
        .next()?
        .trim()
        .parse()
        .ok()
}

/// Whether `postmaster.pid` says the server accepts connections: from
/// PostgreSQL 10 its eighth line is the postmaster's status, `ready` once it
/// listens (what `pg_ctl start -w` waits for).
pub(crate) fn postmaster_ready(data_dir: &Path) -> bool {
    fs::read_to_string(data_dir.join("postmaster.pid"))
        .ok()
        .and_then(|text| text.lines().nth(7).map(|line| line.trim() == "ready"))
        .unwrap_or(false)
}

/// Every process whose working folder is `data_dir`: the postmaster and all
/// its children chdir there, and each child is in a session of its own, so
/// this (not the process group) is how to find them all.
pub(crate) fn processes_in(data_dir: &Path) -> Vec<u32> {
    let Ok(entries) = fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|entry| {
            let entry = entry.ok()?;
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let cwd = fs::read_link(entry.path().join("cwd")).ok()?;
            (cwd == data_dir).then_some(pid)
        })
        .collect()
}

/// Sends `signal` ("INT", "KILL") to `pids`, ignoring those already gone.
/// The shell's `kill` is used so that no C library binding is needed.
pub(crate) fn signal(signal: &str, pids: &[u32]) {
    if pids.is_empty() {
        return;
    }
    let result = Command::new("sh")
        .args([
            "-c",
            r#"sig=$1; shift; kill -s "$sig" "$@" 2>/dev/null; true"#,
            "sh",
        ])
        .arg(signal)
        .args(pids.iter().map(u32::to_string))
        .stdin(Stdio::null())
        .status();
    if let Err(error) = result {
        tracing::warn!(%error, signal, ?pids, "could not run the shell to send a signal");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_process_has_an_effective_uid() {
        assert!(effective_uid().is_some());
    }

    #[test]
    fn this_process_is_found_in_its_working_folder() {
        let cwd = std::env::current_dir().unwrap().canonicalize().unwrap();
        assert!(processes_in(&cwd).contains(&std::process::id()));
    }
}
