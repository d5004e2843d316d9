//! The figures as the JSON `--out-json` writes: serde records whose field
//! names are the keys scripts read. Absent figures are `null`.

use anyhow::{Context, Result};
use serde::Serialize;

use deog_world::city::RESOLUTION_M;

use super::figures::LocalizerMemoryFigures;

/// The whole file.
#[derive(Serialize)]
struct LocalizeMemoryRecord<'a> {
    config: ConfigRecord,
    map: MapRecord,
    memory: MemoryRecord<'a>,
    path: PathRecord,
    localizer: LocalizerRecord<'a>,
    tracking: TrackingRecord,
    wall_s: f64,
    commands: &'a [String],
}

/// The settings of the run.
#[derive(Serialize)]
struct ConfigRecord {
    cache_mb: usize,
    max_particles: usize,
    duration_s: f64,
    speed: f64,
    robot_speed_mps: f64,
    seed: u64,
    start: StartRecord,
}

/// The robot's start pose, world frame: metres and radians.
#[derive(Serialize)]
struct StartRecord {
    x: f64,
    y: f64,
    theta: f64,
}

/// The city and its size in the localizer.
#[derive(Serialize)]
struct MapRecord {
    side_m: f64,
    side_px: u32,
    resolution_m: f64,
    blocks: usize,
    tiles: u64,
    localizer_bytes_per_tile: usize,
    localizer_bytes: u64,
    ratio_to_budget: f64,
}

/// The localizer's memory.
#[derive(Serialize)]
struct MemoryRecord<'a> {
    budget_bytes: usize,
    baseline_rss_kb: u64,
    baseline_time_s: f64,
    vm_hwm_kb: u64,
    peak_rss_sampled_kb: u64,
    end_rss_kb: u64,
    samples: u64,
    peak_minus_baseline_kb: u64,
    within_baseline_plus_budget: bool,
    beyond_cache_first_kb: Option<u64>,
    beyond_cache_first_rss_kb: Option<u64>,
    beyond_cache_first_cache_mib: Option<f64>,
    beyond_cache_max_kb: Option<u64>,
    /// `[wall seconds, kB]` pairs.
    rss_per_second_kb: &'a [(f64, u64)],
}

/// The robot's true path.
#[derive(Serialize)]
struct PathRecord {
    distance_m: f64,
    frames: usize,
    tiles_crossed: usize,
    tiles_crossed_until_last_estimate: usize,
}

/// The localizer's own figures and its filter's.
#[derive(Serialize)]
struct LocalizerRecord<'a> {
    kept_up: bool,
    given_up_because: Option<&'a str>,
    frames: Option<u64>,
    sensor_updates: Option<u64>,
    tables_built: Option<u64>,
    cache_end_mib: Option<f64>,
    estimates: u64,
    last_estimated_frame: u64,
    first_particles: u32,
    max_particles_later: Option<u32>,
    max_particles_later_frame: Option<u64>,
    max_lost_score: f64,
    estimates_with_lost_score: u64,
    first_lost_frame: Option<u64>,
    cache_logged_max_mib: Option<f64>,
    max_lag_frames: u64,
    cpu_s: f64,
}

/// The tracking error.
#[derive(Serialize)]
struct TrackingRecord {
    estimates_paired: u64,
    estimates_within_bounds: u64,
    mean_position_error_m: f64,
    max_position_error_m: f64,
    stretches_outside_bounds: u64,
    longest_outside: Option<OutsideRecord>,
    last_estimate_within_bounds: bool,
    converge_s: Option<f64>,
    after_convergence: Option<AfterConvergenceRecord>,
}

/// The longest run of estimates outside the bounds.
#[derive(Serialize)]
struct OutsideRecord {
    from_s: f64,
    seconds: f64,
    estimates: u64,
}

/// The error after convergence, as `deog eval localize` judges it.
#[derive(Serialize)]
struct AfterConvergenceRecord {
    mean_abs_x_m: f64,
    mean_abs_y_m: f64,
    mean_abs_theta_rad: f64,
    rms_position_m: f64,
    max_position_m: f64,
}

