#![allow(missing_docs)] // criterion_group! generates an undocumented function.
//! Frames of laser rays (and, for comparison, the Scout's sonar ring)
//! through [`BeamFrameIntegrator`], at 0.05 m cells in 64 × 64 tiles.
//!
//! Laser frames are a `laser180` scan: 180 rays one degree apart from the
//! robot's right to its left, mapped with the ray model's defaults cut at
//! 20 m (`max_mapped_range`). Two workloads of 200 poses each:
//! - `open20`: every ray echoes at 20 m, the most cells a 20 m frame holds;
//! - `hall`: ranges cast in a 40 m × 30 m hall with pillars and shelves,
//!   from poses on a loop through it.
//!
//! Three ways for the laser frames: `sparse` is [`BeamFrameIntegrator`]
//! (per-tile scratch, tiles made on first touch); `dense` folds the same
//! cells into a scratch over the frame's whole bounding box, as
//! [`FrameIntegrator`] does for cones, then cuts it into tiles; `baseline`
//! combines cells in a hash map and groups them into tiles afterwards.
//! The `scout` groups run the sonar benchmark's room frames through
//! [`FrameIntegrator`] (`dense`) and [`BeamFrameIntegrator`] (`sparse`).
//! Run with `cargo bench -p deog-grid --bench beam_frame_integration`.

use std::collections::HashMap;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::frame::combine;
use deog_grid::{
    BeamFrameIntegrator, BeamModel, BeamReading, CellBox, CellIndex, ClampLimits, FrameBeam,
    FrameIntegrator, Pose2, RayModel, RayModelParams, Resolution, SensorRing, SonarModel,
    SonarModelParams, TileDelta, TileKey, TileMap, TileSize, cast_cone, cast_ray,
};

const FRAMES: usize = 200;
const RES: Resolution = Resolution::DEFAULT;
const SIZE: TileSize = TileSize::DEFAULT;

/// A map whose cells inside `boxes` (x0, y0, x1, y1, metres) are occupied.
fn occupied(boxes: &[(f64, f64, f64, f64)]) -> TileMap {
    let mut map = TileMap::new(RES, SIZE, ClampLimits::default());
    for &(x0, y0, x1, y1) in boxes {
        let (a, b) = (
            RES.cell_of(x0, y0).unwrap(),
            RES.cell_of(x1 - 1e-9, y1 - 1e-9).unwrap(),
        );
        for y in a.y..=b.y {
            for x in a.x..=b.x {
                let (key, offset) = SIZE.split(CellIndex::new(x, y));
                let mut delta = TileDelta::zero(key, SIZE);
                delta.raw_mut()[offset.index(SIZE)] = 3000;
                map.apply(&delta).unwrap();
            }
        }
    }
    map
}

/// A 40 m × 30 m hall: walls, four pillars, two rows of shelves.
fn hall() -> TileMap {
    occupied(&[
        (-0.2, -0.2, 40.2, 0.0),
        (-0.2, 30.0, 40.2, 30.2),
        (-0.2, -0.2, 0.0, 30.2),
        (40.0, -0.2, 40.2, 30.2),
        (10.0, 10.0, 10.5, 10.5),
        (30.0, 10.0, 30.5, 10.5),
        (10.0, 20.0, 10.5, 20.5),
        (30.0, 20.0, 30.5, 20.5),
        (15.0, 4.0, 25.0, 4.6),
        (15.0, 25.4, 25.0, 26.0),
    ])
}

/// The sonar benchmark's furnished 10 m × 8 m room.
fn room() -> TileMap {
    occupied(&[
        (-0.1, -0.1, 10.1, 0.0),
        (-0.1, 8.0, 10.1, 8.1),
        (-0.1, -0.1, 0.0, 8.1),
        (10.0, -0.1, 10.1, 8.1),
        (3.0, 3.0, 4.2, 3.8),
        (7.5, 6.0, 9.9, 7.9),
        (6.0, 2.0, 6.3, 2.3),
        (0.1, 5.0, 0.9, 7.2),
    ])
}

fn laser_beams() -> Vec<FrameBeam> {
    (0..180)
        .map(|i| FrameBeam {
            mount: Pose2::new(0.0, 0.0, f64::from(i - 90).to_radians()),
            model: BeamModel::Ray(0),
        })
        .collect()
}

fn ray_params() -> RayModelParams {
    RayModelParams {
        max_mapped_range: 20.0,
        ..RayModelParams::default()
    }
}

type Frame = (Pose2, Vec<BeamReading>);

fn open_frames() -> Vec<Frame> {
    (0..FRAMES)
        .map(|i| {
            let t = i as f64 / FRAMES as f64 * std::f64::consts::TAU;
            let pose = Pose2::new(3.0 * t.cos(), 2.0 * t.sin(), t);
            (pose, vec![BeamReading::Echo(20.0); 180])
        })
        .collect()
}

