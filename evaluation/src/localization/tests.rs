//! Hand-computed cases for [`evaluate`], the JSON, the table and the plot.

use std::f64::consts::{FRAC_PI_2, PI};

use approx::assert_relative_eq;
use deog_grid::{ClampLimits, Pose2, Resolution, TileDelta, TileKey, TileMap, TileSize};

use super::plot::{
    ESTIMATE_RGB, FREE_RGB, KIDNAP_RGB, MAX_SIDE_PX, OCCUPIED_RGB, TRUTH_RGB, UNKNOWN_RGB,
};
use super::*;

/// Frames 1..=n, 0.1 s apart (time 0.1 · seq), driving along +x at
/// 1 m/s from (0.1, 0): 0.1 m per frame.
fn straight(n: u64) -> Vec<TruthSample> {
    (1..=n)
        .map(|s| TruthSample::new(s, 0.1 * s as f64, Pose2::new(0.1 * s as f64, 0.0, 0.0)))
        .collect()
}

/// An estimate for each truth sample, off by `error(sequence)`.
fn offset(truth: &[TruthSample], error: impl Fn(u64) -> (f64, f64, f64)) -> Vec<EstimateSample> {
    truth
        .iter()
        .map(|t| {
            let (dx, dy, dt) = error(t.sequence);
            EstimateSample::new(
                t.sequence,
                Pose2::new(t.pose.x + dx, t.pose.y + dy, t.pose.theta + dt),
            )
        })
        .collect()
}

fn run(truth: &[TruthSample], estimates: &[EstimateSample]) -> LocalizationReport {
    evaluate(&EvalInput::new("scout", truth, estimates)).expect("evaluates")
}

/// 1..=10 along x, then teleported to (5, 5) (frame 11, 1.1 s) and on
/// along x to frame 20.
fn kidnapped_run() -> Vec<TruthSample> {
    (1..=20)
        .map(|s| {
            let t = 0.1 * s as f64;
            let pose = if s <= 10 {
                Pose2::new(0.1 * s as f64, 0.0, 0.0)
            } else {
                Pose2::new(5.0 + 0.1 * (s - 11) as f64, 5.0, 0.0)
            };
            TruthSample::new(s, t, pose)
        })
        .collect()
}

#[test]
fn constant_offset_gives_its_size_and_no_spread() {
    let truth = straight(10);
    let estimates = offset(&truth, |_| (0.1, -0.05, 0.02));
    let r = run(&truth, &estimates);
    assert!(r.converged());
    assert_eq!(r.converge_s(), Some(0.0));
    let c = r.convergence.expect("converged");
    assert_eq!((c.sequence, c.distance_m), (1, 0.0));
    let s = r.stats.expect("figures");
    assert_eq!(s.count, 10);
    assert_relative_eq!(s.x_m.mean_abs, 0.1, epsilon = 1e-12);
    assert_relative_eq!(s.x_m.mean, 0.1, epsilon = 1e-12);
    assert_relative_eq!(s.x_m.std_dev, 0.0, epsilon = 1e-9);
    assert_relative_eq!(s.y_m.mean_abs, 0.05, epsilon = 1e-12);
    assert_relative_eq!(s.y_m.mean, -0.05, epsilon = 1e-12);
    assert_relative_eq!(s.theta_rad.mean_abs, 0.02, epsilon = 1e-12);
    assert_relative_eq!(s.rms_position_m, 0.0125f64.sqrt(), epsilon = 1e-12);
    assert_relative_eq!(s.max_position_m, 0.0125f64.sqrt(), epsilon = 1e-12);
    assert!(!r.kidnapped());
    assert_eq!((r.recovered(), r.recover_s()), (None, None));
    assert_eq!((r.frames, r.estimates, r.estimates_paired), (10, 10, 10));
    assert_eq!(r.estimates_within_bounds, 10);
}

