//! A real server from the machine's PostgreSQL binaries.

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use deog_pg_cluster::{ClusterError, ClusterOptions, LocalCluster};

#[test]
fn a_killed_cluster_keeps_its_committed_rows() -> anyhow::Result<()> {
    let mut cluster = LocalCluster::start()?;
    let url = cluster.create_database("maps")?;
    assert_eq!(
        url,
        format!("postgres://deog@127.0.0.1:{}/maps", cluster.port())
    );
    assert_eq!(cluster.psql("maps", "SELECT 1")?, "1");
    cluster.psql(
        "maps",
        "CREATE TABLE tiles (key bigint PRIMARY KEY, cells bytea)",
    )?;
    cluster.psql("maps", "INSERT INTO tiles VALUES (42, '\\x0102')")?;

    let port = cluster.port();
    cluster.kill()?;
    cluster.kill()?;
    assert!(
        cluster.psql("maps", "SELECT 1").is_err(),
        "the server is gone"
    );
    cluster.restart()?;
    assert_eq!(cluster.port(), port);
    assert_eq!(
        cluster.psql("maps", "SELECT key, cells FROM tiles")?,
        "42|\\x0102"
    );

    cluster.stop()?;
    cluster.stop()?;
    cluster.restart()?;
    assert_eq!(cluster.psql("maps", "SELECT count(*) FROM tiles")?, "1");
    cluster.stop()?;
    Ok(())
}

#[test]
fn options_reach_the_server_and_drop_removes_the_folder() -> anyhow::Result<()> {
    let options = ClusterOptions {
        fsync: false,
        synchronous_commit: false,
        extra_settings: vec![("work_mem".into(), "8MB".into())],
        ..ClusterOptions::default()
    };
    let cluster = LocalCluster::start_with(&options)?;
    assert_eq!(cluster.psql("postgres", "SHOW fsync")?, "off");
    assert_eq!(cluster.psql("postgres", "SHOW synchronous_commit")?, "off");
    assert_eq!(cluster.psql("postgres", "SHOW work_mem")?, "8MB");
    assert_eq!(cluster.psql("postgres", "SELECT current_user")?, "deog");

    let data_dir = cluster.data_dir().to_path_buf();
    let port = cluster.port();
    assert!(data_dir.join("PG_VERSION").is_file());
    drop(cluster);
    assert!(!data_dir.exists(), "{} is left behind", data_dir.display());
    assert!(!accepts(port), "port {port} still accepts connections");
    Ok(())
}

#[test]
fn creating_a_database_twice_is_an_error() -> anyhow::Result<()> {
    let cluster = LocalCluster::start()?;
    cluster.create_database("twice")?;
    match cluster.create_database("twice") {
        Err(ClusterError::Command { stderr, .. }) => {
            assert!(stderr.contains("already exists"), "{stderr}")
        }
        other => bail!("expected a command error, got {other:?}"),
    }
    Ok(())
}

#[test]
fn a_taken_port_is_reported_with_the_servers_log() -> anyhow::Result<()> {
    let holder = std::net::TcpListener::bind("127.0.0.1:0")?;
    let options = ClusterOptions {
        port: Some(holder.local_addr()?.port()),
        ..ClusterOptions::default()
    };
    match LocalCluster::start_with(&options) {
        Err(ClusterError::NotReady { log_tail, .. }) => {
            assert!(log_tail.contains("Address already in use"), "{log_tail}");
        }
        other => bail!("expected the server not to start, got {other:?}"),
    }
    Ok(())
}

/// Set in the child process of the next test.
const CHILD_VAR: &str = "DEOG_PG_CLUSTER_TEST_CHILD";
const CHILD_TEST: &str = "child_holds_a_cluster_until_killed";
/// How the child's line reporting its cluster starts.
const REPORT: &str = "child's cluster: ";

#[test]
fn a_cluster_dies_with_the_process_that_started_it() -> anyhow::Result<()> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(["--exact", CHILD_TEST, "--nocapture", "--test-threads=1"])
        .env(CHILD_VAR, "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .context("re-running this test binary")?;
    let stdout = child.stdout.take().context("the child's stdout")?;
    let (lines, received) = mpsc::channel();
    thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if lines.send(line).is_err() {
                break;
            }
        }
    });

    let deadline = Instant::now() + Duration::from_secs(60);
    let (port, data_dir) = loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = match received.recv_timeout(left) {
            Ok(line) => line,
            Err(error) => {
                let _ = child.kill();
                let _ = child.wait();
                bail!("the child did not report its cluster: {error}");
            }
        };
        // libtest prints the test's name on the same line, before it.
        if let Some((_, report)) = line.split_once(REPORT) {
            let (port, data_dir) = report.split_once(' ').context("port and folder")?;
            break (port.parse::<u16>()?, PathBuf::from(data_dir));
        }
    };
    assert!(accepts(port), "the child's cluster is up");

    child.kill()?; // SIGKILL: no destructor runs.
    child.wait()?;

    let deadline = Instant::now() + Duration::from_secs(10);
    while accepts(port) || data_dir.exists() {
        if Instant::now() >= deadline {
            bail!(
                "10 s after the child died: port {port} accepts: {}, {} exists: {}",
                accepts(port),
                data_dir.display(),
                data_dir.exists()
            );
        }
        thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

/// Does nothing unless run as the child of the test above: then starts a
/// cluster, reports it, and waits to be killed.
#[test]
fn child_holds_a_cluster_until_killed() -> anyhow::Result<()> {
    if std::env::var_os(CHILD_VAR).is_none() {
        return Ok(());
    }
    let cluster = LocalCluster::start()?;
    println!(
        "{REPORT}{} {}",
        cluster.port(),
        cluster.data_dir().display()
    );
    // Bounded, should the parent never kill us.
    thread::sleep(Duration::from_secs(60));
    Ok(())
}

fn accepts(port: u16) -> bool {
    let address = SocketAddr::from(([127, 0, 0, 1], port));
    TcpStream::connect_timeout(&address, Duration::from_secs(1)).is_ok()
}

#[test]
fn clusters_after_the_first_start_from_its_template_and_are_their_own() -> anyhow::Result<()> {
    let first = LocalCluster::start()?;
    // The first start (this one, or another test's) left the template.
    let templates: Vec<PathBuf> = [PathBuf::from("/tmp"), std::env::temp_dir()]
        .iter()
        .filter_map(|dir| std::fs::read_dir(dir).ok())
        .flatten()
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|path| {
            path.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("deog-pg-template"))
                && path.join("PG_VERSION").is_file()
        })
        .collect();
    assert!(!templates.is_empty(), "no template in the temporary folder");

    let second = LocalCluster::start()?;
    assert!(
        second.from_template(),
        "the second cluster ran initdb rather than copying the template"
    );
    assert_ne!(first.data_dir(), second.data_dir());
    first.create_database("only_in_the_first")?;
    second.create_database("maps")?;
    assert_eq!(second.psql("maps", "SELECT 1")?, "1");
    let databases = "SELECT count(*) FROM pg_database WHERE datname = 'only_in_the_first'";
    assert_eq!(first.psql("postgres", databases)?, "1");
    assert_eq!(second.psql("postgres", databases)?, "0");
    Ok(())
}
