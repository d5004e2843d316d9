//! The two real map_server maps (the copies in `mapfile/tests/data`) as
//! worlds: free pixels free, solid pixels solid, few polygons.

use std::path::PathBuf;

use deog_mapfile::{Cell, MapImage};
use deog_world::{ImageWorldOptions, Point2, World, load_map_world, load_world_any};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../mapfile/tests/data")
        .join(rel)
}

/// Checks every pixel centre of `map` against `world`; returns the count of
/// solid pixels.
fn check_pixels(map: &MapImage, world: &World, unknown_is_free: bool) -> usize {
    let mut solid = 0;
    for row in 0..map.height {
        for col in 0..map.width {
            let (x, y) = map.cell_center(col, row).expect("centre");
            let free = world.is_free(Point2::new(x, y));
            let cell = map.occupancy(col, row);
            let expect_free = match cell {
                Cell::Free => true,
                Cell::Occupied => false,
                Cell::Unknown => unknown_is_free,
            };
            assert_eq!(free, expect_free, "pixel ({col}, {row}) is {cell:?}");
            solid += usize::from(!expect_free);
        }
    }
    solid
}

fn check_map(rel: &str, name: &str) {
    let map = MapImage::load(data(rel)).expect("map");
    for unknown_is_free in [false, true] {
        let options = ImageWorldOptions { unknown_is_free };
        let world = load_map_world(data(rel), &options).expect("world");
        assert_eq!(world.name(), name);
        let ((x0, y0), (x1, y1)) = map.world_bounds().expect("bounds");
        assert_eq!(world.bounds(), (Point2::new(x0, y0), Point2::new(x1, y1)));
        assert!(world.boundary().is_some(), "the map's edge is a wall");
        let solid = check_pixels(&map, &world, unknown_is_free);
        let rects = world.obstacles().len();
        println!(
            "{rel} (unknown_is_free: {unknown_is_free}): {solid} solid pixels in {rects} rectangles"
        );
        if unknown_is_free {
            // Only the occupied pixels are left: in a laser map they are
            // one-pixel-thin, ragged walls, which merge less well.
            assert!(rects * 3 <= solid, "{rects} rectangles for {solid} pixels");
        } else {
            assert!(rects * 30 <= solid, "{rects} rectangles for {solid} pixels");
        }
    }
}

#[test]
fn lse_arena_becomes_a_world() {
    check_map("lse_arena.yaml", "lse_arena");
}

#[test]
fn turtlebot3_world_becomes_a_world() {
    check_map("turtlebot3_world/map.yaml", "map");
}

#[test]
fn load_world_any_takes_a_yaml_map() {
    let world = load_world_any(data("lse_arena.yaml")).expect("world");
    let direct =
        load_map_world(data("lse_arena.yaml"), &ImageWorldOptions::default()).expect("world");
    assert_eq!(world, direct);
}

#[test]
fn a_rotated_map_names_its_origin_line() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rotated-map");
    std::fs::create_dir_all(&dir).expect("dir");
    std::fs::copy(data("lse_arena.pgm"), dir.join("lse_arena.pgm")).expect("copy");
    let yaml = std::fs::read_to_string(data("lse_arena.yaml"))
        .expect("yaml")
        .replace("[0.000000, 0.000000, 0.000000]", "[0, 0, 1.57]");
    let path = dir.join("rot.yaml");
    std::fs::write(&path, yaml).expect("write");
    let e = load_map_world(&path, &ImageWorldOptions::default()).expect_err("rotated");
    assert_eq!(
        e.to_string(),
        format!(
            "{}:3: origin: yaw must be 0 (rotated maps are not supported), got 1.57",
            path.display()
        )
    );
}

#[test]
fn a_broken_map_is_an_error_not_a_panic() {
    let e =
        load_map_world(data("no-such.yaml"), &ImageWorldOptions::default()).expect_err("missing");
    assert!(e.to_string().contains("no-such.yaml"), "{e}");
}