#[test]
fn alternating_errors_have_zero_bias_and_their_spread() {
    let truth = straight(10);
    let estimates = offset(&truth, |s| {
        let sign = if s % 2 == 0 { 1.0 } else { -1.0 };
        (0.1 * sign, 0.0, 0.1 * sign)
    });
    let s = run(&truth, &estimates).stats.expect("figures");
    assert_relative_eq!(s.x_m.mean_abs, 0.1, epsilon = 1e-12);
    assert_relative_eq!(s.x_m.mean, 0.0, epsilon = 1e-12);
    // Population form: every error is 0.1 from the mean of 0.
    assert_relative_eq!(s.x_m.std_dev, 0.1, epsilon = 1e-12);
    assert_relative_eq!(s.theta_rad.std_dev, 0.1, epsilon = 1e-12);
    assert_relative_eq!(s.y_m.mean_abs, 0.0);
}

#[test]
fn convergence_is_where_the_error_stays_within_the_bounds() {
    let truth = straight(10);
    // Off by 1 m at first; frame 2 happens to be close, frame 3 is not,
    // so the estimate settles from frame 4 on.
    let estimates = offset(&truth, |s| match s {
        1 | 3 => (1.0, 0.0, 0.0),
        2 => (0.0, 0.1, 0.0),
        _ => (0.0, 0.2, 0.0),
    });
    let r = run(&truth, &estimates);
    let c = r.convergence.expect("converged");
    assert_eq!(c.sequence, 4);
    assert_relative_eq!(c.after_s, 0.3, epsilon = 1e-12);
    assert_relative_eq!(c.distance_m, 0.3, epsilon = 1e-12);
    let s = r.stats.expect("figures");
    assert_eq!(s.count, 7);
    assert_relative_eq!(s.y_m.mean_abs, 0.2, epsilon = 1e-12);
    assert_relative_eq!(s.x_m.mean_abs, 0.0, epsilon = 1e-12);
    assert_eq!(r.estimates_within_bounds, 8);
}

#[test]
fn the_first_estimate_within_the_bounds_is_said_beside_the_settling() {
    let truth = straight(10);
    // Within from frame 2, out again at frame 5, within for good from 6.
    let estimates = offset(&truth, |s| match s {
        1 | 5 => (1.0, 0.0, 0.0),
        _ => (0.0, 0.1, 0.0),
    });
    let r = run(&truth, &estimates);
    assert_eq!(r.convergence.expect("converged").sequence, 6);
    let first = r.first_within.expect("within at frame 2");
    assert_eq!(first.sequence, 2);
    assert_relative_eq!(r.first_within_s().expect("seconds"), 0.1, epsilon = 1e-12);
    assert!(
        r.table()
            .contains("first within the bounds after 0.100 s (frame 2)"),
        "{}",
        r.table()
    );
    let json = r.record();
    assert_eq!(json.first_within_s, r.first_within_s());
    assert_eq!(json.first_back_s, None);

    // Settled at once: the same estimate, and the table says nothing more.
    let settled = run(&truth, &offset(&truth, |_| (0.0, 0.1, 0.0)));
    assert_eq!(settled.first_within, settled.convergence);
    assert!(!settled.table().contains("first within"));

    // Never within: neither.
    let lost = run(&truth, &offset(&truth, |_| (1.0, 0.0, 0.0)));
    assert_eq!(lost.first_within, None);
}

#[test]
fn after_a_kidnap_the_first_estimate_back_within_the_bounds() {
    let truth = kidnapped_run();
    // Back within at frame 13, out at 15, within for good from 16.
    let estimates = offset(&truth, |s| match s {
        11 | 12 | 15 => (2.0, 0.0, 0.0),
        _ => (0.0, 0.05, 0.0),
    });
    let r = run(&truth, &estimates);
    let k = r.kidnaps[0];
    assert_eq!(k.recovery.expect("recovered").sequence, 16);
    assert_eq!(k.first_within.expect("back").sequence, 13);
    assert_relative_eq!(r.first_back_s().expect("seconds"), 0.2, epsilon = 1e-12);
    let json = r.record();
    assert_eq!(json.first_back_s, r.first_back_s());
    assert_eq!(json.kidnaps[0].first_within_s, r.first_back_s());
    assert!(
        r.table().contains("| 0.500 | 0.500 | 0.200 |"),
        "{}",
        r.table()
    );
}

