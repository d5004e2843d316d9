//! The search against rooms drawn cell by cell: it finds the pose a scan
//! was taken at, keeps a symmetric room's two poses, agrees with scoring
//! every pose one by one, and stops at its budget.

use deog_grid::{Pose2, normalize_angle};

use super::*;

const CELL: f64 = 0.1;

/// A room of `w` × `h` cells walled round, with extra walls where
/// `inner` says; free inside.
fn room(w: usize, h: usize, inner: impl Fn(usize, usize) -> bool) -> Vec<SearchCell> {
    let mut cells = vec![SearchCell::Free; w * h];
    for y in 0..h {
        for x in 0..w {
            if x == 0 || y == 0 || x == w - 1 || y == h - 1 || inner(x, y) {
                cells[y * w + x] = SearchCell::Occupied;
            }
        }
    }
    cells
}

fn grid_of(w: usize, h: usize, cells: &[SearchCell]) -> SearchGrid {
    SearchGrid::new([0.0, 0.0], CELL, w, h, cells, 0.1, 6).expect("grid")
}

/// A 360-beam scan at `pose`, each ray marched to the first wall.
fn scan(w: usize, h: usize, cells: &[SearchCell], pose: &Pose2) -> ScanCloud {
    let mut cloud = ScanCloud::new();
    for i in 0..360 {
        let a = f64::from(i).to_radians();
        let (dx, dy) = ((pose.theta + a).cos(), (pose.theta + a).sin());
        let mut r = 0.0;
        while r < 8.0 {
            r += 0.01;
            let (x, y) = (pose.x + r * dx, pose.y + r * dy);
            let (cx, cy) = ((x / CELL).floor() as i64, (y / CELL).floor() as i64);
            if cx < 0 || cy < 0 || cx >= w as i64 || cy >= h as i64 {
                break;
            }
            if cells[cy as usize * w + cx as usize] == SearchCell::Occupied {
                cloud.push_group([[r * a.cos(), r * a.sin()]]);
                break;
            }
        }
    }
    cloud
}

fn near(a: &Pose2, b: &Pose2, metres: f64, radians: f64) -> bool {
    (a.x - b.x).hypot(a.y - b.y) <= metres && normalize_angle(a.theta - b.theta).abs() <= radians
}

/// An L of a room: nothing about it repeats.
fn l_room() -> (usize, usize, Vec<SearchCell>) {
    let (w, h) = (80, 60);
    let cells = room(w, h, |x, y| {
        (x >= 50 && y >= 35) || (x == 20 && (10..30).contains(&y))
    });
    (w, h, cells)
}

#[test]
fn the_best_hypothesis_is_where_the_scan_was_taken() {
    let (w, h, cells) = l_room();
    let grid = grid_of(w, h, &cells);
    for truth in [
        Pose2::new(3.03, 2.47, 0.4),
        Pose2::new(6.5, 1.2, -2.0),
        Pose2::new(1.2, 4.6, 3.0),
    ] {
        let cloud = scan(w, h, &cells, &truth);
        let out = search(
            &grid,
            &cloud,
            SearchWindow::Global,
            &SearchSettings::default(),
        )
        .expect("searches");
        assert!(out.complete);
        let best = out.hypotheses.first().expect("a hypothesis");
        assert!(
            near(&best.pose, &truth, 0.15, 0.06),
            "{best:?} for {truth:?}"
        );
        assert!(best.score > 0.8, "{best:?}");
    }
}

#[test]
fn a_symmetric_room_keeps_both_poses() {
    let (w, h) = (60, 40);
    let cells = room(w, h, |_, _| false);
    let grid = grid_of(w, h, &cells);
    let truth = Pose2::new(1.55, 1.25, 0.3);
    let cloud = scan(w, h, &cells, &truth);
    let out = search(
        &grid,
        &cloud,
        SearchWindow::Global,
        &SearchSettings::default(),
    )
    .expect("searches");
    // Turned half a turn about the room's centre, the scan fits as well.
    let image = Pose2::new(
        6.0 - truth.x,
        4.0 - truth.y,
        normalize_angle(truth.theta + std::f64::consts::PI),
    );
    let has = |p: &Pose2| out.hypotheses.iter().any(|h| near(&h.pose, p, 0.15, 0.06));
    assert!(has(&truth) && has(&image), "{:?}", out.hypotheses);
    assert!(out.runner_up_ratio() > 0.95, "{:?}", out.hypotheses);
}

