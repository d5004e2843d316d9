//! End-to-end tests of deog live in `tests/tests/`; this library holds the
//! helpers they share.
//!
//! # Layout
//! - [`deog_binary`]: the `deog` executable, built once per test run.
//! - [`wander_frames`]: frames of a robot wandering in map2, made
//!   in-process.
//! - [`ServerProcess`]: a `deog server` or `deog sim` child process on a free loopback
//!   port, ready once its health service says so; killed when dropped.

use std::ffi::OsString;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

/// Path of a freshly built `deog` binary (the debug profile), building it
/// with the same cargo that runs the tests on first use. Panics with cargo's
/// output if the build fails: the tests cannot run without it.
///
/// The build is the workspace's test build (`cargo test --workspace
/// --no-run`): `deog`'s own tests (`cli/tests`) make cargo build the binary
/// there, its dependencies with the features every test of the workspace
/// unifies. After `cargo test --workspace` or `cargo nextest run
/// --workspace` it is fresh, and the call only checks it; `cargo build -p
/// deog` would unify fewer features and rebuild half the dependencies.
/// Under cargo-nextest, where every test is a process of its own, the
/// first check of a run is noted in the target folder and the later
/// processes of the same run trust it.
pub fn deog_binary() -> PathBuf {
    static BINARY: OnceLock<PathBuf> = OnceLock::new();
    BINARY
        .get_or_init(|| {
            let target = std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"));
            let binary = target
                .join("debug")
                .join(format!("deog{}", std::env::consts::EXE_SUFFIX));
            let run = std::env::var("NEXTEST_RUN_ID").ok();
            let checked = target.join("debug").join("deog-binary-checked-for-run");
            if run.is_some() && std::fs::read_to_string(&checked).ok() == run {
                return binary;
            }
            build_workspace_tests();
            if let Some(run) = run {
                // Only a shortcut: a process that cannot write it builds too.
                let _ = std::fs::write(&checked, run);
            }
            binary
        })
        .clone()
}

