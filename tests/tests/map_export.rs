//! `deog import --map` and `deog export` through the real binary and a real
//! map server: two real map_server maps go in and come back out with every
//! pixel's occupancy intact, and the exported pixels agree with the cells
//! the server holds.

use deog_grid::{CellIndex, ClampLimits, LogOdds, Resolution, Tile, TileKey, TileMap, TileSize};
use deog_mapfile::{Cell, MapImage};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, failure, run_deog, succeeded};
use std::path::{Path, PathBuf};
use std::process::Output;

fn deog(args: &[&str], server: &ServerProcess) -> Output {
    run_deog(args, &[("DEOG_SERVER", server.addr.to_string())])
}

fn stdout(output: &Output) -> String {
    succeeded(output)
}

fn data(path: &str) -> String {
    format!(
        "{}/../mapfile/tests/data/{path}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// The cell of an unrotated image's lower-left pixel.
fn origin_cell(image: &MapImage) -> CellIndex {
    CellIndex::new(
        (image.origin.0 / image.resolution).round() as i32,
        (image.origin.1 / image.resolution).round() as i32,
    )
}

/// The occupancy of the image's pixel over `cell`; unknown outside it.
fn occupancy_at(image: &MapImage, cell: CellIndex) -> Cell {
    let origin = origin_cell(image);
    match (
        u32::try_from(i64::from(cell.x) - i64::from(origin.x)),
        u32::try_from(i64::from(cell.y) - i64::from(origin.y)),
    ) {
        (Ok(col), Ok(row)) => image.occupancy(col, row),
        _ => Cell::Unknown,
    }
}

/// The class map_server's default thresholds give a server cell.
fn server_class(belief: Option<LogOdds>) -> Cell {
    match belief.map(LogOdds::probability) {
        Some(p) if p > 0.65 => Cell::Occupied,
        Some(p) if p < 0.196 => Cell::Free,
        _ => Cell::Unknown,
    }
}

/// Every tile of `map` on the server, and its info.
async fn server_map(client: &MapClient, map: &str) -> (pb::MapInfo, TileMap) {
    let info = client.map_info(map).await.expect("map info");
    let size = TileSize::new(info.tile_size).expect("tile size");
    let mut tiles = TileMap::new(
        Resolution::new(info.resolution_m).expect("resolution"),
        size,
        ClampLimits::default(),
    );
    let fetched = client
        .tiles(pb::TileQuery {
            map: map.into(),
            selection: Some(pb::tile_query::Selection::Region(
                info.bounds_cells.expect("bounds"),
            )),
            newer_than_version: 0,
        })
        .await
        .expect("tiles");
    assert_eq!(fetched.len() as u64, info.tile_count);
    for tile in fetched {
        let key = tile.key.expect("key");
        let cells = Tile::from_dense_bytes(size, &tile.cells).expect("dense cells");
        tiles
            .insert(TileKey::new(key.x, key.y), cells)
            .expect("insert");
    }
    (info, tiles)
}

/// Imports `file` as `map`, exports it to `out`, and checks the export
/// against the original and against the server.
async fn round_trip(server: &ServerProcess, client: &MapClient, map: &str, file: &str, out: &Path) {
    let said = stdout(&deog(&["import", "--map", map, file], server));
    assert!(said.contains(&format!("written to map {map}")), "{said}");
    let out_str = out.to_str().expect("utf-8 path");
    let said = stdout(&deog(&["export", "--map", map, "--out", out_str], server));
    assert!(said.starts_with(&format!("map {map}: ")), "{said}");
    assert!(
        said.contains(" pixels ") && said.contains(" cells occupied, "),
        "{said}"
    );
    for ext in ["pgm", "yaml", "png"] {
        assert!(out.join(format!("{map}.{ext}")).is_file(), "{map}.{ext}");
    }
    let original = MapImage::load(file).expect("original");
    let exported: MapImage = MapImage::load(out.join(format!("{map}.yaml"))).expect("export");
    assert_eq!(exported.resolution, original.resolution);
    assert_eq!(exported.origin.2, 0.0);

    // (a) Every original pixel reads the same at its world cell in the
    // export, and the export lies within the original (it is cropped to
    // the known cells, so its origin may differ).
    let (o, e) = (origin_cell(&original), origin_cell(&exported));
    assert!(
        e.x >= o.x && e.y >= o.y,
        "{map}: export starts at {e:?}, original at {o:?}"
    );
    assert!(e.x + exported.width as i32 <= o.x + original.width as i32);
    assert!(e.y + exported.height as i32 <= o.y + original.height as i32);
    let mut known = 0u64;
    for row in 0..original.height {
        for col in 0..original.width {
            let cell = CellIndex::new(o.x + col as i32, o.y + row as i32);
            let class = original.occupancy(col, row);
            known += u64::from(class != Cell::Unknown);
            assert_eq!(
                occupancy_at(&exported, cell),
                class,
                "{map}: pixel ({col}, {row})"
            );
        }
    }

    // (b) Each exported pixel's class is the class of the server's cell,
    // and every cell the server holds is inside the export.
    let (info, tiles) = server_map(client, map).await;
    assert_eq!(info.cell_count, known, "{map}: one cell per known pixel");
    let mut observed_inside = 0u64;
    for row in 0..exported.height {
        for col in 0..exported.width {
            let cell = CellIndex::new(e.x + col as i32, e.y + row as i32);
            let belief = tiles.get(cell);
            observed_inside += u64::from(belief.is_some());
            assert_eq!(
                exported.occupancy(col, row),
                server_class(belief),
                "{map}: cell {cell:?}"
            );
        }
    }
    assert_eq!(
        observed_inside, info.cell_count,
        "{map}: cells outside the export"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn real_maps_round_trip_through_import_and_export() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("map client");
    let out: PathBuf = dir.path().join("out");
    let arena = data("lse_arena.yaml");
    round_trip(&server, &client, "arena", &arena, &out).await;
    round_trip(
        &server,
        &client,
        "turtlebot3",
        &data("turtlebot3_world/map.yaml"),
        &out,
    )
    .await;

    // Importing again would add the same evidence twice: refused, and the
    // map is left as it was.
    let before = client.map_info("arena").await.expect("info");
    let said = failure(&deog(&["import", "--map", "arena", &arena], &server));
    assert!(
        said.contains("map \"arena\" already holds") && said.contains("--force"),
        "{said}"
    );
    let after = client.map_info("arena").await.expect("info");
    assert_eq!(
        (after.version, after.cell_count),
        (before.version, before.cell_count)
    );
    // With --force it is added: the cells are already at the clamp limits,
    // so they stay there, but the map takes the batches.
    stdout(&deog(
        &["import", "--map", "arena", "--force", &arena],
        &server,
    ));
    let forced = client.map_info("arena").await.expect("info");
    assert!(forced.version > after.version);
    assert_eq!(forced.cell_count, after.cell_count);

    // A map of another resolution is not written into.
    client
        .ensure_map(pb::CreateMapRequest {
            name: "coarse".into(),
            resolution_m: 0.1,
            ..Default::default()
        })
        .await
        .expect("coarse map");
    let said = failure(&deog(&["import", "--map", "coarse", &arena], &server));
    assert!(said.contains("exists with cells of 0.1 m"), "{said}");
    assert_eq!(client.map_info("coarse").await.expect("info").version, 0);

    // Exporting a map that does not exist names it; an empty one says so.
    let out_str = out.to_str().expect("utf-8 path");
    let said = failure(&deog(
        &["export", "--map", "no-such-map", "--out", out_str],
        &server,
    ));
    assert!(said.contains("no map named \"no-such-map\""), "{said}");
    let said = failure(&deog(
        &["export", "--map", "coarse", "--out", out_str],
        &server,
    ));
    assert!(said.contains("map \"coarse\" is empty"), "{said}");
    assert!(!out.join("no-such-map.yaml").exists() && !out.join("coarse.yaml").exists());
}
