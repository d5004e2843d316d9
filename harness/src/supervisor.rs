//! Child processes of `deog demo` and the benchmarks: each started from
//! the `deog` executable in its own process group (so a ctrl-c at the
//! terminal reaches only the parent, which then stops them in order), its
//! output in a log file, watched for failure, and stopped with SIGTERM,
//! then SIGKILL, when the run ends for any reason, including an error or a
//! panic.

use std::ffi::OsString;
use std::fs::File;
use std::net::{SocketAddr, TcpListener};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// How long a child has to stop after SIGTERM before it gets SIGKILL.
const STOP_GRACE: Duration = Duration::from_secs(5);

/// What a child is expected to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Runs until it is stopped (server, simulator): exiting at all is a
    /// failure.
    Service,
    /// Runs to its own end (wanderer, cartographer, localizer): exiting
    /// with success is its end, any other exit a failure.
    Task,
}

/// One child process.
#[derive(Debug)]
pub struct Process {
    /// The name it goes by in messages and its log file's name.
    pub name: String,
    role: Role,
    child: Child,
    log: PathBuf,
    command_line: String,
    exit: Option<ExitStatus>,
    /// Left running when the supervisor is dropped (`deog demo --keep`).
    keep: bool,
}

/// The children of one run.
#[derive(Debug)]
pub struct Supervisor {
    program: PathBuf,
    log_dir: PathBuf,
    processes: Vec<Process>,
}

impl Supervisor {
    /// Children are started from this process's own executable and log
    /// into `log_dir`, which is created.
    pub fn new(log_dir: &Path) -> Result<Self> {
        let program = std::env::current_exe().context("finding the deog executable")?;
        std::fs::create_dir_all(log_dir)
            .with_context(|| format!("creating {}", log_dir.display()))?;
        Ok(Self {
            program,
            log_dir: log_dir.to_path_buf(),
            processes: Vec::new(),
        })
    }

    /// Starts `deog <args>` as `name`. The child's environment has no
    /// `DEOG_*` variables: everything it needs is in `args`, so a setting
    /// meant for the user's own processes cannot leak into the demo.
    pub fn start(&mut self, name: &str, role: Role, args: &[OsString]) -> Result<()> {
        self.start_with_env(name, role, args, &[])
    }

