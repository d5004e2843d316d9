//! What the search matches: a robot's echoes as points in its own frame,
//! from one laser scan or from the last few sonar frames carried to the
//! present by the odometry. A sonar's echo came from somewhere across its
//! cone, so it is a group of points (the cone's centre line and its
//! edges' inner parts), and the reading scores the best of its group.

use std::collections::VecDeque;
use std::ops::Range;

use deog_grid::Pose2;
use deog_rig::rig::{Beam, BeamShape, Reading};

use crate::motion::OdometryMove;

/// Within a sonar's cone, the offsets from its axis of the points a
/// reading stands for, as shares of the half-angle.
const CONE_SPREAD: [f64; 5] = [0.0, -0.5, 0.5, -0.95, 0.95];

/// Echoes, in the robot's frame, grouped by reading.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanCloud {
    points: Vec<[f64; 2]>,
    /// Where each reading's group ends in `points`.
    ends: Vec<u32>,
    reach: f64,
}

impl ScanCloud {
    /// An empty cloud.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one reading's points, robot frame; none adds nothing.
    pub fn push_group(&mut self, points: impl IntoIterator<Item = [f64; 2]>) {
        let before = self.points.len();
        for p in points {
            if p[0].is_finite() && p[1].is_finite() {
                self.reach = self.reach.max(p[0].hypot(p[1]));
                self.points.push(p);
            }
        }
        if self.points.len() > before {
            self.ends.push(self.points.len() as u32);
        }
    }

    /// Every point.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Readings (groups of points).
    pub fn groups(&self) -> usize {
        self.ends.len()
    }

    /// Each group's points, as ranges into [`Self::points`].
    pub fn group_ranges(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        let mut start = 0usize;
        self.ends.iter().map(move |&end| {
            let range = start..end as usize;
            start = end as usize;
            range
        })
    }

    /// At most `most` of the groups, evenly spread (all of them when
    /// there are no more): a laser's hundreds of echoes cost a search
    /// more than they tell it.
    pub fn thinned(&self, most: usize) -> Self {
        let groups = self.groups();
        if most == 0 || groups <= most {
            return self.clone();
        }
        let ranges: Vec<_> = self.group_ranges().collect();
        let mut out = Self::new();
        for k in 0..most {
            let range = ranges[k * groups / most].clone();
            out.push_group(self.points[range].iter().copied());
        }
        out
    }

    /// The farthest point from the robot, metres.
    pub fn reach(&self) -> f64 {
        self.reach
    }

    /// Adds the echoes of one frame of `ranges` from `beams` (a rig's,
    /// in order), the robot at `at` in the frame of the cloud: echoes at
    /// or past `max_range` are left out (far sonar echoes are the least
    /// sure of where they came from).
    pub fn add_frame(&mut self, beams: &[Beam], ranges: &[f64], at: &Pose2, max_range: f64) {
        let (s, c) = at.theta.sin_cos();
        let to_cloud = |p: [f64; 2]| [at.x + c * p[0] - s * p[1], at.y + s * p[0] + c * p[1]];
        for (beam, &range) in beams.iter().zip(ranges) {
            let Some(Reading::Echo(r)) = beam.classify(range) else {
                continue;
            };
            if r >= max_range {
                continue;
            }
            let m = beam.mount;
            let along = |angle: f64| {
                let heading = m.theta + angle;
                to_cloud([m.x + r * heading.cos(), m.y + r * heading.sin()])
            };
            match beam.shape {
                BeamShape::Ray => self.push_group([along(0.0)]),
                BeamShape::Cone { half_angle } => {
                    self.push_group(CONE_SPREAD.map(|share| along(share * half_angle)))
                }
            }
        }
    }
}

/// The last frames a robot took, to gather into a cloud at its latest
/// pose: enough sonar frames to outline a room, or one laser scan.
#[derive(Debug, Clone)]
pub struct RecentFrames {
    frames: VecDeque<(Pose2, Vec<f64>)>,
    most_frames: usize,
    span_m: f64,
}

impl RecentFrames {
    /// Keeps at most `most_frames`, over at most `span_m` metres driven.
    pub fn new(most_frames: usize, span_m: f64) -> Self {
        Self {
            frames: VecDeque::new(),
            most_frames: most_frames.max(1),
            span_m,
        }
    }

    /// Notes a frame of `ranges` taken at odometry pose `odometry`.
    pub fn push(&mut self, odometry: Pose2, ranges: &[f64]) {
        self.frames.push_back((odometry, ranges.to_vec()));
        while self.frames.len() > self.most_frames {
            self.frames.pop_front();
        }
        // Drop frames further back than the span, by the path driven.
        let mut driven = 0.0;
        let mut keep = self.frames.len();
        for i in (1..self.frames.len()).rev() {
            let (a, b) = (&self.frames[i - 1].0, &self.frames[i].0);
            driven += (a.x - b.x).hypot(a.y - b.y);
            if driven > self.span_m {
                keep = self.frames.len() - i;
                break;
            }
        }
        while self.frames.len() > keep {
            self.frames.pop_front();
        }
    }

