//! The `octomap` method: OctoMap mapping the same frames, through
//! `bench/octomap_insert.py` (a child Python process, as in
//! `deog bench laser-mapping`).
//!
//! OctoMap has no sonar model: it takes rays. Each reading with an echo
//! becomes one ray from its transducer (the frame's true pose composed
//! with the transducer's mount on the Scout's rig) along the transducer's
//! axis to the echo's range; readings without an echo are left out, as
//! OctoMap's users leave out laser beams without a return (a ray gives no
//! free space for them). The transducers of a frame sit at different
//! places and `insertPointCloud` takes one origin per call, so every ray
//! is a scan of its own: one `insertPointCloud(point, origin, maxrange)`
//! call per echo, which updates each cell of its ray once (a cell two rays
//! of a frame cross is updated twice, as separate calls do).
//!
//! The settings are OctoMap's defaults, which are also laser-mapping's:
//! hit 0.7, miss 0.4, clamping 0.12 and 0.97; voxels of deog's map
//! resolution; `maxrange` the sonar methods' mapped range (5 m,
//! [`mapping_sonar_model`]'s `max_mapped_range`): an echo farther frees
//! its ray out to 5 m and adds no hit, as deog's cones stop there.
//! `--max-free-range` is not OctoMap's to follow: `maxrange` cuts the hit
//! with the free space.
//!
//! The final map's z = 0 layer comes back with OctoMap's log-odds and
//! becomes a deog map ([`to_tile_map`]), judged like the others. Only the
//! insertion calls are timed (the script's loop over them included); the
//! calls' own cost is timed apart with the same calls holding no point.
//! OctoMap does not count the cells it updates: [`ray_cell_updates`]
//! counts them in Rust, as its ray walk visits them.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_grid::{ClampLimits, Pose2, RayModelParams, Resolution, TileMap, TileSize};
use deog_mapping::mapping_sonar_model;
use deog_rig::{Reading, Rig};
use serde::Serialize;

use super::RecordedFrame;
use crate::octomap::cell_list::to_tile_map;
use crate::octomap::point_cloud::{ScanCloud, write_clouds};
use crate::octomap::{OctomapScript, OctomapSettings, Versions};

/// OctoMap's settings here, as reported.
#[derive(Debug, Clone, Serialize)]
pub(super) struct OctomapRecord {
    /// The interpreter's version.
    pub python: String,
    /// numpy's.
    pub numpy: String,
    /// octomap-python's (it bundles OctoMap).
    pub octomap: String,
    /// Metres per voxel.
    pub resolution_m: f64,
    /// `prob_hit`.
    pub prob_hit: f64,
    /// `prob_miss`.
    pub prob_miss: f64,
    /// Clamping, lower, as a probability.
    pub clamp_min: f64,
    /// Clamping, upper.
    pub clamp_max: f64,
    /// `insertPointCloud`'s `maxrange`, metres.
    pub max_range_m: f64,
}

/// OctoMap's side, ready: the script written out, its versions known.
pub(super) struct OctomapSide {
    script: OctomapScript,
    settings: OctomapSettings,
    versions: Versions,
    work: tempfile::TempDir,
}

/// What the `octomap` method made of one world's frames.
pub(super) struct OctomapBuild {
    /// The final map's z = 0 layer as a deog map.
    pub map: TileMap,
    /// Seconds of insertion.
    pub seconds: f64,
    /// Cells the rays update, counted by [`ray_cell_updates`].
    pub cell_updates: u64,
    /// What the script reported beyond that.
    pub details: OctomapDetails,
}

/// The script's figures of one world, as reported.
#[derive(Debug, Clone, Serialize)]
pub(super) struct OctomapDetails {
    /// Rays inserted: readings with an echo, one call each.
    pub rays: u64,
    /// Seconds of insertion.
    pub seconds: f64,
    /// Seconds of the same calls holding no point: the calls' own cost
    /// (Python's loop, the call, the conversion of its arguments).
    pub empty_call_seconds: Option<f64>,
    /// Leaves of the final tree.
    pub leaf_cells: u64,
    /// Nodes of the final tree.
    pub tree_nodes: u64,
    /// The tree's memory as OctoMap reckons it, bytes.
    pub memory_bytes: u64,
}

