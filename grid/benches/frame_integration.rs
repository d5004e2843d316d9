#![allow(missing_docs)] // criterion_group! generates an undocumented function.
//! Frame integration: Scout frames (16 sonars) at 0.05 m cells, ranges cast
//! in a furnished 10 m × 8 m room, turned into per-tile log-odds deltas.
//!
//! `fast` is [`FrameIntegrator`]: row-clipped cones, tabled deltas, a dense
//! scratch buffer. `baseline` is the plain way: every cell of each cone's
//! bounding box, angle by atan2, delta by ln, cells combined in a hash map
//! and grouped into tiles afterwards. `guarded` is
//! [`FrameIntegrator::integrate_guarded`] with the room itself as the map
//! the cones stop at (the keep-walls method once the walls are known:
//! every cone that reaches a wall walks its cells twice). Run with
//! `cargo bench -p deog-grid --bench frame_integration`.

use std::collections::HashMap;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::frame::combine;
use deog_grid::{
    CellIndex, ClampLimits, ConeGuard, FrameIntegrator, Occupancy, OccupancyView, Pose2,
    Resolution, SensorRing, SonarModel, SonarModelParams, TileDelta, TileMap, TileSize, cast_cone,
};

const FRAMES: usize = 200;

/// Walls of a 10 m × 8 m room with a table, a cabinet, a pillar and a
/// sofa, as a map of occupied cells.
fn room() -> TileMap {
    let res = Resolution::DEFAULT;
    let mut map = TileMap::new(res, TileSize::DEFAULT, ClampLimits::default());
    let boxes: [(f64, f64, f64, f64); 8] = [
        (-0.1, -0.1, 10.1, 0.0), // south wall
        (-0.1, 8.0, 10.1, 8.1),  // north wall
        (-0.1, -0.1, 0.0, 8.1),  // west wall
        (10.0, -0.1, 10.1, 8.1), // east wall
        (3.0, 3.0, 4.2, 3.8),    // table
        (7.5, 6.0, 9.9, 7.9),    // cabinet
        (6.0, 2.0, 6.3, 2.3),    // pillar
        (0.1, 5.0, 0.9, 7.2),    // sofa
    ];
    let size = TileSize::DEFAULT;
    for (x0, y0, x1, y1) in boxes {
        let (a, b) = (
            res.cell_of(x0, y0).unwrap(),
            res.cell_of(x1 - 1e-9, y1 - 1e-9).unwrap(),
        );
        for y in a.y..=b.y {
            for x in a.x..=b.x {
                let (key, offset) = size.split(CellIndex::new(x, y));
                let mut delta = TileDelta::zero(key, size);
                delta.raw_mut()[offset.index(size)] = 3000;
                map.apply(&delta).unwrap();
            }
        }
    }
    map
}

/// Poses along a loop around the table, each with its 16 ranges.
fn frames(model: &SonarModel, ring: &SensorRing) -> Vec<(Pose2, Vec<f64>)> {
    let room = room();
    let p = model.params();
    (0..FRAMES)
        .map(|i| {
            let t = i as f64 / FRAMES as f64 * std::f64::consts::TAU;
            let pose = Pose2::new(5.0 + 3.0 * t.cos(), 4.0 + 2.2 * t.sin(), t + 1.7);
            let ranges = ring
                .sensor_poses(&pose)
                .map(|s| {
                    cast_cone(&room, Resolution::DEFAULT, &s, p.half_angle, p.max_range)
                        .unwrap()
                        .map_or(p.max_range, |r| r.max(p.min_range))
                })
                .collect();
            (pose, ranges)
        })
        .collect()
}

fn baseline(
    model: &SonarModel,
    ring: &SensorRing,
    size: TileSize,
    pose: &Pose2,
    ranges: &[f64],
) -> Vec<TileDelta> {
    let mut cells: HashMap<CellIndex, i16> = HashMap::new();
    for (sensor, &range) in ring.sensor_poses(pose).zip(ranges) {
        model
            .for_each_cell_reference(&sensor, range, Resolution::DEFAULT, |cell, d| {
                let slot = cells.entry(cell).or_insert(0);
                *slot = combine(*slot, d);
            })
            .unwrap();
    }
    let mut tiles: HashMap<_, TileDelta> = HashMap::new();
    for (cell, d) in cells {
        let (key, offset) = size.split(cell);
        tiles
            .entry(key)
            .or_insert_with(|| TileDelta::zero(key, size))
            .raw_mut()[offset.index(size)] = d;
    }
    tiles.into_values().collect()
}

/// The room's occupied cells as the walls a guarded cone stops at.
struct RoomWalls(TileMap);

impl ConeGuard for RoomWalls {
    fn shadows(&self, cell: CellIndex) -> bool {
        self.0.occupancy(cell) == Occupancy::Occupied
    }

    fn keeps(&self, cell: CellIndex) -> bool {
        self.shadows(cell)
    }
}

fn bench(c: &mut Criterion) {
    let model = SonarModel::new(SonarModelParams::default()).unwrap();
    let ring = SensorRing::scout();
    let size = TileSize::DEFAULT;
    let frames = frames(&model, &ring);
    let walls = RoomWalls(room());
    let mut integrator =
        FrameIntegrator::new(model.clone(), ring.clone(), Resolution::DEFAULT, size);

    let mut out = Vec::new();
    let mut cell_deltas = 0u64;
    for (pose, ranges) in &frames {
        cell_deltas += integrator.integrate(pose, ranges, &mut out).unwrap().cells as u64;
    }
    eprintln!(
        "{} frames, {} cell deltas ({:.0} per frame)",
        frames.len(),
        cell_deltas,
        cell_deltas as f64 / frames.len() as f64
    );

    for (unit, amount) in [
        ("frames", frames.len() as u64),
        ("cell_deltas", cell_deltas),
    ] {
        let mut group = c.benchmark_group(format!("frame_integration/{unit}"));
        group.throughput(Throughput::Elements(amount));
        group.sample_size(20);
        group.bench_function("fast", |b| {
            b.iter(|| {
                for (pose, ranges) in &frames {
                    out.clear();
                    black_box(integrator.integrate(pose, ranges, &mut out).unwrap());
                }
            })
        });
        group.bench_function("guarded", |b| {
            b.iter(|| {
                for (pose, ranges) in &frames {
                    out.clear();
                    black_box(
                        integrator
                            .integrate_guarded(pose, ranges, &walls, &mut out)
                            .unwrap(),
                    );
                }
            })
        });
        group.bench_function("baseline", |b| {
            b.iter(|| {
                for (pose, ranges) in &frames {
                    black_box(baseline(&model, &ring, size, pose, ranges));
                }
            })
        });
        group.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default();
    targets = bench
}
criterion_main!(benches);
