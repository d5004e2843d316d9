//! `deog view`: a live web page of a running system. The shared map as it
//! grows (tiles pushed as they change, never the whole map again), each
//! robot's true pose and path, its latest frame's sonar cones or laser
//! rays, each localizer's estimate with its covariance ellipse and its
//! converged or lost state, and kidnaps as they happen.
//!
//! # Layout
//! - [`state`]: pure. [`ViewState`] takes tiles, frames, true poses and
//!   estimates and says what each changed; shades, world beams, kidnaps
//!   and errors are worked out there.
//! - [`feeds`]: the followers of the map server (maps, robots, frames,
//!   estimates, tile events) and of the simulator, feeding the state.
//! - [`protocol`]: the JSON and binary messages the page is sent.
//! - [`web`]: the HTTP routes, the page's embedded files (`web/`), and one
//!   WebSocket connection per open page.
//! - [`foxglove`]: the same live data over the Foxglove WebSocket protocol
//!   (`--foxglove`), built by the pure [`foxglove_messages`].

pub mod feeds;
pub mod foxglove;
pub mod foxglove_messages;
pub mod protocol;
pub mod state;
pub mod web;

use std::net::SocketAddr;
use std::sync::Arc;

use deog_robot_client::{ClientConfig, ClientError, MapClient, SimClient};
use tokio::net::TcpListener;
use tokio_util::sync::CancellationToken;

pub use state::{TrackLimits, ViewState};

/// What can stop the view.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The listening address could not be taken.
    #[error("listening on {addr}: {source}")]
    Listen {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The map server or the simulator could not be reached.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// Serving the page failed.
    #[error("serving the page: {0}")]
    Serve(std::io::Error),
    /// The Foxglove WebSocket server could not start.
    #[error("serving Foxglove on {addr}: {source}")]
    Foxglove {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: ::foxglove::FoxgloveError,
    },
}

/// What the view follows and where it serves.
#[derive(Debug, Clone)]
pub struct ViewConfig {
    /// The map server.
    pub server: ClientConfig,
    /// The simulator, for true poses at its own rate and its world's name.
    pub simulator: Option<ClientConfig>,
    /// Where the page is served.
    pub listen: SocketAddr,
    /// The map shown when a page names none (else the server's first).
    pub map: Option<String>,
    /// What is kept per robot.
    pub limits: TrackLimits,
    /// Where the Foxglove WebSocket server listens, when one is wanted.
    pub foxglove: Option<SocketAddr>,
}

/// A view bound to its address, its followers not yet started.
pub struct View {
    listener: TcpListener,
    shared: Arc<Shared>,
    simulator: Option<SimClient>,
    foxglove: Option<crate::foxglove::FoxgloveServer>,
}

use feeds::Shared;

impl View {
    /// Connects to the map server (and the simulator) and takes the
    /// listening address.
    pub async fn bind(config: ViewConfig, shutdown: CancellationToken) -> Result<Self, ViewError> {
        // The address first: a port in use is said at once, not after the
        // servers were waited for.
        let listener =
            TcpListener::bind(config.listen)
                .await
                .map_err(|source| ViewError::Listen {
                    addr: config.listen,
                    source,
                })?;
        let foxglove = match config.foxglove {
            Some(addr) => Some(
                crate::foxglove::FoxgloveServer::start(addr)
                    .await
                    .map_err(|source| ViewError::Foxglove { addr, source })?,
            ),
            None => None,
        };
        let client = MapClient::connect(config.server).await?;
        let simulator = match config.simulator {
            Some(sim) => Some(SimClient::connect(sim).await?),
            None => None,
        };
        let shared = Shared::new(client, ViewState::new(config.limits), config.map, shutdown);
        Ok(Self {
            listener,
            shared,
            simulator,
            foxglove,
        })
    }

    /// The address the page is served on.
    pub fn local_addr(&self) -> Result<SocketAddr, ViewError> {
        self.listener.local_addr().map_err(ViewError::Serve)
    }

    /// The address the Foxglove WebSocket server listens on, when there is one.
    pub fn foxglove_addr(&self) -> Option<SocketAddr> {
        self.foxglove.as_ref().map(|f| f.local_addr())
    }

    /// Follows the system and serves the page until the shutdown token is
    /// cancelled.
    pub async fn run(self) -> Result<(), ViewError> {
        feeds::start(&self.shared, self.simulator);
        if let Some(foxglove) = self.foxglove {
            tokio::spawn(foxglove.run(Arc::clone(&self.shared)));
        }
        let shutdown = self.shared.shutdown.clone();
        axum::serve(self.listener, web::router(self.shared))
            .with_graceful_shutdown(async move { shutdown.cancelled().await })
            .await
            .map_err(ViewError::Serve)
    }
}
