//! Running the map server on a listener until a shutdown future resolves.

use crate::convert::Limits;
use crate::events::Events;
use crate::read_streams::ReadStreamLimits;
use crate::rigs::RigRegistry;
use crate::service::{MapServer, ServiceSettings};
use crate::store::{Store, StoreChange};
use crate::writer::{StoreHealth, Writer};
use deog_proto::auth::BearerAuth;
use deog_proto::connection::{self, ConnectionLimits};
use deog_proto::reflection;
use deog_proto::tls::{TlsError, TlsIdentity};
use deog_proto::v1::map_service_server::MapServiceServer;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;

/// How long the server waits, at start, to hear other servers' changes
/// before it serves anyway.
const FIRST_FOREIGN_CHANGE_WAIT: Duration = Duration::from_secs(5);

/// The gRPC name of the map service, as the health service reports it.
pub const MAP_SERVICE_NAME: &str = "deog.v1.MapService";
const HEALTH_SERVICE_NAME: &str = "grpc.health.v1.Health";

/// How the server runs.
#[derive(Debug, Clone)]
pub struct ServerConfig {
    /// Request limits.
    pub limits: Limits,
    /// Bearer token every map-service call must carry; `None` turns
    /// authentication off. Health and reflection stay open.
    pub token: Option<String>,
    /// Serve TLS with this identity; `None` serves plain HTTP/2.
    pub tls: Option<TlsIdentity>,
    /// Messages buffered per response stream.
    pub stream_buffer: usize,
    /// Events buffered per broadcast channel before a watcher is lagging.
    pub event_buffer: usize,
    /// Writes queued for the writer before senders wait.
    pub write_queue: usize,
    /// How long in-flight calls may take to finish after shutdown begins.
    pub shutdown_grace: Duration,
    /// How many connections are held, and how long a new one may stay
    /// silent.
    pub connections: ConnectionLimits,
    /// Streams (calls) open at once on one connection; a client asking
    /// more waits for one to end (HTTP/2's own limit, announced to it).
    pub max_streams_per_connection: u32,
    /// Read streams (GetTiles, ReadFrames, ReadPoses) at once, and how
    /// long one waits for a client that does not read.
    pub reads: ReadStreamLimits,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            limits: Limits::default(),
            token: None,
            tls: None,
            stream_buffer: 32,
            event_buffer: 1024,
            write_queue: 64,
            shutdown_grace: Duration::from_secs(5),
            connections: ConnectionLimits::default(),
            max_streams_per_connection: 256,
            reads: ReadStreamLimits::default(),
        }
    }
}

