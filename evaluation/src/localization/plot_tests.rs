//! Pixel checks of the path plot: faint, unjoined estimates before
//! convergence, the kidnap and recovery marks, the legend and the scale
//! bar.

use deog_grid::Pose2;
use deog_mapfile::ScaleBar;

use super::plot::{
    BEFORE_CONVERGENCE_RGB, ESTIMATE_RGB, FREE_RGB, KIDNAP_RGB, LEGEND_EDGE_RGB, RECOVERY_RGB,
    TEXT_RGB,
};
use super::plot_path::split_path;
use super::*;

fn render(truth: &[TruthSample], estimates: &[EstimateSample]) -> (LocalizationReport, Raster) {
    let report = evaluate(&EvalInput::new("scout", truth, estimates)).expect("evaluates");
    let robots = [RobotPath {
        truth,
        estimates,
        kidnaps: &report.kidnaps,
        convergence: report.convergence,
    }];
    let raster = render_plot(&PlotInput {
        map: None,
        robots: &robots,
    })
    .expect("plot");
    (report, raster)
}

fn at(raster: &Raster, x: f64, y: f64) -> [u8; 3] {
    let (col, row) = raster.pixel_of(x, y).expect("inside");
    raster.pixel(col, row).expect("pixel")
}

fn count(raster: &Raster, rgb: [u8; 3]) -> usize {
    raster.rgb.chunks(3).filter(|p| *p == rgb).count()
}

/// The legend's box (first and last column, first and last row), found
/// by its edge colour: its swatches hold every mark's colour.
fn legend_box(raster: &Raster) -> (u32, u32, u32, u32) {
    let (mut c0, mut r0, mut c1, mut r1) = (u32::MAX, u32::MAX, 0, 0);
    for r in 0..raster.height {
        for c in 0..raster.width {
            if raster.pixel(c, r) == Some(LEGEND_EDGE_RGB) {
                (c0, r0, c1, r1) = (c0.min(c), r0.min(r), c1.max(c), r1.max(r));
            }
        }
    }
    assert!(c0 < c1 && r0 < r1, "no legend");
    (c0, r0, c1, r1)
}

/// Pixels of `rgb` outside the legend: `(column, row)`.
fn outside_legend(raster: &Raster, rgb: [u8; 3]) -> Vec<(u32, u32)> {
    let (c0, r0, c1, r1) = legend_box(raster);
    let mut found = Vec::new();
    for r in 0..raster.height {
        for c in 0..raster.width {
            let inside = (c0..=c1).contains(&c) && (r0..=r1).contains(&r);
            if !inside && raster.pixel(c, r) == Some(rgb) {
                found.push((c, r));
            }
        }
    }
    found
}

/// 200 frames along +x from (0.1, 0), 0.1 m and 0.1 s apart; the filter
/// searches for 8 frames (estimates scattered 1.5 m off the path), then
/// follows 0.1 m to the left of the truth.
fn searching_then_tracking() -> (Vec<TruthSample>, Vec<EstimateSample>) {
    let truth: Vec<TruthSample> = (1..=200)
        .map(|s| TruthSample::new(s, 0.1 * s as f64, Pose2::new(0.1 * s as f64, 0.0, 0.0)))
        .collect();
    let searching = [
        (8.0, 1.5),
        (12.0, -1.5),
        (9.0, -1.5),
        (11.0, 1.5),
        (8.0, -1.5),
        (12.0, 1.5),
        (10.0, 1.5),
        (10.0, -1.5),
    ];
    let estimates = truth
        .iter()
        .map(|t| {
            let (x, y) = match searching.get(t.sequence as usize - 1) {
                Some(&(x, y)) => (x, y),
                None => (t.pose.x, 0.1),
            };
            EstimateSample::new(t.sequence, Pose2::new(x, y, 0.0))
        })
        .collect();
    (truth, estimates)
}

