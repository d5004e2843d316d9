//! `deog demo`, in-process for now: a Scout drives a loop through the
//! embedded default room, its 16 sonar ranges cast against the room's ground
//! truth with ±1% noise, and the grid core folds every frame into tiles. The
//! map is written as a PGM image and scored against the ground truth.

use std::fs;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_grid::{
    CellBox, CellIndex, ClampLimits, FrameIntegrator, Occupancy, OccupancyView, Pose2, Resolution,
    SensorRing, SonarModel, SonarModelParams, TileDelta, TileMap, TileSize, cast_cone,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Options of `deog demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Folder the map and summary are written to.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// Number of sonar frames to take.
    #[arg(long, default_value_t = 2000)]
    frames: usize,
    /// Seed of the range noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Walls and furniture of the embedded 10 m × 8 m room, metres.
const ROOM: [(f64, f64, f64, f64); 8] = [
    (-0.1, -0.1, 10.1, 0.0),
    (-0.1, 8.0, 10.1, 8.1),
    (-0.1, -0.1, 0.0, 8.1),
    (10.0, -0.1, 10.1, 8.1),
    (3.0, 3.0, 4.2, 3.8),
    (7.5, 6.0, 9.9, 7.9),
    (6.0, 2.0, 6.3, 2.3),
    (0.1, 5.0, 0.9, 7.2),
];

/// The room's ground truth: a cell is occupied if its centre is in a box.
struct GroundTruth {
    res: Resolution,
}

impl OccupancyView for GroundTruth {
    fn occupancy(&self, cell: CellIndex) -> Occupancy {
        let (x, y) = self.res.cell_center(cell);
        if ROOM
            .iter()
            .any(|&(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y))
        {
            Occupancy::Occupied
        } else {
            Occupancy::Free
        }
    }
}

/// Runs the demo.
pub fn run(args: DemoArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let res = Resolution::DEFAULT;
    let size = TileSize::DEFAULT;
    let params = SonarModelParams::default();
    let model = SonarModel::new(params)?;
    let mut integrator = FrameIntegrator::new(model, SensorRing::scout(), res, size);
    let truth = GroundTruth { res };
    let mut map = TileMap::new(res, size, ClampLimits::default());
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let mut deltas: Vec<TileDelta> = Vec::new();

    for i in 0..args.frames {
        // Two laps of an ellipse around the table, turning as it goes.
        let t = i as f64 / args.frames as f64 * 2.0 * std::f64::consts::TAU;
        let pose = Pose2::new(5.0 + 3.0 * t.cos(), 4.0 + 2.2 * t.sin(), t + 1.7);
        let ranges = integrator
            .ring()
            .sensor_poses(&pose)
            .map(|sensor| {
                let hit = cast_cone(&truth, res, &sensor, params.half_angle, params.max_range)?;
                Ok(hit.map_or(params.max_range, |r| {
                    (r * (1.0 + rng.random_range(-0.01..=0.01))).max(params.min_range)
                }))
            })
            .collect::<Result<Vec<f64>, deog_grid::GridError>>()?;
        deltas.clear();
        integrator.integrate(&pose, &ranges, &mut deltas)?;
        for delta in &deltas {
            map.apply(delta)?;
        }
    }

    let bounds = map.tile_bounds().context("no cell was observed")?;
    fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let image = args.out.join("map.pgm");
    write_pgm(&map, &bounds, &image)?;
    let score = score(&map, &truth, &bounds);
    println!(
        "{} frames, {} tiles, {} cells observed; {:.1}% of the {} classified cells match the room",
        args.frames,
        map.tile_count(),
        map.observed_count(),
        100.0 * score.correct as f64 / score.classified.max(1) as f64,
        score.classified,
    );
    println!("map written to {}", image.display());
    Ok(())
}

struct Score {
    classified: usize,
    correct: usize,
}

fn score(map: &TileMap, truth: &GroundTruth, bounds: &CellBox) -> Score {
    let mut score = Score {
        classified: 0,
        correct: 0,
    };
    for y in bounds.min.y..=bounds.max.y {
        for x in bounds.min.x..=bounds.max.x {
            let cell = CellIndex::new(x, y);
            let state = map.occupancy(cell);
            if state != Occupancy::Unknown {
                score.classified += 1;
                score.correct += usize::from(state == truth.occupancy(cell));
            }
        }
    }
    score
}

/// A binary PGM, top row first, as map_server's images are: 0 occupied,
/// 254 free, 205 unknown.
fn write_pgm(map: &TileMap, bounds: &CellBox, path: &PathBuf) -> Result<()> {
    let (width, height) = (bounds.width(), bounds.height());
    let mut bytes = format!("P5\n{width} {height}\n255\n").into_bytes();
    for y in (bounds.min.y..=bounds.max.y).rev() {
        for x in bounds.min.x..=bounds.max.x {
            bytes.push(match map.occupancy(CellIndex::new(x, y)) {
                Occupancy::Occupied => 0,
                Occupancy::Free => 254,
                Occupancy::Unknown => 205,
            });
        }
    }
    fs::File::create(path)
        .and_then(|mut f| f.write_all(&bytes))
        .with_context(|| format!("writing {}", path.display()))
}
