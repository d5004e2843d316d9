//! A real map server on 127.0.0.1:0 over a store directory in a temp dir.
//!
//! Every test in `server/tests` opens its store through [`SuiteBackend`], so
//! the whole suite runs on one [`Store`] backend: sled today. A new backend
//! runs the same suite by implementing [`TestBackend`] (how it opens, and
//! after a restart reopens, a directory) and pointing `SuiteBackend` at it.
#![allow(dead_code)]

use deog_grid::TileKey;
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use deog_server::store::{
    ClientCursor, FrameWrite, MapRecord, MapWrite, RobotSummary, StoreChange, StoredTile,
    TileRange, Transaction,
};
use deog_server::{
    PostgresConfig, PostgresStore, ServerConfig, SledConfig, SledStore, Store, StoreError,
};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tonic::transport::Channel;

/// A store backend the suite can run on.
pub trait TestBackend {
    /// The store it opens (a [`Store`], or a box of one).
    type Store;
    /// Opens the store kept in `path`, creating it if missing; a restart
    /// reopens the same path and must find what was flushed there.
    fn open(path: &Path) -> Self::Store;
}

/// The embedded default.
pub struct Sled;

impl TestBackend for Sled {
    type Store = SledStore;

    fn open(path: &Path) -> SledStore {
        SledStore::open(&SledConfig::new(path)).expect("open sled store")
    }
}

/// PostgreSQL: a database of its own per store path, on the server
/// `DEOG_TEST_POSTGRES` names (a URL to its `postgres` database) or else
/// on a private server this test process starts; it stops with the
/// process.
pub struct Postgres;

impl TestBackend for Postgres {
    type Store = PostgresStore;

    fn open(path: &Path) -> PostgresStore {
        let url = postgres_database(path);
        PostgresStore::open(&PostgresConfig::new(url)).expect("open PostgreSQL store")
    }
}

/// The URL of the database standing for store `path`, created on first use.
pub fn postgres_database(path: &Path) -> String {
    static DATABASES: std::sync::Mutex<Vec<(PathBuf, String)>> = std::sync::Mutex::new(Vec::new());
    let mut databases = DATABASES.lock().expect("database list");
    if let Some((_, url)) = databases.iter().find(|(p, _)| p == path) {
        return url.clone();
    }
    let name = format!("deog_test_{}_{}", std::process::id(), databases.len() + 1);
    let url = create_postgres_database(&name);
    databases.push((path.to_path_buf(), url.clone()));
    url
}

/// The private PostgreSQL server of this test process, started on first
/// use; it stops when the process ends, however it ends.
fn local_cluster() -> &'static deog_pg_cluster::LocalCluster {
    static CLUSTER: std::sync::OnceLock<deog_pg_cluster::LocalCluster> = std::sync::OnceLock::new();
    CLUSTER.get_or_init(|| {
        deog_pg_cluster::LocalCluster::start().expect("start a private PostgreSQL server")
    })
}

/// Creates database `name` (dropping an older one of that name) on the
/// test server and returns its URL.
fn create_postgres_database(name: &str) -> String {
    let admin =
        std::env::var("DEOG_TEST_POSTGRES").unwrap_or_else(|_| local_cluster().url("postgres"));
    let base = admin
        .rsplit_once('/')
        .map(|(base, _)| base.to_string())
        .expect("a URL ending in /DATABASE");
    let name = name.to_string();
    let url = format!("{base}/{name}");
    // Its own thread: the tests run inside a runtime, which may not block.
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        runtime.block_on(async {
            let (client, connection) = tokio_postgres::connect(&admin, tokio_postgres::NoTls)
                .await
                .expect("connect to the test PostgreSQL");
            tokio::spawn(connection);
            for statement in [
                format!("DROP DATABASE IF EXISTS {name}"),
                format!("CREATE DATABASE {name}"),
            ] {
                client
                    .batch_execute(&statement)
                    .await
                    .expect("create the test database");
            }
        });
    })
    .join()
    .expect("create database");
    url
}

/// The backend every test of the suite runs on: PostgreSQL where
/// [`on_postgres`] says so, sled otherwise.
pub struct SuiteBackend;

impl TestBackend for SuiteBackend {
    type Store = SuiteStore;

    fn open(path: &Path) -> SuiteStore {
        let inner: Box<dyn Store> = if on_postgres() {
            Box::new(Postgres::open(path))
        } else {
            Box::new(Sled::open(path))
        };
        SuiteStore {
            inner,
            flushes: Arc::new(AtomicU64::new(0)),
        }
    }
}

