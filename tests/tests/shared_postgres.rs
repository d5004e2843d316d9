//! Two `deog server` processes on one PostgreSQL database, with clients
//! given both addresses: batches through both land without a lost update,
//! and when one server is killed (SIGKILL) mid-write the clients carry on
//! through the other, each batch applied exactly once.

use deog_grid::{TileDelta, TileKey, TileSize};
use deog_pg_cluster::LocalCluster;
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, RetryPolicy, UpdateSenderConfig};
use deog_tests::{ServerProcess, whole_map};
use std::time::Duration;

const CLIENTS: usize = 3;
const BATCHES: u64 = 50;
/// The tiles every client adds to: all of them, in every batch.
const TILES: [(i32, i32); 4] = [(0, 0), (1, 0), (0, 1), (5, 5)];

fn config(servers: &str) -> ClientConfig {
    let mut config = ClientConfig::new(servers);
    config.retry = RetryPolicy {
        max_attempts: Some(200),
        ..RetryPolicy::default()
    };
    config
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_carry_on_through_the_other_server_and_every_batch_lands_once() {
    let cluster = tokio::task::block_in_place(LocalCluster::start).expect("start PostgreSQL");
    let url = tokio::task::block_in_place(|| cluster.create_database("maps")).expect("database");
    let dir = tempfile::tempdir().expect("temp dir");
    let first = ServerProcess::start(&dir.path().join("unused-1"), &["--store", &url]).await;
    let second = ServerProcess::start(&dir.path().join("unused-2"), &["--store", &url]).await;
    let both = format!("{},{}", first.addr, second.addr);

    let admin = MapClient::connect(config(&both)).await.expect("connect");
    admin
        .ensure_map(pb::CreateMapRequest {
            name: "m".into(),
            tile_size: 16,
            ..Default::default()
        })
        .await
        .expect("map");
    let size = TileSize::new(16).expect("size");

    let mut writers = Vec::new();
    for client in 0..CLIENTS {
        let both = both.clone();
        writers.push(tokio::spawn(async move {
            let connection = MapClient::connect(config(&both)).await.expect("connect");
            let mut sender = connection
                .updates(
                    "m",
                    &format!("writer-{client}"),
                    UpdateSenderConfig {
                        max_batch_tiles: TILES.len(),
                        window: 4,
                    },
                )
                .await
                .expect("sender");
            for _ in 0..BATCHES {
                for (x, y) in TILES {
                    let delta =
                        TileDelta::from_raw(TileKey::new(x, y), size, vec![1; 256]).expect("delta");
                    sender.push(delta).await.expect("push");
                }
                sender.send_batch().await.expect("batch");
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            sender.close().await.expect("every batch acknowledged")
        }));
    }
    // Mid-write, the first server dies without a word.
    tokio::time::sleep(Duration::from_millis(400)).await;
    first.kill();

    let mut resent = 0;
    for writer in writers {
        let state = writer.await.expect("writer");
        assert_eq!(state.last_acked, BATCHES, "{state:?}");
        resent += state.duplicates;
    }
    eprintln!("{resent} batches were resent and recognised as applied");

    // Through the survivor: every cell holds one unit per batch sent, so no
    // batch was lost or applied twice, and the map counted each once.
    let survivor = MapClient::connect(config(&second.addr.to_string()))
        .await
        .expect("connect");
    let tiles = survivor.tiles(whole_map("m")).await.expect("tiles");
    assert_eq!(tiles.len(), TILES.len());
    let expected = (CLIENTS as u64 * BATCHES) as i16;
    for tile in &tiles {
        let cells = deog_tests::tile_cells(tile);
        assert!(
            cells.iter().all(|&c| c == expected),
            "tile {:?}: {} rather than {expected}",
            tile.key,
            cells[0]
        );
    }
    let info = survivor.map_info("m").await.expect("info");
    assert_eq!(info.version, CLIENTS as u64 * BATCHES);
}