impl LocalizerMemoryFigures {
    fn record(&self) -> LocalizeMemoryRecord<'_> {
        let m = &self.memory;
        let s = self.summary.as_ref();
        let f = &self.filter;
        let t = &self.tracking;
        let b = &self.beyond_cache;
        LocalizeMemoryRecord {
            config: ConfigRecord {
                cache_mb: self.cache_mb,
                max_particles: self.max_particles,
                duration_s: self.duration_s,
                speed: self.speed,
                robot_speed_mps: self.robot_speed,
                seed: self.seed,
                start: StartRecord {
                    x: self.start.x,
                    y: self.start.y,
                    theta: self.start.theta,
                },
            },
            map: MapRecord {
                side_m: f64::from(self.side_px) * RESOLUTION_M,
                side_px: self.side_px,
                resolution_m: RESOLUTION_M,
                blocks: self.blocks,
                tiles: self.tiles,
                localizer_bytes_per_tile: self.tile_bytes,
                localizer_bytes: self.map_bytes(),
                ratio_to_budget: self.ratio(),
            },
            memory: MemoryRecord {
                budget_bytes: self.budget_bytes,
                baseline_rss_kb: self.baseline_kb,
                baseline_time_s: self.baseline_time_s,
                vm_hwm_kb: m.hwm_kb,
                peak_rss_sampled_kb: m.peak_rss_kb,
                end_rss_kb: m.last_rss_kb,
                samples: m.samples,
                peak_minus_baseline_kb: self.peak_kb().saturating_sub(self.baseline_kb),
                within_baseline_plus_budget: self.within(),
                beyond_cache_first_kb: b.first_kb(),
                beyond_cache_first_rss_kb: b.first.map(|(rss, _)| rss),
                beyond_cache_first_cache_mib: b.first.map(|(_, cache)| cache),
                beyond_cache_max_kb: (b.count > 0).then_some(b.max_kb),
                rss_per_second_kb: &m.series,
            },
            path: PathRecord {
                distance_m: self.distance_m,
                frames: self.frames_on_server,
                tiles_crossed: self.tiles_crossed,
                tiles_crossed_until_last_estimate: self.tiles_estimated,
            },
            localizer: LocalizerRecord {
                kept_up: s.is_some(),
                given_up_because: self.gave_up.as_deref(),
                frames: s.map(|s| s.frames),
                sensor_updates: s.map(|s| s.sensor_updates),
                tables_built: s.map(|s| s.tables_built),
                cache_end_mib: s.map(|s| s.cache_mib),
                estimates: f.estimates,
                last_estimated_frame: f.last_frame,
                first_particles: f.first_particles,
                max_particles_later: f.max_particles_later.map(|(n, _)| n),
                max_particles_later_frame: f.max_particles_later.map(|(_, frame)| frame),
                max_lost_score: f.max_lost_score,
                estimates_with_lost_score: f.lost,
                first_lost_frame: f.first_lost_frame,
                cache_logged_max_mib: self.logged_cache_max_mib,
                max_lag_frames: self.max_lag_frames,
                cpu_s: m.cpu_s,
            },
            tracking: TrackingRecord {
                estimates_paired: t.paired,
                estimates_within_bounds: t.within,
                mean_position_error_m: t.mean_m,
                max_position_error_m: t.max_m,
                stretches_outside_bounds: t.lost_stretches,
                longest_outside: t.longest_lost.map(|l| OutsideRecord {
                    from_s: l.from_s,
                    seconds: l.duration_s,
                    estimates: l.estimates,
                }),
                last_estimate_within_bounds: t.last_within,
                converge_s: self.report.converge_s(),
                after_convergence: self.report.stats.as_ref().map(|st| AfterConvergenceRecord {
                    mean_abs_x_m: st.x_m.mean_abs,
                    mean_abs_y_m: st.y_m.mean_abs,
                    mean_abs_theta_rad: st.theta_rad.mean_abs,
                    rms_position_m: st.rms_position_m,
                    max_position_m: st.max_position_m,
                }),
            },
            wall_s: self.wall_s,
            commands: &self.commands,
        }
    }

    /// The figures as pretty-printed JSON, ending with a newline.
    pub fn json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(&self.record()).context("assembling the JSON")
    }
}

#[cfg(test)]
mod tests {
    use deog_evaluation::localization::{EstimateSample, EvalInput, TruthSample, evaluate};
    use deog_evaluation::tracking::{LostStretch, Tracking};
    use deog_grid::Pose2;

    use super::super::ROBOT;
    use super::super::log::LocalizerSummary;
    use super::super::sampling::{BeyondCache, MemorySamples};
    use super::super::server_reads::FilterFigures;
    use super::*;