    /// The frames held, oldest first: odometry pose and readings.
    pub fn frames(&self) -> impl Iterator<Item = (&Pose2, &[f64])> {
        self.frames
            .iter()
            .map(|(pose, ranges)| (pose, ranges.as_slice()))
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Forgets every frame.
    pub fn clear(&mut self) {
        self.frames.clear();
    }

    /// The path driven over the frames held, metres.
    pub fn driven_m(&self) -> f64 {
        self.frames
            .iter()
            .zip(self.frames.iter().skip(1))
            .map(|(a, b)| (a.0.x - b.0.x).hypot(a.0.y - b.0.y))
            .sum()
    }

    /// The frames' echoes in the frame of the latest one's robot pose.
    pub fn cloud(&self, beams: &[Beam], max_range: f64) -> ScanCloud {
        let mut cloud = ScanCloud::new();
        let Some((now, _)) = self.frames.back() else {
            return cloud;
        };
        let origin = Pose2::new(0.0, 0.0, 0.0);
        for (odometry, ranges) in &self.frames {
            let at = OdometryMove::between(now, odometry).apply(&origin);
            cloud.add_frame(beams, ranges, &at, max_range);
        }
        cloud
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_laser_echo_is_one_point_and_a_sonar_echo_a_group() {
        let laser = deog_rig::builtin::built_in_rig("laser180").expect("laser180");
        let mut ranges = vec![f64::INFINITY; laser.readings()];
        ranges[90] = 2.0;
        let mut cloud = ScanCloud::new();
        cloud.add_frame(laser.beams(), &ranges, &Pose2::new(0.0, 0.0, 0.0), 100.0);
        assert_eq!((cloud.groups(), cloud.points().len()), (1, 1));
        let p = cloud.points()[0];
        let m = laser.beams()[90].mount;
        assert!((p[0] - (m.x + 2.0 * m.theta.cos())).abs() < 1e-9, "{p:?}");

        let scout = deog_rig::builtin::scout();
        let mut ranges = vec![100.0; scout.readings()];
        ranges[0] = 3.0;
        ranges[1] = 9.0;
        let mut cloud = ScanCloud::new();
        cloud.add_frame(scout.beams(), &ranges, &Pose2::new(0.0, 0.0, 0.0), 5.0);
        // The far echo is left out, the near one is five points.
        assert_eq!((cloud.groups(), cloud.points().len()), (1, 5));
        assert!(cloud.reach() > 3.0 && cloud.reach() < 3.5);

        // Thinned, a laser scan keeps an even spread of its echoes.
        let mut ranges = vec![2.0; laser.readings()];
        ranges[0] = 1.0;
        let mut scan = ScanCloud::new();
        scan.add_frame(laser.beams(), &ranges, &Pose2::new(0.0, 0.0, 0.0), 100.0);
        let thin = scan.thinned(30);
        assert_eq!(thin.groups(), 30);
        assert_eq!(thin.points()[0], scan.points()[0]);
        assert_eq!(scan.thinned(0), scan);
    }

    #[test]
    fn recent_frames_are_carried_to_the_latest_pose() {
        let laser = deog_rig::builtin::built_in_rig("laser180").expect("laser180");
        let mut ranges = vec![f64::INFINITY; laser.readings()];
        ranges[90] = 2.0;
        let mut recent = RecentFrames::new(10, 5.0);
        recent.push(Pose2::new(0.0, 0.0, 0.0), &ranges);
        // One metre on: the wall the first frame saw 2 m ahead is 1 m ahead.
        recent.push(Pose2::new(1.0, 0.0, 0.0), &ranges);
        let cloud = recent.cloud(laser.beams(), 100.0);
        let m = laser.beams()[90].mount;
        let ahead = m.x + 2.0 * m.theta.cos();
        let xs: Vec<f64> = cloud.points().iter().map(|p| p[0]).collect();
        assert!((xs[0] - (ahead - 1.0)).abs() < 1e-9, "{xs:?}");
        assert!((xs[1] - ahead).abs() < 1e-9, "{xs:?}");
        assert!((recent.driven_m() - 1.0).abs() < 1e-12);
        // Past the span, the oldest frames go.
        for i in 2..10 {
            recent.push(Pose2::new(f64::from(i), 0.0, 0.0), &ranges);
        }
        assert!(recent.driven_m() <= 5.0 + 1e-9);
        assert_eq!(recent.len(), 6);
    }
}
