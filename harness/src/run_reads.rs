//! A run read back from the map server for judging: the map, where the
//! robots started, and each robot's true poses (or, for a recording, its
//! reference poses) beside its estimates.

use anyhow::{Context, Result};
use deog_evaluation::localization::{EstimateSample, TruthSample};
use deog_grid::TileMap;

use crate::Progress;
use deog_robot_client::MapClient;
use deog_robot_client::convert::pose_from_wire;
use deog_world::Point2;

/// Every stored tile of map `name`, as a tile map with the map's settings,
/// its progress shown.
pub async fn read_map(client: &MapClient, name: &str) -> Result<TileMap> {
    let progress = Progress::new(format!("reading map {name}"), "tiles", 0);
    let (_, map) = client
        .download_with_progress(name, &mut |read, total| {
            progress.set_total(total);
            progress.set_done(read);
        })
        .await
        .with_context(|| format!("reading map {name}"))?;
    progress.finish();
    Ok(map)
}

/// Where each robot whose frames the server holds started: the true pose
/// of its first frame. Robots whose first frame has no true pose (frames
/// imported with odometry only) give none; with no seed at all the whole
/// free space of the world counts as reachable.
pub async fn robot_starts(client: &MapClient) -> Result<Vec<Point2>> {
    let robots = client
        .robots()
        .await
        .context("listing the robots whose frames the server holds")?;
    let mut seeds = Vec::new();
    for robot in robots {
        let first = client
            .read_frames(&robot.robot, robot.first_sequence, robot.first_sequence)
            .await
            .with_context(|| format!("reading the first frame of robot {}", robot.robot))?;
        match first.first().and_then(|f| f.true_pose.or(f.reference_pose)) {
            Some(p) => seeds.push(Point2::new(p.x, p.y)),
            None => {
                tracing::warn!(robot = %robot.robot, "first frame has no true pose: not a seed")
            }
        }
    }
    Ok(seeds)
}

/// One robot's true poses and estimates, as the evaluation takes them.
#[derive(Debug, Clone, Default)]
pub struct RobotSamples {
    /// The robot.
    pub name: String,
    /// Its frames that carry a true pose.
    pub truth: Vec<TruthSample>,
    /// Its localizer's estimates.
    pub estimates: Vec<EstimateSample>,
}

/// A robot's frames with a true pose and its estimates (on `map`, when
/// given) for frames `from..=to` (0 = open).
pub async fn read_robot(
    client: &MapClient,
    name: &str,
    map: Option<&str>,
    from: u64,
    to: u64,
) -> Result<RobotSamples> {
    let frames = client
        .read_frames(name, from, to)
        .await
        .with_context(|| format!("reading the frames of robot {name}"))?;
    let poses = client
        .read_poses(name, from, to)
        .await
        .with_context(|| format!("reading the pose estimates of robot {name}"))?;
    // A simulator's true pose where there is one; else a recording's
    // reference pose (a corrected log's), the best truth a real robot has.
    let truth: Vec<TruthSample> = frames
        .iter()
        .filter_map(|f| {
            f.true_pose.or(f.reference_pose).map(|p| {
                TruthSample::new(f.sequence, f.time_s, pose_from_wire(p))
                    .with_odometry(f.odometry.map(pose_from_wire))
            })
        })
        .collect();
    let by_reference = frames
        .iter()
        .filter(|f| f.true_pose.is_none() && f.reference_pose.is_some())
        .count();
    if by_reference > 0 {
        tracing::info!(
            robot = name,
            frames = by_reference,
            "frames judged against their reference pose (no true pose)"
        );
    }
    if truth.len() < frames.len() {
        tracing::info!(
            robot = name,
            skipped = frames.len() - truth.len(),
            "frames with neither a true nor a reference pose skipped"
        );
    }
    let mut maps: Vec<&str> = Vec::new();
    let mut estimates = Vec::with_capacity(poses.len());
    for estimate in &poses {
        if map.is_some_and(|m| m != estimate.map) {
            continue;
        }
        if !maps.contains(&estimate.map.as_str()) {
            maps.push(&estimate.map);
        }
        let p = estimate.pose.with_context(|| {
            format!(
                "the estimate of robot {name} for frame {} has no pose",
                estimate.frame_sequence
            )
        })?;
        estimates.push(EstimateSample {
            sequence: estimate.frame_sequence,
            pose: pose_from_wire(p),
            filter_converged: estimate.converged,
        });
    }
    if maps.len() > 1 {
        tracing::warn!(
            robot = name,
            maps = maps.join(", "),
            "estimates on several maps are judged together; --map picks one"
        );
    }
    Ok(RobotSamples {
        name: name.to_string(),
        truth,
        estimates,
    })
}