    /// A run whose estimates match the truth, with every optional figure
    /// present.
    fn figures() -> LocalizerMemoryFigures {
        let truth: Vec<TruthSample> = (1..=20)
            .map(|i| TruthSample::new(i, i as f64 * 0.1, Pose2::new(i as f64 * 0.05, 1.0, 0.0)))
            .collect();
        let estimates: Vec<EstimateSample> = truth
            .iter()
            .map(|t| EstimateSample {
                sequence: t.sequence,
                pose: t.pose,
                filter_converged: true,
            })
            .collect();
        let report = evaluate(&EvalInput::new(ROBOT, &truth, &estimates)).expect("judged");
        let memory = MemorySamples {
            series: vec![(0.1, 1000), (1.1, 1200)],
            ..MemorySamples::default()
        };
        let mut beyond_cache = BeyondCache::default();
        beyond_cache.note(2048, 1.0);
        LocalizerMemoryFigures {
            cache_mb: 16,
            max_particles: 10_000,
            budget_bytes: 16 << 20,
            side_px: 2688,
            blocks: 121,
            tiles: 1764,
            tile_bytes: 995_840,
            start: Pose2::new(1.0, 2.0, 0.0),
            duration_s: 30.0,
            speed: 2.0,
            robot_speed: 0.8,
            seed: 1,
            memory,
            beyond_cache,
            baseline_kb: 1000,
            baseline_time_s: 1.2,
            tiles_crossed: 1,
            tiles_estimated: 1,
            distance_m: 0.95,
            frames_on_server: 20,
            summary: Some(LocalizerSummary {
                frames: 20,
                sensor_updates: 18,
                tables_built: 4,
                cache_mib: 3.5,
            }),
            gave_up: None,
            filter: FilterFigures::default(),
            logged_cache_max_mib: Some(3.5),
            max_lag_frames: 2,
            report,
            tracking: Tracking {
                longest_lost: Some(LostStretch {
                    from_s: 1.0,
                    duration_s: 0.5,
                    estimates: 5,
                }),
                ..Tracking::default()
            },
            wall_s: 21.0,
            work: None,
            commands: vec!["deog server".into()],
        }
    }

    /// Every key path of `value`: objects by key, arrays by their first
    /// element.
    fn key_paths(value: &serde_json::Value, prefix: &str, out: &mut Vec<String>) {
        match value {
            serde_json::Value::Object(map) => {
                for (key, inner) in map {
                    key_paths(inner, &format!("{prefix}/{key}"), out);
                }
            }
            serde_json::Value::Array(items) => match items.first() {
                Some(first) => key_paths(first, &format!("{prefix}[]"), out),
                None => out.push(format!("{prefix}[]")),
            },
            _ => out.push(prefix.to_string()),
        }
    }

    #[test]
    fn the_json_keeps_the_keys_scripts_read() {
        let json = figures().json().expect("JSON");
        let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
        let mut paths = Vec::new();
        key_paths(&value, "", &mut paths);
        paths.sort_unstable();
        let expected = "/commands[] /config/cache_mb /config/duration_s /config/max_particles \
            /config/robot_speed_mps /config/seed /config/speed /config/start/theta \
            /config/start/x /config/start/y /localizer/cache_end_mib \
            /localizer/cache_logged_max_mib /localizer/cpu_s /localizer/estimates \
            /localizer/estimates_with_lost_score /localizer/first_lost_frame \
            /localizer/first_particles /localizer/frames /localizer/given_up_because \
            /localizer/kept_up /localizer/last_estimated_frame /localizer/max_lag_frames \
            /localizer/max_lost_score /localizer/max_particles_later \
            /localizer/max_particles_later_frame /localizer/sensor_updates \
            /localizer/tables_built /map/blocks /map/localizer_bytes \
            /map/localizer_bytes_per_tile /map/ratio_to_budget /map/resolution_m /map/side_m \
            /map/side_px /map/tiles /memory/baseline_rss_kb /memory/baseline_time_s \
            /memory/beyond_cache_first_cache_mib /memory/beyond_cache_first_kb \
            /memory/beyond_cache_first_rss_kb /memory/beyond_cache_max_kb \
            /memory/budget_bytes /memory/end_rss_kb /memory/peak_minus_baseline_kb \
            /memory/peak_rss_sampled_kb /memory/rss_per_second_kb[][] /memory/samples \
            /memory/vm_hwm_kb /memory/within_baseline_plus_budget /path/distance_m \
            /path/frames /path/tiles_crossed /path/tiles_crossed_until_last_estimate \
            /tracking/after_convergence/max_position_m \
            /tracking/after_convergence/mean_abs_theta_rad \
            /tracking/after_convergence/mean_abs_x_m /tracking/after_convergence/mean_abs_y_m \
            /tracking/after_convergence/rms_position_m /tracking/converge_s \
            /tracking/estimates_paired /tracking/estimates_within_bounds \
            /tracking/last_estimate_within_bounds /tracking/longest_outside/estimates \
            /tracking/longest_outside/from_s /tracking/longest_outside/seconds \
            /tracking/max_position_error_m /tracking/mean_position_error_m \
            /tracking/stretches_outside_bounds /wall_s";
        assert_eq!(paths, expected.split_whitespace().collect::<Vec<_>>());
        assert_eq!(value["memory"]["rss_per_second_kb"][1][1], 1200);
        assert_eq!(value["memory"]["beyond_cache_first_kb"], 1024);
        assert!(value["localizer"]["given_up_because"].is_null());
    }
}