#[test]
fn a_heading_error_alone_keeps_it_from_converging() {
    let truth = straight(10);
    let estimates = offset(&truth, |s| (0.0, 0.0, if s < 6 { 0.3 } else { 0.1 }));
    let c = run(&truth, &estimates).convergence.expect("converged");
    assert_eq!(c.sequence, 6);
}

#[test]
fn kidnap_and_recovery() {
    let truth = kidnapped_run();
    // Right along x before the kidnap; after it the estimate stays where
    // the robot was for three frames, then finds it 0.05 m off in y.
    let before = Pose2::new(1.0, 0.0, 0.0);
    let estimates: Vec<EstimateSample> = truth
        .iter()
        .map(|t| {
            let pose = match t.sequence {
                ..=10 => Pose2::new(t.pose.x + 0.1, t.pose.y, 0.0),
                11..=13 => before,
                _ => Pose2::new(t.pose.x, t.pose.y + 0.05, 0.0),
            };
            EstimateSample::new(t.sequence, pose)
        })
        .collect();
    let r = run(&truth, &estimates);
    assert_eq!(r.converge_s(), Some(0.0));
    assert_eq!(r.kidnaps.len(), 1);
    let k = r.kidnaps[0];
    assert_eq!((k.sequence_before, k.sequence), (10, 11));
    assert_relative_eq!(k.time_s, 1.1, epsilon = 1e-12);
    assert_relative_eq!(k.jump_m, 41f64.sqrt(), epsilon = 1e-12);
    assert_eq!(k.from, Pose2::new(1.0, 0.0, 0.0));
    assert_eq!(k.to, Pose2::new(5.0, 5.0, 0.0));
    let recovery = k.recovery.expect("recovered");
    assert_eq!(recovery.sequence, 14);
    assert_relative_eq!(recovery.after_s, 0.3, epsilon = 1e-12);
    assert_relative_eq!(recovery.distance_m, 0.3, epsilon = 1e-12);
    assert!(r.kidnapped());
    assert_eq!(r.recovered(), Some(true));
    assert_relative_eq!(r.recover_s().expect("recover_s"), 0.3, epsilon = 1e-12);

    // Frames 1..=10 (x off by 0.1) and 14..=20 (y off by 0.05) count;
    // 11..=13, between the kidnap and the recovery, do not.
    let s = r.stats.expect("figures");
    assert_eq!(s.count, 17);
    assert_relative_eq!(s.x_m.mean_abs, 1.0 / 17.0, epsilon = 1e-12);
    assert_relative_eq!(s.y_m.mean_abs, 0.35 / 17.0, epsilon = 1e-12);
    let x_mean: f64 = 1.0 / 17.0;
    let x_var = (10.0 * (0.1 - x_mean).powi(2) + 7.0 * x_mean.powi(2)) / 17.0;
    assert_relative_eq!(s.x_m.std_dev, x_var.sqrt(), epsilon = 1e-12);
    assert_relative_eq!(
        s.rms_position_m,
        ((10.0 * 0.01 + 7.0 * 0.0025) / 17.0f64).sqrt(),
        epsilon = 1e-12
    );
}

#[test]
fn a_kidnap_never_recovered_from() {
    let truth = kidnapped_run();
    let estimates: Vec<EstimateSample> = truth
        .iter()
        .map(|t| {
            let pose = if t.sequence <= 10 {
                t.pose
            } else {
                Pose2::new(1.0, 0.0, 0.0)
            };
            EstimateSample::new(t.sequence, pose)
        })
        .collect();
    let r = run(&truth, &estimates);
    assert!(r.converged());
    assert_eq!(r.recovered(), Some(false));
    assert_eq!(r.recover_s(), None);
    assert_eq!(r.stats.expect("figures").count, 10);
    let json = r.to_json();
    assert!(json.contains("\"recovered\": false"), "{json}");
    assert!(json.contains("\"recover_s\": null"), "{json}");
}

