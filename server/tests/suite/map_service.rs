//! The map service over real TCP and a real sled directory: maps, updates
//! from many clients, exactly-once resends, tiles, watches.

use crate::common::{TestServer, all_tiles, batch, create_map, dense_delta, send_batches};
use deog_grid::{ClampLimits, Tile, TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;
use std::time::Duration;

#[tokio::test]
async fn maps_are_created_listed_cleared_and_deleted() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let info = create_map(&mut client, "lab", 0).await;
    assert_eq!(
        (info.tile_size, info.resolution_m, info.version),
        (64, 0.05, 0)
    );
    assert_eq!(
        (info.clamp_min_probability, info.clamp_max_probability),
        (0.12, 0.97)
    );
    assert!(info.bounds_cells.is_none());
    create_map(&mut client, "hall", 16).await;
    let names: Vec<String> = client
        .list_maps(pb::ListMapsRequest {})
        .await
        .unwrap()
        .into_inner()
        .maps
        .into_iter()
        .map(|m| m.name)
        .collect();
    assert_eq!(names, ["hall", "lab"]);

    let cells: Vec<i16> = (0..64 * 64)
        .map(|i| if i == 65 { 500 } else { 0 })
        .collect();
    let (acks, error) = send_batches(
        &mut client,
        vec![batch("lab", "c", 1, vec![dense_delta(-1, 2, &cells)])],
    )
    .await;
    assert!(error.is_none(), "{error:?}");
    assert_eq!(acks.len(), 1);
    let info = client
        .get_map_info(pb::MapRef { name: "lab".into() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((info.version, info.tile_count, info.cell_count), (1, 1, 1));
    // Cell 65 of tile (-1, 2) is (ox 1, oy 1): cell (-63, 129).
    let b = info.bounds_cells.unwrap();
    assert_eq!((b.min_x, b.min_y, b.max_x, b.max_y), (-63, 129, -63, 129));
    assert_eq!((info.width_cells, info.height_cells), (1, 1));
    let m = info.bounds_m.unwrap();
    assert!((m.min_x + 3.15).abs() < 1e-9 && (m.max_y - 6.5).abs() < 1e-9);

    let cleared = client
        .clear_map(pb::MapRef { name: "lab".into() })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        (cleared.version, cleared.tile_count, cleared.cell_count),
        (2, 0, 0)
    );
    assert!(all_tiles(&mut client, "lab").await.is_empty());

    client
        .delete_map(pb::MapRef { name: "lab".into() })
        .await
        .unwrap();
    let gone = client
        .get_map_info(pb::MapRef { name: "lab".into() })
        .await
        .unwrap_err();
    assert_eq!(gone.code(), tonic::Code::NotFound);
    // The name is free again, and the new map starts empty.
    let again = create_map(&mut client, "lab", 0).await;
    assert_eq!(again.version, 0);
}

/// Random deltas for `tiles` tiles of `size`, mixed signs, many zero.
fn random_batch(rng: &mut ChaCha8Rng, size: TileSize, tiles: &[TileKey]) -> Vec<TileDelta> {
    let mut out = Vec::new();
    for &key in tiles {
        if !rng.random_bool(0.7) {
            continue;
        }
        let raw = (0..size.area())
            .map(|_| {
                if rng.random_bool(0.5) {
                    rng.random_range(-900..=900)
                } else {
                    0
                }
            })
            .collect();
        out.push(TileDelta::from_raw(key, size, raw).unwrap());
    }
    out
}

fn wire(deltas: &[TileDelta]) -> Vec<pb::TileDelta> {
    deltas.iter().map(deog_robot_client_encode).collect()
}

fn deog_robot_client_encode(delta: &TileDelta) -> pb::TileDelta {
    // Sparse when half the cells are zero, as clients send them.
    pb::TileDelta {
        key: Some(pb::TileKey {
            x: delta.key.x,
            y: delta.key.y,
        }),
        encoding: pb::CellEncoding::SparseI16Le as i32,
        cells: delta.to_sparse_bytes().unwrap(),
    }
}

struct Sent {
    deltas: Vec<TileDelta>,
    ack_version: u64,
}

/// Eight clients, each on its own connection, send interleaved batches to
/// the same tiles at once. Returns every batch with the map version its ack
/// carried.
async fn eight_clients_at_once(server: &TestServer, map: &str, size: TileSize) -> Vec<Sent> {
    let keys = [
        TileKey::new(0, 0),
        TileKey::new(-1, 0),
        TileKey::new(0, -1),
        TileKey::new(3, 7),
    ];
    let mut tasks = Vec::new();
    for client_index in 0..8u64 {
        let mut client = server.client().await;
        let map = map.to_string();
        tasks.push(tokio::spawn(async move {
            let mut rng = ChaCha8Rng::seed_from_u64(client_index);
            let plan: Vec<Vec<TileDelta>> = (0..25)
                .map(|_| random_batch(&mut rng, size, &keys))
                .collect();
            let batches = plan
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    batch(
                        &map,
                        &format!("robot-{client_index}"),
                        i as u64 + 1,
                        wire(d),
                    )
                })
                .collect();
            let (acks, error) = send_batches(&mut client, batches).await;
            assert!(error.is_none(), "{error:?}");
            assert_eq!(acks.len(), plan.len());
            plan.into_iter()
                .zip(acks)
                .map(|(deltas, ack)| {
                    assert!(ack.applied);
                    Sent {
                        deltas,
                        ack_version: ack.map_version,
                    }
                })
                .collect::<Vec<_>>()
        }));
    }
    let mut sent = Vec::new();
    for task in tasks {
        sent.extend(task.await.unwrap());
    }
    sent
}