    /// As [`Supervisor::start`], with `env` set in the child's environment
    /// (a secret such as a database URL with its password stays out of the
    /// argument list, which `ps` shows to everyone); the command line
    /// kept for reports names them with passwords hidden.
    pub fn start_with_env(
        &mut self,
        name: &str,
        role: Role,
        args: &[OsString],
        env: &[(&str, &str)],
    ) -> Result<()> {
        let log = self.log_dir.join(format!("{name}.log"));
        let out = File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let err = out
            .try_clone()
            .with_context(|| format!("opening {}", log.display()))?;
        let mut command = Command::new(&self.program);
        command
            .args(args)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .process_group(0);
        for (key, _) in std::env::vars_os() {
            if key.to_string_lossy().starts_with("DEOG_") {
                command.env_remove(key);
            }
        }
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "info");
        }
        for (key, value) in env {
            command.env(key, value);
        }
        let command_line = env
            .iter()
            .map(|(key, value)| format!("{key}='{}'", crate::redact::url_without_password(value)))
            .chain(std::iter::once("deog".to_string()))
            .chain(args.iter().map(|a| a.to_string_lossy().into_owned()))
            .collect::<Vec<_>>()
            .join(" ");
        let child = command
            .spawn()
            .with_context(|| format!("starting {name}: {command_line}"))?;
        tracing::debug!(%name, pid = child.id(), %command_line, "started");
        self.processes.push(Process {
            name: name.to_string(),
            role,
            child,
            log,
            command_line,
            exit: None,
            keep: false,
        });
        Ok(())
    }

    /// The command line each child was started with, in order.
    pub fn command_lines(&self) -> impl Iterator<Item = (&str, &str)> {
        self.processes
            .iter()
            .map(|p| (p.name.as_str(), p.command_line.as_str()))
    }

    /// The process id of child `name`.
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.processes
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.child.id())
    }

    /// Leaves child `name` running when the supervisor is dropped.
    pub fn keep(&mut self, name: &str) {
        for process in &mut self.processes {
            if process.name == name {
                process.keep = true;
            }
        }
    }

    /// Notes which children have exited; fails, naming the child and
    /// quoting the end of its log, if one failed or a service ended.
    pub fn check(&mut self) -> Result<()> {
        for process in &mut self.processes {
            if process.exit.is_some() {
                continue;
            }
            let Some(status) = process
                .child
                .try_wait()
                .with_context(|| format!("watching {}", process.name))?
            else {
                continue;
            };
            process.exit = Some(status);
            if process.role == Role::Service || !status.success() {
                bail!(
                    "{} stopped ({status}); the end of its log, {}:\n{}",
                    process.name,
                    process.log.display(),
                    log_tail(&process.log, 15)
                );
            }
            tracing::debug!(name = %process.name, "finished");
        }
        Ok(())
    }

    /// Whether every child whose name starts with `prefix` has exited.
    pub fn all_done(&self, prefix: &str) -> bool {
        self.processes
            .iter()
            .filter(|p| p.name.starts_with(prefix))
            .all(|p| p.exit.is_some())
    }

    /// The names of the children still running whose name starts with
    /// `prefix`.
    pub fn running(&self, prefix: &str) -> Vec<&str> {
        self.processes
            .iter()
            .filter(|p| p.name.starts_with(prefix) && p.exit.is_none())
            .map(|p| p.name.as_str())
            .collect()
    }

    /// Stops every running child not marked to keep, the last started first:
    /// SIGTERM, and SIGKILL for any still there after a grace period.
    pub fn stop_all(&mut self) {
        let mut stopping = Vec::new();
        for (i, process) in self.processes.iter_mut().enumerate().rev() {
            if process.exit.is_some() || process.keep {
                continue;
            }
            if let Ok(Some(status)) = process.child.try_wait() {
                process.exit = Some(status);
                continue;
            }
            let pid = Pid::from_raw(process.child.id() as i32);
            if kill(pid, Signal::SIGTERM).is_err() {
                let _ = process.child.kill();
            }
            stopping.push(i);
        }
        let deadline = Instant::now() + STOP_GRACE;
        for i in stopping {
            let process = &mut self.processes[i];
            loop {
                match process.child.try_wait() {
                    Ok(Some(status)) => {
                        process.exit = Some(status);
                        break;
                    }
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    _ => {
                        tracing::warn!(name = %process.name, "did not stop on SIGTERM: killed");
                        let _ = process.child.kill();
                        process.exit = process.child.wait().ok();
                        break;
                    }
                }
            }
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        self.stop_all();
    }
}

/// The last `lines` lines of a log file, or why it cannot be read.
pub fn log_tail(path: &Path, lines: usize) -> String {
    match std::fs::read(path) {
        Ok(bytes) => {
            let text = String::from_utf8_lossy(&bytes);
            let all: Vec<&str> = text.lines().collect();
            let tail = &all[all.len().saturating_sub(lines)..];
            if tail.is_empty() {
                "  (empty)".to_string()
            } else {
                tail.iter().map(|l| format!("  {l}\n")).collect()
            }
        }
        Err(e) => format!("  (cannot read it: {e})"),
    }
}

/// Creates a run's output folder `out` and clears the server data and
/// logs an earlier run left in it (other files stay).
pub fn prepare_run_folder(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for folder in ["server-data", "logs"] {
        let path = out.join(folder);
        if path.exists() {
            std::fs::remove_dir_all(&path)
                .with_context(|| format!("clearing {} of an earlier run", path.display()))?;
        }
    }
    Ok(())
}

/// A loopback address no one listens on at the moment of asking.
pub fn free_loopback_addr() -> Result<SocketAddr> {
    let listener = TcpListener::bind("127.0.0.1:0").context("finding a free loopback port")?;
    listener
        .local_addr()
        .context("finding a free loopback port")
}

/// Arguments as the `OsString`s [`Supervisor::start`] takes.
pub fn os(args: &[&str]) -> Vec<OsString> {
    args.iter().map(OsString::from).collect()
}

/// Connects to a child's service, retrying while the child starts, and
/// failing at once if it dies.
pub async fn connect<C, E, F, Fut>(
    children: &mut Supervisor,
    what: &str,
    mut attempt: F,
) -> Result<C>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<C, E>>,
    E: std::fmt::Display,
{
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        children.check()?;
        match tokio::time::timeout(Duration::from_secs(5), attempt()).await {
            Ok(Ok(client)) => return Ok(client),
            Ok(Err(e)) if Instant::now() > deadline => bail!("connecting to the {what}: {e}"),
            Err(_) if Instant::now() > deadline => bail!("connecting to the {what}: timed out"),
            _ => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
}
