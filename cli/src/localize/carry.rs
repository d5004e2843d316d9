//! Estimates of now while the filter is busy: a slow sensor update (a
//! global search, a kidnap, range tables rebuilt) would otherwise leave
//! the robot's last estimate as old as the update is long. Meanwhile a
//! thread beside it takes the frames that arrive and publishes, for the
//! newest, the estimate before the update carried by that frame's odometry
//! (as amcl's pose follows odometry between its updates). The frames go
//! back to the filter afterwards; its own estimate for each replaces the
//! carried one.

use std::time::Duration;

use anyhow::{Context, Result};
use deog_localizer::filter::CarriedEstimate;
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_from_wire;
use tokio::sync::oneshot;

use super::server::estimate_message;
use crate::frame_queue::FrameQueue;

/// How often the carrier looks for new frames: a tenth of the frames' own
/// period, so a carried estimate is never far behind its frame.
const LOOK_EVERY: Duration = Duration::from_millis(10);

/// A step is carried when the filter holds this many particles (a search:
/// its updates take tens of milliseconds)...
const CARRY_PARTICLES: usize = 5_000;
/// ...or when the last step took this long. Below both a step is over
/// sooner than a thread would start.
const CARRY_AFTER: Duration = Duration::from_millis(5);

/// Whether a step is worth carrying, from the filter's particle count and
/// how long the last step took.
pub(super) fn worth_carrying(particles: usize, last_step: Duration) -> bool {
    particles >= CARRY_PARTICLES || last_step >= CARRY_AFTER
}

/// Where carried estimates go.
pub(super) struct Carrier<'a> {
    pub client: &'a MapClient,
    pub robot: &'a str,
    pub map: &'a str,
}

impl Carrier<'_> {
    /// Until `done` fires (or its sender is dropped): takes the frames
    /// that arrive in `queue` and publishes `carried` moved to the newest
    /// of them past `after`. Returns the frames taken, oldest first.
    pub(super) async fn carry_until(
        &self,
        queue: &mut FrameQueue,
        carried: CarriedEstimate,
        after: u64,
        mut done: oneshot::Receiver<()>,
    ) -> Result<Vec<pb::SonarFrame>> {
        let mut arrived = Vec::new();
        let mut published = after;
        loop {
            tokio::select! {
                _ = &mut done => break,
                () = tokio::time::sleep(LOOK_EVERY) => {}
            }
            while let Some(frame) = queue.try_next() {
                arrived.push(frame);
            }
            let Some(newest) = arrived.last().filter(|f| f.sequence > published) else {
                continue;
            };
            let Some(odometry) = newest.odometry.map(pose_from_wire) else {
                continue;
            };
            published = newest.sequence;
            let estimate = carried.at(&odometry);
            self.client
                .publish_pose(estimate_message(
                    self.robot,
                    self.map,
                    newest,
                    &estimate,
                    &[],
                ))
                .await
                .with_context(|| {
                    format!(
                        "publishing the carried estimate of frame {}",
                        newest.sequence
                    )
                })?;
        }
        Ok(arrived)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn searches_and_slow_steps_are_carried_quick_tracking_is_not() {
        assert!(worth_carrying(100_000, Duration::ZERO));
        assert!(worth_carrying(500, Duration::from_millis(40)));
        assert!(!worth_carrying(500, Duration::from_micros(300)));
        assert!(!worth_carrying(CARRY_PARTICLES - 1, CARRY_AFTER / 2));
    }
}
