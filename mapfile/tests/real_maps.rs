//! The two real map_server maps (copies in `tests/data`, see its README):
//! load, check, write back, reload.

use std::path::PathBuf;

use deog_mapfile::{Cell, MapFileError, MapImage, Mode, write_map};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

fn count(map: &MapImage, cell: Cell) -> usize {
    (0..map.height)
        .flat_map(|r| (0..map.width).map(move |c| (c, r)))
        .filter(|&(c, r)| map.occupancy(c, r) == cell)
        .count()
}

#[test]
fn lse_arena_loads() {
    let map = MapImage::load(data("lse_arena.yaml")).expect("load");
    assert_eq!((map.width, map.height), (80, 60));
    assert_eq!(map.resolution, 0.05);
    assert_eq!(map.origin, (0.0, 0.0, 0.0));
    assert!(!map.negate);
    assert_eq!((map.occupied_thresh, map.free_thresh), (0.65, 0.196));
    assert_eq!(map.mode, Mode::Trinary);
    assert_eq!(map.pixels.len(), 80 * 60);
    // Its border is a wall, its inside free (239 or 255), nothing unknown.
    assert_eq!(map.occupancy(0, 0), Cell::Occupied);
    assert_eq!(count(&map, Cell::Unknown), 0);
    assert!(count(&map, Cell::Free) > count(&map, Cell::Occupied));
}

#[test]
fn turtlebot3_world_loads() {
    let map = MapImage::load(data("turtlebot3_world/map.yaml")).expect("load");
    assert_eq!((map.width, map.height), (384, 384));
    assert_eq!(map.origin, (-10.0, -10.0, 0.0));
    assert_eq!(map.cell_center(0, 0).expect("centre"), (-9.975, -9.975));
    // map_saver's three grays: 0 occupied, 205 unknown, 254 free.
    let (free, occupied, unknown) = (
        count(&map, Cell::Free),
        count(&map, Cell::Occupied),
        count(&map, Cell::Unknown),
    );
    assert_eq!(free + occupied + unknown, 384 * 384);
    assert!(
        free > 0 && occupied > 0 && unknown > free,
        "{free} {occupied} {unknown}"
    );
    // The corner was never seen.
    assert_eq!(map.occupancy(0, 0), Cell::Unknown);
}

#[test]
fn both_maps_round_trip_through_write_map() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (rel, stem) in [
        ("lse_arena.yaml", "lse"),
        ("turtlebot3_world/map.yaml", "tb3"),
    ] {
        let map = MapImage::load(data(rel)).expect("load");
        let yaml = write_map(dir.path(), stem, &map).expect("write");
        let back = MapImage::load(&yaml).expect("reload");
        assert_eq!(back, map, "{rel}");
        // Written as map_saver does: P5, maxval 255, nothing after the pixels.
        let pgm = std::fs::read(dir.path().join(format!("{stem}.pgm"))).expect("pgm");
        let header = format!(
            "P5\n# CREATOR: deog-mapfile 0.050 m/pix\n{} {}\n255\n",
            map.width, map.height
        );
        assert!(pgm.starts_with(header.as_bytes()));
        assert_eq!(pgm.len(), header.len() + map.pixels.len());
    }
}

#[test]
fn a_plain_p2_copy_loads_the_same() {
    let map = MapImage::load(data("lse_arena.yaml")).expect("load");
    let dir = tempfile::tempdir().expect("tempdir");
    let mut p2 = format!("P2\n# plain copy\n{} {}\n255\n", map.width, map.height);
    for row in map.pixels.chunks(map.width as usize) {
        let line: Vec<String> = row.iter().map(u8::to_string).collect();
        p2.push_str(&line.join(" "));
        p2.push('\n');
    }
    std::fs::write(dir.path().join("plain.pgm"), p2).expect("pgm");
    let yaml = std::fs::read_to_string(data("lse_arena.yaml"))
        .expect("yaml")
        .replace("lse_arena.pgm", "plain.pgm");
    std::fs::write(dir.path().join("plain.yaml"), yaml).expect("yaml");
    assert_eq!(
        MapImage::load(dir.path().join("plain.yaml")).expect("p2"),
        map
    );
}

#[test]
fn png_export_of_a_real_map() {
    let map = MapImage::load(data("turtlebot3_world/map.yaml")).expect("load");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("map.png");
    deog_mapfile::to_png(&path, &map).expect("png");
    let bytes = std::fs::read(&path).expect("read");
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    // Mostly uniform grays compress far below the raw 147 456 bytes.
    assert!(bytes.len() < 20_000, "{}", bytes.len());
}

#[test]
fn a_missing_yaml_names_the_file() {
    let e = MapImage::load("no/such/map.yaml").expect_err("missing");
    assert!(matches!(e, MapFileError::Io { .. }));
    assert!(e.to_string().starts_with("no/such/map.yaml: "), "{e}");
}

#[test]
fn a_missing_image_names_the_image() {
    let dir = tempfile::tempdir().expect("tempdir");
    let yaml = std::fs::read_to_string(data("lse_arena.yaml"))
        .expect("yaml")
        .replace("lse_arena.pgm", "gone.pgm");
    let path = dir.path().join("m.yaml");
    std::fs::write(&path, yaml).expect("write");
    let e = MapImage::load(&path).expect_err("missing image");
    let gone = dir.path().join("gone.pgm").display().to_string();
    assert!(e.to_string().starts_with(&format!("{gone}: ")), "{e}");
}

#[test]
fn a_rotated_map_loads_but_is_refused_where_axes_matter() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::copy(data("lse_arena.pgm"), dir.path().join("lse_arena.pgm")).expect("copy");
    let yaml = std::fs::read_to_string(data("lse_arena.yaml"))
        .expect("yaml")
        .replace("[0.000000, 0.000000, 0.000000]", "[0, 0, 0.3]");
    let path = dir.path().join("rot.yaml");
    std::fs::write(&path, yaml).expect("write");
    assert_eq!(MapImage::load(&path).expect("load").origin.2, 0.3);
    let e = MapImage::load_axis_aligned(&path).expect_err("rotated");
    assert_eq!(
        e.to_string(),
        format!(
            "{}:3: origin: yaw must be 0 (rotated maps are not supported), got 0.3",
            path.display()
        )
    );
}

#[test]
fn the_copies_match_the_shared_originals() {
    // Where shared/ sits beside the repository, the copies must be byte for
    // byte the originals; on a machine without it there is nothing to check.
    let shared = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/maps");
    if !shared.is_dir() {
        return;
    }
    for rel in [
        "lse_arena.yaml",
        "lse_arena.pgm",
        "turtlebot3_world/map.yaml",
        "turtlebot3_world/map.pgm",
    ] {
        let original = std::fs::read(shared.join(rel)).expect("original");
        assert_eq!(std::fs::read(data(rel)).expect("copy"), original, "{rel}");
    }
}
