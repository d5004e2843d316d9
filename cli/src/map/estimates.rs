//! `deog map --pose estimate`: the poses a localizer published for the
//! robot, followed from the map server as the cartographer reaches each
//! frame.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::Pose2;
use deog_mapping::{EstimateBook, EstimateLookup};
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_from_wire;
use tokio_util::sync::CancellationToken;

/// How often to ask for new estimates while a frame waits for one.
const POLL: Duration = Duration::from_millis(100);

/// A robot's estimates on one map, read as they are published.
#[derive(Debug)]
pub struct EstimateFollower {
    client: MapClient,
    robot: String,
    map: String,
    book: EstimateBook,
    /// How long one frame waits for the localizer to reach it.
    wait: Duration,
    /// Cancelled when the process is asked to stop: a frame's wait ends.
    shutdown: CancellationToken,
    /// Frames skipped, by why.
    pub not_converged: u64,
    /// Frames the localizer passed over or never reached in time.
    pub missed: u64,
}

impl EstimateFollower {
    /// Follows `robot`'s estimates on `map`; a frame waits at most `wait`,
    /// or until `shutdown` is cancelled.
    pub fn new(
        client: MapClient,
        robot: &str,
        map: &str,
        wait: Duration,
        shutdown: CancellationToken,
    ) -> Self {
        Self {
            client,
            robot: robot.to_owned(),
            map: map.to_owned(),
            book: EstimateBook::new(),
            wait,
            shutdown,
            not_converged: 0,
            missed: 0,
        }
    }

    /// Whether the process was asked to stop: a `None` from
    /// [`Self::pose_for`] then means the frame was not reached, not that it
    /// is to be skipped.
    pub fn stopping(&self) -> bool {
        self.shutdown.is_cancelled()
    }

    /// The converged estimate for frame `sequence`, waiting for the
    /// localizer to reach it; `None` when the frame is to be skipped, or
    /// when the process is stopping ([`Self::stopping`]).
    pub async fn pose_for(&mut self, sequence: u64) -> Result<Option<Pose2>> {
        let began = Instant::now();
        let mut logged = false;
        let shutdown = self.shutdown.clone();
        loop {
            if shutdown.is_cancelled() {
                return Ok(None);
            }
            match self.book.lookup(sequence) {
                EstimateLookup::Converged(pose) => {
                    self.book.forget_before(sequence);
                    return Ok(Some(pose));
                }
                EstimateLookup::NotConverged => {
                    self.not_converged += 1;
                    return Ok(None);
                }
                EstimateLookup::Passed => {
                    self.missed += 1;
                    return Ok(None);
                }
                EstimateLookup::Pending => {}
            }
            if began.elapsed() >= self.wait {
                tracing::warn!(robot = %self.robot, map = %self.map, frame = sequence, waited_s = self.wait.as_secs_f64(), "no estimate for the frame in time: skipped");
                self.missed += 1;
                return Ok(None);
            }
            let fetched = tokio::select! {
                () = shutdown.cancelled() => return Ok(None),
                fetched = self.fetch(sequence) => fetched?,
            };
            if !fetched {
                if !logged {
                    tracing::info!(robot = %self.robot, map = %self.map, frame = sequence, "waiting for the localizer's estimate");
                    logged = true;
                }
                tokio::select! {
                    () = shutdown.cancelled() => return Ok(None),
                    () = tokio::time::sleep(POLL) => {}
                }
            }
        }
    }

    /// Reads the estimates published since the last one seen (at least
    /// from `sequence`); whether any arrived.
    async fn fetch(&mut self, sequence: u64) -> Result<bool> {
        let from = (self.book.latest() + 1).max(sequence);
        let estimates = self
            .client
            .read_poses(&self.robot, from, 0)
            .await
            .with_context(|| format!("reading the estimates of robot {}", self.robot))?;
        let mut any = false;
        for e in estimates.into_iter().filter(|e| e.map == self.map) {
            if let Some(pose) = e.pose {
                self.book
                    .insert(e.frame_sequence, pose_from_wire(pose), e.converged);
                any = true;
            }
        }
        Ok(any)
    }
}
