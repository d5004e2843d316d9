//! The log both sides map: one laser's scans, each at its reference pose,
//! with the rig the log's geometry makes, and the same scans as world-frame
//! echoes for OctoMap.

use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_grid::Pose2;
use deog_logs::{CarmenLog, LaserSource};
use deog_rig::{Reading, Rig};

use crate::octomap::point_cloud::ScanCloud;

/// How close, metres, the beams' starting points must be to count as one
/// sensor origin (OctoMap takes one origin per point cloud).
const SHARED_ORIGIN_TOLERANCE_M: f64 = 1e-9;

/// One scan placed where the log says the robot was.
#[derive(Debug, Clone)]
pub(super) struct PlacedScan {
    /// The 1-based line of the log it came from, for messages.
    pub line: usize,
    /// The robot's reference pose, world frame.
    pub pose: Pose2,
    /// Metres, one per beam of the rig.
    pub ranges: Vec<f64>,
}

/// One laser of a log, with its reference poses.
#[derive(Debug, Clone)]
pub(super) struct LaserLog {
    /// Which laser: the front one, or the log's only one.
    pub source: LaserSource,
    /// The rig the log's geometry makes for that laser.
    pub rig: Rig,
    /// Its scans, in file order.
    pub scans: Vec<PlacedScan>,
}

impl LaserLog {
    /// Reads `path` (a CARMEN log, plain or gzip): its front laser, or its
    /// only one. Fails on a log without
    /// reference poses (they place the scans), or whose laser's beams do
    /// not start from one point.
    pub fn load(path: &Path) -> Result<Self> {
        let log = CarmenLog::load(path)?;
        let sources = log.sources();
        let source = match sources.as_slice() {
            [only] => *only,
            _ if sources.contains(&LaserSource::Front) => LaserSource::Front,
            _ => bail!(
                "{}: scans of several lasers and none of the front one; this bench maps one laser",
                path.display()
            ),
        };
        let rig = log.rig(
            source,
            &format!("carmen-{}", source.tag().to_ascii_lowercase()),
        )?;
        log.check_rig(source, &rig)?;
        let start = rig.beams().first().map(|b| (b.mount.x, b.mount.y));
        if rig.beams().iter().any(|b| {
            start.is_some_and(|(x, y)| {
                (b.mount.x - x).hypot(b.mount.y - y) > SHARED_ORIGIN_TOLERANCE_M
            })
        }) {
            bail!(
                "{}: the {source} laser's beams start from different points; OctoMap takes one origin per scan",
                path.display()
            );
        }
        let scans = log
            .scans_from(source)
            .map(|s| {
                let pose = s.reference.with_context(|| {
                    format!(
                        "{} line {}: the scan has no reference pose; this bench places scans at a corrected log's (or TRUEPOS) poses",
                        path.display(),
                        s.line
                    )
                })?;
                Ok(PlacedScan {
                    line: s.line,
                    pose,
                    ranges: s.ranges.clone(),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { source, rig, scans })
    }

    /// Beams per scan.
    pub fn beams_per_scan(&self) -> usize {
        self.rig.readings()
    }

    /// The scans as OctoMap gets them: each echo where the rig's beam puts
    /// it, world frame; readings the rig calls no echo left out (OctoMap
    /// users filter them, and deog's ray model is told to ignore them).
    /// Echoes past the mapped range are kept: the insertion's `maxrange`
    /// cuts their rays as deog's `max_mapped_range` does.
    pub fn clouds(&self) -> Result<Vec<ScanCloud>> {
        self.scans
            .iter()
            .map(|scan| {
                let mut points = Vec::with_capacity(scan.ranges.len());
                for (index, (beam, &range)) in self.rig.beams().iter().zip(&scan.ranges).enumerate()
                {
                    match beam.classify(range) {
                        Some(Reading::Echo(r)) => {
                            let end = scan
                                .pose
                                .compose(&beam.mount)
                                .compose(&Pose2::new(r, 0.0, 0.0));
                            points.push([end.x, end.y]);
                        }
                        Some(Reading::NoEcho) => {}
                        None => bail!(
                            "line {}: reading {index} ({range}) is not a range",
                            scan.line
                        ),
                    }
                }
                let origin = match self.rig.beams().first() {
                    Some(beam) => scan.pose.compose(&beam.mount),
                    None => scan.pose,
                };
                Ok(ScanCloud {
                    origin: [origin.x, origin.y],
                    points,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use approx::assert_relative_eq;

    use super::*;

    /// A corrected log of two scans of four beams; 50.0 is its no-return
    /// value, so each scan has three echoes.
    const LOG: &str = "\
PARAM robot_frontlaser_offset 0.0 nohost 0
ODOM 0 0 0 0 0 0 0.1 pippo 0.1
FLASER 4 1.0 2.0 50.0 3.0 0 0 0 0 0 0 0.2 pippo 0.2
ODOM 0 0 0 0 0 0 0 pippo 0
ODOM 0.5 0 0 0 0 0 0.3 pippo 0.3
FLASER 4 1.0 2.0 50.0 3.0 1 2 1.5 1 2 1.5 0.4 pippo 0.4
ODOM 1 2 1.5 0 0 0 0 pippo 0
";

    #[test]
    fn echoes_land_at_their_range_from_the_reference_pose_and_no_returns_are_left_out() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("two.log");
        std::fs::write(&path, LOG).expect("write log");
        let log = LaserLog::load(&path).expect("load");
        assert_eq!(log.source, LaserSource::Front);
        assert_eq!((log.scans.len(), log.beams_per_scan()), (2, 4));
        let clouds = log.clouds().expect("clouds");
        assert_eq!(clouds[0].origin, [0.0, 0.0]);
        assert_eq!(clouds[1].origin, [1.0, 2.0]);
        for cloud in &clouds {
            let ranges: Vec<f64> = cloud
                .points
                .iter()
                .map(|p| (p[0] - cloud.origin[0]).hypot(p[1] - cloud.origin[1]))
                .collect();
            assert_eq!(ranges.len(), 3, "the no-return beam is left out");
            for (got, want) in ranges.iter().zip([1.0, 2.0, 3.0]) {
                assert_relative_eq!(*got, want, epsilon = 1e-12);
            }
        }
        // The same beam, turned by the second pose's 1.5 rad heading.
        let bearing = |c: &ScanCloud, i: usize| {
            (c.points[i][1] - c.origin[1]).atan2(c.points[i][0] - c.origin[0])
        };
        assert_relative_eq!(
            deog_grid::normalize_angle(bearing(&clouds[1], 0) - bearing(&clouds[0], 0)),
            1.5,
            epsilon = 1e-12
        );
    }

    #[test]
    fn a_log_without_reference_poses_is_refused_naming_the_line() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("raw.log");
        std::fs::write(&path, "FLASER 2 1.0 2.0 0 0 0 0 0 0 0.2 pippo 0.2\n").expect("write");
        let error = LaserLog::load(&path).expect_err("no reference");
        assert!(error.to_string().contains("line 1"), "{error:#}");
    }
}
