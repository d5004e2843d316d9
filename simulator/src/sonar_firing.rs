//! When each sonar of a ring fires within a sensor period.
//!
//! A real ring cannot fire all its sonars at once (their echoes would
//! mix), so it fires them one after another while the robot moves. The
//! simulator models this as ring order spread evenly over the period: a
//! modelling choice, since real controllers fire in groups and orders of
//! their own.

/// When the sonars of a frame fire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SonarFiring {
    /// All at once, at the frame's pose.
    #[default]
    Together,
    /// One at a time in ring order (the rig's order of its sonars), spread
    /// evenly over the sensor period: of n sonars, sonar k fires
    /// (k + 1) / n of the way through the period that ends with the frame,
    /// at the physics step nearest that time, and reads from the pose the
    /// robot had then. The last fires with the frame. The frame still
    /// carries one odometry and one true pose, the frame's.
    Sequential,
}

/// How many physics steps before the frame sonar `k` of `n` fires, with
/// `steps_per_period` physics steps (at least 1) in a sensor period: 0 for
/// the last sonar, up to `steps_per_period - 1` for the first.
pub fn steps_before_frame(k: usize, n: usize, steps_per_period: u64) -> u64 {
    if n == 0 || k >= n {
        return 0;
    }
    let steps = steps_per_period.max(1);
    let fraction = (k + 1) as f64 / n as f64;
    // The step of the period at that time, 1..=steps.
    let step = ((fraction * steps as f64).round() as u64).clamp(1, steps);
    steps - step
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_firings_spread_over_the_period_in_ring_order() {
        let offsets: Vec<u64> = (0..16).map(|k| steps_before_frame(k, 16, 10)).collect();
        assert_eq!(offsets[15], 0, "the last fires with the frame");
        assert_eq!(offsets[0], 9, "the first one step after the last frame");
        assert!(offsets.windows(2).all(|w| w[0] >= w[1]), "{offsets:?}");
        // One sonar, or one step per period: all with the frame.
        assert_eq!(steps_before_frame(0, 1, 10), 0);
        assert!((0..16).all(|k| steps_before_frame(k, 16, 1) == 0));
        assert_eq!(steps_before_frame(3, 2, 10), 0, "no such sonar");
    }
}
