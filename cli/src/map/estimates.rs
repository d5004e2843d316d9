//! `deog map --pose estimate`: the poses a localizer published for the
//! robot, followed from the map server as the cartographer reaches each
//! frame.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::Pose2;
use deog_mapping::{EstimateBook, EstimateLookup};
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_from_wire;

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
    /// Frames skipped, by why.
    pub not_converged: u64,
    /// Frames the localizer passed over or never reached in time.
    pub missed: u64,
}

impl EstimateFollower {
    /// Follows `robot`'s estimates on `map`; a frame waits at most `wait`.
    pub fn new(client: MapClient, robot: &str, map: &str, wait: Duration) -> Self {
        Self {
            client,
            robot: robot.to_owned(),
            map: map.to_owned(),
            book: EstimateBook::new(),
            wait,
            not_converged: 0,
            missed: 0,
        }
    }

    /// The converged estimate for frame `sequence`, waiting for the
    /// localizer to reach it; `None` when the frame is to be skipped.
    pub async fn pose_for(&mut self, sequence: u64) -> Result<Option<Pose2>> {
        let began = Instant::now();
        let mut logged = false;
        loop {
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
            if !self.fetch(sequence).await? {
                if !logged {
                    tracing::info!(robot = %self.robot, map = %self.map, frame = sequence, "waiting for the localizer's estimate");
                    logged = true;
                }
                tokio::time::sleep(POLL).await;
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
