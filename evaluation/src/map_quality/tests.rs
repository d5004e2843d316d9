//! Worlds of 0.25 m cells (exact in binary), walls on cell edges, so
//! every figure below is counted by hand.

use std::collections::HashMap;

use deog_grid::{ClampLimits, Resolution, Tile, TileKey, TileSize};
use deog_world::Polygon;

use super::*;

const FREE_RAW: i16 = -2000;
const OCC_RAW: i16 = 2000;
/// p ≈ 0.5: observed, between the thresholds.
const UNCERTAIN_RAW: i16 = 0;

fn res() -> Resolution {
    Resolution::new(0.25).unwrap()
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon {
    Polygon::rectangle(Point2::new(x0, y0), Point2::new(x1, y1))
}

/// A 3 x 2 m room (cells 0..=11 x 0..=7 inside) with a 0.5 x 0.5 m box
/// at (1.0, 0.75)..(1.5, 1.25).
///
/// Truth-occupied inside the room: the ring of cells along the walls
/// (x = 0, x = 11, y = 0, y = 7) and the box's cells x 3..=6, y 2..=5
/// (cells 3 and 6 touch the box's sides; (3, 2) and its like touch
/// only its corner). Truth-free: x 1..=10, y 1..=6 minus the box, 44
/// cells, each at least 0.375 m from every wall.
fn room() -> World {
    World::new(
        "room",
        Some(rect(0.0, 0.0, 3.0, 2.0)),
        vec![rect(1.0, 0.75, 1.5, 1.25)],
    )
    .unwrap()
}

fn room_free(x: i32, y: i32) -> bool {
    (1..=10).contains(&x) && (1..=6).contains(&y) && !((3..=6).contains(&x) && (2..=5).contains(&y))
}

/// A 4 x 2 m room cut in two by a wall at x 2.0..2.5: the left room's
/// free cells are x 1..=6, y 1..=6 (36), the right room's x 11..=14,
/// y 1..=6 (24).
fn two_rooms() -> World {
    World::new(
        "two-rooms",
        Some(rect(0.0, 0.0, 4.0, 2.0)),
        vec![rect(2.0, -0.5, 2.5, 2.5)],
    )
    .unwrap()
}

fn left_free(x: i32, y: i32) -> bool {
    (1..=6).contains(&x) && (1..=6).contains(&y)
}

fn right_free(x: i32, y: i32) -> bool {
    (11..=14).contains(&x) && (1..=6).contains(&y)
}

/// A map holding exactly `cells` (raw values), 8-cell tiles.
fn map_of(cells: impl IntoIterator<Item = ((i32, i32), i16)>) -> TileMap {
    let size = TileSize::new(8).unwrap();
    let mut tiles: HashMap<TileKey, Vec<i16>> = HashMap::new();
    for ((x, y), raw) in cells {
        let (key, offset) = size.split(CellIndex::new(x, y));
        tiles
            .entry(key)
            .or_insert_with(|| vec![LogOdds::UNKNOWN_RAW; size.area()])[offset.index(size)] = raw;
    }
    let mut map = TileMap::new(res(), size, ClampLimits::NONE);
    for (key, raw) in tiles {
        let bytes: Vec<u8> = raw.iter().flat_map(|v| v.to_le_bytes()).collect();
        map.insert(key, Tile::from_dense_bytes(size, &bytes).unwrap())
            .unwrap();
    }
    map
}

/// The truth of every cell in `xs` x `ys` as `free` says, written
/// perfectly, with `edits` on top.
fn perfect(
    xs: std::ops::RangeInclusive<i32>,
    ys: std::ops::RangeInclusive<i32>,
    free: impl Fn(i32, i32) -> bool,
    edits: &[((i32, i32), i16)],
) -> TileMap {
    let mut cells: HashMap<(i32, i32), i16> = HashMap::new();
    for y in ys {
        for x in xs.clone() {
            cells.insert((x, y), if free(x, y) { FREE_RAW } else { OCC_RAW });
        }
    }
    cells.extend(edits.iter().copied());
    map_of(cells)
}

fn judge(map: &TileMap, world: &World, seeds: &[Point2], radius: f64) -> MapQuality {
    map_quality(&QualityInput {
        map,
        world,
        seeds,
        robot_radius_m: radius,
    })
    .unwrap()
}

#[test]
fn the_verdict_image_paints_each_cell_by_its_verdict() {
    let world = room();
    let map = map_of([
        ((1, 1), FREE_RAW),
        ((0, 0), OCC_RAW),
        ((2, 1), UNCERTAIN_RAW),
        ((1, 2), OCC_RAW),
        ((11, 0), FREE_RAW),
        ((0, 3), UNCERTAIN_RAW),
    ]);
    let image = verdict_image(&QualityInput::new(&map, &world)).unwrap();
    // The world's cells 0..=12 x 0..=8 and one more each side.
    assert_eq!((image.width, image.height), (15, 11));
    assert_eq!(image.min_cell, CellIndex::new(-1, -1));
    assert_eq!(image.rgb.len(), 15 * 11 * 3);
    let at = |x: i32, y: i32| {
        let (col, row) = ((x + 1) as usize, (9 - y) as usize);
        let i = 3 * (row * 15 + col);
        [image.rgb[i], image.rgb[i + 1], image.rgb[i + 2]]
    };
    assert_eq!(at(1, 1), Verdict::FreeAsFree.rgb());
    assert_eq!(at(0, 0), Verdict::OccupiedAsOccupied.rgb());
    assert_eq!(at(2, 1), Verdict::FreeAsUncertain.rgb());
    assert_eq!(at(1, 2), Verdict::FreeAsOccupied.rgb());
    assert_eq!(at(11, 0), Verdict::OccupiedAsFree.rgb());
    assert_eq!(at(0, 3), Verdict::OccupiedAsUncertain.rgb());
    // Never observed: the box's cell by its truth, a free cell, and
    // the cells beyond the walls.
    assert_eq!(at(4, 3), UNOBSERVED_OCCUPIED_RGB);
    assert_eq!(at(8, 4), UNOBSERVED_FREE_RGB);
    assert_eq!(at(-1, -1), UNOBSERVED_OCCUPIED_RGB);
    // The same cells as map_quality counts them.
    let q = judge(&map, &world, &[], 0.3);
    let c = q.confusion;
    assert_eq!(
        (c.free_as_free, c.occupied_as_occupied, c.free_as_uncertain),
        (1, 1, 1)
    );
    assert_eq!(
        (
            c.free_as_occupied,
            c.occupied_as_free,
            c.occupied_as_uncertain
        ),
        (1, 1, 1)
    );
    // Scaled: each pixel a square, in place.
    let big = image.scaled(3);
    assert_eq!((big.width, big.height), (45, 33));
    let big_at = |col: usize, row: usize| {
        let i = 3 * (row * 45 + col);
        [big.rgb[i], big.rgb[i + 1], big.rgb[i + 2]]
    };
    for (dc, dr) in [(0, 0), (2, 2), (1, 2)] {
        // Cell (2, 1): column 3, row 8 of the small image.
        assert_eq!(big_at(9 + dc, 24 + dr), Verdict::FreeAsUncertain.rgb());
    }
    assert_eq!(image.fit_factor(1000), 66);
    assert_eq!(image.fit_factor(10), 1);
    // The same refusals as map_quality.
    let empty = map_of([]);
    assert!(verdict_image(&QualityInput::new(&empty, &world)).is_err());
}

#[test]
fn a_perfect_map_scores_one_everywhere() {
    let world = room();
    let map = perfect(0..=11, 0..=7, room_free, &[]);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.cells_observed(), 96);
    assert_eq!(q.fraction_correct(), 1.0);
    assert_eq!(q.cells_uncertain(), 0);
    assert_eq!((q.map_occupied, q.map_occupied_near_truth), (52, 52));
    assert_eq!(q.occupied_precision(), Some(1.0));
    // Walls: 8 + 8 + 10 + 10 cells of the ring, 12 of the box's 16
    // (its 4 inner cells see no free space).
    assert_eq!((q.surface_cells, q.surface_cells_found), (48, 48));
    assert_eq!(q.occupied_recall(), Some(1.0));
    assert_eq!((q.reachable_cells, q.reachable_cells_free), (44, 44));
    assert_eq!(q.coverage(), Some(1.0));
    assert_eq!(
        q.confusion,
        Confusion {
            free_as_free: 44,
            occupied_as_occupied: 52,
            ..Confusion::default()
        }
    );
}

