//! deog's side: every scan of the log through the cartographer at its
//! reference pose, the deltas applied to a [`TileMap`] as the map server
//! merges them, the two steps timed apart.

use std::time::Instant;

use anyhow::{Context, Result};
use deog_grid::{ClampLimits, RayModelParams, Resolution, SonarModelParams, TileMap, TileSize};
use deog_harness::Progress;
use deog_mapping::{Cartographer, FrameInput, PoseChoice};

use super::laser_log::LaserLog;

/// What deog's side did, and the map it made.
#[derive(Debug)]
pub(super) struct DeogRun {
    /// Scans integrated, all passes.
    pub scans: u64,
    /// Cells the scans' deltas touched, all passes: one per cell per scan
    /// (a frame's beams are folded into one delta per cell).
    pub cell_updates: u64,
    /// Seconds spent turning scans into tile deltas.
    pub integrate_s: f64,
    /// Seconds spent applying the deltas to the map.
    pub apply_s: f64,
    /// Seconds of each pass, integration and application together.
    pub pass_seconds: Vec<f64>,
    /// The map after the last pass.
    pub map: TileMap,
}

impl DeogRun {
    /// Integration and application together, seconds.
    pub fn seconds(&self) -> f64 {
        self.integrate_s + self.apply_s
    }
}

/// The ray model both sides share: OctoMap's hit and miss probabilities,
/// rays cut at `mapped_range` metres, readings without a return ignored.
pub(super) fn ray_params(mapped_range: f64) -> RayModelParams {
    RayModelParams {
        no_echo_free_range: 0.0,
        max_mapped_range: mapped_range,
        ..RayModelParams::default()
    }
}

/// Maps every scan of `log` `passes` times at `resolution`, rays cut at
/// `mapped_range` metres, into one map clamped as OctoMap clamps.
pub(super) fn map_log(
    log: &LaserLog,
    resolution: Resolution,
    mapped_range: f64,
    passes: u32,
) -> Result<DeogRun> {
    let progress = Progress::new(
        "deog mapping scans",
        "scans",
        log.scans.len() as u64 * u64::from(passes),
    );
    let tile_size = TileSize::DEFAULT;
    let mut cartographer = Cartographer::for_rig(
        &log.rig,
        PoseChoice::Reference,
        SonarModelParams::default(),
        ray_params(mapped_range),
        resolution,
        tile_size,
    )
    .context("setting up the cartographer for the log's laser")?;
    let mut deltas = Vec::new();
    let mut run = DeogRun {
        scans: 0,
        cell_updates: 0,
        integrate_s: 0.0,
        apply_s: 0.0,
        pass_seconds: Vec::with_capacity(passes as usize),
        map: TileMap::new(resolution, tile_size, ClampLimits::default()),
    };
    for _ in 0..passes {
        let (integrate_before, apply_before) = (run.integrate_s, run.apply_s);
        for (sequence, scan) in log.scans.iter().enumerate() {
            let frame = FrameInput {
                sequence: sequence as u64,
                pace: None,
                true_pose: None,
                odometry: scan.pose,
                reference_pose: Some(scan.pose),
                estimate: None,
                ranges: &scan.ranges,
            };
            deltas.clear();
            let started = Instant::now();
            let cells = cartographer
                .integrate(&frame, &mut deltas)
                .with_context(|| format!("mapping the scan of line {}", scan.line))?;
            let integrated = Instant::now();
            for delta in &deltas {
                run.map.apply(delta)?;
            }
            let applied = Instant::now();
            run.integrate_s += (integrated - started).as_secs_f64();
            run.apply_s += (applied - integrated).as_secs_f64();
            run.scans += 1;
            run.cell_updates += cells as u64;
            progress.inc(1);
        }
        run.pass_seconds
            .push(run.integrate_s - integrate_before + run.apply_s - apply_before);
    }
    progress.finish();
    Ok(run)
}
