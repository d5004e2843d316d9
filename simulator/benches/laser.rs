#![allow(missing_docs)] // criterion_group! generates an undocumented function.

//! Laser frames per second on one core, in the 40 x 30 m office world: the
//! built-in `laser180` rig (180 rays, 50 m) fired through the wall index
//! (`Lasers::fire`, noise on), against a baseline that intersects every
//! ray with every wall. One frame is 180 readings
//! (`Throughput::Elements(180)`); robots stand at 1000 random free poses,
//! visited in turn so caches see many places. A robot reads 10 frames a
//! second, so frames/s over 10 is how many laser robots one core keeps up
//! with.

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::Pose2;
use deog_simulator::{LaserParams, Lasers, Robot, ScoutParams};
use deog_world::{Point2, Segment, SegmentIndex, load_world};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OFFICE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../worlds/office.toml");

/// The baseline: every ray against every wall.
fn all_walls(walls: &[Segment], rig: &deog_rig::Rig, pose: &Pose2, out: &mut [f64]) {
    for (beam, range) in rig.beams().iter().zip(out.iter_mut()) {
        let m = pose.compose(&beam.mount);
        let (dy, dx) = m.theta.sin_cos();
        let mut best = f64::INFINITY;
        for w in walls {
            let (ex, ey) = (w.b.x - w.a.x, w.b.y - w.a.y);
            let denom = dx * ey - dy * ex;
            if denom == 0.0 {
                continue;
            }
            let (wx, wy) = (w.a.x - m.x, w.a.y - m.y);
            let t = (wx * ey - wy * ex) / denom;
            let u = (wx * dy - wy * dx) / denom;
            if t >= 0.0 && (0.0..=1.0).contains(&u) && t < best {
                best = t;
            }
        }
        *range = if best <= beam.max_range {
            best.max(beam.min_range)
        } else {
            beam.no_echo.at_or_beyond
        };
    }
}

fn laser_frames(c: &mut Criterion) {
    let world = load_world(OFFICE).expect("worlds/office.toml loads");
    let walls = world.walls();
    let index = SegmentIndex::new(walls.clone());
    let rig = deog_rig::load_rig_spec("laser180").expect("built in");
    let lasers = Lasers::new(&rig, LaserParams::default()).expect("valid figures");

    // Free poses where the laser robot's body fits.
    let params = ScoutParams {
        radius: rig.body_radius(),
        ..ScoutParams::default()
    };
    let probe = Robot::new(Pose2::default(), params, Default::default())
        .expect("default robot figures are valid");
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let (min, max) = world.bounds();
    let mut poses = Vec::new();
    while poses.len() < 1000 {
        let p = Point2::new(
            rng.random_range(min.x..max.x),
            rng.random_range(min.y..max.y),
        );
        if probe.fits(p, &index, &world) {
            poses.push(Pose2::new(p.x, p.y, rng.random_range(-PI..PI)));
        }
    }
    println!(
        "office: {} walls, {} free poses, {} rays per frame",
        walls.len(),
        poses.len(),
        rig.readings()
    );

    let mut group = c.benchmark_group("laser_frame_office");
    group.throughput(Throughput::Elements(rig.readings() as u64));
    let mut out = vec![0.0; rig.readings()];
    let mut i = 0usize;
    group.bench_function("indexed_rays", |b| {
        b.iter(|| {
            let pose = &poses[i % poses.len()];
            i += 1;
            lasers
                .fire(&index, black_box(pose), &mut rng, &mut out)
                .expect("valid pose");
            black_box(&out);
        })
    });
    let mut i = 0usize;
    group.bench_function("every_ray_every_wall", |b| {
        b.iter(|| {
            let pose = &poses[i % poses.len()];
            i += 1;
            all_walls(&walls, &rig, black_box(pose), &mut out);
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, laser_frames);
criterion_main!(benches);