#[test]
fn converging_only_after_a_kidnap() {
    let truth = kidnapped_run();
    let estimates = offset(&truth, |s| {
        if s < 15 {
            (2.0, 0.0, 0.0)
        } else {
            (0.0, 0.0, 0.0)
        }
    });
    let r = run(&truth, &estimates);
    let c = r.convergence.expect("converged");
    assert_eq!(c.sequence, 15);
    assert_relative_eq!(c.after_s, 1.4, epsilon = 1e-12);
    // Nine steps of 0.1 m before the jump, four after it; not the jump.
    assert_relative_eq!(c.distance_m, 1.3, epsilon = 1e-12);
    let recovery = r.kidnaps[0].recovery.expect("recovered");
    assert_relative_eq!(recovery.after_s, 0.4, epsilon = 1e-12);
    assert_eq!(r.stats.expect("figures").count, 6);
}

#[test]
fn never_converging_gives_no_figures_and_nulls() {
    let truth = straight(10);
    let estimates = offset(&truth, |s| (if s == 10 { 0.3 } else { 0.0 }, 0.0, 0.0));
    let r = run(&truth, &estimates);
    assert!(!r.converged());
    assert_eq!(r.converge_s(), None);
    assert_eq!(r.stats, None);
    let json = r.to_json();
    for key in [
        "converge_s",
        "mean_abs_error_deg",
        "rms_position_m",
        "recovered",
        "recover_s",
    ] {
        assert!(json.contains(&format!("\"{key}\": null")), "{key}: {json}");
    }
    let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    assert_eq!(
        value["mean_abs_error_m"],
        serde_json::json!({"x": null, "y": null}),
        "{json}"
    );
    assert!(json.contains("\"converged\": false"), "{json}");
    assert!(!json.contains("NaN") && !json.contains("inf"), "{json}");
    assert!(r.table().contains("never converged"), "{}", r.table());
}

#[test]
fn heading_errors_wrap_around_pi() {
    // True heading 179°, estimated -179°: 2° off, not 358°. The true
    // heading flips between ±179° without that being a kidnap.
    let theta = PI - 0.01;
    let truth: Vec<TruthSample> = (1..=6)
        .map(|s| {
            let sign = if s % 2 == 0 { -1.0 } else { 1.0 };
            TruthSample::new(s, 0.1 * s as f64, Pose2::new(0.0, 0.0, sign * theta))
        })
        .collect();
    let estimates = offset(&truth, |s| {
        (0.0, 0.0, if s % 2 == 0 { -0.02 } else { 0.02 })
    });
    let r = run(&truth, &estimates);
    assert!(!r.kidnapped());
    let s = r.stats.expect("figures");
    assert_eq!(s.count, 6);
    assert_relative_eq!(s.theta_rad.mean_abs, 0.02, epsilon = 1e-9);
    // Each estimate crosses ±π: +0.02 from 179° reads as -179° + 0.01.
    assert_relative_eq!(s.theta_rad.mean, 0.0, epsilon = 1e-9);
    assert_relative_eq!(s.theta_rad.std_dev, 0.02, epsilon = 1e-9);
}

#[test]
fn a_sudden_turn_is_a_kidnap_and_a_long_gap_is_not() {
    // 90° in 0.1 s is more than 45° + 9°.
    let mut truth = straight(5);
    for t in &mut truth[3..] {
        t.pose.theta = FRAC_PI_2;
    }
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let r = run(&truth, &estimates);
    assert_eq!(r.kidnaps.len(), 1);
    assert_eq!(r.kidnaps[0].sequence, 4);
    assert_relative_eq!(r.kidnaps[0].turn_rad, FRAC_PI_2);

    // 3 m in 10 s at up to 1 m/s could be driven: no kidnap.
    let truth = vec![
        TruthSample::new(1, 0.0, Pose2::new(0.0, 0.0, 0.0)),
        TruthSample::new(2, 10.0, Pose2::new(3.0, 0.0, 0.0)),
    ];
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let r = run(&truth, &estimates);
    assert!(!r.kidnapped());
    let c = r.convergence.expect("converged");
    assert_relative_eq!(c.distance_m, 0.0);
    assert_relative_eq!(r.end_time_s, 10.0);
}

