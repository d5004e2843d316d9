//! The likelihood field's sensor update: a 180-beam laser frame scored at
//! 5,000 particles, reported as beam evaluations per second on one core.
//! Beside it, in the same run, the plain way: per beam, the endpoint's
//! tile looked up in a hash map of per-tile distances (metres, `f32`),
//! the Gaussian's `exp()` and the mixture's `ln()` worked out anew.
//!
//! The map is three 8 × 10 m rooms side by side at 5 cm cells, joined by
//! doorways, with a few boxes; its distance fields are built before
//! timing (they are built once per tile and kept). The particles track
//! one pose in the middle room (a cloud of 0.3 m and 0.3 rad), or spread
//! over all three rooms (global localization). `model` times the
//! sensor model alone on the tiles the frame needs; `mcl_score` adds
//! finding those tiles ([`Mcl::score`], what a correction does).

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use std::collections::HashMap;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::{
    CellIndex, Occupancy, OccupancyThresholds, OccupancyView, Pose2, Resolution, Tile, TileKey,
    TileSize,
};
use deog_localizer::distance_field::FieldSpec;
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::sensors::{LikelihoodField, LikelihoodFieldParams, SensorModel};
use deog_rig::Rig;

const OCCUPIED: i16 = 3000;
const FREE: i16 = -3000;
const PARTICLES: usize = 5_000;

/// Whether a point of the three rooms is solid.
fn solid(x: f64, y: f64) -> bool {
    let outer = !(0.1..=23.9).contains(&x) || !(0.1..=9.9).contains(&y);
    // Inner walls at x = 8 and 16, each with a 1 m doorway.
    let inner = [8.0, 16.0]
        .iter()
        .any(|&w| (w - 0.05..w + 0.05).contains(&x) && !(4.5..5.5).contains(&y));
    let boxes = [
        (2.0, 1.5, 3.2, 2.3),
        (5.0, 6.0, 6.0, 8.5),
        (10.0, 2.0, 11.5, 2.6),
        (13.0, 7.0, 14.5, 8.0),
        (19.0, 3.0, 20.0, 4.5),
        (21.0, 7.5, 22.5, 8.2),
    ];
    outer
        || inner
        || boxes
            .iter()
            .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y))
}

