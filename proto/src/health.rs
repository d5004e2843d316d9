//! The gRPC health service (`grpc.health.v1.Health`) both servers serve,
//! to the protocol's word: `Check` on a service it does not know is
//! NOT_FOUND, while `Watch` on one streams SERVICE_UNKNOWN and stays open,
//! sending the service's status once it becomes known and each time it
//! changes. (tonic-health ends such a watch with NOT_FOUND.)

use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::{mpsc, watch};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};
use tonic_health::pb::health_check_response::ServingStatus as WireStatus;
use tonic_health::pb::health_server::{Health, HealthServer};
use tonic_health::pb::{HealthCheckRequest, HealthCheckResponse};

pub use tonic_health::ServingStatus;

/// Messages a watcher may fall behind by before it waits: statuses only
/// change a few times in a server's life.
const WATCH_BUFFER: usize = 4;

type Statuses = HashMap<String, ServingStatus>;

/// Sets the statuses the health service reports; cheap to clone.
#[derive(Debug, Clone)]
pub struct HealthReporter {
    statuses: Arc<watch::Sender<Statuses>>,
}

impl HealthReporter {
    /// Sets `service`'s status ("" is the server as a whole); watchers of
    /// it hear of the change.
    pub fn set_service_status(&self, service: &str, status: ServingStatus) {
        self.statuses.send_modify(|statuses| {
            statuses.insert(service.to_owned(), status);
        });
    }
}

/// The health service, its statuses set through the [`HealthReporter`].
#[derive(Debug, Clone)]
pub struct HealthService {
    statuses: watch::Receiver<Statuses>,
}

/// A reporter and the service it reports through; the server as a whole
/// ("") is SERVING.
pub fn health_service() -> (HealthReporter, HealthServer<HealthService>) {
    let statuses = Statuses::from([(String::new(), ServingStatus::Serving)]);
    let (sender, receiver) = watch::channel(statuses);
    let reporter = HealthReporter {
        statuses: Arc::new(sender),
    };
    (
        reporter,
        HealthServer::new(HealthService { statuses: receiver }),
    )
}

fn wire(status: Option<ServingStatus>) -> HealthCheckResponse {
    let status = match status {
        None => WireStatus::ServiceUnknown,
        Some(ServingStatus::Unknown) => WireStatus::Unknown,
        Some(ServingStatus::Serving) => WireStatus::Serving,
        Some(ServingStatus::NotServing) => WireStatus::NotServing,
    };
    HealthCheckResponse {
        status: status as i32,
    }
}

#[tonic::async_trait]
impl Health for HealthService {
    async fn check(
        &self,
        request: Request<HealthCheckRequest>,
    ) -> Result<Response<HealthCheckResponse>, Status> {
        let service = request.into_inner().service;
        match self.statuses.borrow().get(&service) {
            Some(status) => Ok(Response::new(wire(Some(*status)))),
            None => Err(Status::not_found(format!("no service {service:?} here"))),
        }
    }

    type WatchStream = ReceiverStream<Result<HealthCheckResponse, Status>>;

    async fn watch(
        &self,
        request: Request<HealthCheckRequest>,
    ) -> Result<Response<Self::WatchStream>, Status> {
        let service = request.into_inner().service;
        let mut statuses = self.statuses.clone();
        let (tx, rx) = mpsc::channel(WATCH_BUFFER);
        tokio::spawn(async move {
            let mut last = None;
            loop {
                let now = statuses.borrow_and_update().get(&service).copied();
                if last != Some(now) {
                    if tx.send(Ok(wire(now))).await.is_err() {
                        return;
                    }
                    last = Some(now);
                }
                tokio::select! {
                    changed = statuses.changed() => if changed.is_err() { return },
                    () = tx.closed() => return,
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }
}