impl OctomapSide {
    /// OctoMap's side run by `python`, for maps of `resolution`; `Ok(Err)`
    /// with the reason (how to install what is missing) when it cannot run.
    pub fn new(python: &Path, resolution: Resolution) -> Result<Result<Self, String>> {
        let work = tempfile::tempdir().context("creating a temporary directory")?;
        let script = OctomapScript::new(python.as_os_str(), work.path())?;
        let versions = match script.probe() {
            Ok(versions) => versions,
            Err(reason) => return Ok(Err(reason)),
        };
        let rays = RayModelParams::default();
        Ok(Ok(Self {
            script,
            settings: OctomapSettings {
                resolution: resolution.metres(),
                prob_hit: rays.hit_probability,
                prob_miss: rays.miss_probability,
                clamp: ClampLimits::DEFAULT_PROBABILITIES,
                max_range: mapping_sonar_model().max_mapped_range,
                passes: 1,
                time_empty_calls: true,
            },
            versions,
            work,
        }))
    }

    /// The settings and versions, as reported.
    pub fn record(&self) -> OctomapRecord {
        let s = &self.settings;
        OctomapRecord {
            python: self.versions.python.clone(),
            numpy: self.versions.numpy.clone(),
            octomap: self.versions.octomap.clone(),
            resolution_m: s.resolution,
            prob_hit: s.prob_hit,
            prob_miss: s.prob_miss,
            clamp_min: s.clamp.0,
            clamp_max: s.clamp.1,
            max_range_m: s.max_range,
        }
    }

    /// Maps `frames`, taken with `rig`, into a map of `tile_size` tiles.
    pub fn build(
        &self,
        rig: &Rig,
        frames: &[RecordedFrame],
        tile_size: TileSize,
    ) -> Result<OctomapBuild> {
        let resolution = Resolution::new(self.settings.resolution)?;
        let clouds = reading_clouds(rig, frames)?;
        let mut cell_updates = 0;
        for cloud in &clouds {
            for point in &cloud.points {
                cell_updates +=
                    ray_cell_updates(cloud.origin, *point, resolution, self.settings.max_range)?;
            }
        }
        let scans_file = self.work.path().join("readings.bin");
        let cells_file = self.work.path().join("cells.bin");
        let file = File::create(&scans_file)
            .with_context(|| format!("creating {}", scans_file.display()))?;
        write_clouds(BufWriter::new(file), &clouds)
            .with_context(|| format!("writing {}", scans_file.display()))?;
        let run = self.script.run(&scans_file, &cells_file, &self.settings)?;
        let r = &run.report;
        if r.calls != clouds.len() as u64 {
            bail!(
                "OctoMap's script made {} calls for {} rays",
                r.calls,
                clouds.len()
            );
        }
        let map = to_tile_map(&run.cells, resolution, tile_size)?;
        Ok(OctomapBuild {
            map,
            seconds: r.seconds,
            cell_updates,
            details: OctomapDetails {
                rays: r.calls,
                seconds: r.seconds,
                empty_call_seconds: r.empty_call_seconds,
                leaf_cells: r.leaf_cells,
                tree_nodes: r.tree_nodes,
                memory_bytes: r.memory_bytes,
            },
        })
    }
}

/// The frames' readings as OctoMap gets them: one scan per reading with an
/// echo, its origin the transducer (the frame's true pose composed with
/// the beam's mount), its one point the echo, along the transducer's
/// axis at the range read (clamped to the sonar's limits as deog's models
/// take it). Readings without an echo are left out; a reading that is no
/// range at all is an error.
pub(super) fn reading_clouds(rig: &Rig, frames: &[RecordedFrame]) -> Result<Vec<ScanCloud>> {
    let mut clouds = Vec::new();
    for frame in frames {
        if frame.ranges.len() != rig.readings() {
            bail!(
                "frame {}: {} readings, the {} rig takes {}",
                frame.sequence,
                frame.ranges.len(),
                rig.name(),
                rig.readings()
            );
        }
        for (index, (beam, &range)) in rig.beams().iter().zip(&frame.ranges).enumerate() {
            match beam.classify(range) {
                Some(Reading::Echo(r)) => {
                    let origin = frame.true_pose.compose(&beam.mount);
                    let end = origin.compose(&Pose2::new(r, 0.0, 0.0));
                    clouds.push(ScanCloud {
                        origin: [origin.x, origin.y],
                        points: vec![[end.x, end.y]],
                    });
                }
                Some(Reading::NoEcho) => {}
                None => bail!(
                    "frame {}: reading {index} ({range}) is not a range",
                    frame.sequence
                ),
            }
        }
    }
    Ok(clouds)
}

