//! `deog eval map` against a real server: a map written as map2's ground
//! truth scores 1.0, and known mistakes cost exactly what they should.

use std::collections::HashMap;
use std::f64::consts::FRAC_1_SQRT_2;
use std::path::Path;
use std::process::Command;

use deog_grid::{CellIndex, LogOdds, Resolution, TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient, UpdateSenderConfig};
use deog_tests::{ServerProcess, deog_binary, json_field};
use deog_world::{Point2, SegmentIndex, World, load_world};

const RESOLUTION_M: f64 = 0.05;
/// The patch written: cells covering [-0.1, 5.0) x [-0.1, 4.0) m, the
/// room's lower-left quarter with its corner, walls and the table, and a
/// strip outside the walls.
const XS: std::ops::Range<i32> = -2..100;
const YS: std::ops::Range<i32> = -2..80;

/// The ground-truth rule of `deog_evaluation::map_quality`, restated: a cell is
/// occupied when a wall passes within half its diagonal (plus 1e-9
/// relative) of its centre or its centre is not free.
struct Truth {
    world: World,
    walls: SegmentIndex,
    resolution: Resolution,
}

impl Truth {
    fn map2() -> Self {
        let path = format!("{}/../worlds/map2.toml", env!("CARGO_MANIFEST_DIR"));
        let world = load_world(Path::new(&path)).expect("map2");
        Self {
            walls: SegmentIndex::new(world.walls()),
            world,
            resolution: Resolution::new(RESOLUTION_M).expect("resolution"),
        }
    }

    fn occupied(&self, x: i32, y: i32) -> bool {
        let (cx, cy) = self.resolution.cell_center(CellIndex::new(x, y));
        let centre = Point2::new(cx, cy);
        let touch = RESOLUTION_M * FRAC_1_SQRT_2 * (1.0 + 1e-9);
        self.walls.min_distance(centre, 2.0 * touch) <= touch || !self.world.is_free(centre)
    }
}

/// Adds `deltas` (cell → raw delta) to map `m` as one client's batches.
async fn write(client: &MapClient, client_id: &str, deltas: &HashMap<(i32, i32), i16>) {
    let size = TileSize::DEFAULT;
    let mut tiles: HashMap<TileKey, Vec<i16>> = HashMap::new();
    for (&(x, y), &delta) in deltas {
        let (key, offset) = size.split(CellIndex::new(x, y));
        tiles.entry(key).or_insert_with(|| vec![0; size.area()])[offset.index(size)] = delta;
    }
    let mut sender = client
        .updates("m", client_id, UpdateSenderConfig::default())
        .await
        .expect("update stream");
    for (key, raw) in tiles {
        sender
            .push(TileDelta::from_raw(key, size, raw).expect("delta"))
            .await
            .expect("push");
    }
    let acks = sender.close().await.expect("close");
    assert_eq!(acks.failure, None);
}

/// Runs `deog eval map` on map `name` and returns its JSON, or its stderr
/// as the error when it fails; the picture goes to `out` with `.png`.
fn eval(server: &ServerProcess, name: &str, out: &Path) -> Result<String, String> {
    let output = Command::new(deog_binary())
        .args(["eval", "map", "--map", name, "--world", "map2", "--json"])
        .arg(out)
        .arg("--png")
        .arg(out.with_extension("png"))
        .env("DEOG_SERVER", server.addr.to_string())
        .env("RUST_LOG", "warn")
        .output()
        .expect("run deog eval");
    if !output.status.success() {
        return Err(String::from_utf8_lossy(&output.stderr).into_owned());
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("| fraction correct |"), "{stdout}");
    Ok(std::fs::read_to_string(out).expect("json written"))
}

/// The colour `deog eval map --png` gave cell (`x`, `y`) of map2: the
/// picture covers the world's cells and one more on each side, top row
/// first, each cell a square of pixels.
fn verdict_colour(png_path: &Path, truth: &Truth, x: i32, y: i32) -> [u8; 3] {
    let bytes = std::fs::read(png_path).expect("picture written");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut rgb = vec![0; reader.output_buffer_size().expect("size")];
    let frame = reader.next_frame(&mut rgb).expect("decodes");
    assert_eq!(frame.color_type, png::ColorType::Rgb);
    let (min, max) = truth.world.bounds();
    let lo = truth.resolution.cell_of(min.x, min.y).expect("cell");
    let hi = truth.resolution.cell_of(max.x, max.y).expect("cell");
    let (width, height) = (hi.x - lo.x + 3, hi.y - lo.y + 3);
    // Scaled up, each cell a square of pixels, to about 1000 across.
    let scale = frame.width as i32 / width;
    assert!(scale >= 1 && scale * width.max(height) <= 1000, "{scale}");
    assert_eq!(
        (frame.width, frame.height),
        ((width * scale) as u32, (height * scale) as u32)
    );
    let (col, row) = (x - (lo.x - 1), height - 1 - (y - (lo.y - 1)));
    // The square's far corner: every pixel of it has the cell's colour.
    let (col, row) = (col * scale + scale - 1, row * scale + scale - 1);
    let i = 3 * (row * width * scale + col) as usize;
    [rgb[i], rgb[i + 1], rgb[i + 2]]
}

