//! Running the simulator's `RobotService` on a listener until a shutdown
//! future resolves: optionally behind the map server's bearer-token check
//! and with TLS (both from `deog-proto`), with caps on robots and watch
//! streams, and the map server's bounds on connections (`deog-proto`'s
//! `connection`).

use std::future::Future;
use std::time::Duration;

use deog_proto::auth::BearerAuth;
use deog_proto::connection::{self, ConnectionLimits};
use deog_proto::tls::{TlsIdentity, error_chain};
use deog_proto::v1::robot_service_server::RobotServiceServer;
use tokio::net::TcpListener;
use tokio_util::sync::CancellationToken;
use tonic::service::interceptor::InterceptedService;

use crate::error::SimError;
use crate::service::SimServer;
use crate::simulation::Simulation;

/// The gRPC name of the robot service, as health reports it.
pub const ROBOT_SERVICE_NAME: &str = "deog.v1.RobotService";

/// The smallest request limit [`serve_sim`] takes: room for any sane
/// request.
pub const MIN_MESSAGE_BYTES: usize = 1024;

/// The most robots [`SimServeConfig::max_robots`] allows: each robot costs
/// every physics step, and past a few thousand the world falls behind real
/// time.
pub const MAX_ROBOTS_LIMIT: usize = 4096;

/// The most watch streams [`SimServeConfig::max_watchers`] allows.
pub const MAX_WATCHERS_LIMIT: usize = 65_536;

/// How the simulator serves.
#[derive(Debug, Clone)]
pub struct SimServeConfig {
    /// Simulated seconds per wall-clock second.
    pub speed: f64,
    /// Wall-clock time between two advances of the clock.
    pub tick: Duration,
    /// Messages buffered per watch stream.
    pub stream_buffer: usize,
    /// Largest request accepted, bytes, at least [`MIN_MESSAGE_BYTES`]
    /// (requests are small; this stops absurd ones early).
    pub max_message_bytes: usize,
    /// How long open calls may take to finish after shutdown begins.
    pub shutdown_grace: Duration,
    /// Robots the world may hold, 1 to [`MAX_ROBOTS_LIMIT`]; a spawn past
    /// it is `RESOURCE_EXHAUSTED`.
    pub max_robots: usize,
    /// Watch streams open at once, 1 to [`MAX_WATCHERS_LIMIT`]; a watch
    /// past it is `RESOURCE_EXHAUSTED`.
    pub max_watchers: usize,
    /// Bearer token every `RobotService` call must carry; `None` turns
    /// authentication off. Health and reflection stay open.
    pub token: Option<String>,
    /// Serve TLS with this identity; `None` serves plain HTTP/2.
    pub tls: Option<TlsIdentity>,
    /// How many connections are held, and how long a new one may stay
    /// silent (as the map server's).
    pub connections: ConnectionLimits,
    /// Calls open at once on one connection; a client asking more waits
    /// (HTTP/2's own limit, announced to it).
    pub max_streams_per_connection: u32,
}

impl Default for SimServeConfig {
    fn default() -> Self {
        Self {
            speed: 1.0,
            tick: Duration::from_millis(5),
            stream_buffer: 64,
            max_message_bytes: 64 << 10,
            shutdown_grace: Duration::from_secs(3),
            max_robots: 64,
            max_watchers: 256,
            token: None,
            tls: None,
            connections: ConnectionLimits::default(),
            max_streams_per_connection: 256,
        }
    }
}

impl SimServeConfig {
    /// Checks every figure; the error names the field.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 1000.0) {
            return Err(SimError::invalid(
                "speed",
                format!("must be in (0, 1000], got {}", self.speed),
            ));
        }
        if self.max_message_bytes < MIN_MESSAGE_BYTES {
            return Err(SimError::invalid(
                "max_message_bytes",
                format!(
                    "must be at least {MIN_MESSAGE_BYTES} bytes, got {}",
                    self.max_message_bytes
                ),
            ));
        }
        if !(1..=MAX_ROBOTS_LIMIT).contains(&self.max_robots) {
            return Err(SimError::invalid(
                "max_robots",
                format!("must be 1 to {MAX_ROBOTS_LIMIT}, got {}", self.max_robots),
            ));
        }
        if !(1..=MAX_WATCHERS_LIMIT).contains(&self.max_watchers) {
            return Err(SimError::invalid(
                "max_watchers",
                format!(
                    "must be 1 to {MAX_WATCHERS_LIMIT}, got {}",
                    self.max_watchers
                ),
            ));
        }
        if self.connections.max_connections == 0 {
            return Err(SimError::invalid("max_connections", "must be at least 1"));
        }
        if self.max_streams_per_connection == 0 {
            return Err(SimError::invalid(
                "max_streams_per_connection",
                "must be at least 1",
            ));
        }
        if self.token.as_deref().is_some_and(|t| t.trim().is_empty()) {
            return Err(SimError::invalid("token", "must not be empty"));
        }
        Ok(())
    }
}