fn hall_frames(beams: &[FrameBeam]) -> Vec<Frame> {
    let hall = hall();
    let max_range = RayModelParams::default().max_range;
    (0..FRAMES)
        .map(|i| {
            let t = i as f64 / FRAMES as f64 * std::f64::consts::TAU;
            let pose = Pose2::new(20.0 + 14.0 * t.cos(), 15.0 + 8.0 * t.sin(), t + 1.7);
            let readings = beams
                .iter()
                .map(|b| {
                    cast_ray(&hall, RES, &pose.compose(&b.mount), max_range)
                        .unwrap()
                        .map_or(BeamReading::NoEcho, BeamReading::Echo)
                })
                .collect();
            (pose, readings)
        })
        .collect()
}

fn range_of(reading: &BeamReading) -> f64 {
    match reading {
        BeamReading::Echo(r) => *r,
        BeamReading::NoEcho => f64::INFINITY,
    }
}

/// The laser frame's cells as (cell, delta), ray after ray.
fn ray_cells(
    model: &RayModel,
    beams: &[FrameBeam],
    frame: &Frame,
    mut f: impl FnMut(CellIndex, i16),
) {
    for (beam, reading) in beams.iter().zip(&frame.1) {
        let range = range_of(reading).min(model.params().max_range);
        model
            .for_each_cell(&frame.0.compose(&beam.mount), range, RES, &mut f)
            .unwrap();
    }
}

/// The dense way: a scratch over the frame's bounding box, cut into tiles.
fn dense(
    model: &RayModel,
    beams: &[FrameBeam],
    frame: &Frame,
    scratch: &mut Vec<i16>,
) -> Vec<TileDelta> {
    let mut frame_box: Option<CellBox> = None;
    for (beam, reading) in beams.iter().zip(&frame.1) {
        let s = frame.0.compose(&beam.mount);
        let reach = match reading {
            BeamReading::Echo(r) => model.echo(*r).unwrap().extent,
            BeamReading::NoEcho => model.no_echo().extent,
        };
        for (x, y) in [
            (s.x, s.y),
            (s.x + reach * s.theta.cos(), s.y + reach * s.theta.sin()),
        ] {
            let c = RES.cell_of(x, y).unwrap();
            let b = CellBox { min: c, max: c };
            frame_box = Some(frame_box.map_or(b, |f| f.union(&b)));
        }
    }
    let frame_box = frame_box.unwrap();
    let width = frame_box.width() as usize;
    scratch.clear();
    scratch.resize(width * frame_box.height() as usize, 0);
    ray_cells(model, beams, frame, |cell, d| {
        let i = (cell.y - frame_box.min.y) as usize * width + (cell.x - frame_box.min.x) as usize;
        scratch[i] = combine(scratch[i], d);
    });
    let side = SIZE.cells() as usize;
    let (first, last) = SIZE.tiles_covering(&frame_box);
    let mut out = Vec::new();
    for ty in first.y..=last.y {
        for tx in first.x..=last.x {
            let key = TileKey::new(tx, ty);
            let tile_box = SIZE.cell_box(key).unwrap();
            let overlap = tile_box.intersection(&frame_box).unwrap();
            let run = overlap.width() as usize;
            let mut delta: Option<TileDelta> = None;
            for y in overlap.min.y..=overlap.max.y {
                let src = (y - frame_box.min.y) as usize * width
                    + (overlap.min.x - frame_box.min.x) as usize;
                let src = &scratch[src..src + run];
                if src.iter().all(|&d| d == 0) {
                    continue;
                }
                let dst = (y - tile_box.min.y) as usize * side
                    + (overlap.min.x - tile_box.min.x) as usize;
                delta
                    .get_or_insert_with(|| TileDelta::zero(key, SIZE))
                    .raw_mut()[dst..dst + run]
                    .copy_from_slice(src);
            }
            out.extend(delta);
        }
    }
    out
}

/// The plain way: cells combined in a hash map, grouped into tiles after.
fn baseline(model: &RayModel, beams: &[FrameBeam], frame: &Frame) -> Vec<TileDelta> {
    let mut cells: HashMap<CellIndex, i16> = HashMap::new();
    ray_cells(model, beams, frame, |cell, d| {
        let slot = cells.entry(cell).or_insert(0);
        *slot = combine(*slot, d);
    });
    let mut tiles: HashMap<TileKey, TileDelta> = HashMap::new();
    for (cell, d) in cells {
        let (key, offset) = SIZE.split(cell);
        tiles
            .entry(key)
            .or_insert_with(|| TileDelta::zero(key, SIZE))
            .raw_mut()[offset.index(SIZE)] = d;
    }
    tiles.into_values().collect()
}