/// The cells one ray from `origin` to the echo at `point` updates in
/// OctoMap's `insertPointCloud` with `maxrange` `max_range`: its walk
/// (`computeRayKeys`, stepping one axis at a time) visits the cells from
/// the origin's to the echo's, `1 + |Δx| + |Δy|` of them, all but the last
/// freed and the last hit; an echo past `max_range` frees the cells up to
/// the cut and neither the cut's own cell nor any other is hit. OctoMap
/// walks in single precision, so a ray grazing a cell corner may differ by
/// a cell.
pub(super) fn ray_cell_updates(
    origin: [f64; 2],
    point: [f64; 2],
    resolution: Resolution,
    max_range: f64,
) -> Result<u64> {
    let (dx, dy) = (point[0] - origin[0], point[1] - origin[1]);
    let length = dx.hypot(dy);
    let (end, hit) = if length <= max_range {
        (point, 1)
    } else {
        let scale = max_range / length;
        ([origin[0] + dx * scale, origin[1] + dy * scale], 0)
    };
    let from = resolution.cell_of(origin[0], origin[1])?;
    let to = resolution.cell_of(end[0], end[1])?;
    let steps = (i64::from(to.x) - i64::from(from.x)).unsigned_abs()
        + (i64::from(to.y) - i64::from(from.y)).unsigned_abs();
    Ok(steps + hit)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use approx::assert_relative_eq;
    use deog_grid::CellIndex;

    use super::*;

    fn frame(pose: Pose2, echoes: &[(usize, f64)]) -> RecordedFrame {
        // The Scout's sonars read 10.668 m (their maximum) for no echo.
        let mut ranges = vec![10.668; 16];
        for &(i, r) in echoes {
            ranges[i] = r;
        }
        RecordedFrame {
            sequence: 1,
            robot: 0,
            pace: None,
            true_pose: pose,
            ranges,
        }
    }

    #[test]
    fn each_echo_is_a_ray_along_its_transducers_axis_from_the_transducer() {
        let rig = deog_rig::scout();
        // Facing +y; sonar 0 faces forward, sonar 4 a quarter turn
        // counter-clockwise (to the robot's left, -x here), sonar 8 back.
        let frames = [frame(
            Pose2::new(1.0, 2.0, FRAC_PI_2),
            &[(0, 2.0), (4, 3.0), (8, 0.05)],
        )];
        let clouds = reading_clouds(&rig, &frames).expect("clouds");
        assert_eq!(clouds.len(), 3, "the 13 no-echo readings are left out");
        let close = |got: [f64; 2], want: [f64; 2]| {
            assert_relative_eq!(got[0], want[0], epsilon = 1e-12);
            assert_relative_eq!(got[1], want[1], epsilon = 1e-12);
        };
        // Sonar 0 sits 0.2 m ahead of the centre, at (1, 2.2).
        close(clouds[0].origin, [1.0, 2.2]);
        close(clouds[0].points[0], [1.0, 4.2]);
        // Sonar 4 sits 0.2 m to the left, at (0.8, 2), facing -x.
        close(clouds[1].origin, [0.8, 2.0]);
        close(clouds[1].points[0], [-2.2, 2.0]);
        // Sonar 8 behind, at (1, 1.8); a range under the sonar's minimum
        // (0.1524 m) is taken as the minimum, as deog's cones take it.
        close(clouds[2].origin, [1.0, 1.8]);
        close(clouds[2].points[0], [1.0, 1.8 - 0.1524]);
        assert!(clouds.iter().all(|c| c.points.len() == 1));

        let bad = [frame(Pose2::new(0.0, 0.0, 0.0), &[(3, f64::NAN)])];
        let error = reading_clouds(&rig, &bad).expect_err("NaN");
        assert!(error.to_string().contains("reading 3"), "{error}");
    }

    #[test]
    fn a_ray_updates_its_walks_cells_and_a_cut_one_no_hit() {
        let res = Resolution::DEFAULT;
        let centre = |x: i32, y: i32| {
            let (cx, cy) = res.cell_center(CellIndex::new(x, y));
            [cx, cy]
        };
        let count = |from, to, max| ray_cell_updates(from, to, res, max).expect("count");
        // Along an axis: 11 cells, the echo's included.
        assert_eq!(count(centre(0, 0), centre(10, 0), 5.0), 11);
        // Diagonally, one axis at a time: 1 + 3 + 4.
        assert_eq!(count(centre(0, 0), centre(-3, 4), 5.0), 8);
        // Within one cell: the hit alone.
        assert_eq!(count(centre(2, 2), [0.11, 0.12], 5.0), 1);
        // Cut at 0.5 m: the cells before the cut's, no hit.
        assert_eq!(count(centre(0, 0), centre(0, 100), 0.5), 10);
    }
}