/// Whether the suite runs on PostgreSQL: in the `on_postgres` test
/// binary, which holds the whole suite again, or when `DEOG_TEST_STORE`
/// says `postgres`.
pub fn on_postgres() -> bool {
    env!("CARGO_CRATE_NAME") == "on_postgres"
        || std::env::var("DEOG_TEST_STORE").is_ok_and(|v| v == "postgres")
}

pub struct TestServer {
    pub addr: SocketAddr,
    pub dir: Option<tempfile::TempDir>,
    pub path: PathBuf,
    flushes: Arc<AtomicU64>,
    stop: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<Result<(), deog_server::ServeError>>>,
}

impl TestServer {
    pub async fn start() -> Self {
        Self::start_with(ServerConfig::default()).await
    }

    pub async fn start_with(config: ServerConfig) -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("store");
        let mut server = Self::start_at(path, config).await;
        server.dir = Some(dir);
        server
    }

    /// A server over an existing directory (a restart).
    pub async fn start_at(path: PathBuf, config: ServerConfig) -> Self {
        let store = SuiteBackend::open(&path);
        Self::start_over(store, path, config).await
    }

    /// A server on PostgreSQL whatever the suite runs on, over the
    /// database standing for `path`: several servers started at one path
    /// share one database.
    pub async fn start_postgres_at(path: PathBuf, config: ServerConfig) -> Self {
        Self::start_postgres_with(path, config, PostgresConfig::new).await
    }

    /// As [`TestServer::start_postgres_at`], with the store's settings
    /// made from the database URL by `settings`.
    pub async fn start_postgres_with(
        path: PathBuf,
        config: ServerConfig,
        settings: impl FnOnce(String) -> PostgresConfig,
    ) -> Self {
        let opened = PostgresStore::open(&settings(postgres_database(&path)))
            .expect("open PostgreSQL store");
        let store = SuiteStore {
            inner: Box::new(opened),
            flushes: Arc::new(AtomicU64::new(0)),
        };
        Self::start_over(store, path, config).await
    }

    /// A server on the PostgreSQL database at `url` (one the test manages
    /// itself, to stop and start it under the server).
    pub async fn start_on_database(url: &str, config: ServerConfig) -> Self {
        let store = SuiteStore {
            inner: Box::new(
                PostgresStore::open(&PostgresConfig::new(url)).expect("open PostgreSQL store"),
            ),
            flushes: Arc::new(AtomicU64::new(0)),
        };
        Self::start_over(store, PathBuf::from(url), config).await
    }

    /// The map service's health, or `None` if the server does not answer.
    pub async fn serving_status(&self) -> Option<i32> {
        let channel = Channel::from_shared(self.url())
            .ok()?
            .connect()
            .await
            .ok()?;
        let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
        let request = tonic_health::pb::HealthCheckRequest {
            service: deog_server::MAP_SERVICE_NAME.into(),
        };
        Some(health.check(request).await.ok()?.into_inner().status)
    }

    async fn start_over(store: SuiteStore, path: PathBuf, config: ServerConfig) -> Self {
        let flushes = store.flushes.clone();
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let (stop, stopped) = oneshot::channel::<()>();
        let plain = config.tls.is_none();
        let task = tokio::spawn(deog_server::serve(
            Arc::new(store),
            listener,
            config,
            async {
                let _ = stopped.await;
            },
        ));
        let server = Self {
            addr,
            dir: None,
            path,
            flushes,
            stop: Some(stop),
            task: Some(task),
        };
        if plain {
            server.wait_ready().await;
        }
        server
    }

    /// Store flushes that succeeded since this server started.
    pub fn flushes(&self) -> u64 {
        self.flushes.load(Ordering::Relaxed)
    }

    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Waits on the health service, with a bounded number of tries.
    pub async fn wait_ready(&self) {
        for _ in 0..100 {
            if let Ok(channel) = Channel::from_shared(self.url())
                .expect("url")
                .connect()
                .await
            {
                let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
                let request = tonic_health::pb::HealthCheckRequest {
                    service: deog_server::MAP_SERVICE_NAME.into(),
                };
                if let Ok(reply) = health.check(request).await
                    && reply.into_inner().status
                        == tonic_health::pb::health_check_response::ServingStatus::Serving as i32
                {
                    return;
                }
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        panic!("server at {} never became ready", self.addr);
    }

    pub async fn client(&self) -> MapServiceClient<Channel> {
        MapServiceClient::connect(self.url())
            .await
            .expect("connect")
            .max_decoding_message_size(usize::MAX)
            .max_encoding_message_size(usize::MAX)
    }

    /// Graceful stop: in-flight calls finish, the store is flushed.
    pub async fn stop(mut self) -> Option<tempfile::TempDir> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(task) = self.task.take() {
            task.await.expect("server task").expect("server result");
        }
        self.dir.take()
    }
}

