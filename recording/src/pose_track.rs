//! A pose over time from timestamped samples (odometry, a reference), read
//! at any time between the first and the last by linear interpolation.

use deog_grid::{Pose2, normalize_angle};

/// Poses in time order, one per distinct stamp.
#[derive(Debug, Clone, Default)]
pub struct PoseTrack {
    times: Vec<f64>,
    poses: Vec<Pose2>,
}

impl PoseTrack {
    /// A track from samples `(seconds, pose)` in any order; of samples
    /// with the same stamp the last is kept.
    pub fn new(mut samples: Vec<(f64, Pose2)>) -> Self {
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut track = Self::default();
        for (time, pose) in samples {
            if track.times.last() == Some(&time) {
                if let Some(last) = track.poses.last_mut() {
                    *last = pose;
                }
            } else {
                track.times.push(time);
                track.poses.push(pose);
            }
        }
        track
    }

    /// Number of distinct stamps.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the track has no sample.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The first and last stamps, seconds.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((*self.times.first()?, *self.times.last()?))
    }

    /// The pose at `time`: a sample's own at its stamp, interpolated
    /// between the two around it (the heading the short way round);
    /// `None` outside the track.
    pub fn at(&self, time: f64) -> Option<Pose2> {
        let after = self.times.partition_point(|&t| t < time);
        if self.times.get(after) == Some(&time) {
            return Some(self.poses[after]);
        }
        if after == 0 || after == self.times.len() {
            return None;
        }
        let (t0, t1) = (self.times[after - 1], self.times[after]);
        let (p0, p1) = (self.poses[after - 1], self.poses[after]);
        let f = (time - t0) / (t1 - t0);
        Some(Pose2::new(
            p0.x + f * (p1.x - p0.x),
            p0.y + f * (p1.y - p0.y),
            normalize_angle(p0.theta + f * normalize_angle(p1.theta - p0.theta)),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use std::f64::consts::PI;

    #[test]
    fn poses_interpolate_between_samples_and_stop_at_the_ends() {
        let track = PoseTrack::new(vec![
            (2.0, Pose2::new(2.0, 0.0, PI - 0.1)),
            (1.0, Pose2::new(0.0, 0.0, 0.0)),
            (3.0, Pose2::new(2.0, 2.0, -PI + 0.1)),
        ]);
        assert_eq!(track.span(), Some((1.0, 3.0)));
        let mid = track.at(1.5).unwrap();
        assert_abs_diff_eq!(mid.x, 1.0);
        assert_abs_diff_eq!(mid.theta, (PI - 0.1) / 2.0, epsilon = 1e-12);
        // Across ±pi the short way: through pi, not through 0.
        let wrap = track.at(2.5).unwrap();
        assert_abs_diff_eq!(wrap.theta.abs(), PI, epsilon = 1e-9);
        assert_eq!(track.at(3.0).unwrap(), Pose2::new(2.0, 2.0, -PI + 0.1));
        assert!(track.at(0.999).is_none());
        assert!(track.at(3.001).is_none());
    }

    #[test]
    fn the_last_of_samples_with_one_stamp_is_kept() {
        let track = PoseTrack::new(vec![
            (1.0, Pose2::new(0.0, 0.0, 0.0)),
            (1.0, Pose2::new(5.0, 0.0, 0.0)),
        ]);
        assert_eq!(track.len(), 1);
        assert_eq!(track.at(1.0).unwrap().x, 5.0);
    }
}
