#![allow(missing_docs)] // criterion_group! generates an undocumented function.

//! Sonar readings per second on one core, in the 40 x 30 m office world:
//! the indexed cone path (`SonarRing::fire`) against a plain baseline that
//! marches 31 rays across each sonar's cone and tests every wall per ray.
//! One frame is 16 readings (`Throughput::Elements(16)`); robots stand at
//! 1000 random free poses, visited in turn so caches see many places.

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use deog_grid::{Pose2, SensorRing};
use deog_simulator::{Robot, SonarParams, SonarRing};
use deog_world::{Point2, Segment, SegmentIndex, load_world};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OFFICE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../worlds/office.toml");

/// Rays per cone in the baseline: one every degree across 30°.
const BASELINE_RAYS: usize = 31;

/// The baseline: for each sonar, `BASELINE_RAYS` rays spread evenly across
/// its cone, each tested against every wall; the nearest hit of any ray.
fn ray_march(
    walls: &[Segment],
    ring: &SensorRing,
    params: &SonarParams,
    pose: &Pose2,
    rng: &mut ChaCha8Rng,
    out: &mut [f64],
) {
    for (sensor, range) in ring.sensor_poses(pose).zip(out.iter_mut()) {
        let mut best = params.max_range;
        for k in 0..BASELINE_RAYS {
            let offset = params.half_angle * (2.0 * k as f64 / (BASELINE_RAYS - 1) as f64 - 1.0);
            let (dy, dx) = (sensor.theta + offset).sin_cos();
            for w in walls {
                let (ex, ey) = (w.b.x - w.a.x, w.b.y - w.a.y);
                let denom = dx * ey - dy * ex;
                if denom == 0.0 {
                    continue;
                }
                let (wx, wy) = (w.a.x - sensor.x, w.a.y - sensor.y);
                let t = (wx * ey - wy * ex) / denom;
                let u = (wx * dy - wy * dx) / denom;
                if t >= 0.0 && (0.0..=1.0).contains(&u) && t < best {
                    best = t;
                }
            }
        }
        if best < params.max_range {
            best *= 1.0 + rng.random_range(-params.noise_fraction..=params.noise_fraction);
        }
        *range = best.clamp(params.min_range, params.max_range);
    }
}

fn sonar_frames(c: &mut Criterion) {
    let world = load_world(OFFICE).expect("worlds/office.toml loads");
    let walls = world.walls();
    let index = SegmentIndex::new(walls.clone());
    let sonar = SonarRing::scout();
    let params = *sonar.params();
    let ring = SensorRing::scout();

    // Free poses where a Scout fits, as the wanderer would put robots.
    let probe = Robot::new(Pose2::default(), Default::default(), Default::default())
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
        "office: {} walls, {} free poses, bucket {} m",
        walls.len(),
        poses.len(),
        index.cell_size()
    );

    let mut group = c.benchmark_group("sonar_frame_office");
    group.throughput(Throughput::Elements(16));
    let mut out = [0.0; 16];
    let mut i = 0usize;
    group.bench_function("indexed_cone", |b| {
        b.iter(|| {
            let pose = &poses[i % poses.len()];
            i += 1;
            sonar
                .fire(&index, black_box(pose), &mut rng, &mut out)
                .expect("valid pose");
            black_box(&out);
        })
    });
    let mut i = 0usize;
    group.bench_function("ray_march_31_rays_all_walls", |b| {
        b.iter(|| {
            let pose = &poses[i % poses.len()];
            i += 1;
            ray_march(&walls, &ring, &params, black_box(pose), &mut rng, &mut out);
            black_box(&out);
        })
    });
    group.finish();
}

criterion_group!(benches, sonar_frames);
criterion_main!(benches);
