//! `deog server`: the map server process.

use crate::store_location::StoreLocation;
use anyhow::{Context, Result};
use clap::Args;
use deog_server::{ConnectionLimits, Limits, ReadStreamLimits, ServerConfig, Store};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// Options of `deog server`.
#[derive(Debug, Args)]
pub struct ServerArgs {
    /// Address to listen on (port 0 picks a free port, printed at start).
    #[arg(long, env = "DEOG_LISTEN", default_value = "127.0.0.1:50051")]
    listen: SocketAddr,
    /// Data directory of the embedded store; created if missing.
    #[arg(long, env = "DEOG_DATA", default_value = "deog-data")]
    data: PathBuf,
    /// The store: a data directory (as --data), or a PostgreSQL database,
    /// `postgres://USER@HOST/DB`, which several servers may share. Give
    /// several hosts and `target_session_attrs=read-write` to follow a
    /// failover. The server creates and migrates the schema.
    #[arg(long, env = "DEOG_STORE")]
    store: Option<String>,
    /// File holding the bearer token every map call must carry.
    #[arg(long, env = "DEOG_TOKEN_FILE")]
    token_file: Option<PathBuf>,
    /// TLS certificate chain (PEM); needs --tls-key.
    #[arg(long, env = "DEOG_TLS_CERT", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// TLS private key (PEM); needs --tls-cert.
    #[arg(long, env = "DEOG_TLS_KEY", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Page cache of the store, MiB: what bounds the server's memory.
    #[arg(long, env = "DEOG_CACHE_MB", default_value_t = 64)]
    cache_mb: u64,
    /// Largest request message accepted, bytes.
    #[arg(long, env = "DEOG_MAX_MESSAGE_BYTES", default_value_t = Limits::default().max_message_bytes)]
    max_message_bytes: usize,
    /// Connections held at once; one more is closed as soon as it is
    /// accepted.
    #[arg(long, env = "DEOG_MAX_CONNECTIONS", default_value_t = ConnectionLimits::default().max_connections)]
    max_connections: usize,
    /// Seconds a new connection has to start speaking (HTTP/2 or TLS)
    /// before it is closed.
    #[arg(long, env = "DEOG_HANDSHAKE_TIMEOUT_S", default_value_t = ConnectionLimits::default().handshake_timeout.as_secs_f64())]
    handshake_timeout_s: f64,
    /// Calls open at once on one connection; a client asking more waits.
    #[arg(long, env = "DEOG_MAX_STREAMS_PER_CONNECTION", default_value_t = ServerConfig::default().max_streams_per_connection)]
    max_streams_per_connection: u32,
    /// Read streams (GetTiles, ReadFrames, ReadPoses) at once; one more is
    /// refused with RESOURCE_EXHAUSTED.
    #[arg(long, env = "DEOG_MAX_READ_STREAMS", default_value_t = ReadStreamLimits::default().max_streams)]
    max_read_streams: usize,
    /// Read streams one connection may hold at once; one more is refused
    /// with RESOURCE_EXHAUSTED, so that one client leaves the others
    /// theirs.
    #[arg(long, env = "DEOG_MAX_READ_STREAMS_PER_CONNECTION", default_value_t = ReadStreamLimits::default().max_streams_per_connection)]
    max_read_streams_per_connection: usize,
    /// Seconds a read stream waits for a client that takes nothing before
    /// it ends.
    #[arg(long, env = "DEOG_STALLED_READ_TIMEOUT_S", default_value_t = ReadStreamLimits::default().stalled_timeout.as_secs_f64())]
    stalled_read_timeout_s: f64,
}

/// Runs the server until ctrl-c or SIGTERM.
pub fn run(args: ServerArgs) -> Result<()> {
    let connections =
        crate::connection::connection_limits(args.max_connections, args.handshake_timeout_s)?;
    anyhow::ensure!(
        args.max_read_streams >= 1,
        "--max-read-streams must be at least 1, got {}",
        args.max_read_streams
    );
    anyhow::ensure!(
        args.max_read_streams_per_connection >= 1,
        "--max-read-streams-per-connection must be at least 1, got {}",
        args.max_read_streams_per_connection
    );
    anyhow::ensure!(
        args.stalled_read_timeout_s.is_finite()
            && (0.1..=3600.0).contains(&args.stalled_read_timeout_s),
        "--stalled-read-timeout-s must be within 0.1 and 3600 seconds, got {}",
        args.stalled_read_timeout_s
    );
    anyhow::ensure!(
        args.max_streams_per_connection >= 1,
        "--max-streams-per-connection must be at least 1, got {}",
        args.max_streams_per_connection
    );
    let token = args
        .token_file
        .as_deref()
        .map(crate::connection::read_token_file)
        .transpose()?;
    let tls =
        crate::connection::read_tls_identity(args.tls_cert.as_deref(), args.tls_key.as_deref())?;
    let config = ServerConfig {
        limits: Limits {
            max_message_bytes: args.max_message_bytes,
            ..Limits::default()
        },
        token,
        tls,
        connections,
        max_streams_per_connection: args.max_streams_per_connection,
        reads: ReadStreamLimits {
            max_streams: args.max_read_streams,
            max_streams_per_connection: args.max_read_streams_per_connection,
            stalled_timeout: Duration::from_secs_f64(args.stalled_read_timeout_s),
        },
        ..ServerConfig::default()
    };
    let location = match &args.store {
        Some(store) => StoreLocation::parse(store)?,
        None => StoreLocation::Directory(args.data.clone()),
    };
    match &location {
        StoreLocation::Directory(path) => {
            let store = StoreLocation::open_sled(path, args.cache_mb, "--data")?;
            serve(store, &location, args.listen, config)
        }
        StoreLocation::Postgres(url) => {
            let store = StoreLocation::open_postgres(url, "--store")?;
            serve(store, &location, args.listen, config)
        }
    }
}

fn serve<S: Store>(
    store: S,
    location: &StoreLocation,
    listen: SocketAddr,
    config: ServerConfig,
) -> Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("binding {listen}"))?;
        let addr = listener.local_addr()?;
        tracing::info!(
            %addr,
            store = %location.describe(),
            tls = config.tls.is_some(),
            auth = config.token.is_some(),
            "map server listening"
        );
        deog_server::serve(
            Arc::new(store),
            listener,
            config,
            deog_harness::shutdown_signal(),
        )
        .await?;
        Ok(())
    })
}