#[test]
fn estimates_before_convergence_are_faint_points_never_joined() {
    let (truth, estimates) = searching_then_tracking();
    let (report, raster) = render(&truth, &estimates);
    assert_eq!(report.convergence.expect("converges").sequence, 9);
    // Each estimate of the search is a faint point where it was.
    for e in &estimates[..8] {
        assert_eq!(at(&raster, e.pose.x, e.pose.y), BEFORE_CONVERGENCE_RGB);
    }
    assert!(count(&raster, BEFORE_CONVERGENCE_RGB) >= 8 * 4);
    // No line leaves a searching estimate: along every step to or from
    // one, away from its ends and from the tracked path along y = 0,
    // nothing is drawn.
    for pair in estimates[..9].windows(2) {
        let (a, b) = (&pair[0].pose, &pair[1].pose);
        for i in 1..100 {
            let t = f64::from(i) / 100.0;
            let (x, y) = (a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
            // Clear of every searching estimate's own point.
            let near_a_point = estimates[..8]
                .iter()
                .any(|e| (e.pose.x - x).hypot(e.pose.y - y) * raster.px_per_m < 4.0);
            if near_a_point || y.abs() < 0.3 {
                continue;
            }
            assert_eq!(
                at(&raster, x, y),
                FREE_RGB,
                "a line from ({}, {}) to ({}, {}) at ({x:.2}, {y:.2})",
                a.x,
                a.y,
                b.x,
                b.y
            );
        }
    }
    // Converged estimates are joined by the estimate's line.
    assert_eq!(at(&raster, 10.05, 0.1), ESTIMATE_RGB);
    assert_eq!(at(&raster, 15.55, 0.1), ESTIMATE_RGB);
    // The legend says what the colours mean.
    assert!(count(&raster, TEXT_RGB) > 100);
}

#[test]
fn the_plots_scale_bar_is_its_round_metres_at_the_plots_scale() {
    let (truth, estimates) = searching_then_tracking();
    let (_, raster) = render(&truth, &estimates);
    // The bar is the longest unbroken run of text colour in any row: the
    // font's strokes are at most 5 dots wide.
    let mut longest = 0u32;
    for row in 0..raster.height {
        let mut run = 0u32;
        for col in 0..raster.width {
            if raster.pixel(col, row) == Some(TEXT_RGB) {
                run += 1;
                longest = longest.max(run);
            } else {
                run = 0;
            }
        }
    }
    let bar = ScaleBar::choose(raster.px_per_m, raster.width / 4).expect("a bar fits");
    assert_eq!(longest, bar.length_px);
    // 22 m across 1000 px: 45.5 px a metre, at most 250 px: 5 m.
    assert_eq!(bar.metres, 5.0);
    assert_eq!(
        f64::from(longest),
        (bar.metres * raster.px_per_m).round(),
        "{} m at {} px/m",
        bar.metres,
        raster.px_per_m
    );
}

#[test]
fn a_kidnap_and_its_recovery_have_their_own_marks_and_break_the_line() {
    // Along x to frame 20 (2.0, 0), then set down at (10, 5) and on along
    // x; the estimate stays behind for frames 21..=25 and recovers at 26.
    let truth: Vec<TruthSample> = (1..=40)
        .map(|s| {
            let pose = if s <= 20 {
                Pose2::new(0.1 * s as f64, 0.0, 0.0)
            } else {
                Pose2::new(10.0 + 0.1 * (s - 21) as f64, 5.0, 0.0)
            };
            TruthSample::new(s, 0.1 * s as f64, pose)
        })
        .collect();
    let estimates: Vec<EstimateSample> = truth
        .iter()
        .map(|t| {
            let pose = if (21..=25).contains(&t.sequence) {
                Pose2::new(2.0 + 0.1 * (t.sequence - 20) as f64, 0.1, 0.0)
            } else {
                Pose2::new(t.pose.x, t.pose.y + 0.1, 0.0)
            };
            EstimateSample::new(t.sequence, pose)
        })
        .collect();
    let (report, raster) = render(&truth, &estimates);
    let kidnap = report.kidnaps.first().expect("a kidnap");
    assert_eq!(kidnap.recovery.expect("recovers").sequence, 26);

    assert_eq!(at(&raster, 2.0, 0.0), KIDNAP_RGB);
    assert_eq!(at(&raster, 10.0, 5.0), KIDNAP_RGB);
    // The recovery ring, about 9 px round the estimate of frame 26, and
    // nowhere else.
    let (col, row) = raster.pixel_of(10.5, 5.1).expect("inside");
    let near = |c: u32, r: u32| c.abs_diff(col) <= 11 && r.abs_diff(row) <= 11;
    let rings = outside_legend(&raster, RECOVERY_RGB);
    for &(c, r) in &rings {
        assert!(near(c, r), "recovery colour at ({c}, {r})");
    }
    assert!(rings.len() > 30, "{}", rings.len());
    assert_eq!(raster.pixel(col, row), Some(ESTIMATE_RGB));
    // The estimates left behind are faint; nothing joins the last of
    // them to the recovery across the map.
    assert_eq!(at(&raster, 2.3, 0.1), BEFORE_CONVERGENCE_RGB);
    assert_eq!(at(&raster, 6.5, 2.6), FREE_RGB);
    assert_eq!(at(&raster, 11.05, 5.1), ESTIMATE_RGB);
}

#[test]
fn a_jump_between_converged_estimates_breaks_the_line() {
    // Frame 11 has no true pose, and its estimate lies 5 m off: the line
    // stops at frame 10 and starts again at 12.
    let truth: Vec<TruthSample> = (1..=20)
        .filter(|&s| s != 11)
        .map(|s| TruthSample::new(s, 0.1 * s as f64, Pose2::new(0.1 * s as f64, 0.0, 0.0)))
        .collect();
    let estimates: Vec<EstimateSample> = (1..=20)
        .map(|s| {
            let y = if s == 11 { 5.0 } else { 0.05 };
            EstimateSample::new(s, Pose2::new(0.1 * s as f64, y, 0.0))
        })
        .collect();
    let report = evaluate(&EvalInput::new("scout", &truth, &estimates)).expect("evaluates");
    let robot = RobotPath {
        truth: &truth,
        estimates: &estimates,
        kidnaps: &report.kidnaps,
        convergence: report.convergence,
    };
    let parts = split_path(&robot);
    let runs: Vec<Vec<u64>> = parts
        .runs
        .iter()
        .map(|run| run.iter().map(|e| e.sequence).collect())
        .collect();
    assert_eq!(
        runs,
        vec![(1..=10).collect(), vec![11], (12..=20).collect()]
    );
    assert!(parts.before_convergence.is_empty());
    let raster = render_plot(&PlotInput {
        map: None,
        robots: &[robot],
    })
    .expect("plot");
    // Halfway up to the stray estimate: nothing.
    assert_eq!(at(&raster, 1.05, 2.5), FREE_RGB);
    assert_eq!(at(&raster, 1.1, 5.0), ESTIMATE_RGB);
}

#[test]
fn without_a_convergence_every_estimate_is_faint() {
    let (truth, mut estimates) = searching_then_tracking();
    for e in &mut estimates {
        e.pose.y += 1.0;
    }
    let (report, raster) = render(&truth, &estimates);
    assert!(report.convergence.is_none());
    assert_eq!(outside_legend(&raster, ESTIMATE_RGB), vec![]);
    assert!(count(&raster, BEFORE_CONVERGENCE_RGB) > 150 * 4);
}