#[test]
fn with_odometry_a_kidnap_is_a_jump_the_wheels_did_not_make() {
    // Scans a metre apart in a tenth of a second, as a corrected log's
    // may be: faster than the top speed, but the odometry drove them.
    let with_odometry = |jump_at: Option<u64>| -> Vec<TruthSample> {
        (1..=10)
            .map(|s| {
                let x = s as f64;
                // The odometry's frame is turned and shifted: only its
                // moves count.
                let odometry = Pose2::new(5.0, -3.0 + x, FRAC_PI_2);
                let pose = match jump_at {
                    Some(at) if s >= at => Pose2::new(x + 2.0, 0.0, 0.0),
                    _ => Pose2::new(x, 0.0, 0.0),
                };
                TruthSample::new(s, 0.1 * s as f64, pose).with_odometry(Some(odometry))
            })
            .collect()
    };
    let truth = with_odometry(None);
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    assert!(!run(&truth, &estimates).kidnapped());
    // Without the odometry the same steps are faster than driving.
    let bare: Vec<TruthSample> = truth
        .iter()
        .map(|t| TruthSample::new(t.sequence, t.time_s, t.pose))
        .collect();
    assert!(run(&bare, &estimates).kidnapped());
    // The reference jumping 2 m where the wheels drove 1 m is a kidnap.
    let truth = with_odometry(Some(6));
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let r = run(&truth, &estimates);
    assert_eq!(r.kidnaps.len(), 1);
    assert_eq!(r.kidnaps[0].sequence, 6);
}

#[test]
fn a_truth_sample_with_odometry_that_is_not_finite_is_refused() {
    let mut truth = straight(3);
    truth[1].odometry = Some(Pose2::new(f64::NAN, 0.0, 0.0));
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let err = evaluate(&EvalInput::new("r", &truth, &estimates)).unwrap_err();
    assert!(err.to_string().contains("truth[1].odometry"), "{err}");
}

#[test]
fn unpaired_estimates_and_frames_after_the_last_estimate_are_left_out() {
    let truth = straight(10);
    let mut estimates = offset(&truth[..6], |_| (0.1, 0.0, 0.0));
    // No frame 20 among the truth samples.
    estimates.push(EstimateSample::new(20, Pose2::new(9.0, 9.0, 0.0)));
    estimates[1].filter_converged = true;
    estimates[6].filter_converged = true;
    let r = run(&truth, &estimates);
    assert_eq!((r.estimates, r.estimates_paired), (7, 6));
    assert_eq!((r.frames, r.frames_after_last_estimate), (6, 4));
    assert_relative_eq!(r.end_time_s, 0.6, epsilon = 1e-12);
    // The unpaired one does not count among the filter's claims.
    assert_eq!(
        (r.filter_converged, r.filter_converged_within_bounds),
        (1, 1)
    );
    assert_eq!(r.stats.expect("figures").count, 6);
}

#[test]
fn false_convergence_counts_flagged_estimates_past_half_a_metre_or_a_quarter_radian() {
    let truth = straight(6);
    // Errors: within the bounds; outside them but not false; 0.6 m off;
    // 0.3 rad off; 2 m off but not flagged; 0.42 m and 0.2 rad off.
    let errors = [
        (0.1, 0.0, 0.0),
        (0.3, 0.2, 0.0),
        (0.0, 0.6, 0.0),
        (0.05, 0.0, 0.3),
        (2.0, 0.0, 0.0),
        (0.3, 0.3, 0.2),
    ];
    let mut estimates = offset(&truth, |s| errors[s as usize - 1]);
    for (i, e) in estimates.iter_mut().enumerate() {
        e.filter_converged = i != 4;
    }
    let r = run(&truth, &estimates);
    assert_eq!(r.filter_converged, 5);
    assert_eq!(r.filter_converged_within_bounds, 1);
    assert_eq!(r.false_converged, 2);
    assert_eq!(r.record().false_converged, 2);
}