fn server_cells(tiles: &[(pb::TileKey, u64, Vec<i16>)]) -> HashMap<TileKey, Vec<i16>> {
    tiles
        .iter()
        .map(|(k, _, cells)| (TileKey::new(k.x, k.y), cells.clone()))
        .collect()
}

#[tokio::test]
async fn concurrent_clients_clamped_map_equals_batches_applied_in_ack_order() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let info = create_map(&mut client, "shared", 16).await;
    let size = TileSize::new(info.tile_size).unwrap();
    let limits = ClampLimits::default();
    let mut sent = eight_clients_at_once(&server, "shared", size).await;

    // Every applied batch got its own version: the commit order.
    sent.sort_by_key(|s| s.ack_version);
    let versions: Vec<u64> = sent.iter().map(|s| s.ack_version).collect();
    assert_eq!(versions, (1..=200).collect::<Vec<u64>>());

    let mut expected: HashMap<TileKey, Tile> = HashMap::new();
    for s in &sent {
        for d in &s.deltas {
            expected
                .entry(d.key)
                .or_insert_with(|| Tile::unknown(size))
                .apply(d, limits)
                .unwrap();
        }
    }
    let got = server_cells(&all_tiles(&mut client, "shared").await);
    assert_eq!(got.len(), expected.len());
    let mut clamped = 0;
    for (key, tile) in &expected {
        assert_eq!(&got[key][..], tile.raw_cells(), "tile {key:?}");
        clamped += tile
            .raw_cells()
            .iter()
            .filter(|&&c| c == limits.max().raw() || c == limits.min().raw())
            .count();
    }
    // The test only means something if clamping actually happened.
    assert!(clamped > 100, "only {clamped} clamped cells");
    let info = client
        .get_map_info(pb::MapRef {
            name: "shared".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.version, 200);
    let observed: usize = expected.values().map(Tile::observed_count).sum();
    assert_eq!(info.cell_count, observed as u64);
}