/// `cargo test --workspace --no-run`, quietly, with the variables cargo
/// set for this test removed.
fn build_workspace_tests() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut build = Command::new(cargo);
    build
        .args(["test", "--workspace", "--no-run", "--quiet"])
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    // Cargo sets these for the test; some build scripts (ring's) rebuild
    // when they change. Without them the build is the one the test run
    // made, reused rather than redone.
    for (key, _) in std::env::vars() {
        let per_crate = [
            "CARGO_PKG_",
            "CARGO_MANIFEST_",
            "CARGO_CRATE_",
            "CARGO_BIN_",
        ]
        .iter()
        .any(|prefix| key.starts_with(prefix));
        let single = ["CARGO_PRIMARY_PACKAGE", "CARGO_TARGET_TMPDIR", "OUT_DIR"];
        if per_crate || single.contains(&key.as_str()) {
            build.env_remove(key);
        }
    }
    let output = build.output().expect("cargo runs");
    assert!(
        output.status.success(),
        "building deog failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// A tile's cells, decoded from the wire's little-endian `i16`s.
pub fn tile_cells(tile: &deog_proto::v1::Tile) -> Vec<i16> {
    tile.cells
        .chunks_exact(2)
        .map(|b| i16::from_le_bytes([b[0], b[1]]))
        .collect()
}

/// Runs `deog <args>` to its end with `env` set, the `DEOG_*` variables
/// of the test's own environment removed (so they cannot change what a
/// test means) and logs quiet.
pub fn run_deog(args: &[&str], env: &[(&str, String)]) -> Output {
    let mut command = Command::new(deog_binary());
    command.args(args).env("RUST_LOG", "warn");
    for (key, _) in std::env::vars() {
        if key.starts_with("DEOG_") {
            command.env_remove(key);
        }
    }
    for (key, value) in env {
        command.env(key, value);
    }
    command.output().expect("run deog")
}

/// Fails the test, saying what to install, unless python3 runs and
/// imports `modules` (comma-separated, as `import` takes them) from the
/// PyPI `packages` (space-separated, as pip takes them).
pub fn require_python(modules: &str, packages: &str) {
    let install = format!("python3 -m pip install {packages}");
    match Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
    {
        Err(error) => panic!("this test needs python3 ({error}); install it, then: {install}"),
        Ok(out) if !out.status.success() => panic!(
            "this test needs the PyPI packages {packages}: {install}\n{}",
            String::from_utf8_lossy(&out.stderr)
        ),
        Ok(_) => {}
    }
}

/// The stdout of a run that must have succeeded; panics with its stderr
/// otherwise.
pub fn succeeded(output: &Output) -> String {
    assert!(
        output.status.success(),
        "deog failed: {}\n{}",
        String::from_utf8_lossy(&output.stderr),
        String::from_utf8_lossy(&output.stdout)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The stderr of a run that must have failed; panics with its stdout
/// otherwise.
pub fn failure(output: &Output) -> String {
    assert!(
        !output.status.success(),
        "deog succeeded but should not have: {}",
        String::from_utf8_lossy(&output.stdout)
    );
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The text of the value after the first `"name": ` in a JSON report
/// (numbers, `true`, `null`), for tests that read a few figures.
pub fn json_field(json: &str, name: &str) -> String {
    let key = format!("\"{name}\": ");
    let start = json
        .find(&key)
        .unwrap_or_else(|| panic!("{name} in {json}"))
        + key.len();
    let rest = &json[start..];
    let end = rest.find([',', '\n', '}']).unwrap_or(rest.len());
    rest[..end].trim().to_string()
}

/// A free port on 127.0.0.1: bound, then released for a child to bind.
pub fn free_loopback_addr() -> SocketAddr {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a free port");
    listener.local_addr().expect("local address")
}

/// A running serving `deog` process: the map server or the simulator.
#[derive(Debug)]
pub struct ServerProcess {
    /// Where it listens.
    pub addr: SocketAddr,
    child: Option<Child>,
    /// The service its health reports on.
    service: &'static str,
    /// The CA certificate (PEM) its TLS certificate for "localhost" is
    /// checked against; `None` for a plain process.
    tls_ca: Option<Vec<u8>>,
}

impl ServerProcess {
    /// Starts `deog server --listen <free port> --data <data>` plus `extra`
    /// arguments and waits until its health service reports the map service
    /// as serving (bounded: 30 s).
    pub async fn start(data: &Path, extra: &[&str]) -> Self {
        Self::start_on(free_loopback_addr(), data, extra).await
    }

    /// As [`ServerProcess::start`], on a given address (a restart).
    pub async fn start_on(addr: SocketAddr, data: &Path, extra: &[&str]) -> Self {
        let mut args: Vec<OsString> =
            vec!["server".into(), "--listen".into(), addr.to_string().into()];
        args.push("--data".into());
        args.push(data.into());
        args.extend(extra.iter().map(OsString::from));
        Self::spawn(args, addr, "deog.v1.MapService").await
    }

    /// Starts `deog sim --world <world> --listen <free port>` plus `extra`
    /// arguments and waits until its health service reports the robot
    /// service as serving (bounded: 30 s).
    pub async fn start_sim(world: &str, extra: &[&str]) -> Self {
        Self::start_sim_with(world, extra, None).await
    }

    /// As [`ServerProcess::start_sim`] for a simulator serving TLS with a
    /// certificate for "localhost" that `ca_pem` vouches for (given in
    /// `extra`), waiting for its health over TLS.
    pub async fn start_sim_tls(world: &str, extra: &[&str], ca_pem: &[u8]) -> Self {
        Self::start_sim_with(world, extra, Some(ca_pem.to_vec())).await
    }

    async fn start_sim_with(world: &str, extra: &[&str], tls_ca: Option<Vec<u8>>) -> Self {
        let addr = free_loopback_addr();
        let mut args: Vec<OsString> = vec!["sim".into(), "--world".into(), world.into()];
        args.push("--listen".into());
        args.push(addr.to_string().into());
        args.extend(extra.iter().map(OsString::from));
        Self::spawn_with(args, addr, "deog.v1.RobotService", tls_ca).await
    }

    /// As [`ServerProcess::start`], with the process allowed at most
    /// `open_files` file descriptors (`ulimit -n`).
    pub async fn start_with_open_files(data: &Path, extra: &[&str], open_files: u32) -> Self {
        let addr = free_loopback_addr();
        let mut args: Vec<OsString> = vec![
            "-c".into(),
            format!("ulimit -n {open_files} && exec \"$0\" \"$@\"").into(),
            deog_binary().into(),
            "server".into(),
            "--listen".into(),
            addr.to_string().into(),
            "--data".into(),
            data.into(),
        ];
        args.extend(extra.iter().map(OsString::from));
        Self::spawn_program("sh".as_ref(), args, addr, "deog.v1.MapService", None).await
    }

    async fn spawn(args: Vec<OsString>, addr: SocketAddr, service: &'static str) -> Self {
        Self::spawn_program(&deog_binary(), args, addr, service, None).await
    }

    async fn spawn_with(
        args: Vec<OsString>,
        addr: SocketAddr,
        service: &'static str,
        tls_ca: Option<Vec<u8>>,
    ) -> Self {
        Self::spawn_program(&deog_binary(), args, addr, service, tls_ca).await
    }

    async fn spawn_program(
        program: &Path,
        args: Vec<OsString>,
        addr: SocketAddr,
        service: &'static str,
        tls_ca: Option<Vec<u8>>,
    ) -> Self {
        let child = Command::new(program)
            .args(&args)
            // Quiet unless a test run asks for more.
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "warn".into()),
            )
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start deog");
        let server = Self {
            addr,
            child: Some(child),
            service,
            tls_ca,
        };
        server.wait_ready().await;
        server
    }

    /// `http://<addr>`, or `https://<addr>` when it serves TLS.
    pub fn url(&self) -> String {
        let scheme = if self.tls_ca.is_some() {
            "https"
        } else {
            "http"
        };
        format!("{scheme}://{}", self.addr)
    }

    fn endpoint(&self) -> Option<tonic::transport::Endpoint> {
        let endpoint = tonic::transport::Channel::from_shared(self.url()).ok()?;
        match &self.tls_ca {
            None => Some(endpoint),
            Some(ca) => endpoint
                .tls_config(
                    tonic::transport::ClientTlsConfig::new()
                        .ca_certificate(tonic::transport::Certificate::from_pem(ca))
                        .domain_name("localhost"),
                )
                .ok(),
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    async fn wait_ready(&self) {
        for _ in 0..300 {
            if let Some(endpoint) = self.endpoint()
                && let Ok(channel) = endpoint.connect().await
            {
                let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
                let request = tonic_health::pb::HealthCheckRequest {
                    service: self.service.into(),
                };
                if let Ok(reply) = health.check(request).await
                    && reply.into_inner().status
                        == tonic_health::pb::health_check_response::ServingStatus::Serving as i32
                {
                    return;
                }
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        panic!("deog server on {} never became ready", self.addr);
    }

    /// SIGKILL: the process ends at once, with no chance to flush.
    pub fn kill(mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// SIGTERM, then waits (bounded: 30 s) for the process to exit; returns
    /// whether it exited successfully.
    pub fn terminate(self) -> bool {
        self.stop_with("-TERM")
    }

    /// SIGINT (ctrl-c), then as [`Self::terminate`].
    pub fn interrupt(self) -> bool {
        self.stop_with("-INT")
    }

    fn stop_with(mut self, signal: &str) -> bool {
        let Some(mut child) = self.child.take() else {
            return false;
        };
        let sent = Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .is_ok_and(|s| s.success());
        if sent {
            for _ in 0..300 {
                if let Ok(Some(status)) = child.try_wait() {
                    return status.success();
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
        let _ = child.kill();
        let _ = child.wait();
        false
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A `deog` process a test runs beside its servers (a wanderer, a
/// cartographer, the view), its logs quiet; killed when dropped.
#[derive(Debug)]
pub struct RunningDeog(Child);

impl RunningDeog {
    /// Starts `deog <args>`, the test's own `DEOG_*` variables removed.
    pub fn spawn(args: &[&str]) -> Self {
        let mut command = Command::new(deog_binary());
        command
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        for (key, _) in std::env::vars() {
            if key.starts_with("DEOG_") {
                command.env_remove(key);
            }
        }
        Self(command.spawn().expect("start deog"))
    }

    /// Whether it is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.0.try_wait(), Ok(None))
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.0.id()
    }
}

impl Drop for RunningDeog {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A small tmpfs mounted at a fresh temporary directory, to fill and empty
/// under a running server; unmounted when dropped.
#[derive(Debug)]
pub struct SmallDisk {
    dir: tempfile::TempDir,
}

impl SmallDisk {
    /// Mounts a tmpfs of `size` (as `mount -o size=` takes it: `24m`);
    /// `None` where this process may not mount.
    pub fn mount(size: &str) -> Option<Self> {
        let dir = tempfile::tempdir().expect("temp dir");
        let mounted = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        mounted.then_some(Self { dir })
    }

    /// The mount point.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// Takes every free byte with a file of its own; returns its size.
    pub fn fill(&self) -> u64 {
        use std::io::Write;
        let mut file = std::fs::File::create(self.filler()).expect("create the filler");
        let chunk = vec![0xA5u8; 64 << 10];
        let mut written = 0u64;
        // A tmpfs refuses the write that no longer fits; bounded by its size.
        while let Ok(n) = file.write(&chunk) {
            if n == 0 {
                break;
            }
            written += n as u64;
        }
        written
    }

    /// Gives back what [`SmallDisk::fill`] took.
    pub fn empty(&self) {
        let _ = std::fs::remove_file(self.filler());
    }

    fn filler(&self) -> std::path::PathBuf {
        self.dir.path().join("filler")
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.dir.path()).status();
    }
}

/// A query for every tile of map `map`.
pub fn whole_map(map: &str) -> deog_proto::v1::TileQuery {
    use deog_proto::v1 as pb;
    pb::TileQuery {
        map: map.into(),
        selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
            min_x: i32::MIN,
            min_y: i32::MIN,
            max_x: i32::MAX,
            max_y: i32::MAX,
        })),
        newer_than_version: 0,
    }
}

/// Waits (bounded: 30 s) until the process at `url` reports `service` as
/// `wanted`; panics if it never does.
pub async fn wait_for_health(
    url: &str,
    service: &str,
    wanted: tonic_health::pb::health_check_response::ServingStatus,
) {
    for _ in 0..300 {
        if health_status(url, service).await == Some(wanted) {
            return;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("the health of {service} at {url} never became {wanted:?}");
}

/// The health a serving process reports for `service` at `url` (plain
/// HTTP/2), or `None` when it does not answer within 2 s.
pub async fn health_status(
    url: &str,
    service: &str,
) -> Option<tonic_health::pb::health_check_response::ServingStatus> {
    let ask = async {
        let channel = tonic::transport::Channel::from_shared(url.to_string())
            .ok()?
            .connect()
            .await
            .ok()?;
        let reply = tonic_health::pb::health_client::HealthClient::new(channel)
            .check(tonic_health::pb::HealthCheckRequest {
                service: service.into(),
            })
            .await
            .ok()?;
        tonic_health::pb::health_check_response::ServingStatus::try_from(reply.into_inner().status)
            .ok()
    };
    tokio::time::timeout(Duration::from_secs(2), ask)
        .await
        .ok()
        .flatten()
}

/// `count` frames of robot `robot` wandering in `worlds/map2.toml` from a
/// random start (seeded), as `deog wander` would publish them: computed
/// in-process with the simulator's library, so tests need no simulator
/// process to have frames.
pub fn wander_frames(robot: &str, seed: u64, count: usize) -> Vec<deog_proto::v1::SonarFrame> {
    wander_frames_with(robot, seed, count, deog_simulator::SonarParams::default())
}

/// [`wander_frames`] from a simulator whose sonars are `sonar`.
pub fn wander_frames_with(
    robot: &str,
    seed: u64,
    count: usize,
    sonar: deog_simulator::SonarParams,
) -> Vec<deog_proto::v1::SonarFrame> {
    use deog_proto::v1 as pb;
    use deog_simulator::simulation::{SimConfig, Simulation};
    use deog_simulator::{WanderParams, Wanderer};
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/map2.toml");
    let world = deog_world::load_world(&path).expect("map2 loads");
    let config = SimConfig {
        sonar,
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(world, config, seed).expect("simulation");
    let mut state = sim.spawn(robot, None).expect("spawn");
    let mut wanderer = Wanderer::new(
        WanderParams::default(),
        &deog_grid::SensorRing::scout(),
        seed,
    )
    .expect("wanderer");
    let pose = |p: deog_grid::Pose2| pb::Pose2 {
        x: p.x,
        y: p.y,
        theta: p.theta,
    };
    let mut frames = Vec::new();
    let mut fired = Vec::new();
    while frames.len() < count {
        let (v, w) = wanderer
            .command(&state.ranges, state.bumper, 0.1)
            .expect("command");
        sim.drive(robot, v, w).expect("drive");
        fired.clear();
        while fired.is_empty() {
            sim.advance(0.1, &mut fired).expect("advance");
        }
        state = fired.pop().expect("a firing");
        frames.push(pb::SonarFrame {
            robot: robot.into(),
            sequence: state.sequence,
            time_s: state.time_s,
            odometry: Some(pose(state.odometry)),
            true_pose: Some(pose(state.true_pose)),
            ranges: state.ranges.clone(),
            rig: String::new(),
            reference_pose: None,
        });
    }
    frames
}