#[test]
fn empty_input_is_a_clear_error() {
    let truth = straight(3);
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let error = evaluate(&EvalInput::new("r1", &[], &estimates)).expect_err("no truth");
    let text = error.to_string();
    assert!(text.contains("r1") && text.contains("true pose"), "{text}");

    let mut input = EvalInput::new("r1", &truth, &[]);
    input.map = Some("m");
    let text = evaluate(&input).expect_err("no estimate").to_string();
    assert!(text.contains("no pose estimate on map m"), "{text}");

    let far = [EstimateSample::new(100, Pose2::default())];
    let text = evaluate(&EvalInput::new("r1", &truth, &far))
        .expect_err("nothing paired")
        .to_string();
    assert!(
        text.contains("frames 100 to 100") && text.contains("frames 1 to 3"),
        "{text}"
    );
}

#[test]
fn bad_input_names_the_field() {
    let truth = straight(3);
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let mut bad = truth.clone();
    bad[1].pose.y = f64::NAN;
    let text = evaluate(&EvalInput::new("r", &bad, &estimates))
        .expect_err("NaN")
        .to_string();
    assert!(text.starts_with("truth[1].pose"), "{text}");

    let mut bad = truth.clone();
    bad[2].time_s = 0.0;
    let text = evaluate(&EvalInput::new("r", &bad, &estimates))
        .expect_err("time backwards")
        .to_string();
    assert!(text.starts_with("truth[2].time_s"), "{text}");

    let mut bad = estimates.clone();
    bad.swap(0, 1);
    let text = evaluate(&EvalInput::new("r", &truth, &bad))
        .expect_err("out of order")
        .to_string();
    assert!(text.starts_with("estimates[1].sequence"), "{text}");

    for (field, params) in [
        (
            "converge_m",
            EvalParams {
                converge_m: 0.0,
                ..EvalParams::default()
            },
        ),
        (
            "converge_rad",
            EvalParams {
                converge_rad: 4.0,
                ..EvalParams::default()
            },
        ),
        (
            "kidnap_jump_m",
            EvalParams {
                kidnap_jump_m: f64::NAN,
                ..EvalParams::default()
            },
        ),
        (
            "max_speed_mps",
            EvalParams {
                max_speed_mps: -1.0,
                ..EvalParams::default()
            },
        ),
    ] {
        let mut input = EvalInput::new("r", &truth, &estimates);
        input.params = params;
        let text = evaluate(&input).expect_err(field).to_string();
        assert!(text.starts_with(field), "{text}");
    }
}

#[test]
fn json_has_the_interface_keys_and_escapes_names() {
    let truth = kidnapped_run();
    let estimates = offset(&truth, |s| {
        if (11..14).contains(&s) {
            (3.0, 0.0, 0.0)
        } else {
            (0.1, 0.0, 0.0)
        }
    });
    let mut input = EvalInput::new("r\"1", &truth, &estimates);
    input.map = Some("m");
    let r = evaluate(&input).expect("evaluates");
    let json = r.to_json();
    for key in [
        "name",
        "converged",
        "converge_s",
        "mean_abs_error_m",
        "mean_abs_error_deg",
        "rms_position_m",
        "kidnapped",
        "recovered",
        "recover_s",
        "kidnaps",
    ] {
        assert!(json.contains(&format!("\"{key}\": ")), "{key}: {json}");
    }
    assert!(json.contains("\"name\": \"r\\\"1\""), "{json}");
    assert!(json.contains("\"map\": \"m\""), "{json}");
    assert!(json.contains("\"kidnapped\": true"), "{json}");
    assert!(json.contains("\"recovered\": true"), "{json}");
    let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    let x = value["mean_abs_error_m"]["x"].as_f64().expect("x");
    assert!((x - 0.1).abs() < 1e-3, "{json}");
    assert_eq!(value["mean_abs_error_m"]["y"].as_f64(), Some(0.0), "{json}");
    assert_eq!(value["kidnaps"][0]["sequence_before"], 10, "{json}");
    assert_eq!(value["kidnaps"][0]["sequence"], 11, "{json}");
    let all = reports_to_json(&[r.clone(), r]);
    assert!(all.starts_with("{\n  \"robots\": [\n    {\n"), "{all}");
    assert_eq!(all.matches("\"name\": ").count(), 2);
    assert_eq!(reports_to_json(&[]), "{\n  \"robots\": []\n}\n");
    // Braces and brackets balance (strings hold none but the escaped name).
    let opens = all.matches(['{', '[']).count();
    let closes = all.matches(['}', ']']).count();
    assert_eq!(opens, closes, "{all}");
}

