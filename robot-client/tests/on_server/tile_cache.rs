//! `TileCache` against a real map server on 127.0.0.1 over a sled directory
//! in a temp dir: versioned refreshes, watch events, and the resync after a
//! watcher fell behind.

use deog_grid::{CellBox, CellIndex, TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{TileCache, TileChange, TileWatch, UpdateSender, UpdateSenderConfig};
use deog_server::ServerConfig;
use std::time::Duration;

use crate::common::Server;

const MAP: &str = "cache";
/// Cells per tile side of the test map.
const SIDE: u32 = 8;

/// The common server with the test map created.
async fn server_with_map(config: ServerConfig) -> Server {
    Server::with_map(config, MAP, SIDE).await
}

/// What the tests below ask of the server.
trait TestServer {
    async fn sender(&self) -> UpdateSender;
    async fn server_tiles(&self) -> Vec<(TileKey, u64, Vec<i16>)>;
}

impl TestServer for Server {
    async fn sender(&self) -> UpdateSender {
        self.client
            .updates(
                MAP,
                "writer",
                UpdateSenderConfig {
                    max_batch_tiles: 1024,
                    window: 8,
                },
            )
            .await
            .expect("sender")
    }

    /// Every tile of the map as the server has it: version and raw cells.
    async fn server_tiles(&self) -> Vec<(TileKey, u64, Vec<i16>)> {
        let tiles = self
            .client
            .tiles(pb::TileQuery {
                map: MAP.into(),
                selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
                    min_x: -1000,
                    min_y: -1000,
                    max_x: 1000,
                    max_y: 1000,
                })),
                newer_than_version: 0,
            })
            .await
            .expect("tiles");
        tiles
            .iter()
            .map(|t| {
                let (key, version, tile) = deog_robot_client::decode_tile(t, size()).expect("tile");
                (key, version, tile.raw_cells().to_vec())
            })
            .collect()
    }
}

fn size() -> TileSize {
    TileSize::new(SIDE).expect("size")
}

/// The cells of tiles `(x0, y0)..=(x1, y1)`.
fn tiles_box(x0: i32, y0: i32, x1: i32, y1: i32) -> CellBox {
    let side = SIDE as i32;
    CellBox::new(
        CellIndex::new(x0 * side, y0 * side),
        CellIndex::new(x1 * side + side - 1, y1 * side + side - 1),
    )
    .expect("box")
}

/// Adds `value` to every cell of each tile in one batch; returns the map
/// version after it.
async fn add(sender: &mut UpdateSender, keys: &[(i32, i32)], value: i16) -> u64 {
    for &(x, y) in keys {
        let delta = TileDelta::from_raw(TileKey::new(x, y), size(), vec![value; size().area()])
            .expect("delta");
        sender.push(delta).await.expect("push");
    }
    sender.flush().await.expect("flush").map_version
}

/// A cached tile's version and first cell.
fn cached(cache: &TileCache, x: i32, y: i32) -> Option<(u64, i16)> {
    cache
        .tile(TileKey::new(x, y))
        .map(|(version, tile)| (version, tile.raw_cells()[0]))
}

/// Asserts that the cache holds exactly the server's tiles, at their versions.
async fn assert_current(cache: &TileCache, server: &Server) {
    let tiles = server.server_tiles().await;
    assert_eq!(cache.len(), tiles.len(), "tile count");
    for (key, version, cells) in tiles {
        let (cached_version, tile) = cache.tile(key).expect("tile cached");
        assert_eq!(cached_version, version, "version of {key:?}");
        assert_eq!(tile.raw_cells(), &cells[..], "cells of {key:?}");
    }
}

/// The next event of a watch stream, within a bounded wait.
async fn next_event(stream: &mut tonic::Streaming<pb::TileEvent>) -> pb::TileEvent {
    tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("an event in time")
        .expect("stream")
        .expect("open")
}

async fn watch(server: &Server, include_cells: bool) -> tonic::Streaming<pb::TileEvent> {
    let region = tiles_box(-100, -100, 100, 100);
    server
        .client
        .watch_tiles(MAP, region, include_cells)
        .await
        .expect("watch")
}