#[test]
fn branch_and_bound_finds_the_score_of_trying_every_pose() {
    let (w, h) = (40, 30);
    let cells = room(w, h, |x, y| (x == 12 && y < 18) || (y == 20 && x > 25));
    let grid = grid_of(w, h, &cells);
    let truth = Pose2::new(2.0, 1.0, 1.0);
    let mut cloud = scan(w, h, &cells, &truth);
    // Noise the scan a little, so the best is not a perfect fit.
    let mut noisy = ScanCloud::new();
    for (i, p) in cloud.points().iter().enumerate() {
        let jitter = 0.03 * ((i * 7919 % 13) as f64 / 6.0 - 1.0);
        noisy.push_group([[p[0] + jitter, p[1] - jitter]]);
    }
    cloud = noisy;
    let settings = SearchSettings {
        min_score: 0.0,
        ..SearchSettings::default()
    };
    let out = search(&grid, &cloud, SearchWindow::Global, &settings).expect("searches");
    // The same headings the search tries, every free cell's centre.
    let reach = cloud.reach();
    let step = (1.0 - CELL * CELL / (2.0 * reach * reach))
        .acos()
        .clamp(1e-4, settings.max_angle_step);
    let n = (std::f64::consts::TAU / step).ceil() as usize;
    let mut best = 0.0f64;
    for i in 0..n {
        let theta = normalize_angle(i as f64 * std::f64::consts::TAU / n as f64);
        for y in 0..h {
            for x in 0..w {
                if cells[y * w + x] != SearchCell::Free {
                    continue;
                }
                let (px, py) = grid.centre(x as i64, y as i64);
                best = best.max(score_pose(&grid, &cloud, &Pose2::new(px, py, theta)));
            }
        }
    }
    let found = out.hypotheses[0].score;
    assert!(
        (found - best).abs() < 1e-9,
        "branch and bound {found}, every pose {best}"
    );
    // It scored far fewer candidates than there are poses.
    let poses = (n * w * h) as u64;
    assert!(
        out.evaluations * 4 < poses,
        "{} of {poses}",
        out.evaluations
    );
}

#[test]
fn a_window_searches_near_its_centre_only() {
    let (w, h) = (60, 40);
    let cells = room(w, h, |_, _| false);
    let grid = grid_of(w, h, &cells);
    let truth = Pose2::new(1.55, 1.25, 0.3);
    let cloud = scan(w, h, &cells, &truth);
    let window = SearchWindow::Around {
        around: Pose2::new(1.8, 1.0, 0.4),
        linear_m: 0.5,
        angular_rad: 0.3,
    };
    let out = search(&grid, &cloud, window, &SearchSettings::default()).expect("searches");
    assert!(
        near(&out.hypotheses[0].pose, &truth, 0.15, 0.06),
        "{:?}",
        out.hypotheses
    );
    // The mirror image lies outside the window.
    assert!(
        out.hypotheses.iter().all(|h| h.pose.x < 3.0),
        "{:?}",
        out.hypotheses
    );
}

#[test]
fn the_budget_bounds_the_work() {
    let (w, h, cells) = l_room();
    let grid = grid_of(w, h, &cells);
    let cloud = scan(w, h, &cells, &Pose2::new(3.0, 2.5, 0.4));
    let settings = SearchSettings {
        budget: 50_000,
        ..SearchSettings::default()
    };
    let out = search(&grid, &cloud, SearchWindow::Global, &settings).expect("searches");
    assert!(!out.complete);
    // The coarsest level is scored whole (it is what orders the rest);
    // past the budget no block is split.
    let unbounded = search(
        &grid,
        &cloud,
        SearchWindow::Global,
        &SearchSettings::default(),
    )
    .expect("searches");
    assert!(
        out.evaluations < unbounded.evaluations / 2,
        "{} of {}",
        out.evaluations,
        unbounded.evaluations
    );
}

#[test]
fn an_empty_cloud_or_bad_settings() {
    let (w, h, cells) = l_room();
    let grid = grid_of(w, h, &cells);
    let out = search(
        &grid,
        &ScanCloud::new(),
        SearchWindow::Global,
        &SearchSettings::default(),
    )
    .expect("searches");
    assert!(out.hypotheses.is_empty());
    let bad = SearchSettings {
        keep_ratio: f64::NAN,
        ..SearchSettings::default()
    };
    let cloud = scan(w, h, &cells, &Pose2::new(3.0, 2.5, 0.4));
    assert!(search(&grid, &cloud, SearchWindow::Global, &bad).is_err());
    let window = SearchWindow::Around {
        around: Pose2::new(f64::NAN, 0.0, 0.0),
        linear_m: 1.0,
        angular_rad: 0.1,
    };
    assert!(search(&grid, &cloud, window, &SearchSettings::default()).is_err());
}

#[test]
fn a_search_in_slices_finds_what_a_whole_one_finds() {
    let (w, h, cells) = l_room();
    let grid = grid_of(w, h, &cells);
    let truth = Pose2::new(3.03, 2.47, 0.4);
    let cloud = scan(w, h, &cells, &truth);
    let settings = SearchSettings::default();
    let whole = search(&grid, &cloud, SearchWindow::Global, &settings).expect("searches");
    for slice in [1, 10_000, 1_000_000] {
        let mut job =
            SearchJob::new(&grid, cloud.clone(), SearchWindow::Global, &settings).expect("job");
        let mut runs = 0;
        while !job.run(&grid, slice) {
            runs += 1;
            assert!(runs < 10_000_000, "slices of {slice} never end");
        }
        assert!(job.done());
        assert!(slice >= 1_000_000 || runs > 1, "slices of {slice}: {runs}");
        let sliced = job.finish();
        assert_eq!(sliced, whole, "slices of {slice}");
    }
}

#[test]
fn a_job_finished_early_is_incomplete_with_what_it_found() {
    let (w, h, cells) = l_room();
    let grid = grid_of(w, h, &cells);
    let cloud = scan(w, h, &cells, &Pose2::new(3.03, 2.47, 0.4));
    let mut job = SearchJob::new(
        &grid,
        cloud,
        SearchWindow::Global,
        &SearchSettings::default(),
    )
    .expect("job");
    assert!(!job.run(&grid, 1));
    let outcome = job.finish();
    assert!(!outcome.complete);
    assert!(outcome.lookups > 0);
}