/// Why the server could not run.
#[derive(Debug, Error)]
pub enum ServeError {
    /// TLS could not be set up from the identity: what is wrong with the
    /// certificate or the key.
    #[error(transparent)]
    Tls(#[from] TlsError),
    /// The transport failed while serving.
    #[error("serving failed: {0}")]
    Transport(#[from] tonic::transport::Error),
    /// The writer thread could not be started.
    #[error("could not start the writer thread: {0}")]
    Writer(#[from] std::io::Error),
    /// The store's last flush at shutdown failed.
    #[error("the store's last flush failed: {0}")]
    FinalFlush(crate::error::StoreError),
    /// The stored rigs could not be read.
    #[error("reading the stored rigs: {0}")]
    Rigs(#[from] crate::error::StoreError),
}

/// Turns the writer's view of the store into the health service's status:
/// NOT_SERVING while the store cannot write, SERVING once it recovered.
/// Stops at shutdown, which sets NOT_SERVING for good.
async fn report_store_health(
    mut store: watch::Receiver<StoreHealth>,
    health: deog_proto::health::HealthReporter,
    shutdown: CancellationToken,
) {
    loop {
        tokio::select! {
            () = shutdown.cancelled() => return,
            changed = store.changed() => {
                if changed.is_err() {
                    return;
                }
            }
        }
        let status = match &*store.borrow_and_update() {
            StoreHealth::Writable => tonic_health::ServingStatus::Serving,
            StoreHealth::Failing { .. } => tonic_health::ServingStatus::NotServing,
        };
        if !shutdown.is_cancelled() {
            health.set_service_status(MAP_SERVICE_NAME, status);
        }
    }
}

/// Serves the map service, health and reflection on `listener` until
/// `shutdown` resolves; then stops long-lived streams, lets in-flight calls
/// finish (up to the grace period), and flushes the store.
pub async fn serve<S: Store>(
    store: Arc<S>,
    listener: TcpListener,
    config: ServerConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), ServeError> {
    // TLS first: a bad certificate or key leaves no writer thread behind.
    let mut builder =
        connection::server_builder(config.max_streams_per_connection, config.tls.as_ref())?;
    let rigs = Arc::new(RigRegistry::load(store.as_ref())?);
    let events = Arc::new(Events::new(config.event_buffer));
    let writer = Writer::start(store.clone(), events.clone(), config.write_queue)?;
    let stop_streams = CancellationToken::new();
    if let Some(mut feed) = store.foreign_changes() {
        // Serve once other servers' changes are heard: a watcher that came
        // earlier would be told at once to resync for nothing. The feed's
        // first resync marks that moment; a store that cannot be reached
        // yet does not hold the server up for long.
        let first = match tokio::time::timeout(FIRST_FOREIGN_CHANGE_WAIT, feed.recv()).await {
            Ok(Some(StoreChange::Resync)) | Err(_) => None,
            Ok(first) => first,
        };
        tokio::spawn(crate::foreign::relay(
            store.clone(),
            events.clone(),
            first,
            feed,
            stop_streams.clone(),
        ));
    }
    let service = MapServer::new(
        store,
        rigs,
        writer.handle(),
        events,
        ServiceSettings {
            limits: config.limits,
            stream_buffer: config.stream_buffer,
            reads: config.reads,
        },
        stop_streams.clone(),
    );
    let transport_limit = config.limits.transport_message_bytes();
    let map_service = tonic::service::interceptor::InterceptedService::new(
        MapServiceServer::new(service)
            .max_decoding_message_size(transport_limit)
            .max_encoding_message_size(usize::MAX),
        BearerAuth::new(config.token.clone()),
    );

    let (health, health_service) = deog_proto::health::health_service();
    health.set_service_status(MAP_SERVICE_NAME, tonic_health::ServingStatus::Serving);
    tokio::spawn(report_store_health(
        writer.health(),
        health.clone(),
        stop_streams.clone(),
    ));
    // Advertise exactly what this process serves: the deog descriptor set
    // also describes the simulator's service, which lives elsewhere.
    // Both versions of reflection: grpcurl asks v1, many tools (Python's
    // grpcio-reflection among them) v1alpha.
    let reflection = reflection::Reflection::new(
        &[
            deog_proto::FILE_DESCRIPTOR_SET,
            tonic_health::pb::FILE_DESCRIPTOR_SET,
        ],
        &[
            MAP_SERVICE_NAME,
            HEALTH_SERVICE_NAME,
            reflection::V1_SERVICE_NAME,
            reflection::V1ALPHA_SERVICE_NAME,
        ],
    )
    .map_err(|e| std::io::Error::other(e.to_string()))?;

    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let router = builder
        .add_service(health_service)
        .add_service(reflection.v1())
        .add_service(reflection.v1alpha())
        .add_service(map_service);
    let cut_connections = CancellationToken::new();
    let incoming = connection::incoming(listener, cut_connections.clone(), config.connections);
    let serving = router.serve_with_incoming_shutdown(incoming, async {
        let _ = stop_rx.await;
    });
    tokio::pin!(serving);
    let result = tokio::select! {
        result = &mut serving => result,
        () = shutdown => {
            tracing::info!("shutting down: finishing in-flight calls");
            health.set_service_status(MAP_SERVICE_NAME, tonic_health::ServingStatus::NotServing);
            stop_streams.cancel();
            let _ = stop_tx.send(());
            match tokio::time::timeout(config.shutdown_grace, &mut serving).await {
                Ok(result) => result,
                Err(_) => {
                    tracing::warn!("calls still open after the grace period; closing them");
                    cut_connections.cancel();
                    // Connections end at their next poll; give them a moment
                    // so that their tasks let go of the store.
                    let _ = tokio::time::timeout(Duration::from_secs(1), &mut serving).await;
                    Ok(())
                }
            }
        }
    };
    let flushed = writer.stop().await;
    match &flushed {
        Ok(()) => tracing::info!("store flushed; map server stopped"),
        Err(error) => tracing::error!(
            %error,
            "the store's last flush failed: writes not yet on disk are lost (none was acknowledged); map server stopped"
        ),
    }
    result.map_err(ServeError::from)?;
    flushed.map_err(ServeError::FinalFlush)
}
