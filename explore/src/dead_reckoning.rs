//! A pose for steering from a localizer's estimates: the newest converged
//! estimate, carried forward to the present by the odometry driven since
//! its frame. Estimates arrive late (the localizer works behind the robot)
//! and now and then not at all; odometry is there every frame and drifts
//! little over the seconds between two estimates.

use std::collections::VecDeque;

use deog_grid::Pose2;

/// Odometry readings kept to match an estimate's frame: at 10 frames a
/// second, a minute of them.
const ODOMETRY_KEPT: usize = 600;

/// The newest estimate and the recent odometry.
#[derive(Debug, Clone, Default)]
pub struct DeadReckoning {
    /// Frame sequence and odometry, oldest first.
    odometry: VecDeque<(u64, Pose2)>,
    /// The newest estimate placed: (its frame's odometry, the estimate).
    anchor: Option<(Pose2, Pose2)>,
    anchor_sequence: u64,
}

impl DeadReckoning {
    /// Nothing known yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Frame `sequence`'s odometry, as the robot reports it.
    pub fn odometry(&mut self, sequence: u64, odometry: Pose2) {
        if self
            .odometry
            .back()
            .is_some_and(|&(last, _)| sequence <= last)
        {
            return;
        }
        if self.odometry.len() == ODOMETRY_KEPT {
            self.odometry.pop_front();
        }
        self.odometry.push_back((sequence, odometry));
    }

    /// A converged estimate of the robot's pose at frame `sequence`. Older
    /// than the one held, or for a frame whose odometry is no longer kept,
    /// it is ignored; returns whether it was taken.
    pub fn estimate(&mut self, sequence: u64, pose: Pose2) -> bool {
        if self.anchor.is_some() && sequence <= self.anchor_sequence {
            return false;
        }
        let Ok(at) = self.odometry.binary_search_by_key(&sequence, |&(s, _)| s) else {
            return false;
        };
        self.anchor = Some((self.odometry[at].1, pose));
        self.anchor_sequence = sequence;
        true
    }

    /// The pose now: the estimate composed with the odometry driven since
    /// its frame; `None` before any estimate.
    pub fn pose(&self) -> Option<Pose2> {
        let (anchor_odometry, estimate) = self.anchor?;
        let &(_, now) = self.odometry.back()?;
        Some(estimate.compose(&now.relative_to(&anchor_odometry)))
    }

    /// The frame of the estimate in use.
    pub fn estimate_sequence(&self) -> Option<u64> {
        self.anchor.map(|_| self.anchor_sequence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn an_estimate_is_carried_forward_by_the_odometry_since_its_frame() {
        let mut reckoning = DeadReckoning::new();
        assert_eq!(reckoning.pose(), None);
        // Odometry in its own frame: driving along its x.
        for s in 1..=10 {
            reckoning.odometry(s, Pose2::new(0.1 * s as f64, 0.0, 0.0));
        }
        // The localizer says the robot was at (5, 5) facing +y at frame 4.
        assert!(reckoning.estimate(4, Pose2::new(5.0, 5.0, FRAC_PI_2)));
        let now = reckoning.pose().expect("a pose");
        // Six frames of 0.1 m forward since: along +y in the map.
        assert_relative_eq!(now.x, 5.0, epsilon = 1e-9);
        assert_relative_eq!(now.y, 5.6, epsilon = 1e-9);
        assert_relative_eq!(now.theta, FRAC_PI_2, epsilon = 1e-9);
        assert_eq!(reckoning.estimate_sequence(), Some(4));
    }

    #[test]
    fn stale_or_unmatched_estimates_are_ignored() {
        let mut reckoning = DeadReckoning::new();
        for s in 1..=5 {
            reckoning.odometry(s, Pose2::new(s as f64, 0.0, 0.0));
        }
        assert!(!reckoning.estimate(9, Pose2::default()), "no odometry yet");
        assert!(reckoning.estimate(3, Pose2::new(1.0, 1.0, 0.0)));
        assert!(!reckoning.estimate(2, Pose2::default()), "older");
        assert_eq!(reckoning.estimate_sequence(), Some(3));
        // A repeated or older odometry sequence changes nothing.
        reckoning.odometry(5, Pose2::new(100.0, 0.0, 0.0));
        assert_relative_eq!(reckoning.pose().unwrap().x, 3.0, epsilon = 1e-9);
    }

    #[test]
    fn only_the_last_minute_of_odometry_is_kept() {
        let mut reckoning = DeadReckoning::new();
        for s in 1..=(ODOMETRY_KEPT as u64 + 50) {
            reckoning.odometry(s, Pose2::default());
        }
        assert!(!reckoning.estimate(10, Pose2::default()));
        assert!(reckoning.estimate(60, Pose2::default()));
    }
}
