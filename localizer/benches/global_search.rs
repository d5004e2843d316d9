//! The global search's cost as the building grows: a floor of furnished
//! rooms, one, four and sixteen times as large, searched whole for a
//! 360-beam laser scan taken in one room. A uniform start's cost grows
//! with the free area; the search's should grow far slower.

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use deog_grid::Pose2;
use deog_localizer::search::{
    ScanCloud, SearchCell, SearchGrid, SearchSettings, SearchWindow, search,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const CELL: f64 = 0.1;
/// A room's side in cells (6 m), walls included.
const ROOM: usize = 60;

/// `rooms` × `rooms` rooms with doors between them and a few boxes in
/// each, drawn from `seed`.
fn floor(rooms: usize, seed: u64) -> (usize, Vec<SearchCell>) {
    let side = rooms * ROOM + 1;
    let mut cells = vec![SearchCell::Free; side * side];
    let mut set = |x: usize, y: usize| cells[y * side + x] = SearchCell::Occupied;
    for i in 0..side {
        for k in 0..=rooms {
            let wall = k * ROOM;
            // Doors in the middle of each inner wall.
            let door = (i % ROOM) > ROOM / 2 - 5 && (i % ROOM) < ROOM / 2 + 5;
            if !door || k == 0 || k == rooms {
                set(wall, i);
                set(i, wall);
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for ry in 0..rooms {
        for rx in 0..rooms {
            for _ in 0..3 {
                let (w, h) = (rng.random_range(3..12), rng.random_range(3..12));
                let x0 = rx * ROOM + rng.random_range(5..ROOM - 15);
                let y0 = ry * ROOM + rng.random_range(5..ROOM - 15);
                for y in y0..y0 + h {
                    for x in x0..x0 + w {
                        set(x, y);
                    }
                }
            }
        }
    }
    (side, cells)
}

/// A 360-beam scan at `pose`, each ray marched to the first wall.
fn scan(side: usize, cells: &[SearchCell], pose: &Pose2) -> ScanCloud {
    let mut cloud = ScanCloud::new();
    for i in 0..360 {
        let a = f64::from(i).to_radians();
        let (dx, dy) = ((pose.theta + a).cos(), (pose.theta + a).sin());
        let mut r = 0.0;
        while r < 10.0 {
            r += 0.01;
            let (x, y) = (pose.x + r * dx, pose.y + r * dy);
            let (cx, cy) = ((x / CELL).floor() as i64, (y / CELL).floor() as i64);
            if cx < 0 || cy < 0 || cx >= side as i64 || cy >= side as i64 {
                break;
            }
            if cells[cy as usize * side + cx as usize] == SearchCell::Occupied {
                cloud.push_group([[r * a.cos(), r * a.sin()]]);
                break;
            }
        }
    }
    cloud
}

fn global_search(c: &mut Criterion) {
    let mut group = c.benchmark_group("global_search");
    group.sample_size(10);
    for rooms in [2usize, 4, 8] {
        let (side, cells) = floor(rooms, 7);
        let grid = SearchGrid::new([0.0, 0.0], CELL, side, side, &cells, 0.1, 7).expect("grid");
        let mut pose = Pose2::new(2.13, 3.37, 0.7);
        // Off any box.
        while cells[(pose.y / CELL) as usize * side + (pose.x / CELL) as usize] != SearchCell::Free
        {
            pose.x += 0.3;
        }
        let cloud = scan(side, &cells, &pose);
        let settings = SearchSettings {
            budget: u64::MAX,
            ..SearchSettings::default()
        };
        let found = search(&grid, &cloud, SearchWindow::Global, &settings).expect("searches");
        let best = found.hypotheses[0].pose;
        assert!(
            (best.x - pose.x).hypot(best.y - pose.y) < 0.2,
            "{best:?} for {pose:?}"
        );
        eprintln!(
            "{rooms} x {rooms} rooms ({:.0} m²): {} lookups, {} hypotheses",
            (side as f64 * CELL).powi(2),
            found.lookups,
            found.hypotheses.len()
        );
        group.bench_with_input(
            BenchmarkId::from_parameter(rooms * rooms),
            &rooms,
            |b, _| {
                b.iter(|| {
                    search(&grid, &cloud, SearchWindow::Global, &settings).expect("searches")
                });
            },
        );
    }
    group.finish();
}

criterion_group!(benches, global_search);
criterion_main!(benches);