/// The number after `"name": ` in the report.
fn field(json: &str, name: &str) -> f64 {
    json_field(json, name)
        .parse()
        .unwrap_or_else(|_| panic!("{name} is a number in {json}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eval_map_scores_a_perfect_patch_one_and_counts_each_mistake() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("client");
    let info = client
        .ensure_map(pb::CreateMapRequest {
            name: "m".into(),
            resolution_m: RESOLUTION_M,
            tile_size: TileSize::DEFAULT.cells(),
            ..Default::default()
        })
        .await
        .expect("map");
    // One robot that started on open floor: the seed of the reachable space.
    let start = pb::Pose2 {
        x: 4.0,
        y: 3.0,
        theta: 0.0,
    };
    client
        .publish_frames(vec![pb::SonarFrame {
            robot: "r".into(),
            sequence: 1,
            time_s: 0.0,
            odometry: Some(start),
            true_pose: Some(start),
            ranges: vec![2.0; 16],
            rig: String::new(),
            reference_pose: None,
        }])
        .await
        .expect("frame");

    let truth = Truth::map2();
    let mut cells = HashMap::new();
    for y in YS {
        for x in XS {
            let raw = if truth.occupied(x, y) { 2000 } else { -2000 };
            cells.insert((x, y), raw);
        }
    }
    write(&client, "test/raster", &cells).await;
    let observed = (XS.len() * YS.len()) as f64;

    let out = dir.path().join("quality.json");
    let json = eval(&server, "m", &out).expect("eval");
    assert_eq!(field(&json, "cells_observed"), observed, "{json}");
    assert_eq!(field(&json, "fraction_correct"), 1.0, "{json}");
    assert_eq!(field(&json, "cells_uncertain"), 0.0, "{json}");
    assert_eq!(field(&json, "occupied_precision"), 1.0, "{json}");
    assert_eq!(field(&json, "seeds_used"), 1.0, "{json}");
    let occupied = field(&json, "map_occupied");
    let reachable_free = field(&json, "reachable_cells_free");
    let recall = field(&json, "occupied_recall");
    let coverage = field(&json, "coverage");
    // A quarter of the room: some of the walls and the floor, not all.
    assert!(occupied > 100.0 && recall > 0.1 && recall < 1.0, "{json}");
    assert!(coverage > 0.1 && coverage < 1.0, "{json}");

    // Open floor, well away from every wall: 3 cells turned occupied, 2
    // brought back to p = 0.5 (uncertain). The free cells were clamped at
    // the map's lower limit, so these deltas land exactly.
    let floor_min = -LogOdds::from_probability(info.clamp_min_probability)
        .expect("clamp")
        .raw();
    let occupied_cells = [(90, 70), (91, 70), (92, 70)];
    let uncertain_cells = [(90, 73), (91, 73)];
    let mut edits = HashMap::new();
    for (x, y) in occupied_cells {
        edits.insert((x, y), 4000);
    }
    for (x, y) in uncertain_cells {
        edits.insert((x, y), floor_min);
    }
    for &(x, y) in edits.keys() {
        for (dx, dy) in (-1..=1).flat_map(|dx| (-1..=1).map(move |dy| (dx, dy))) {
            assert!(!truth.occupied(x + dx, y + dy), "({x}, {y}) is open floor");
        }
    }
    write(&client, "test/corrupt", &edits).await;

    let json = eval(&server, "m", &out).expect("eval");
    assert_eq!(field(&json, "cells_observed"), observed, "{json}");
    assert_eq!(field(&json, "cells_correct"), observed - 5.0, "{json}");
    assert_eq!(
        field(&json, "fraction_correct"),
        (observed - 5.0) / observed,
        "{json}"
    );
    assert_eq!(field(&json, "cells_uncertain"), 2.0, "{json}");
    assert_eq!(field(&json, "free_as_occupied"), 3.0, "{json}");
    assert_eq!(field(&json, "free_as_uncertain"), 2.0, "{json}");
    assert_eq!(field(&json, "map_occupied"), occupied + 3.0, "{json}");
    assert_eq!(
        field(&json, "occupied_precision"),
        occupied / (occupied + 3.0),
        "{json}"
    );
    assert_eq!(field(&json, "occupied_recall"), recall, "{json}");
    assert_eq!(
        field(&json, "reachable_cells_free"),
        reachable_free - 5.0,
        "{json}"
    );

    // The picture shows the mistakes where they are: red for free cells
    // mapped occupied, yellow for free ones left uncertain, white for the
    // free floor around them.
    let picture = out.with_extension("png");
    for (x, y) in occupied_cells {
        assert_eq!(verdict_colour(&picture, &truth, x, y), [220, 0, 0]);
    }
    for (x, y) in uncertain_cells {
        assert_eq!(verdict_colour(&picture, &truth, x, y), [255, 200, 0]);
    }
    assert_eq!(verdict_colour(&picture, &truth, 90, 75), [255, 255, 255]);

    // Bad input: a clear error, no report.
    let err = eval(&server, "no-such-map", &dir.path().join("none.json")).expect_err("fails");
    assert!(err.contains("no-such-map"), "{err}");
    assert!(!dir.path().join("none.json").exists());
    drop(server);
}