fn laser(c: &mut Criterion, name: &str, frames: &[Frame]) {
    let beams = laser_beams();
    let model = RayModel::new(ray_params()).unwrap();
    let mut integrator =
        BeamFrameIntegrator::new(vec![], vec![model.clone()], beams.clone(), RES, SIZE).unwrap();
    let mut out = Vec::new();
    let (mut cells, mut tiles) = (0u64, 0u64);
    for (pose, readings) in frames {
        let stats = integrator.integrate(pose, readings, &mut out).unwrap();
        (cells, tiles) = (cells + stats.cells as u64, tiles + stats.tiles as u64);
    }
    // The three ways agree, cell for cell.
    let mut scratch = Vec::new();
    for frame in frames.iter().take(5) {
        out.clear();
        integrator.integrate(&frame.0, &frame.1, &mut out).unwrap();
        let by_key = |v: Vec<TileDelta>| {
            let mut v = v;
            v.sort_by_key(|d| (d.key.y, d.key.x));
            v
        };
        assert!(by_key(dense(&model, &beams, frame, &mut scratch)) == out);
        assert!(by_key(baseline(&model, &beams, frame)) == out);
    }
    eprintln!(
        "laser {name}: {} frames, {:.0} cell deltas and {:.1} tiles per frame",
        frames.len(),
        cells as f64 / frames.len() as f64,
        tiles as f64 / frames.len() as f64
    );
    for (unit, amount) in [("frames", frames.len() as u64), ("cell_deltas", cells)] {
        let mut group = c.benchmark_group(format!("laser_{name}/{unit}"));
        group.throughput(Throughput::Elements(amount));
        group.sample_size(20);
        group.bench_function("sparse", |b| {
            b.iter(|| {
                for (pose, readings) in frames {
                    out.clear();
                    black_box(integrator.integrate(pose, readings, &mut out).unwrap());
                }
            })
        });
        group.bench_function("dense", |b| {
            b.iter(|| {
                for frame in frames {
                    black_box(dense(&model, &beams, frame, &mut scratch));
                }
            })
        });
        group.bench_function("baseline", |b| {
            b.iter(|| {
                for frame in frames {
                    black_box(baseline(&model, &beams, frame));
                }
            })
        });
        group.finish();
    }
}

fn scout(c: &mut Criterion) {
    let model = SonarModel::new(SonarModelParams::default()).unwrap();
    let ring = SensorRing::scout();
    let room = room();
    let p = *model.params();
    let frames: Vec<(Pose2, Vec<f64>, Vec<BeamReading>)> = (0..FRAMES)
        .map(|i| {
            let t = i as f64 / FRAMES as f64 * std::f64::consts::TAU;
            let pose = Pose2::new(5.0 + 3.0 * t.cos(), 4.0 + 2.2 * t.sin(), t + 1.7);
            let ranges: Vec<f64> = ring
                .sensor_poses(&pose)
                .map(|s| {
                    cast_cone(&room, RES, &s, p.half_angle, p.max_range)
                        .unwrap()
                        .map_or(p.max_range, |r| r.max(p.min_range))
                })
                .collect();
            let judged = ranges
                .iter()
                .map(|&r| {
                    if r >= p.max_range {
                        BeamReading::NoEcho
                    } else {
                        BeamReading::Echo(r)
                    }
                })
                .collect();
            (pose, ranges, judged)
        })
        .collect();
    let mut dense = FrameIntegrator::new(model.clone(), ring.clone(), RES, SIZE);
    let mut sparse = BeamFrameIntegrator::for_ring(model, &ring, RES, SIZE);
    let mut out = Vec::new();
    let mut cells = 0u64;
    for (pose, _, judged) in &frames {
        cells += sparse.integrate(pose, judged, &mut out).unwrap().cells as u64;
    }
    for (unit, amount) in [("frames", frames.len() as u64), ("cell_deltas", cells)] {
        let mut group = c.benchmark_group(format!("scout/{unit}"));
        group.throughput(Throughput::Elements(amount));
        group.sample_size(20);
        group.bench_function("dense", |b| {
            b.iter(|| {
                for (pose, ranges, _) in &frames {
                    out.clear();
                    black_box(dense.integrate(pose, ranges, &mut out).unwrap());
                }
            })
        });
        group.bench_function("sparse", |b| {
            b.iter(|| {
                for (pose, _, judged) in &frames {
                    out.clear();
                    black_box(sparse.integrate(pose, judged, &mut out).unwrap());
                }
            })
        });
        group.finish();
    }
}

fn bench(c: &mut Criterion) {
    laser(c, "open20", &open_frames());
    laser(c, "hall", &hall_frames(&laser_beams()));
    scout(c);
}

criterion_group! {
    name = benches;
    config = Criterion::default();
    targets = bench
}
criterion_main!(benches);
