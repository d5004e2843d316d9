//! The optional per-frame printouts of `deog bench localize`: beams
//! measured against the map's prediction, a pose's mirror image, and the
//! particles near a pose.

use anyhow::Result;
use deog_evaluation::localization::{DEFAULT_CONVERGE_M, DEFAULT_CONVERGE_RAD};
use deog_grid::{Pose2, SensorRing, normalize_angle};
use deog_localizer::beam_model::table_len;
use deog_localizer::filter::Mcl;
use deog_localizer::local_map::LocalMap;

/// One line: each beam's measured range and, after a slash, the range the
/// map's tables predict at `pose` for the sonar of `ring` (centimetres;
/// `-` for no echo).
pub(super) fn print_beams(
    map: &mut LocalMap,
    ring: &SensorRing,
    pose: &Pose2,
    ranges: &[f64],
    time_s: f64,
) -> Result<()> {
    let keys = map.tables_under(ring, pose)?;
    let max_range = map.settings().geometry.max_range;
    let no_echo = table_len(max_range) - 1;
    let window = map.window(&keys);
    let mut line = format!(
        "    beams t {time_s:6.1} ({:5.2}, {:5.2}, {:6.1}°)",
        pose.x,
        pose.y,
        pose.theta.to_degrees()
    );
    for (sensor, z) in ring.sensor_poses(pose).zip(ranges) {
        let (sin, cos) = sensor.theta.sin_cos();
        let slot = window.expected_slot(sensor.x, sensor.y, sensor.theta, (cos, sin), no_echo);
        let measured = if z.is_finite() && *z < max_range {
            format!("{:.0}", z * 100.0)
        } else {
            "-".into()
        };
        let expected = if slot == no_echo {
            "-".into()
        } else {
            slot.to_string()
        };
        line.push_str(&format!(" {measured}/{expected}"));
    }
    deog_harness::println_above_bars!("{line}");
    Ok(())
}

/// `pose` turned 180° about `centre` ("x,y", as `--mirror-about` gives it,
/// checked to hold two numbers).
pub(super) fn image_of(pose: &Pose2, centre: &[f64]) -> Pose2 {
    Pose2::new(
        2.0 * centre[0] - pose.x,
        2.0 * centre[1] - pose.y,
        pose.theta + std::f64::consts::PI,
    )
}

/// How many particles lie within the convergence bounds of `pose`, and
/// their weight.
pub(super) fn particles_near(mcl: &Mcl, pose: &Pose2) -> (usize, f64) {
    let (mut near, mut weight) = (0usize, 0.0f64);
    for (p, w) in mcl.particles().iter().zip(mcl.weights()) {
        if (p.x - pose.x).hypot(p.y - pose.y) <= DEFAULT_CONVERGE_M
            && normalize_angle(p.theta - pose.theta).abs() <= DEFAULT_CONVERGE_RAD
        {
            near += 1;
            weight += w;
        }
    }
    (near, weight)
}
