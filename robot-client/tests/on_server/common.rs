//! A map server in-process on 127.0.0.1 over a sled directory in a temp
//! dir, for the client's tests.

use std::sync::Arc;

use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use deog_server::{ServerConfig, SledConfig, SledStore};
use tokio::sync::oneshot;

/// A running map server and a client of it; stopped when dropped.
pub struct Server {
    /// A client connected to it.
    pub client: MapClient,
    stop: Option<oneshot::Sender<()>>,
    _dir: tempfile::TempDir,
}

impl Server {
    /// Starts a server with `config` on a free loopback port.
    pub async fn start(config: ServerConfig) -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let store = SledStore::open(&SledConfig::new(dir.path().join("store"))).expect("store");
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let (stop, stopped) = oneshot::channel::<()>();
        tokio::spawn(deog_server::serve(
            Arc::new(store),
            listener,
            config,
            async {
                let _ = stopped.await;
            },
        ));
        let client = MapClient::connect(ClientConfig::new(addr.to_string()))
            .await
            .expect("connect");
        Self {
            client,
            stop: Some(stop),
            _dir: dir,
        }
    }

    /// Starts a server with `config` and creates map `name` on it, with
    /// tiles of `tile_size` cells a side.
    pub async fn with_map(config: ServerConfig, name: &str, tile_size: u32) -> Self {
        let server = Self::start(config).await;
        server
            .client
            .ensure_map(pb::CreateMapRequest {
                name: name.into(),
                tile_size,
                ..Default::default()
            })
            .await
            .expect("map");
        server
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}