#[tokio::test]
async fn a_refresh_fetches_only_the_tiles_changed_since_the_last() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let mut cache = TileCache::new(MAP, size());
    let everything = tiles_box(-4, -4, 4, 4);
    assert_eq!(cache.refresh(&server.client, everything).await.unwrap(), 0);
    assert!(cache.is_empty());

    let v1 = add(&mut sender, &[(0, 0), (1, 0), (-1, 2)], 100).await;
    assert_eq!(cache.refresh(&server.client, everything).await.unwrap(), 3);
    assert_eq!(cached(&cache, 1, 0), Some((v1, 100)));
    assert_eq!(
        cache.cell(CellIndex::new(-1, 16)).map(|l| l.raw()),
        Some(100)
    );

    let v2 = add(&mut sender, &[(1, 0)], 50).await;
    assert_eq!(cache.refresh(&server.client, everything).await.unwrap(), 1);
    assert_eq!(cached(&cache, 1, 0), Some((v2, 150)));
    assert_eq!(cached(&cache, 0, 0), Some((v1, 100)), "unchanged, kept");
    assert_eq!(cache.refresh(&server.client, everything).await.unwrap(), 0);
    assert_current(&cache, &server).await;
}

#[tokio::test]
async fn a_tile_changed_while_another_region_was_refreshed_is_fetched() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let mut cache = TileCache::new(MAP, size());
    let (west, east) = (tiles_box(-3, 0, -3, 0), tiles_box(3, 0, 3, 0));
    add(&mut sender, &[(-3, 0), (3, 0)], 100).await;
    assert_eq!(cache.refresh(&server.client, west).await.unwrap(), 1);
    assert_eq!(cache.refresh(&server.client, east).await.unwrap(), 1);
    // West changes, then a refresh of the east moves the sync point past it.
    let west_version = add(&mut sender, &[(-3, 0)], 10).await;
    add(&mut sender, &[(3, 0)], 10).await;
    assert_eq!(cache.refresh(&server.client, east).await.unwrap(), 1);
    assert_eq!(cache.refresh(&server.client, west).await.unwrap(), 1);
    assert_eq!(cached(&cache, -3, 0), Some((west_version, 110)));
    assert_current(&cache, &server).await;
}

#[tokio::test]
async fn tiles_cleared_on_the_server_are_dropped_by_the_next_refresh() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let mut cache = TileCache::new(MAP, size());
    let region = tiles_box(0, 0, 2, 0);
    add(&mut sender, &[(0, 0), (2, 0), (9, 9)], 100).await;
    assert_eq!(
        cache
            .refresh(&server.client, tiles_box(0, 0, 9, 9))
            .await
            .unwrap(),
        3
    );
    server
        .client
        .raw()
        .clear_map(pb::MapRef { name: MAP.into() })
        .await
        .expect("clear");
    let version = add(&mut sender, &[(2, 0)], 7).await;
    assert_eq!(cache.refresh(&server.client, region).await.unwrap(), 1);
    assert_eq!(cached(&cache, 0, 0), None, "cleared away");
    assert_eq!(cached(&cache, 2, 0), Some((version, 7)));
    // Outside the refreshed region nothing is known, so nothing is dropped.
    assert!(cached(&cache, 9, 9).is_some());
}

#[tokio::test]
async fn changes_arrive_through_the_watch_stream() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let mut cache = TileCache::new(MAP, size());
    let everything = tiles_box(-4, -4, 4, 4);
    add(&mut sender, &[(0, 0), (1, 1)], 100).await;
    cache.refresh(&server.client, everything).await.unwrap();

    // Without cells: the tile is dropped and fetched by the next refresh.
    let mut keys_only = watch(&server, false).await;
    let version = add(&mut sender, &[(0, 0)], 5).await;
    cache
        .apply_event(&next_event(&mut keys_only).await)
        .unwrap();
    assert_eq!(cached(&cache, 0, 0), None);
    assert!(cache.needs_resync());
    assert_eq!(cache.refresh(&server.client, everything).await.unwrap(), 1);
    assert_eq!(cached(&cache, 0, 0), Some((version, 105)));
    assert!(!cache.needs_resync());
    drop(keys_only);

    // With cells: the event itself updates the cache.
    let mut with_cells = watch(&server, true).await;
    let version = add(&mut sender, &[(1, 1), (2, 2)], 20).await;
    for _ in 0..2 {
        cache
            .apply_event(&next_event(&mut with_cells).await)
            .unwrap();
    }
    assert_eq!(cached(&cache, 1, 1), Some((version, 120)));
    assert_eq!(cached(&cache, 2, 2), Some((version, 20)));
    assert!(!cache.needs_resync());
    assert_current(&cache, &server).await;

    // A clear empties the cache.
    server
        .client
        .raw()
        .clear_map(pb::MapRef { name: MAP.into() })
        .await
        .expect("clear");
    cache
        .apply_event(&next_event(&mut with_cells).await)
        .unwrap();
    assert!(cache.is_empty());
    assert_current(&cache, &server).await;
}

