//! deog's side: `deog_localizer::step::Localizer` with the Scout's beam
//! model over the recorded frames, each step timed on the thread's CPU
//! clock.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::{Pose2, TileMap};
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::LocalMap;
use deog_localizer::sensors::{LikelihoodFieldParams, SensorChoice};
use deog_localizer::step::{Localizer, TileSource};
use deog_rig::Rig;
use serde::Serialize;

use super::cpu_clock::thread_cpu_s;
use super::recording::Frame;

/// Where a run's particles start.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub(super) enum Prior {
    /// Drawn around a pose (the true initial pose, for tracking).
    Gaussian {
        /// The centre: x, y (metres), theta (radians).
        centre: [f64; 3],
        /// Standard deviation of x and of y, metres.
        std_xy: f64,
        /// Standard deviation of the heading, radians.
        std_theta: f64,
    },
    /// Uniform over the map's known-free cells, all headings (deog's
    /// global localization; the amcl package has no way to start so).
    Uniform,
}

/// One run of a filter over the frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(super) struct RunSpec {
    /// The run's name in the table ("tracking-500").
    pub name: String,
    /// Fewest and most particles (equal: a fixed count).
    pub min_particles: usize,
    pub max_particles: usize,
    /// Where the particles start.
    pub prior: Prior,
}

/// What one run measured.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct FilterRun {
    /// Sensor updates made.
    pub updates: u64,
    /// Thread CPU seconds of the steps that made a sensor update.
    pub update_cpu_s: f64,
    /// Thread CPU seconds of every step.
    pub step_cpu_s: f64,
    /// Particles scored, summed over the updates (`None`: not known).
    pub particles_scored: Option<u64>,
    /// The estimate after each frame (`None` before the filter has one).
    pub estimates: Vec<Option<Pose2>>,
}

/// Runs deog's filter as `spec` says over `frames` on `map` (its tiles
/// from `tiles`), seeded by `seed`; returns its figures and the map, with
/// the tables it built, for the next run.
pub(super) fn run_deog(
    rig: &Rig,
    map: LocalMap,
    tiles: &mut TileMap,
    frames: &[Frame],
    spec: &RunSpec,
    seed: u64,
) -> Result<(FilterRun, LocalMap)> {
    let mut settings = FilterSettings {
        seed,
        ..FilterSettings::default()
    };
    settings.kld.min_particles = spec.min_particles;
    settings.kld.max_particles = spec.max_particles;
    // The beam model's no-echo range is the cone's the map's tables are for.
    settings.beam.max_range = map.settings().geometry.max_range;
    let sensor = SensorChoice::Beam;
    let model = sensor
        .build(rig, settings.beam, LikelihoodFieldParams::default())
        .with_context(|| format!("the {sensor} model for rig {}", rig.name()))?;
    let mcl = Mcl::with_sensor(settings, model)?;
    // No change is ever reported: the map in memory is the whole map.
    let mut localizer = Localizer::new(mcl, map, Duration::MAX, Instant::now());
    match spec.prior {
        Prior::Uniform => {
            let keys: Vec<_> = tiles.tiles().map(|(k, _)| *k).collect();
            let whole = tiles.fetch(&keys).map_err(|e| anyhow::anyhow!(e))?;
            localizer.start_global(whole)?;
        }
        Prior::Gaussian {
            centre,
            std_xy,
            std_theta,
        } => {
            let pose = Pose2::new(centre[0], centre[1], centre[2]);
            localizer.mcl_mut().start_at(pose, std_xy, std_theta)?;
        }
    }
    let mut run = FilterRun {
        updates: 0,
        update_cpu_s: 0.0,
        step_cpu_s: 0.0,
        particles_scored: Some(0),
        estimates: Vec::with_capacity(frames.len()),
    };
    let mut scored = 0u64;
    for frame in frames {
        let particles = localizer.mcl().particles().len() as u64;
        let start = thread_cpu_s()?;
        let report = localizer.step(&frame.odometry, &frame.ranges, Instant::now(), tiles)?;
        let cpu = thread_cpu_s()? - start;
        run.step_cpu_s += cpu;
        if report.correction.is_some() {
            run.updates += 1;
            run.update_cpu_s += cpu;
            scored += particles;
        }
        run.estimates.push(report.estimate.map(|e| e.pose));
    }
    run.particles_scored = Some(scored);
    Ok((run, localizer.into_map()))
}
