//! What the map server holds of the run: the robot's latest frame, the
//! localizer's estimates and what they say of the filter, and the tiles
//! the robot's true path crossed.

use std::collections::HashSet;

use anyhow::{Context, Result};
use deog_evaluation::localization::TruthSample;
use deog_grid::{Resolution, TileKey, TileSize};
use deog_robot_client::MapClient;
use deog_world::city::RESOLUTION_M;

use super::{MAP, ROBOT};

/// What the published estimates say of the filter itself.
#[derive(Debug, Default)]
pub(super) struct FilterFigures {
    /// Estimates published.
    pub estimates: u64,
    /// The frame of the last one.
    pub last_frame: u64,
    /// Particles of the first estimate (the filter starts with its most).
    pub first_particles: u32,
    /// The most particles an estimate had once the count had first fallen
    /// below that, and the frame: a burst of injected particles.
    pub max_particles_later: Option<(u32, u64)>,
    /// The largest lost score (the share of particles the filter would
    /// inject from free space: `1 − w_fast / w_slow`). An injection resets
    /// it, so the estimates published after one show none.
    pub max_lost_score: f64,
    /// Estimates with a lost score above zero.
    pub lost: u64,
    /// The first frame whose estimate had a lost score above zero.
    pub first_lost_frame: Option<u64>,
}

/// Reads the localizer's estimates as published, particle counts and lost
/// scores included.
pub(super) async fn filter_figures(client: &MapClient) -> Result<FilterFigures> {
    let poses = client
        .read_poses(ROBOT, 0, 0)
        .await
        .context("reading the localizer's estimates")?;
    let mut f = FilterFigures::default();
    let mut settled = false;
    for estimate in poses.iter().filter(|p| p.map == MAP) {
        if f.estimates == 0 {
            f.first_particles = estimate.particle_count;
        }
        f.estimates += 1;
        f.last_frame = f.last_frame.max(estimate.frame_sequence);
        settled |= estimate.particle_count < f.first_particles;
        if settled
            && f.max_particles_later
                .is_none_or(|(most, _)| estimate.particle_count > most)
        {
            f.max_particles_later = Some((estimate.particle_count, estimate.frame_sequence));
        }
        f.max_lost_score = f.max_lost_score.max(estimate.lost_score);
        if estimate.lost_score > 0.0 {
            f.lost += 1;
            f.first_lost_frame.get_or_insert(estimate.frame_sequence);
        }
    }
    Ok(f)
}

/// The last frame sequence the server holds for the robot (0: none yet).
pub(super) async fn last_frame(client: &MapClient) -> u64 {
    client
        .robots()
        .await
        .map(|robots| {
            robots
                .iter()
                .find(|r| r.robot == ROBOT)
                .map_or(0, |r| r.last_sequence)
        })
        .unwrap_or(0)
}

/// The frame of the localizer's latest estimate after frame `after`.
pub(super) async fn latest_estimate(client: &MapClient, after: u64) -> Option<u64> {
    let poses = client.read_poses(ROBOT, after + 1, 0).await.ok()?;
    poses
        .iter()
        .filter(|p| p.map == MAP)
        .map(|p| p.frame_sequence)
        .max()
}

/// The distinct tiles under the robot's true positions, and the distance
/// it drove, metres.
pub(super) fn path_tiles(truth: &[TruthSample], tile_size: u32) -> Result<(usize, f64)> {
    let resolution = Resolution::new(RESOLUTION_M)?;
    let size = TileSize::new(tile_size)?;
    let mut tiles: HashSet<TileKey> = HashSet::new();
    let mut distance = 0.0;
    for (i, sample) in truth.iter().enumerate() {
        let cell = resolution.cell_of(sample.pose.x, sample.pose.y)?;
        tiles.insert(size.split(cell).0);
        if i > 0 {
            let before = truth[i - 1].pose;
            distance += (sample.pose.x - before.x).hypot(sample.pose.y - before.y);
        }
    }
    Ok((tiles.len(), distance))
}

#[cfg(test)]
mod tests {
    use deog_grid::Pose2;

    use super::*;

    #[test]
    fn a_path_across_a_tile_edge_crosses_two_tiles() {
        // Tiles of 64 cells of 5 cm: the edge is at 3.2 m.
        let truth: Vec<TruthSample> = [3.0, 3.1, 3.3]
            .iter()
            .enumerate()
            .map(|(i, &x)| TruthSample::new(i as u64 + 1, i as f64, Pose2::new(x, 1.0, 0.0)))
            .collect();
        let (tiles, distance) = path_tiles(&truth, 64).expect("a path");
        assert_eq!(tiles, 2);
        assert!((distance - 0.3).abs() < 1e-9, "{distance}");
        assert_eq!(path_tiles(&[], 64).expect("no path"), (0, 0.0));
    }
}