#[test]
fn the_truth_holds_beyond_the_walls_and_at_corners() {
    // Everything from well outside the world to well past it: cells
    // outside the room or the raster are occupied, and the cells that
    // touch the box only at a corner ((3, 2), (6, 2), (3, 5), (6, 5))
    // are occupied too.
    let world = room();
    let map = perfect(-4..=16, -4..=12, room_free, &[]);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.cells_observed(), 21 * 17);
    assert_eq!(q.fraction_correct(), 1.0);
    assert_eq!(q.occupied_precision(), Some(1.0));
    assert_eq!(q.occupied_recall(), Some(1.0));
    assert_eq!(q.coverage(), Some(1.0));
}

#[test]
fn one_wrong_cell_costs_exactly_one_cell() {
    let world = room();
    // (8, 3) is open floor, two cells from the box.
    let map = perfect(0..=11, 0..=7, room_free, &[((8, 3), OCC_RAW)]);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.cells_observed(), 96);
    assert_eq!(q.cells_correct(), 95);
    assert_eq!(q.fraction_correct(), 95.0 / 96.0);
    assert_eq!(q.confusion.free_as_occupied, 1);
    assert_eq!(q.occupied_precision(), Some(52.0 / 53.0));
    assert_eq!(q.occupied_recall(), Some(1.0));
    assert_eq!(q.coverage(), Some(43.0 / 44.0));

    // Next to the box, the same mistake is within one cell of a wall:
    // wrong, but not imprecise.
    let map = perfect(0..=11, 0..=7, room_free, &[((7, 3), OCC_RAW)]);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.fraction_correct(), 95.0 / 96.0);
    assert_eq!(q.occupied_precision(), Some(1.0));
}