impl Drop for TestServer {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}

/// A store of any backend that counts its successful flushes, so tests can
/// see how writes were grouped.
pub struct SuiteStore {
    inner: Box<dyn Store>,
    flushes: Arc<AtomicU64>,
}

impl Store for SuiteStore {
    fn maps(&self) -> Result<Vec<MapRecord>, StoreError> {
        self.inner.maps()
    }
    fn map(&self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        self.inner.map(name)
    }
    fn create_map(&self, record: &MapRecord) -> Result<(), StoreError> {
        self.inner.create_map(record)
    }
    fn delete_map(&self, name: &str) -> Result<(), StoreError> {
        self.inner.delete_map(name)
    }
    fn write_map(&self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        self.inner.write_map(name, write)
    }
    fn tile(&self, map: &MapRecord, key: TileKey) -> Result<Option<StoredTile>, StoreError> {
        self.inner.tile(map, key)
    }
    fn tiles_in(
        &self,
        map: &MapRecord,
        range: TileRange,
        visit: &mut dyn FnMut(TileKey, StoredTile) -> bool,
    ) -> Result<(), StoreError> {
        self.inner.tiles_in(map, range, visit)
    }
    fn cursor(&self, name: &str, client: &str) -> Result<ClientCursor, StoreError> {
        self.inner.cursor(name, client)
    }
    fn cursors(&self, name: &str) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        self.inner.cursors(name)
    }
    fn write_frames(&self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        self.inner.write_frames(writes)
    }
    fn has_frame(&self, robot: &str, sequence: u64) -> Result<bool, StoreError> {
        self.inner.has_frame(robot, sequence)
    }
    fn robot(&self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.inner.robot(robot)
    }
    fn robots(&self) -> Result<Vec<(String, RobotSummary)>, StoreError> {
        self.inner.robots()
    }
    fn read_frames(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        self.inner.read_frames(robot, from, to, visit)
    }
    fn write_poses(&self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        self.inner.write_poses(poses)
    }
    fn read_poses(
        &self,
        robot: &str,
        from: u64,
        to: u64,
        visit: &mut dyn FnMut(u64, &[u8]) -> bool,
    ) -> Result<(), StoreError> {
        self.inner.read_poses(robot, from, to, visit)
    }
    fn rigs(&self) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        self.inner.rigs()
    }
    fn put_rig(&self, name: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.inner.put_rig(name, bytes)
    }
    fn put_goal(&self, map: &str, robot: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        self.inner.put_goal(map, robot, bytes)
    }
    fn goals(&self, map: &str) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
        self.inner.goals(map)
    }
    fn flush(&self) -> Result<(), StoreError> {
        self.inner.flush()?;
        self.flushes.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
    fn recover(&self, failure: &str) -> Result<(), StoreError> {
        self.inner.recover(failure)
    }
    fn foreign_changes(&self) -> Option<tokio::sync::mpsc::Receiver<StoreChange>> {
        self.inner.foreign_changes()
    }
    fn check_writable(&self) -> Result<(), StoreError> {
        self.inner.check_writable()
    }
    fn begin(&self) -> Result<Box<dyn Transaction + '_>, StoreError> {
        Ok(Box::new(CountingTransaction {
            inner: self.inner.begin()?,
            commits: &self.flushes,
        }))
    }
}

/// A transaction that counts its successful commits as flushes.
struct CountingTransaction<'s> {
    inner: Box<dyn Transaction + 's>,
    commits: &'s AtomicU64,
}