#[test]
fn table_reads_like_the_thesis() {
    let truth = kidnapped_run();
    let estimates = offset(&truth, |s| {
        if (11..14).contains(&s) {
            (3.0, 0.0, 0.0)
        } else {
            (0.0254, 0.0, 0.0)
        }
    });
    let table = run(&truth, &estimates).table();
    assert!(table.contains("converged after 0.000 s"), "{table}");
    assert!(
        table.contains("| x | 0.0254 m | 0.0000 m | 1.0000 in | 0.0000 in |"),
        "{table}"
    );
    assert!(
        table.contains("kidnapped once, recovered, in 0.300 s"),
        "{table}"
    );
    assert!(table.contains("| 1 | 10 to 11 | 1.100 |"), "{table}");
}

fn plot_of(truth: &[TruthSample], estimates: &[EstimateSample], map: Option<&TileMap>) -> Raster {
    let report = run(truth, estimates);
    let robots = [RobotPath {
        truth,
        estimates,
        kidnaps: &report.kidnaps,
        convergence: report.convergence,
    }];
    render_plot(&PlotInput {
        map,
        robots: &robots,
    })
    .expect("plot")
}

#[test]
fn plot_frames_the_paths_and_colours_them() {
    // Truth from x = 0.1 to 2.0 along y = 0; estimates 0.2 m above, so
    // within the bounds and joined. The box is 1.9 m by 0.2 m, plus 0.5 m
    // each side: 2.9 m by 1.2 m.
    let truth: Vec<TruthSample> = (1..=20)
        .map(|s| TruthSample::new(s, 0.1 * s as f64, Pose2::new(0.1 * s as f64, 0.0, 0.0)))
        .collect();
    let estimates = offset(&truth, |_| (0.0, 0.2, 0.0));
    let raster = plot_of(&truth, &estimates, None);
    assert_eq!(raster.width, MAX_SIDE_PX);
    assert_eq!(raster.height, (1000.0f64 * 1.2 / 2.9).round() as u32);
    assert_eq!(
        raster.rgb.len(),
        3 * (raster.width * raster.height) as usize
    );
    let at = |x: f64, y: f64| {
        let (col, row) = raster.pixel_of(x, y).expect("inside");
        raster.pixel(col, row).expect("pixel")
    };
    assert_eq!(at(1.0, 0.0), TRUTH_RGB);
    assert_eq!(at(1.05, 0.2), ESTIMATE_RGB);
    assert_eq!(at(1.0, 0.1), FREE_RGB);
    assert_eq!(raster.pixel(0, 0), Some(FREE_RGB));
    assert_eq!(raster.pixel_of(-0.5, 0.0), None);

    let png = raster.to_png().expect("png");
    let decoder = png::Decoder::new(std::io::Cursor::new(png));
    let reader = decoder.read_info().expect("decodes");
    let info = reader.info();
    assert_eq!((info.width, info.height), (raster.width, raster.height));
    assert_eq!(info.color_type, png::ColorType::Rgb);
}