#[tokio::test]
async fn concurrent_clients_unclamped_map_is_the_exact_sum_in_any_order() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    // Limits this wide are never reached by these deltas: updates add exactly.
    let info = client
        .create_map(pb::CreateMapRequest {
            name: "exact".into(),
            tile_size: 16,
            clamp_min_probability: 1e-9,
            clamp_max_probability: 1.0 - 1e-9,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let size = TileSize::new(info.tile_size).unwrap();
    let sent = eight_clients_at_once(&server, "exact", size).await;
    let mut sums: HashMap<TileKey, Vec<i32>> = HashMap::new();
    let mut touched: HashMap<TileKey, Vec<bool>> = HashMap::new();
    for s in &sent {
        for d in &s.deltas {
            let sum = sums.entry(d.key).or_insert_with(|| vec![0; size.area()]);
            let seen = touched
                .entry(d.key)
                .or_insert_with(|| vec![false; size.area()]);
            for (i, &v) in d.raw().iter().enumerate() {
                sum[i] += i32::from(v);
                seen[i] |= v != 0;
            }
        }
    }
    let got = server_cells(&all_tiles(&mut client, "exact").await);
    for (key, sum) in &sums {
        for (i, &s) in sum.iter().enumerate() {
            let want = if touched[key][i] { s as i16 } else { i16::MIN };
            assert_eq!(got[key][i], want, "tile {key:?} cell {i}");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_batches_share_flushes_in_group_commits() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let info = create_map(&mut client, "grouped", 16).await;
    let size = TileSize::new(info.tile_size).unwrap();
    let before = server.flushes();
    let sent = eight_clients_at_once(&server, "grouped", size).await;
    let flushes = server.flushes() - before;
    // Every ack came after its flush, so each batch was covered by one.
    assert!(flushes >= 1);
    assert!(
        flushes < sent.len() as u64,
        "{flushes} flushes for {} acknowledged batches: no group held two",
        sent.len()
    );
}

#[tokio::test]
async fn resent_batches_after_a_reconnect_are_applied_once() {
    let server = TestServer::start().await;
    let mut first = server.client().await;
    create_map(&mut first, "once", 8).await;
    let cells = vec![100i16; 64];
    let batches: Vec<pb::UpdateBatch> = (1..=3)
        .map(|s| batch("once", "carto/scout-1", s, vec![dense_delta(0, 0, &cells)]))
        .collect();
    let (acks, _) = send_batches(&mut first, batches.clone()).await;
    assert!(acks.iter().all(|a| a.applied));
    assert_eq!(acks.last().unwrap().map_version, 3);
    drop(first);

    // A new connection resends 2 and 3 (their acks were "lost"), then 4.
    let mut second = server.client().await;
    let cursor = second
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "once".into(),
            client_id: "carto/scout-1".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(cursor.last_sequence, 3);
    let mut again = batches[1..].to_vec();
    again.push(batch(
        "once",
        "carto/scout-1",
        4,
        vec![dense_delta(0, 0, &cells)],
    ));
    let (acks, error) = send_batches(&mut second, again).await;
    assert!(error.is_none());
    let applied: Vec<(u64, bool, u64)> = acks
        .iter()
        .map(|a| (a.sequence, a.applied, a.map_version))
        .collect();
    assert_eq!(applied, [(2, false, 3), (3, false, 3), (4, true, 4)]);
    let tiles = all_tiles(&mut second, "once").await;
    assert!(
        tiles[0].2.iter().all(|&c| c == 400),
        "four batches of +100 each"
    );
    // Another client's sequences are its own.
    let (acks, _) = send_batches(
        &mut second,
        vec![batch("once", "other", 1, vec![dense_delta(0, 0, &cells)])],
    )
    .await;
    assert!(acks[0].applied);
}

#[tokio::test]
async fn get_tiles_selects_by_region_and_keys_and_skips_cells_not_newer() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "q", 8).await;
    let ones = vec![10i16; 64];
    let tiles = vec![
        dense_delta(0, 0, &ones),
        dense_delta(5, 5, &ones),
        dense_delta(-3, 1, &ones),
    ];
    send_batches(&mut client, vec![batch("q", "a", 1, tiles)]).await;
    send_batches(
        &mut client,
        vec![batch("q", "a", 2, vec![dense_delta(5, 5, &ones)])],
    )
    .await;

    let region = |min_x, min_y, max_x, max_y| {
        Some(pb::tile_query::Selection::Region(pb::CellBox {
            min_x,
            min_y,
            max_x,
            max_y,
        }))
    };
    let fetch = |selection, newer_than_version| {
        let mut client = client.clone();
        async move {
            let mut stream = client
                .get_tiles(pb::TileQuery {
                    map: "q".into(),
                    selection,
                    newer_than_version,
                })
                .await
                .unwrap()
                .into_inner();
            let mut out = Vec::new();
            while let Some(t) = stream.message().await.unwrap() {
                let k = t.key.unwrap();
                out.push((k.x, k.y, t.version, t.cells.len()));
            }
            out
        }
    };
    // Cells 0..=47 along both axes: tiles 0..=5.
    assert_eq!(
        fetch(region(0, 0, 47, 47), 0).await,
        [(0, 0, 1, 128), (5, 5, 2, 128)]
    );
    assert_eq!(
        fetch(region(-24, 0, 7, 15), 0).await,
        [(-3, 1, 1, 128), (0, 0, 1, 128)]
    );
    // Only tile (5, 5) changed after version 1.
    assert_eq!(
        fetch(region(-100, -100, 100, 100), 1).await,
        [(-3, 1, 1, 0), (0, 0, 1, 0), (5, 5, 2, 128)]
    );
    let keys = Some(pb::tile_query::Selection::Keys(pb::TileKeys {
        keys: vec![pb::TileKey { x: 5, y: 5 }, pb::TileKey { x: 9, y: 9 }],
    }));
    assert_eq!(fetch(keys, 0).await, [(5, 5, 2, 128)]);
}

async fn next_event(stream: &mut tonic::Streaming<pb::TileEvent>) -> pb::tile_event::Event {
    tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("event in time")
        .expect("stream ok")
        .expect("stream open")
        .event
        .expect("event")
}

#[tokio::test]
async fn watchers_see_changes_in_their_region_and_clears() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "w", 8).await;
    let mut watch = client
        .watch_tiles(pb::WatchTilesRequest {
            map: "w".into(),
            region: Some(pb::CellBox {
                min_x: 0,
                min_y: 0,
                max_x: 15,
                max_y: 15,
            }),
            include_cells: true,
        })
        .await
        .unwrap()
        .into_inner();
    let cells = vec![7i16; 64];
    // Tile (9, 9) is outside the region; (1, 1) is inside.
    send_batches(
        &mut client,
        vec![batch("w", "a", 1, vec![dense_delta(9, 9, &cells)])],
    )
    .await;
    send_batches(
        &mut client,
        vec![batch("w", "a", 2, vec![dense_delta(1, 1, &cells)])],
    )
    .await;
    match next_event(&mut watch).await {
        pb::tile_event::Event::Changed(tile) => {
            assert_eq!(tile.key, Some(pb::TileKey { x: 1, y: 1 }));
            assert_eq!(tile.version, 2);
            assert_eq!(tile.cells.len(), 128);
        }
        other => panic!("unexpected {other:?}"),
    }
    client
        .clear_map(pb::MapRef { name: "w".into() })
        .await
        .unwrap();
    assert_eq!(
        next_event(&mut watch).await,
        pb::tile_event::Event::Cleared(pb::MapCleared { map_version: 3 })
    );
    client
        .delete_map(pb::MapRef { name: "w".into() })
        .await
        .unwrap();
    let end = tokio::time::timeout(Duration::from_secs(10), watch.message())
        .await
        .unwrap();
    assert_eq!(end.unwrap_err().code(), tonic::Code::NotFound);
}