impl Transaction for CountingTransaction<'_> {
    fn lock_maps(&mut self, names: &[&str]) -> Result<(), StoreError> {
        self.inner.lock_maps(names)
    }
    fn lock_robots(&mut self, names: &[&str]) -> Result<(), StoreError> {
        self.inner.lock_robots(names)
    }
    fn map(&mut self, name: &str) -> Result<Option<MapRecord>, StoreError> {
        self.inner.map(name)
    }
    fn create_map(&mut self, record: &MapRecord) -> Result<(), StoreError> {
        self.inner.create_map(record)
    }
    fn delete_map(&mut self, name: &str) -> Result<(), StoreError> {
        self.inner.delete_map(name)
    }
    fn write_map(&mut self, name: &str, write: MapWrite) -> Result<(), StoreError> {
        self.inner.write_map(name, write)
    }
    fn tiles(
        &mut self,
        map: &MapRecord,
        keys: &[TileKey],
    ) -> Result<Vec<(TileKey, StoredTile)>, StoreError> {
        self.inner.tiles(map, keys)
    }
    fn cursors(
        &mut self,
        name: &str,
        clients: &[&str],
    ) -> Result<Vec<(String, ClientCursor)>, StoreError> {
        self.inner.cursors(name, clients)
    }
    fn robot(&mut self, robot: &str) -> Result<Option<RobotSummary>, StoreError> {
        self.inner.robot(robot)
    }
    fn stored_frames(&mut self, robot: &str, sequences: &[u64]) -> Result<Vec<u64>, StoreError> {
        self.inner.stored_frames(robot, sequences)
    }
    fn write_frames(&mut self, writes: Vec<FrameWrite>) -> Result<(), StoreError> {
        self.inner.write_frames(writes)
    }
    fn write_poses(&mut self, poses: Vec<(String, u64, Vec<u8>)>) -> Result<(), StoreError> {
        self.inner.write_poses(poses)
    }
    fn commit(self: Box<Self>) -> Result<(), StoreError> {
        let commits = self.commits;
        self.inner.commit()?;
        commits.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
}

pub async fn create_map(
    client: &mut MapServiceClient<Channel>,
    name: &str,
    tile_size: u32,
) -> pb::MapInfo {
    client
        .create_map(pb::CreateMapRequest {
            name: name.into(),
            tile_size,
            ..Default::default()
        })
        .await
        .expect("create map")
        .into_inner()
}

/// A dense delta message for tile (x, y) of `size`² cells.
pub fn dense_delta(x: i32, y: i32, cells: &[i16]) -> pb::TileDelta {
    pb::TileDelta {
        key: Some(pb::TileKey { x, y }),
        encoding: pb::CellEncoding::DenseI16Le as i32,
        cells: cells.iter().flat_map(|c| c.to_le_bytes()).collect(),
    }
}

pub fn batch(map: &str, client: &str, sequence: u64, tiles: Vec<pb::TileDelta>) -> pb::UpdateBatch {
    pb::UpdateBatch {
        map: map.into(),
        client_id: client.into(),
        sequence,
        tiles,
    }
}

/// Sends the batches on one stream and collects every ack (or the error
/// that ended the stream).
pub async fn send_batches(
    client: &mut MapServiceClient<Channel>,
    batches: Vec<pb::UpdateBatch>,
) -> (Vec<pb::UpdateAck>, Option<tonic::Status>) {
    let mut stream = match client.apply_updates(tokio_stream::iter(batches)).await {
        Ok(r) => r.into_inner(),
        Err(status) => return (Vec::new(), Some(status)),
    };
    let mut acks = Vec::new();
    loop {
        match stream.message().await {
            Ok(Some(ack)) => acks.push(ack),
            Ok(None) => return (acks, None),
            Err(status) => return (acks, Some(status)),
        }
    }
}

/// Every stored tile of the map, decoded to raw cells.
pub async fn all_tiles(
    client: &mut MapServiceClient<Channel>,
    map: &str,
) -> Vec<(pb::TileKey, u64, Vec<i16>)> {
    let mut stream = client
        .get_tiles(pb::TileQuery {
            map: map.into(),
            selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
                min_x: i32::MIN,
                min_y: i32::MIN,
                max_x: i32::MAX,
                max_y: i32::MAX,
            })),
            newer_than_version: 0,
        })
        .await
        .expect("get tiles")
        .into_inner();
    let mut out = Vec::new();
    while let Some(tile) = stream.message().await.expect("tile") {
        let cells = tile
            .cells
            .chunks_exact(2)
            .map(|b| i16::from_le_bytes([b[0], b[1]]))
            .collect();
        out.push((tile.key.expect("key"), tile.version, cells));
    }
    out
}
