//! A synthetic room and sonar frames cast in it by the plain reference
//! (so the map is exact and any error is the filter's), shared by the
//! filter's and the step's tests.

// Each test binary uses its own share of these.
#![allow(dead_code)]

use deog_grid::{
    CellIndex, OccupancyThresholds, Pose2, Resolution, SensorRing, Tile, TileKey, TileSize,
    normalize_angle,
};
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::range_table::{ConeGeometry, expected_range_by_marching};

pub const OCCUPIED: i16 = 3000;
pub const FREE: i16 = -3000;

/// An asymmetric 8 × 6 m room: walls, an L-shaped block and a box.
pub fn solid(x: f64, y: f64) -> bool {
    let wall = !(0.1..=7.9).contains(&x) || !(0.1..=5.9).contains(&y);
    let blocks = [
        (1.5, 1.0, 2.5, 1.6),
        (5.0, 3.0, 5.5, 5.0),
        (5.5, 3.0, 6.8, 3.5),
    ];
    wall || blocks
        .iter()
        .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y))
}

pub fn settings(budget_bytes: usize) -> MapSettings {
    MapSettings {
        resolution: Resolution::DEFAULT,
        tile_size: TileSize::new(64).unwrap(),
        thresholds: OccupancyThresholds::default(),
        geometry: ConeGeometry::default(),
        budget_bytes,
    }
}

/// The room's tile `key`: cells inside 0..8 × 0..6 m known, the rest unknown.
pub fn room_tile(key: TileKey) -> Tile {
    tile_of(key, room_log_odds)
}

/// The room's log-odds at a point: unknown outside it.
pub fn room_log_odds(x: f64, y: f64) -> i16 {
    if !(0.0..8.0).contains(&x) || !(0.0..6.0).contains(&y) {
        i16::MIN
    } else if solid(x, y) {
        OCCUPIED
    } else {
        FREE
    }
}

/// Tile `key` with each cell's log-odds from its centre.
pub fn tile_of(key: TileKey, log_odds: impl Fn(f64, f64) -> i16) -> Tile {
    let s = settings(0);
    let origin = s.tile_size.origin(key).unwrap();
    let side = s.tile_size.cells() as i32;
    let mut bytes = Vec::new();
    for cy in 0..side {
        for cx in 0..side {
            let (x, y) = s
                .resolution
                .cell_center(CellIndex::new(origin.x + cx, origin.y + cy));
            bytes.extend_from_slice(&log_odds(x, y).to_le_bytes());
        }
    }
    Tile::from_dense_bytes(s.tile_size, &bytes).unwrap()
}

pub fn room() -> LocalMap {
    let mut map = LocalMap::new(settings(1 << 30)).unwrap();
    for ty in -1..=2 {
        for tx in -1..=3 {
            let key = TileKey::new(tx, ty);
            map.insert_tile(key, 1, Some(&room_tile(key))).unwrap();
        }
    }
    map
}

/// The ranges the Scout's sonars read at `pose` in the room (no echo as 11 m).
pub fn frame(map: &LocalMap, pose: &Pose2) -> Vec<f64> {
    frame_of(&SensorRing::scout(), map, pose)
}

/// The ranges `ring`'s sonars read at `pose` in the room.
pub fn frame_of(ring: &SensorRing, map: &LocalMap, pose: &Pose2) -> Vec<f64> {
    let geometry = ConeGeometry::default();
    ring.sensor_poses(pose)
        .map(|s| {
            expected_range_by_marching(map, Resolution::DEFAULT, &geometry, s.x, s.y, s.theta)
                .unwrap_or(11.0)
        })
        .collect()
}

/// A robot driving round a circle of radius `r` about `centre`, 5 cm a
/// frame: (true pose, odometry) per frame, the odometry reading 2 % long.
pub fn circle(centre: (f64, f64), r: f64, frames: usize) -> Vec<(Pose2, Pose2)> {
    let turn = 0.05 / r;
    let mut out = Vec::new();
    let mut odometry = Pose2::new(0.0, 0.0, 0.0);
    for i in 0..frames {
        let a = i as f64 * turn;
        let truth = Pose2::new(
            centre.0 + r * a.cos(),
            centre.1 + r * a.sin(),
            normalize_angle(a + std::f64::consts::FRAC_PI_2),
        );
        assert!(
            !solid(truth.x, truth.y),
            "the test path runs into a wall at frame {i}"
        );
        out.push((truth, odometry));
        odometry = Pose2::new(
            odometry.x + 0.051 * odometry.theta.cos(),
            odometry.y + 0.051 * odometry.theta.sin(),
            normalize_angle(odometry.theta + turn),
        );
    }
    out
}

pub fn path(frames: usize) -> Vec<(Pose2, Pose2)> {
    circle((3.5, 3.2), 1.2, frames)
}

pub fn error(estimate: &Pose2, truth: &Pose2) -> (f64, f64) {
    (
        (estimate.x - truth.x).hypot(estimate.y - truth.y),
        normalize_angle(estimate.theta - truth.theta).abs(),
    )
}

pub fn run(mcl: &mut Mcl, map: &mut LocalMap, steps: &[(Pose2, Pose2)]) -> Vec<(f64, f64)> {
    let mut errors = Vec::new();
    for (truth, odometry) in steps {
        if mcl.predict(odometry).unwrap() {
            let ranges = frame(map, truth);
            mcl.correct(map, &ranges).unwrap();
        }
        let estimate = mcl.estimate(odometry).unwrap();
        errors.push(error(&estimate.pose, truth));
    }
    errors
}

pub fn filter(max_particles: usize, seed: u64) -> Mcl {
    let mut settings = FilterSettings {
        seed,
        ..FilterSettings::default()
    };
    settings.kld.max_particles = max_particles;
    Mcl::new(settings).unwrap()
}