fn rooms() -> LocalMap {
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
    for ty in -1..=4 {
        for tx in -1..=8 {
            let key = TileKey::new(tx, ty);
            let origin = size.origin(key).unwrap();
            let mut bytes = Vec::with_capacity(size.area() * 2);
            for cy in 0..side {
                for cx in 0..side {
                    let (x, y) = res.cell_center(CellIndex::new(origin.x + cx, origin.y + cy));
                    let value = if !(-0.5..24.5).contains(&x) || !(-0.5..10.5).contains(&y) {
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

/// The laser frame at `pose`, each ray marched in 1 cm steps.
fn frame(rig: &Rig, map: &LocalMap, pose: &Pose2) -> Vec<f64> {
    let res = map.settings().resolution;
    rig.beams()
        .iter()
        .map(|b| {
            let s = pose.compose(&b.mount);
            let (sin, cos) = s.theta.sin_cos();
            let mut t = 0.0;
            while t < b.max_range {
                let cell = res.cell_of(s.x + t * cos, s.y + t * sin).unwrap();
                if map.occupancy(cell) == Occupancy::Occupied {
                    return t;
                }
                t += 0.01;
            }
            b.no_echo.at_or_beyond
        })
        .collect()
}

fn params() -> LikelihoodFieldParams {
    LikelihoodFieldParams {
        max_beams: 180,
        ..LikelihoodFieldParams::default()
    }
}

/// The plain way's map: each tile's distances in metres (NaN for
/// unknown), in a hash map.
fn plain_fields(map: &LocalMap, keys: &[TileKey], spec: &FieldSpec) -> HashMap<TileKey, Vec<f32>> {
    keys.iter()
        .filter_map(|k| {
            let field = map.field(*k)?;
            let metres = field
                .codes()
                .iter()
                .map(|&c| spec.distance_of(c).map_or(f32::NAN, |d| d as f32))
                .collect();
            Some((*k, metres))
        })
        .collect()
}

/// The plain way: the same mixture, worked out per beam.
fn plain_scores(
    fields: &HashMap<TileKey, Vec<f32>>,
    rig: &Rig,
    p: &LikelihoodFieldParams,
    particles: &[Pose2],
    ranges: &[f64],
    out: &mut Vec<f64>,
) {
    let res = Resolution::DEFAULT.metres();
    let side = 64i64;
    let norm = 1.0 / (p.sigma_hit * (2.0 * std::f64::consts::PI).sqrt());
    out.clear();
    for particle in particles {
        let mut total = 0.0;
        for (beam, &z) in rig.beams().iter().zip(ranges) {
            if z >= beam.no_echo.at_or_beyond {
                continue;
            }
            let s = particle.compose(&beam.mount);
            let (x, y) = (s.x + z * s.theta.cos(), s.y + z * s.theta.sin());
            let (cx, cy) = ((x / res).floor() as i64, (y / res).floor() as i64);
            let key = TileKey::new(cx.div_euclid(side) as i32, cy.div_euclid(side) as i32);
            let index = (cy.rem_euclid(side) * side + cx.rem_euclid(side)) as usize;
            let d = match fields.get(&key).map(|f| f[index]) {
                Some(d) if !d.is_nan() => f64::from(d).min(p.max_distance),
                _ => p.unknown_distance,
            };
            let pz = p.z_hit * norm * (-0.5 * (d / p.sigma_hit).powi(2)).exp()
                + p.z_rand / beam.max_range;
            total += pz.ln();
        }
        out.push(total * p.tempering);
    }
}

fn field_evaluations(c: &mut Criterion) {
    let rig = deog_rig::built_in_rig("laser180").unwrap();
    let mut map = rooms();
    let truth = Pose2::new(12.0, 5.0, 0.4);
    let ranges = frame(&rig, &map, &truth);
    let echoes = ranges.iter().filter(|&&r| r < 50.0).count() as u64;
    let mut group = c.benchmark_group("likelihood_field");
    group.sample_size(20);
    for (name, tracking) in [("tracking", true), ("global", false)] {
        let mut settings = FilterSettings::default();
        settings.kld.max_particles = PARTICLES;
        let model = LikelihoodField::new(rig.clone(), params()).unwrap();
        let mut mcl = Mcl::with_sensor(settings, Box::new(model.clone())).unwrap();
        if tracking {
            mcl.start_at(truth, 0.3, 0.3).unwrap();
        } else {
            mcl.start_global(&map).unwrap();
        }
        // Build every field the particles need before timing.
        mcl.score(&mut map, &ranges).unwrap();
        let particles = mcl.particles().to_vec();
        let tiles = mcl.tiles_for_frame(&map, &ranges);
        let mut model = model;
        let mut out = Vec::with_capacity(PARTICLES);
        group.throughput(Throughput::Elements(PARTICLES as u64 * echoes));
        group.bench_function(format!("model/{name}/5000_particles"), |b| {
            b.iter(|| {
                out.clear();
                model
                    .score_particles(&mut map, &tiles, &particles, black_box(&ranges), &mut out)
                    .unwrap();
                black_box(out[0])
            })
        });
        group.bench_function(format!("mcl_score/{name}/5000_particles"), |b| {
            b.iter(|| {
                mcl.score(&mut map, black_box(&ranges)).unwrap();
                black_box(mcl.scores()[0])
            })
        });
        let spec = params().field_spec().unwrap();
        let fields = plain_fields(&map, &tiles, &spec);
        let mut plain = Vec::with_capacity(PARTICLES);
        plain_scores(&fields, &rig, &params(), &particles, &ranges, &mut plain);
        // The same figures, but for the fixed point's rounding.
        for (a, b) in plain.iter().zip(&out) {
            assert!((a - b).abs() < 1e-3 * echoes as f64, "{a} vs {b}");
        }
        group.bench_function(format!("plain/{name}/5000_particles"), |b| {
            b.iter(|| {
                plain_scores(
                    &fields,
                    &rig,
                    &params(),
                    &particles,
                    black_box(&ranges),
                    &mut plain,
                );
                black_box(plain[0])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, field_evaluations);
criterion_main!(benches);
