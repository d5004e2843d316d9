//! The localizer's ends at the map server: the tiles it fetches and the
//! estimates it publishes (and logs).

use anyhow::Context;
use deog_grid::{Pose2, TileKey, TileSize};
use deog_localizer::filter::Estimate;
use deog_localizer::step::{FetchedTile, TileSource};
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_to_wire;

/// The map server as the localizer's tile source: each fetch waits on the
/// runtime for one `GetTiles` by key.
pub(super) struct ServerTiles<'a> {
    pub(super) runtime: &'a tokio::runtime::Runtime,
    pub(super) client: &'a MapClient,
    pub(super) map: &'a str,
    pub(super) tile_size: TileSize,
}

impl TileSource for ServerTiles<'_> {
    fn fetch(
        &mut self,
        keys: &[TileKey],
    ) -> Result<Vec<FetchedTile>, Box<dyn std::error::Error + Send + Sync>> {
        let tiles =
            self.runtime
                .block_on(self.client.tiles_by_key(self.map, self.tile_size, keys))?;
        Ok(tiles
            .into_iter()
            .map(|(key, version, tile)| FetchedTile { key, version, tile })
            .collect())
    }
}

/// Where one robot's estimates on one map go: the map server.
pub(super) struct EstimateSink<'a> {
    pub(super) runtime: &'a tokio::runtime::Runtime,
    pub(super) client: &'a MapClient,
    pub(super) robot: &'a str,
    pub(super) map: &'a str,
}

impl EstimateSink<'_> {
    /// Publishes the estimate made after `frame`, with `sample`, a sample
    /// of the particles (often empty).
    pub(super) fn publish(
        &self,
        frame: &pb::SonarFrame,
        estimate: &Estimate,
        sample: &[Pose2],
    ) -> anyhow::Result<()> {
        let message = estimate_message(self.robot, self.map, frame, estimate, sample);
        self.runtime
            .block_on(self.client.publish_pose(message))
            .with_context(|| format!("publishing the estimate of frame {}", frame.sequence))
    }
}

/// The wire message of the estimate made after `frame`, with `sample`, a
/// sample of the particles (often empty).
pub(super) fn estimate_message(
    robot: &str,
    map: &str,
    frame: &pb::SonarFrame,
    estimate: &Estimate,
    sample: &[Pose2],
) -> pb::PoseEstimate {
    pb::PoseEstimate {
        robot: robot.to_string(),
        map: map.to_string(),
        frame_sequence: frame.sequence,
        time_s: frame.time_s,
        pose: Some(pose_to_wire(estimate.pose)),
        covariance: estimate.covariance.to_vec(),
        particle_count: estimate.particle_count as u32,
        converged: estimate.converged,
        lost_score: estimate.lost_score,
        particle_sample: sample
            .iter()
            .flat_map(|p| [p.x as f32, p.y as f32, p.theta as f32])
            .collect(),
    }
}

/// Logs the estimate beside the true pose at debug level, and every
/// hundredth frame at info level with the cache's size (`cache_bytes`).
pub(super) fn log_estimate(
    frame: &pb::SonarFrame,
    estimate: &Estimate,
    processed: u64,
    cache_bytes: usize,
) {
    let (truth, beside) = match (&frame.true_pose, &frame.reference_pose) {
        (Some(truth), _) => (Some(truth), "true"),
        (None, Some(reference)) => (Some(reference), "reference"),
        (None, None) => (None, ""),
    };
    if let Some(truth) = truth {
        tracing::debug!(
            beside,
            frame = frame.sequence,
            x = format!("{:.3}", estimate.pose.x),
            y = format!("{:.3}", estimate.pose.y),
            theta = format!("{:.3}", estimate.pose.theta),
            true_x = format!("{:.3}", truth.x),
            true_y = format!("{:.3}", truth.y),
            true_theta = format!("{:.3}", truth.theta),
            particles = estimate.particle_count,
            weight = format!("{:.2}", estimate.cluster_weight),
            spread_m = spread_m(estimate),
            converged = estimate.converged,
            lost = format!("{:.2}", estimate.lost_score),
            "estimate beside the simulator's true pose or the log's reference"
        );
    }
    if processed % 100 == 0 {
        tracing::info!(
            frame = frame.sequence,
            x = format!("{:.3}", estimate.pose.x),
            y = format!("{:.3}", estimate.pose.y),
            theta = format!("{:.3}", estimate.pose.theta),
            particles = estimate.particle_count,
            weight = format!("{:.2}", estimate.cluster_weight),
            spread_m = spread_m(estimate),
            converged = estimate.converged,
            lost = format!("{:.2}", estimate.lost_score),
            cache_mb = format!("{:.1}", cache_bytes as f64 / f64::from(1 << 20)),
            "estimate"
        );
    }
}

/// The estimate's position spread for a log line: the root of its x and
/// y variances' sum, metres, as the filter's settling compares it.
fn spread_m(estimate: &Estimate) -> String {
    let c = &estimate.covariance;
    format!("{:.2}", (c[0] + c[4]).max(0.0).sqrt())
}