#[test]
fn plot_marks_kidnaps_and_breaks_the_true_path_there() {
    let truth = kidnapped_run();
    let estimates = offset(&truth, |_| (0.0, 0.5, 0.0));
    let raster = plot_of(&truth, &estimates, None);
    let at = |x: f64, y: f64| {
        let (col, row) = raster.pixel_of(x, y).expect("inside");
        raster.pixel(col, row).expect("pixel")
    };
    assert_eq!(at(1.0, 0.0), KIDNAP_RGB);
    assert_eq!(at(5.0, 5.0), KIDNAP_RGB);
    // Halfway along the jump: no red line, the robot did not drive there.
    assert_eq!(at(3.0, 2.5), FREE_RGB);
    assert_eq!(at(0.5, 0.0), TRUTH_RGB);
}

#[test]
fn plot_draws_the_map_under_the_paths() {
    // 10 cm cells: a free row at y in [0, 0.1) from x = 0 to 2, one
    // occupied cell at (2.5, 1.05), the rest unknown.
    let size = TileSize::DEFAULT;
    let mut map = TileMap::new(
        Resolution::new(0.1).expect("resolution"),
        size,
        ClampLimits::default(),
    );
    let mut delta = TileDelta::zero(TileKey::new(0, 0), size);
    let side = size.cells() as usize;
    for x in 0..20 {
        delta.raw_mut()[x] = -2000;
    }
    delta.raw_mut()[10 * side + 25] = 2000;
    map.apply(&delta).expect("apply");

    let truth = straight(10);
    let estimates = offset(&truth, |_| (0.0, 0.0, 0.0));
    let raster = plot_of(&truth, &estimates, Some(&map));
    // The box is the map's cells, (0, 0) to (2.6, 1.1), plus 0.5 m.
    assert_eq!(raster.width, MAX_SIDE_PX);
    assert_eq!(raster.height, (1000.0f64 * 2.1 / 3.6).round() as u32);
    let at = |x: f64, y: f64| {
        let (col, row) = raster.pixel_of(x, y).expect("inside");
        raster.pixel(col, row).expect("pixel")
    };
    assert_eq!(at(2.55, 1.05), OCCUPIED_RGB);
    assert_eq!(at(1.5, 0.05), FREE_RGB);
    assert_eq!(at(1.5, 0.5), UNKNOWN_RGB);
    assert_eq!(at(-0.3, 0.5), UNKNOWN_RGB);
    assert_eq!(at(0.55, 0.0), ESTIMATE_RGB);
}

#[test]
fn plot_of_nothing_is_an_error() {
    let text = render_plot(&PlotInput {
        map: None,
        robots: &[],
    })
    .expect_err("nothing")
    .to_string();
    assert!(text.contains("nothing to draw"), "{text}");
}

#[test]
fn a_known_kidnap_starts_a_segment_however_short_the_jump() {
    // Along x at 0.1 m a frame; at frame 11 the robot is set 0.3 m back,
    // too short a jump to tell from driving.
    let truth: Vec<TruthSample> = (1..=20)
        .map(|s| {
            let x = s as f64 * 0.1 - if s >= 11 { 0.3 } else { 0.0 };
            TruthSample::new(s, s as f64 * 0.1, Pose2::new(x, 0.0, 0.0))
        })
        .collect();
    // The estimate misses the kidnap for three frames.
    let estimates = offset(&truth, |s| {
        if (11..14).contains(&s) {
            (0.3, 0.0, 0.0)
        } else {
            (0.0, 0.0, 0.0)
        }
    });
    let unknown = run(&truth, &estimates);
    assert!(!unknown.kidnapped());
    let mut input = EvalInput::new("r", &truth, &estimates);
    input.known_kidnaps = &[11];
    let known = evaluate(&input).expect("evaluates");
    assert_eq!(known.kidnaps.len(), 1);
    assert_eq!(known.kidnaps[0].sequence, 11);
    assert_relative_eq!(known.converge_s().expect("converged"), 0.0, epsilon = 1e-12);
    assert_relative_eq!(known.recover_s().expect("recovered"), 0.3, epsilon = 1e-12);
}