/// Serves `sim` on `listener` with health and reflection until `shutdown`
/// resolves.
pub async fn serve_sim(
    sim: Simulation,
    listener: TcpListener,
    config: SimServeConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SimError> {
    let stop = CancellationToken::new();
    let server = SimServer::new(sim, config, stop.clone())?;
    serve_sim_server(server, stop, listener, shutdown).await
}

/// Serves `server` (made with `stop` as its shutdown token) on `listener`
/// until `shutdown` resolves; for callers that keep a handle on the server,
/// as the tests do to count its watch channels.
pub async fn serve_sim_server(
    server: SimServer,
    stop: CancellationToken,
    listener: TcpListener,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SimError> {
    let config = server.config().clone();
    // TLS first: a bad certificate or key starts nothing.
    let mut builder =
        connection::server_builder(config.max_streams_per_connection, config.tls.as_ref())
            .map_err(SimError::Tls)?;
    // At most two sonar periods per tick: a stalled process slows the world
    // instead of skipping frames.
    let max_step = Duration::from_millis(200);
    let clock = tokio::spawn(server.clone().run_clock(config.tick, max_step));

    let (health, health_service) = deog_proto::health::health_service();
    health.set_service_status(ROBOT_SERVICE_NAME, tonic_health::ServingStatus::Serving);
    // Both versions of reflection, as the map server serves them.
    let reflection = deog_proto::reflection::Reflection::new(
        &[
            deog_proto::FILE_DESCRIPTOR_SET,
            tonic_health::pb::FILE_DESCRIPTOR_SET,
        ],
        &[
            ROBOT_SERVICE_NAME,
            "grpc.health.v1.Health",
            deog_proto::reflection::V1_SERVICE_NAME,
            deog_proto::reflection::V1ALPHA_SERVICE_NAME,
        ],
    )
    .map_err(|e| SimError::Serve(e.to_string()))?;
    // tonic's own decoder limit is a backstop well above ours, so that an
    // oversized request reaches the handlers' check and gets an answer
    // naming it, as the map server does.
    let transport_limit = config
        .max_message_bytes
        .saturating_mul(2)
        .saturating_add(1 << 20);
    let service = InterceptedService::new(
        RobotServiceServer::new(server).max_decoding_message_size(transport_limit),
        BearerAuth::new(config.token.clone()),
    );

    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let cut_connections = CancellationToken::new();
    let incoming = connection::incoming(listener, cut_connections.clone(), config.connections);
    let serving = builder
        .add_service(health_service)
        .add_service(reflection.v1())
        .add_service(reflection.v1alpha())
        .add_service(service)
        .serve_with_incoming_shutdown(incoming, async {
            let _ = stop_rx.await;
        });
    tokio::pin!(serving);
    let result = tokio::select! {
        result = &mut serving => result,
        () = shutdown => {
            tracing::info!("shutting down the simulator");
            health.set_service_status(ROBOT_SERVICE_NAME, tonic_health::ServingStatus::NotServing);
            stop.cancel();
            let _ = stop_tx.send(());
            match tokio::time::timeout(config.shutdown_grace, &mut serving).await {
                Ok(result) => result,
                Err(_) => {
                    tracing::warn!("calls still open after the grace period; closing them");
                    cut_connections.cancel();
                    let _ = tokio::time::timeout(Duration::from_secs(1), &mut serving).await;
                    Ok(())
                }
            }
        }
    };
    stop.cancel();
    let _ = clock.await;
    result.map_err(|e| SimError::Serve(error_chain(&e)))
}
