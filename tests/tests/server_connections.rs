//! The map server against clients that connect and say nothing, and more
//! of them than it can hold, through the real `deog server` process on
//! 127.0.0.1: silent connections are closed after the handshake timeout,
//! connections over `--max-connections` are closed at once, silent ones
//! give their place to a newcomer, and a process out of file descriptors
//! waits between accepts rather than spinning, serving again once
//! descriptors are free. The simulator (`deog sim`) holds its connections
//! the same way.

use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, health_status};

/// Whether the server closed `stream` (end of file or a reset) within
/// `within`, reading past what it sends first (its HTTP/2 settings); false
/// if it was still open then.
fn closed_within(stream: &mut TcpStream, within: Duration) -> bool {
    let deadline = Instant::now() + within;
    let mut buffer = [0u8; 256];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return false;
        }
        stream.set_read_timeout(Some(left)).expect("read timeout");
        match stream.read(&mut buffer) {
            Ok(0) => return true,
            Ok(_) => continue,
            Err(e) => {
                return !matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                );
            }
        }
    }
}

/// A connection that has spoken: it sent an HTTP/2 client preface (and
/// then nothing), so the server holds it as it holds any client's.
fn speaking(addr: std::net::SocketAddr) -> TcpStream {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .write_all(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n")
        .expect("send the preface");
    stream
}

/// Whether a real client gets an answer from the server within `within`.
async fn answers_within(server: &ServerProcess, within: Duration) -> bool {
    let attempt = async {
        let client = MapClient::connect(ClientConfig::new(server.addr.to_string())).await?;
        client.robots().await
    };
    matches!(tokio::time::timeout(within, attempt).await, Ok(Ok(_)))
}

/// Whether a real client is served again within about a minute, asking
/// every 200 ms (bounded: 30 tries).
async fn serves_again(server: &ServerProcess) -> bool {
    for _ in 0..30 {
        if answers_within(server, Duration::from_secs(2)).await {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    false
}

/// CPU seconds (user and system) the process has used.
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("/proc stat");
    // The fields after the command's closing parenthesis; utime and stime
    // are the 14th and 15th of the whole line, in clock ticks (100 a second).
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .expect("stat format")
        .1
        .split_whitespace()
        .collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    ticks / 100.0
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_connection_is_closed_after_the_handshake_timeout() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(data.path(), &["--handshake-timeout-s", "0.5"]).await;
    let mut silent = TcpStream::connect(server.addr).expect("connect");
    let started = Instant::now();
    let closed =
        tokio::task::block_in_place(|| closed_within(&mut silent, Duration::from_secs(10)));
    assert!(
        closed,
        "a connection that sent nothing was still open after 10 s"
    );
    assert!(
        started.elapsed() >= Duration::from_millis(400),
        "closed after {:?}, before its timeout",
        started.elapsed()
    );
    // A client that speaks is served as before.
    assert!(answers_within(&server, Duration::from_secs(10)).await);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connections_over_the_limit_are_closed_and_the_server_serves_again_once_they_go() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(
        data.path(),
        &["--max-connections", "3", "--handshake-timeout-s", "60"],
    )
    .await;
    // The readiness check's connection must be gone before the count.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let held: Vec<TcpStream> = (0..3).map(|_| speaking(server.addr)).collect();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut over = TcpStream::connect(server.addr).expect("the kernel accepts");
    let closed = tokio::task::block_in_place(|| closed_within(&mut over, Duration::from_secs(5)));
    assert!(
        closed,
        "a fourth connection was held beyond --max-connections 3"
    );
    assert!(
        !answers_within(&server, Duration::from_secs(2)).await,
        "a client was served with every connection taken"
    );
    drop(held);
    assert!(
        serves_again(&server).await,
        "the server did not serve again once connections closed"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silent_connections_filling_the_limit_give_their_places_to_newcomers() {
    let data = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(
        data.path(),
        &["--max-connections", "8", "--handshake-timeout-s", "60"],
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    // Far more silent sockets than places, as a client holding the limit
    // for the whole handshake timeout would open.
    let mut silent: Vec<TcpStream> = (0..40)
        .map(|_| TcpStream::connect(server.addr).expect("connect"))
        .collect();
    tokio::time::sleep(Duration::from_millis(300)).await;
    for attempt in 0..5 {
        assert!(
            answers_within(&server, Duration::from_secs(1)).await,
            "attempt {attempt}: a client was not served within 1 s beside 40 silent sockets"
        );
        // The silent ones come back at once.
        silent.extend((0..8).map(|_| TcpStream::connect(server.addr).expect("connect")));
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let first = &mut silent[0];
    assert!(
        tokio::task::block_in_place(|| closed_within(first, Duration::from_secs(2))),
        "the connection silent longest was still held"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn out_of_file_descriptors_the_server_waits_instead_of_spinning() {
    let data = tempfile::tempdir().expect("temp dir");
    let server =
        ServerProcess::start_with_open_files(data.path(), &["--handshake-timeout-s", "60"], 64)
            .await;
    // More connections than the process has descriptors for: the ones it
    // cannot accept wait in the kernel's backlog.
    let held: Vec<TcpStream> = (0..80)
        .map(|_| TcpStream::connect(server.addr).expect("connect"))
        .collect();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let before = cpu_seconds(server.pid());
    tokio::time::sleep(Duration::from_secs(2)).await;
    let used = cpu_seconds(server.pid()) - before;
    assert!(
        used < 0.5,
        "the server used {used:.2} CPU seconds in 2 s while out of descriptors"
    );
    drop(held);
    assert!(
        serves_again(&server).await,
        "the server did not serve again once descriptors were free"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_simulator_closes_silent_connections_and_those_over_its_limit() {
    let sim = ServerProcess::start_sim(
        "map2",
        &["--max-connections", "2", "--handshake-timeout-s", "0.5"],
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut silent = TcpStream::connect(sim.addr).expect("connect");
    let held = speaking(sim.addr);
    tokio::time::sleep(Duration::from_millis(100)).await;
    // The third takes the silent one's place …
    let mut newcomer = TcpStream::connect(sim.addr).expect("the kernel accepts");
    let started = Instant::now();
    let silent_closed =
        tokio::task::block_in_place(|| closed_within(&mut silent, Duration::from_millis(400)));
    assert!(
        silent_closed,
        "a silent connection kept its place from a newcomer"
    );
    // … and speaks no more than it did: it is closed after its timeout.
    let newcomer_closed =
        tokio::task::block_in_place(|| closed_within(&mut newcomer, Duration::from_secs(10)));
    assert!(
        newcomer_closed && started.elapsed() >= Duration::from_millis(300),
        "the silent newcomer: closed {newcomer_closed} after {:?}",
        started.elapsed()
    );
    // With both places held by connections that spoke, one more is
    // closed at once.
    let second = speaking(sim.addr);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut over = TcpStream::connect(sim.addr).expect("the kernel accepts");
    assert!(
        tokio::task::block_in_place(|| closed_within(&mut over, Duration::from_millis(400))),
        "a third connection was held beyond --max-connections 2"
    );
    drop(held);
    drop(second);
    // Both silent ones are gone after their timeout: a client is served.
    let mut served = false;
    for _ in 0..30 {
        if health_status(&sim.url(), "deog.v1.RobotService")
            .await
            .is_some()
        {
            served = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    assert!(served, "the simulator did not serve again");
}