#[tokio::test]
async fn a_slow_watcher_gets_one_resync_instead_of_an_unbounded_queue() {
    let config = deog_server::ServerConfig {
        event_buffer: 16,
        stream_buffer: 4,
        ..Default::default()
    };
    let server = TestServer::start_with(config).await;
    let mut client = server.client().await;
    create_map(&mut client, "busy", 8).await;
    let mut watch = client
        .watch_tiles(pb::WatchTilesRequest {
            map: "busy".into(),
            region: Some(pb::CellBox {
                min_x: -1000,
                min_y: -1000,
                max_x: 1000,
                max_y: 1000,
            }),
            include_cells: false,
        })
        .await
        .unwrap()
        .into_inner();
    // The watcher reads nothing while 400 tiles change, one batch each.
    let cells = vec![1i16; 64];
    let batches = (0..400)
        .map(|i| {
            batch(
                "busy",
                "a",
                i + 1,
                vec![dense_delta(i as i32 % 40, i as i32 / 40, &cells)],
            )
        })
        .collect();
    let (acks, _) = send_batches(&mut client, batches).await;
    assert_eq!(acks.len(), 400);
    // Then it reads: a bounded number of changes, then a resync. On a
    // shared database the store's change listener may also ask watchers to
    // resync (its own queue of notifications can fall behind 400 quick
    // writes); those say so and are not the one this test is after.
    let mut changes_before_resync = 0;
    let resync = loop {
        match next_event(&mut watch).await {
            pb::tile_event::Event::Changed(_) => changes_before_resync += 1,
            pb::tile_event::Event::Resync(r) if r.reason.contains("another map server") => {}
            pb::tile_event::Event::Resync(r) => break r,
            other => panic!("unexpected {other:?}"),
        }
    };
    assert!(
        changes_before_resync < 400,
        "{changes_before_resync} events were queued"
    );
    // The version when events were dropped: the watcher re-reads from there.
    assert!(
        (1..=400).contains(&resync.map_version),
        "{} ({})",
        resync.map_version,
        resync.reason
    );
    // After the resync, live events flow again.
    send_batches(
        &mut client,
        vec![batch("busy", "a", 401, vec![dense_delta(0, 0, &cells)])],
    )
    .await;
    loop {
        if let pb::tile_event::Event::Changed(t) = next_event(&mut watch).await
            && t.version == 401
        {
            break;
        }
    }
}

