//! Running the simulator's `RobotService` on a listener until a shutdown
//! future resolves.

use std::future::Future;
use std::time::Duration;

use deog_proto::v1::robot_service_server::RobotServiceServer;
use tokio::net::TcpListener;
use tokio_stream::wrappers::TcpListenerStream;
use tokio_util::sync::CancellationToken;
use tonic::transport::Server;

use crate::error::SimError;
use crate::service::SimServer;
use crate::simulation::Simulation;

/// The gRPC name of the robot service, as health reports it.
pub const ROBOT_SERVICE_NAME: &str = "deog.v1.RobotService";

/// The smallest request limit [`serve_sim`] takes: room for any sane
/// request.
pub const MIN_MESSAGE_BYTES: usize = 1024;

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
}

impl Default for SimServeConfig {
    fn default() -> Self {
        Self {
            speed: 1.0,
            tick: Duration::from_millis(5),
            stream_buffer: 64,
            max_message_bytes: 64 << 10,
            shutdown_grace: Duration::from_secs(3),
        }
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
    if !(config.speed.is_finite() && config.speed > 0.0 && config.speed <= 1000.0) {
        return Err(SimError::invalid(
            "speed",
            format!("must be in (0, 1000], got {}", config.speed),
        ));
    }
    if config.max_message_bytes < MIN_MESSAGE_BYTES {
        return Err(SimError::invalid(
            "max_message_bytes",
            format!(
                "must be at least {MIN_MESSAGE_BYTES} bytes, got {}",
                config.max_message_bytes
            ),
        ));
    }
    let stop = CancellationToken::new();
    let server = SimServer::new(
        sim,
        config.speed,
        config.stream_buffer,
        config.max_message_bytes,
        stop.clone(),
    );
    // At most two sonar periods per tick: a stalled process slows the world
    // instead of skipping frames.
    let max_step = Duration::from_millis(200);
    let clock = tokio::spawn(server.clone().run_clock(config.tick, max_step));

    let (health, health_service) = tonic_health::server::health_reporter();
    health
        .set_service_status(ROBOT_SERVICE_NAME, tonic_health::ServingStatus::Serving)
        .await;
    // Both versions of reflection, as the map server serves them.
    let reflection_builder = || {
        tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(deog_proto::FILE_DESCRIPTOR_SET)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
            .with_service_name(ROBOT_SERVICE_NAME)
            .with_service_name("grpc.health.v1.Health")
            .with_service_name("grpc.reflection.v1.ServerReflection")
            .with_service_name("grpc.reflection.v1alpha.ServerReflection")
    };
    let reflection = reflection_builder()
        .build_v1()
        .map_err(|e| SimError::Serve(e.to_string()))?;
    let reflection_v1alpha = reflection_builder()
        .build_v1alpha()
        .map_err(|e| SimError::Serve(e.to_string()))?;
    // tonic's own decoder limit is a backstop well above ours, so that an
    // oversized request reaches the handlers' check and gets an answer
    // naming it, as the map server does.
    let transport_limit = config
        .max_message_bytes
        .saturating_mul(2)
        .saturating_add(1 << 20);
    let service = RobotServiceServer::new(server).max_decoding_message_size(transport_limit);

    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let serving = Server::builder()
        .add_service(health_service)
        .add_service(reflection)
        .add_service(reflection_v1alpha)
        .add_service(service)
        .serve_with_incoming_shutdown(TcpListenerStream::new(listener), async {
            let _ = stop_rx.await;
        });
    tokio::pin!(serving);
    let result = tokio::select! {
        result = &mut serving => result,
        () = shutdown => {
            tracing::info!("shutting down the simulator");
            health.set_service_status(ROBOT_SERVICE_NAME, tonic_health::ServingStatus::NotServing).await;
            stop.cancel();
            let _ = stop_tx.send(());
            match tokio::time::timeout(config.shutdown_grace, &mut serving).await {
                Ok(result) => result,
                Err(_) => {
                    tracing::warn!("calls still open after the grace period");
                    Ok(())
                }
            }
        }
    };
    stop.cancel();
    let _ = clock.await;
    result.map_err(|e| SimError::Serve(e.to_string()))
}