#[test]
fn an_uncertain_cell_is_never_right() {
    let world = room();
    let map = perfect(0..=11, 0..=7, room_free, &[((8, 3), UNCERTAIN_RAW)]);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.cells_observed(), 96);
    assert_eq!(q.cells_uncertain(), 1);
    assert_eq!(q.confusion.free_as_uncertain, 1);
    assert_eq!(q.fraction_correct(), 95.0 / 96.0);
    assert_eq!(q.occupied_precision(), Some(1.0));
    assert_eq!(q.coverage(), Some(43.0 / 44.0));
}

#[test]
fn a_missing_wall_lowers_recall_by_the_cells_not_found_within_one_cell() {
    let world = room();
    // The right wall's inner cells mapped free: (11, 0) and (11, 7) are
    // corners, (11, 1) and (11, 6) still have a mapped corner cell
    // diagonally next to them, (11, 2..=5) have nothing.
    let edits: Vec<_> = (0..=7).map(|y| ((11, y), FREE_RAW)).collect();
    let map = perfect(0..=11, 0..=7, room_free, &edits);
    let q = judge(&map, &world, &[], 0.3);
    assert_eq!(q.fraction_correct(), 88.0 / 96.0);
    assert_eq!(q.confusion.occupied_as_free, 8);
    assert_eq!(q.occupied_precision(), Some(1.0));
    assert_eq!((q.surface_cells, q.surface_cells_found), (48, 44));
    assert_eq!(q.occupied_recall(), Some(44.0 / 48.0));
}

#[test]
fn seeds_choose_the_space_a_robot_could_reach() {
    let world = two_rooms();
    let free = |x, y| left_free(x, y) || right_free(x, y);
    // Only the left room is mapped.
    let map = perfect(0..=7, 0..=7, free, &[]);
    let left = Point2::new(0.8, 1.0);
    let right = Point2::new(3.0, 1.0);

    let q = judge(&map, &world, &[], 0.3);
    assert_eq!((q.seeds_given, q.seeds_used), (0, 0));
    assert_eq!((q.reachable_cells, q.reachable_cells_free), (60, 36));
    // The right room's walls count too: 8 + 8 + 4 + 4 cells unseen.
    assert_eq!((q.surface_cells, q.surface_cells_found), (52, 28));
    // Of the walls the map looked at, it found every one.
    assert_eq!(q.observed_occupied_recall(), Some(1.0));
    assert!(q.surface_cells_observed < q.surface_cells);

    let q = judge(&map, &world, &[left], 0.3);
    assert_eq!((q.seeds_given, q.seeds_used), (1, 1));
    assert_eq!(q.coverage(), Some(1.0));
    // The left room's walls: x = 0, x = 7 (8 each), y = 0, y = 7 (6 each).
    assert_eq!((q.surface_cells, q.surface_cells_found), (28, 28));

    let q = judge(&map, &world, &[left, right], 0.3);
    assert_eq!(q.seeds_used, 2);
    assert_eq!(q.reachable_cells, 60);

    // A wider robot keeps 0.4 m off the walls: cells 2..=5 both ways.
    let q = judge(&map, &world, &[left], 0.4);
    assert_eq!((q.reachable_cells, q.reachable_cells_free), (16, 16));
    // A seed whose own cell is too near the wall starts from the
    // nearest clear neighbour.
    let q = judge(&map, &world, &[Point2::new(0.49, 0.55)], 0.4);
    assert_eq!((q.seeds_used, q.reachable_cells), (1, 16));

    // A seed inside the dividing wall or far away starts nothing.
    let q = judge(
        &map,
        &world,
        &[Point2::new(2.25, 1.0), Point2::new(1e12, 0.0)],
        0.3,
    );
    assert_eq!((q.seeds_given, q.seeds_used), (2, 0));
    assert_eq!(q.reachable_cells, 0);
    assert_eq!(q.coverage(), None);
    assert_eq!(q.occupied_recall(), None);
    assert_eq!(q.fraction_correct(), 1.0);
}

