//! The bench's processes: the map server, and each step run to its end
//! as a child of the same supervisor.

use std::ffi::OsString;
use std::future::Future;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, os};
use deog_robot_client::{ClientConfig, MapClient};

/// How often a running step is looked at.
const POLL: Duration = Duration::from_millis(20);

/// The run's children, its map server among them.
pub(super) struct Processes {
    /// Every child; they stop when it is dropped.
    pub children: Supervisor,
    /// A client of the map server.
    pub client: MapClient,
    /// The map server's address, as the steps take it (`--server`).
    pub server_url: String,
}

impl Processes {
    /// Starts a map server on a free loopback port with its data in
    /// `out/server-data` and its log, like every step's, in `logs`.
    pub async fn start(out: &Path, logs: &Path) -> Result<Self> {
        let mut children = Supervisor::new(logs)?;
        let addr = free_loopback_addr()?;
        let server_url = format!("http://{addr}");
        let args: Vec<OsString> = os(&["server", "--listen", &addr.to_string(), "--data"])
            .into_iter()
            .chain([out.join("server-data").into_os_string()])
            .collect();
        children.start("server", Role::Service, &args)?;
        let client = connect(&mut children, "map server", || {
            MapClient::connect(ClientConfig::new(server_url.clone()))
        })
        .await?;
        Ok(Self {
            children,
            client,
            server_url,
        })
    }

    /// Runs `deog <args> --server <the server>` as `name` to its end and
    /// returns its wall-clock time, start to exit. Fails if it fails, the
    /// server stops, or `shutdown` comes first.
    pub async fn step(
        &mut self,
        name: &str,
        args: &[OsString],
        shutdown: &mut (impl Future<Output = ()> + Unpin),
    ) -> Result<Duration> {
        let args: Vec<OsString> = args
            .iter()
            .cloned()
            .chain(os(&["--server", &self.server_url]))
            .collect();
        let started = Instant::now();
        self.children.start(name, Role::Task, &args)?;
        loop {
            tokio::select! {
                () = &mut *shutdown => bail!("interrupted: every process was stopped"),
                () = tokio::time::sleep(POLL) => {}
            }
            self.children.check()?;
            if self.children.all_done(name) {
                return Ok(started.elapsed());
            }
        }
    }
}
