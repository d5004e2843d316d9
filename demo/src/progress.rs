//! What the status line says while the robots drive: simulated time,
//! frames, map cells, and each robot's latest position error, with how
//! many frames its localizer is behind. Read from the map server each
//! tick; a read that fails leaves its figure out rather than stopping the
//! demo.

use std::fmt::Write as _;

use deog_robot_client::MapClient;

use crate::commands::MAP;

/// A localizer this many frames behind its robot is said to be behind.
const BEHIND_FRAMES: u64 = 10;

/// What the status line last learnt of one robot's localizer.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Follow {
    /// The frame of the latest estimate read; reading goes on from there.
    cursor: u64,
    /// That estimate's position error, metres, and the filter's flag.
    error: Option<(f64, bool)>,
}

/// The status line's figures, kept from tick to tick.
#[derive(Debug)]
pub(crate) struct Progress {
    robots: Vec<(String, Follow)>,
}

impl Progress {
    /// Nothing learnt yet of `robots`.
    pub fn new<'a>(robots: impl IntoIterator<Item = &'a str>) -> Self {
        Self {
            robots: robots
                .into_iter()
                .map(|name| (name.to_string(), Follow::default()))
                .collect(),
        }
    }

    /// Reads what is new from the map server and says it on one line, at
    /// simulated second `now` of `duration`.
    pub async fn line(&mut self, client: &MapClient, now: f64, duration: f64) -> String {
        let listed = client.robots().await.unwrap_or_default();
        let frames: u64 = listed.iter().map(|r| r.frame_count).sum();
        let cells = client.map_info(MAP).await.ok().map(|info| info.cell_count);
        let mut robots = Vec::with_capacity(self.robots.len());
        for (name, follow) in &mut self.robots {
            let last = listed
                .iter()
                .find(|r| &r.robot == name)
                .map_or(0, |r| r.last_sequence);
            if let Some((sequence, error)) = latest_error(client, name, follow.cursor).await {
                *follow = Follow {
                    cursor: sequence,
                    error: Some(error),
                };
            }
            robots.push((name.as_str(), last, *follow));
        }
        format_line(now, duration, frames, cells, &robots)
    }
}

/// The line from its figures: each robot as its name, the latest frame
/// the server holds of it, and what its localizer last said.
fn format_line(
    now: f64,
    duration: f64,
    frames: u64,
    cells: Option<u64>,
    robots: &[(&str, u64, Follow)],
) -> String {
    let mut line = format!("{now:5.0}/{duration:.0} s");
    // Writing to a String cannot fail.
    let _ = write!(line, " | {frames} frames");
    if let Some(cells) = cells {
        let _ = write!(line, " | map {cells} cells");
    }
    for (robot, last, follow) in robots {
        let _ = write!(line, " | {robot} ");
        match follow.error {
            Some((metres, converged)) => {
                let flag = if converged { "" } else { "?" };
                let _ = write!(line, "{metres:.2} m{flag}");
                let behind = last.saturating_sub(follow.cursor);
                if behind > BEHIND_FRAMES {
                    let _ = write!(line, " ({behind} frames behind)");
                }
            }
            None => line.push('-'),
        }
    }
    line
}

/// The frame and position error of a robot's latest estimate after frame
/// `after`, and whether the filter called itself converged.
async fn latest_error(client: &MapClient, robot: &str, after: u64) -> Option<(u64, (f64, bool))> {
    let poses = client.read_poses(robot, after + 1, 0).await.ok()?;
    let estimate = poses.iter().rev().find(|p| p.map == MAP)?;
    let frame = client
        .read_frames(robot, estimate.frame_sequence, estimate.frame_sequence)
        .await
        .ok()?;
    let truth = frame.first()?.true_pose?;
    let pose = estimate.pose?;
    let metres = (pose.x - truth.x).hypot(pose.y - truth.y);
    Some((estimate.frame_sequence, (metres, estimate.converged)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_names_time_frames_cells_and_each_robots_error() {
        let robots = [
            ("scout-1", 500, Follow::default()),
            (
                "scout-2",
                500,
                Follow {
                    cursor: 495,
                    error: Some((0.034, true)),
                },
            ),
            (
                "scout-3",
                500,
                Follow {
                    cursor: 480,
                    error: Some((2.5, false)),
                },
            ),
        ];
        assert_eq!(
            format_line(61.4, 240.0, 1500, Some(12345), &robots),
            "   61/240 s | 1500 frames | map 12345 cells | scout-1 - | scout-2 0.03 m \
             | scout-3 2.50 m? (20 frames behind)"
        );
    }

    #[test]
    fn a_map_not_yet_there_is_left_out() {
        assert_eq!(
            format_line(0.0, 60.0, 0, None, &[]),
            "    0/60 s | 0 frames"
        );
    }
}