#[tokio::test]
async fn update_cursors_name_every_client_writing_to_a_map() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    for map in ["shared", "other", "unwritten"] {
        create_map(&mut client, map, 8).await;
    }
    let cells = vec![10i16; 64];
    let writes = [
        ("shared", "carto/scout-2", 1..=2),
        ("shared", "carto/scout-1", 1..=5),
        ("other", "import/map1", 7..=7),
    ];
    for (map, client_id, sequences) in writes {
        let batches = sequences
            .map(|s| batch(map, client_id, s, vec![dense_delta(0, 0, &cells)]))
            .collect();
        let (acks, error) = send_batches(&mut client, batches).await;
        assert!(error.is_none() && acks.iter().all(|a| a.applied));
    }

    let cursors = |map: &str| {
        let mut client = client.clone();
        let map = map.to_string();
        async move {
            client
                .list_update_cursors(pb::MapRef { name: map })
                .await
                .map(|reply| {
                    reply
                        .into_inner()
                        .cursors
                        .into_iter()
                        .map(|c| (c.client_id, c.last_sequence))
                        .collect::<Vec<_>>()
                })
        }
    };
    assert_eq!(
        cursors("shared").await.unwrap(),
        [
            ("carto/scout-1".to_string(), 5),
            ("carto/scout-2".to_string(), 2)
        ]
    );
    assert_eq!(
        cursors("other").await.unwrap(),
        [("import/map1".to_string(), 7)]
    );
    assert!(cursors("unwritten").await.unwrap().is_empty());
    let missing = cursors("nowhere").await.unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound, "{missing}");
    let bad = cursors("").await.unwrap_err();
    assert_eq!(bad.code(), tonic::Code::InvalidArgument, "{bad}");
}