#[tokio::test]
async fn a_watcher_that_fell_behind_resyncs_to_the_servers_tiles() {
    let server = server_with_map(ServerConfig {
        event_buffer: 16,
        stream_buffer: 4,
        ..ServerConfig::default()
    })
    .await;
    let mut sender = server.sender().await;
    let mut cache = TileCache::new(MAP, size());
    let everything = tiles_box(-20, -20, 20, 20);
    add(&mut sender, &[(0, 0)], 100).await;
    cache.refresh(&server.client, everything).await.unwrap();

    // One batch changes 400 tiles at once, far more events than the
    // server buffers for a watcher that reads nothing meanwhile.
    let mut stream = watch(&server, true).await;
    let keys: Vec<(i32, i32)> = (-10..10)
        .flat_map(|x| (-10..10).map(move |y| (x, y)))
        .collect();
    add(&mut sender, &keys, 10).await;
    let mut events = 0;
    while !cache.needs_resync() {
        assert!(events < keys.len(), "no resync after {events} events");
        cache.apply_event(&next_event(&mut stream).await).unwrap();
        events += 1;
    }
    assert!(cache.len() < keys.len(), "the dropped changes are missing");
    let fetched = cache.refresh(&server.client, everything).await.unwrap();
    assert!(fetched > 0);
    assert!(!cache.needs_resync());
    assert_eq!(cache.len(), keys.len());
    assert_eq!(cached(&cache, 0, 0).map(|(_, cell)| cell), Some(110));
    assert_current(&cache, &server).await;
}

#[tokio::test]
async fn a_tile_watch_names_the_changed_tiles_and_a_clear_as_everything() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let mut changes = TileWatch::spawn(watch(&server, false).await);
    add(&mut sender, &[(2, -3)], 100).await;
    let mut next = async || {
        for _ in 0..200 {
            if let Some(change) = changes.try_next() {
                return change;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        panic!("no change within 10 s");
    };
    assert_eq!(next().await, TileChange::Tile(TileKey::new(2, -3)));
    server
        .client
        .raw()
        .clear_map(pb::MapRef { name: MAP.into() })
        .await
        .expect("clear");
    assert_eq!(next().await, TileChange::All);
}

#[tokio::test]
async fn tiles_by_key_and_download_give_the_servers_tiles() {
    let server = server_with_map(ServerConfig::default()).await;
    let mut sender = server.sender().await;
    let version = add(&mut sender, &[(0, 0), (-1, 2)], 100).await;
    let keys = [TileKey::new(0, 0), TileKey::new(5, 5)];
    let got = server
        .client
        .tiles_by_key(MAP, size(), &keys)
        .await
        .expect("tiles by key");
    assert_eq!(got.len(), 1, "tile (5, 5) was never written");
    assert_eq!((got[0].0, got[0].1), (TileKey::new(0, 0), version));
    let (_, map) = server.client.download(MAP).await.expect("download");
    let mut downloaded: Vec<(TileKey, Vec<i16>)> = map
        .tiles()
        .map(|(k, t)| (*k, t.raw_cells().to_vec()))
        .collect();
    downloaded.sort();
    let mut stored: Vec<(TileKey, Vec<i16>)> = server
        .server_tiles()
        .await
        .into_iter()
        .map(|(k, _, cells)| (k, cells))
        .collect();
    stored.sort();
    assert_eq!(downloaded, stored);
}