#[test]
fn undefined_figures_are_none_and_null() {
    let world = room();
    // One free cell: no occupied cell to be precise about.
    let map = map_of([((8, 3), FREE_RAW)]);
    let q = judge(
        &map,
        &world,
        &[Point2::new(2.25, 0.5), Point2::new(-5.0, -5.0)],
        0.3,
    );
    assert_eq!(q.occupied_precision(), None);
    assert_eq!(q.occupied_recall(), Some(0.0));
    assert_eq!(q.coverage(), Some(1.0 / 44.0));
    let json = q.to_json();
    let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    assert_eq!(
        value["occupied_precision"],
        serde_json::Value::Null,
        "{json}"
    );
    assert_eq!(value["fraction_correct"].as_f64(), Some(1.0), "{json}");
    assert_eq!(value["seeds_used"], 1, "{json}");
    assert_eq!(value["confusion"]["free_as_free"], 1, "{json}");
    let table = q.table();
    assert!(
        table.contains("| occupied precision (±1 cell) | n/a | 0 of 0 |"),
        "{table}"
    );
    assert!(
        table.contains("| coverage of reachable free space | 0.0227 | 1 of 44 |"),
        "{table}"
    );
    assert!(table.contains("| free | 1 | 0 | 0 |"), "{table}");
}

#[test]
fn bad_input_is_an_error() {
    let world = room();
    let empty = map_of([]);
    let err = map_quality(&QualityInput::new(&empty, &world)).unwrap_err();
    assert!(err.to_string().contains("no observed cell"), "{err}");
    // Cells written but never observed are no better.
    let unknown = map_of([((3, 3), LogOdds::UNKNOWN_RAW)]);
    assert!(map_quality(&QualityInput::new(&unknown, &world)).is_err());

    let map = map_of([((8, 3), FREE_RAW)]);
    for radius in [f64::NAN, -0.1, f64::INFINITY, 1e3] {
        let input = QualityInput {
            robot_radius_m: radius,
            ..QualityInput::new(&map, &world)
        };
        let err = map_quality(&input).unwrap_err();
        assert!(err.to_string().contains("robot_radius_m"), "{err}");
    }
    let seeds = [Point2::new(1.0, 1.0), Point2::new(f64::NAN, 0.0)];
    let input = QualityInput {
        seeds: &seeds,
        ..QualityInput::new(&map, &world)
    };
    let err = map_quality(&input).unwrap_err();
    assert!(err.to_string().contains("seeds[1]"), "{err}");

    // 0.1 mm cells over a 3 x 2 m room: 6e8 cells, refused.
    let fine = Resolution::new(1e-4).unwrap();
    let mut tiny = TileMap::new(fine, TileSize::new(8).unwrap(), ClampLimits::NONE);
    let bytes: Vec<u8> = [FREE_RAW; 64]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    tiny.insert(
        TileKey::new(0, 0),
        Tile::from_dense_bytes(TileSize::new(8).unwrap(), &bytes).unwrap(),
    )
    .unwrap();
    let err = map_quality(&QualityInput::new(&tiny, &world)).unwrap_err();
    assert!(err.to_string().contains("cells"), "{err}");
}

#[test]
fn the_truth_uses_the_worlds_own_free_space() {
    let office =
        deog_world::parse_world(include_str!("../../../worlds/office.toml"), "office.toml")
            .unwrap();
    for world in [room(), two_rooms(), office] {
        let truth = Truth::new(&world, res(), 0.2);
        let (min, max) = world.bounds();
        // Every 0.125 m, on the walls and obstacle edges of the test
        // worlds too, and a little past the bounds.
        let steps = |lo: f64, hi: f64| {
            let n = ((hi - lo) / 0.125) as i32 + 8;
            (-4..n).map(move |k| lo + f64::from(k) * 0.125)
        };
        for y in steps(min.y, max.y) {
            for x in steps(min.x, max.x) {
                let p = Point2::new(x, y);
                assert_eq!(
                    truth.is_free(p),
                    world.is_free(p),
                    "{} {x} {y}",
                    world.name()
                );
            }
        }
    }
}
