//! The hostile-client suite: stock grpcio (Python) against the real `deog
//! server` process on 127.0.0.1, knowing only its address
//! (`tests/scripts/hostile_client.py`): it learns the API by reflection,
//! then pipelines one-cell batches beside a watch on the same connection,
//! holds 70 unread read streams while another client reads, publishes a
//! poisoned frame, sends bytes that are no protobuf, and opens silent
//! sockets past `--max-connections`; the server's memory stays bounded.
//! Needs python3 with grpcio,
//! grpcio-reflection and grpcio-health-checking (`.ci/run` installs them).

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use deog_tests::{ServerProcess, require_python};

/// Batches the suite pipelines here: past the 5,294 acknowledgements after
/// which a connection was once closed, and quick (the script's default,
/// 100,000, takes about 30 s; the server's own suite pipelines 100,000).
const BATCHES: &str = "25000";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stock_grpcio_clients_behaving_badly_get_the_answers_the_protocol_gives() {
    require_python(
        "grpc, grpc_reflection, grpc_health",
        "grpcio grpcio-reflection grpcio-health-checking",
    );
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(data.path(), &["--max-connections", "8"]).await;
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join("hostile_client.py");
    let addr = server.addr.to_string();
    let run = tokio::task::spawn_blocking(move || {
        Command::new("python3")
            .arg(script)
            .args([addr.as_str(), "--batches", BATCHES])
            .output()
            .expect("python3 runs")
    });
    let out = tokio::time::timeout(Duration::from_secs(300), run)
        .await
        .expect("the suite ends within 5 minutes")
        .expect("the suite's thread");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        out.status.success() && stdout.contains("7 of 7 checks passed"),
        "the hostile-client suite failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Whatever the clients did, the server's memory stayed bounded (its
    // queues are: an update stream's 16 MiB, all streams' 256 MiB).
    let peak_mb = peak_rss_mb(server.pid());
    println!("server peak RSS {peak_mb:.0} MB");
    assert!(peak_mb < 400.0, "the server's peak RSS was {peak_mb:.0} MB");
}

/// The process's peak resident set (`VmHWM`), MB.
fn peak_rss_mb(pid: u32) -> f64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("/proc status");
    let kb: f64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmHWM:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in /proc status");
    kb / 1000.0
}
