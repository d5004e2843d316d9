//! `deog view`: serves a live web page of the system: the map as it grows,
//! the robots, their frames and their localizers' estimates.

use std::net::SocketAddr;

use anyhow::{Context, Result};
use clap::Args;
use deog_viewer::{TrackLimits, View, ViewConfig};
use tokio_util::sync::CancellationToken;

use crate::connection::ConnectionArgs;

/// Options of `deog view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Where the page is served (host:port; port 0 takes a free one).
    #[arg(long, env = "DEOG_VIEW_LISTEN", default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// The map shown when the page names none (default: the server's
    /// first). The page lists every map and switches between them.
    #[arg(long)]
    pub map: Option<String>,
    /// The simulator's address (host:port or a URL): true poses at the
    /// simulator's own rate rather than with each frame, and its world's
    /// name.
    #[arg(long, value_name = "ADDR")]
    pub sim: Option<String>,
    /// Also serve the live data over the Foxglove WebSocket protocol here
    /// (host:port, e.g. 127.0.0.1:8765): in Foxglove, Open connection,
    /// Foxglove WebSocket, ws://ADDR.
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<SocketAddr>,
    /// Points kept per robot path.
    #[arg(long, default_value_t = 4_000)]
    pub path_points: usize,
    #[command(flatten)]
    pub connection: ConnectionArgs,
}

/// Runs `deog view` until ctrl-c.
pub fn run(args: ViewArgs) -> Result<()> {
    anyhow::ensure!(
        (2..=1_000_000).contains(&args.path_points),
        "--path-points must be within 2 and 1000000, got {}",
        args.path_points
    );
    let server = args.connection.client_config()?.retrying_forever();
    let simulator = args.sim.as_deref().map(|addr| {
        let mut config = deog_robot_client::ClientConfig::simulator(addr.to_string());
        config.announce = true;
        config.retrying_forever()
    });
    let config = ViewConfig {
        server,
        simulator,
        listen: args.listen,
        map: args.map,
        limits: TrackLimits {
            path_points: args.path_points,
            ..TrackLimits::default()
        },
        foxglove: args.foxglove,
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async {
        let shutdown = CancellationToken::new();
        let view = View::bind(config, shutdown.clone()).await?;
        let addr = view.local_addr()?;
        println!("deog view: serving http://{addr}/");
        if let Some(foxglove) = view.foxglove_addr() {
            println!("deog view: Foxglove on ws://{foxglove}");
            tracing::info!(%foxglove, "serving Foxglove");
        }
        tracing::info!(%addr, "serving the view");
        let stop = shutdown.clone();
        let signal = deog_harness::shutdown_signal();
        tokio::spawn(async move {
            signal.await;
            stop.cancel();
        });
        view.run().await?;
        Ok(())
    })
}
