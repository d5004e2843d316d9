//! One sensor update of the particle filter: every particle's 16 sonar
//! beams scored against the map, reported as beam evaluations per second on
//! one core. Beside it, in the same run, the plain way: each beam's cone
//! cast by marching its rays cell by cell over the map, then the same beam
//! model. Then the table-driven update at 1,000 to 100,000 particles, to
//! show the time per update grows linearly, and 100,000 spread over the
//! room (a global start).
//!
//! The map is a 10 × 8 m room at 5 cm cells with walls and three boxes,
//! its range tables built before timing (they are built once per tile and
//! kept). Particles either track one pose (a cloud of 0.3 m and 0.3 rad,
//! the usual case) or spread uniformly over the free space (global
//! localization, the least cache-friendly case).

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::{
    CellIndex, OccupancyThresholds, Pose2, Resolution, SensorRing, Tile, TileKey, TileSize,
};
use deog_localizer::beam_model::{BeamModel, BeamModelParams};
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::range_table::{ConeGeometry, expected_range_by_marching};
use std::hint::black_box;

const OCCUPIED: i16 = 3000;
const FREE: i16 = -3000;

#[path = "common/room.rs"]
mod room;
use room::solid;

fn room() -> LocalMap {
    let res = Resolution::DEFAULT;
    let size = TileSize::new(64).unwrap();
    let mut map = LocalMap::new(MapSettings {
        resolution: res,
        tile_size: size,
        thresholds: OccupancyThresholds::default(),
        geometry: ConeGeometry::default(),
        budget_bytes: 1 << 30,
    })
    .unwrap();
    let side = size.cells() as i32;
    // Cells -10..210 by -10..170 (the room and a margin of unknown).
    for ty in -1..=3 {
        for tx in -1..=4 {
            let key = TileKey::new(tx, ty);
            let origin = size.origin(key).unwrap();
            let mut bytes = Vec::with_capacity(size.area() * 2);
            for cy in 0..side {
                for cx in 0..side {
                    let cell = CellIndex::new(origin.x + cx, origin.y + cy);
                    let (x, y) = res.cell_center(cell);
                    let value = if !(-0.5..10.5).contains(&x) || !(-0.5..8.5).contains(&y) {
                        i16::MIN
                    } else if solid(x, y) {
                        OCCUPIED
                    } else {
                        FREE
                    };
                    bytes.extend_from_slice(&value.to_le_bytes());
                }
            }
            let tile = Tile::from_dense_bytes(size, &bytes).unwrap();
            map.insert_tile(key, 1, Some(&tile)).unwrap();
        }
    }
    map
}

/// A frame a robot at (4.5, 3.5) facing +x might read.
fn frame() -> Vec<f64> {
    (0..16).map(|i| 1.0 + 0.3 * f64::from(i % 7)).collect()
}

/// A filter of `particles` spread over the whole room (`tracking` false)
/// or around one pose with 0.3 m and 0.3 rad of spread (`tracking` true).
fn filter_with(map: &mut LocalMap, particles: usize, tracking: bool) -> Mcl {
    let mut settings = FilterSettings::default();
    settings.kld.max_particles = particles;
    settings.kld.min_particles = particles.min(500);
    let mut mcl = Mcl::new(settings).unwrap();
    if tracking {
        mcl.start_at(Pose2::new(4.5, 3.5, 0.0), 0.3, 0.3).unwrap();
    } else {
        mcl.start_global(map).unwrap();
    }
    // Build every table the particles touch before timing.
    mcl.score(map, &frame()).unwrap();
    mcl
}

fn beam_evaluations(c: &mut Criterion) {
    let mut map = room();
    let ranges = frame();
    let mut group = c.benchmark_group("sensor_update");
    group.sample_size(20);
    for (name, tracking) in [("tracking", true), ("global", false)] {
        let mut mcl = filter_with(&mut map, 10_000, tracking);
        group.throughput(Throughput::Elements(10_000 * 16));
        group.bench_function(format!("tables/{name}/10000_particles"), |b| {
            b.iter(|| {
                mcl.score(&mut map, black_box(&ranges)).unwrap();
                black_box(mcl.scores()[0])
            })
        });
    }
    let mcl = filter_with(&mut map, 10_000, false);
    // The plain way, on a subset of the same particles (it is slow).
    let particles: Vec<Pose2> = mcl.particles()[..200].to_vec();
    let model = BeamModel::new(BeamModelParams::default()).unwrap();
    let ring = SensorRing::scout();
    let geometry = ConeGeometry::default();
    let res = map.settings().resolution;
    group.throughput(Throughput::Elements(200 * 16));
    group.bench_function("marching/200_particles", |b| {
        b.iter(|| {
            let mut total = 0.0;
            for p in &particles {
                for (sensor, &z) in ring.sensor_poses(p).zip(&ranges) {
                    let expected = expected_range_by_marching(
                        &map,
                        res,
                        &geometry,
                        sensor.x,
                        sensor.y,
                        sensor.theta,
                    );
                    let measured = (z < geometry.max_range).then_some(z);
                    total += 0.05 * model.likelihood(measured, expected).ln();
                }
            }
            black_box(total)
        })
    });
    group.finish();

    let mut group = c.benchmark_group("sensor_update_scaling");
    group.sample_size(10);
    // Tracking clouds of growing size, then global localization's usual
    // size spread over the whole room: the case where the order of the
    // reads matters most.
    let cases = [
        ("tables", 1_000usize, true),
        ("tables", 10_000, true),
        ("tables", 100_000, true),
        ("tables_global", 100_000, false),
    ];
    for (name, n, tracking) in cases {
        let mut mcl = filter_with(&mut map, n, tracking);
        group.throughput(Throughput::Elements(n as u64 * 16));
        group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
            b.iter(|| {
                mcl.score(&mut map, black_box(&ranges)).unwrap();
                black_box(mcl.scores()[0])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, beam_evaluations);
criterion_main!(benches);
