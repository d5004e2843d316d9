//! What the status line says while the robots drive: simulated time,
//! frames, map cells, and each robot's latest position error, with how
//! far its localizer is behind: the simulated seconds between its robot's
//! clock (or its newest frame, once it sends no more) and the frame of
//! its latest estimate. Read from the map server
//! each tick; a read that fails leaves its figure out rather than stopping
//! the demo. The largest lag seen goes in report.json (`max_lag_s`).

use std::fmt::Write as _;

use deog_robot_client::MapClient;

use crate::commands::MAP;

/// What the status line last learnt of one robot's localizer.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Follow {
    /// The frame of the latest estimate read; reading goes on from there.
    cursor: u64,
    /// That frame's simulated time, seconds.
    frame_time_s: f64,
    /// That estimate's position error, metres, and the filter's flag.
    error: Option<(f64, bool)>,
    /// The robot's newest stored frame: its sequence and simulated time.
    newest_frame: (u64, f64),
    /// Simulated seconds the localizer was behind its robot at this tick.
    lag_s: Option<f64>,
    /// The largest lag seen so far.
    max_lag_s: Option<f64>,
}

/// The status line's figures, kept from tick to tick.
#[derive(Debug)]
pub(crate) struct Progress {
    robots: Vec<(String, Follow)>,
}

/// A robot's name and its simulated clock, seconds, as the simulator
/// last told it.
pub(crate) type RobotClock<'a> = (&'a str, f64);

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
    /// simulated second `now` of `duration`, with each robot's clock from
    /// `clocks`.
    pub async fn line(
        &mut self,
        client: &MapClient,
        now: f64,
        duration: f64,
        clocks: &[RobotClock<'_>],
    ) -> String {
        let listed = client.robots().await.unwrap_or_default();
        let frames: u64 = listed.iter().map(|r| r.frame_count).sum();
        let cells = client.map_info(MAP).await.ok().map(|info| info.cell_count);
        let mut robots = Vec::with_capacity(self.robots.len());
        for (name, follow) in &mut self.robots {
            if let Some(latest) = latest_error(client, name, follow.cursor).await {
                follow.cursor = latest.sequence;
                follow.frame_time_s = latest.time_s;
                follow.error = Some((latest.metres, latest.converged));
            }
            let newest = listed
                .iter()
                .find(|r| &r.robot == name)
                .map_or(0, |r| r.last_sequence);
            if newest > follow.newest_frame.0
                && let Ok(frames) = client.read_frames(name, newest, newest).await
                && let Some(frame) = frames.first()
            {
                follow.newest_frame = (frame.sequence, frame.time_s);
            }
            let clock = clocks.iter().find(|(robot, _)| robot == name);
            if let (Some((_, clock)), Some(_)) = (clock, follow.error) {
                let newest = (follow.newest_frame.0 > 0).then_some(follow.newest_frame.1);
                follow.note_lag(lag_s(*clock, newest, follow.frame_time_s));
            }
            robots.push((name.as_str(), *follow));
        }
        format_line(now, duration, frames, cells, &robots)
    }

    /// Each robot's largest lag, seconds; `None` for one whose localizer
    /// never published an estimate.
    pub fn max_lags(&self) -> impl Iterator<Item = (&str, Option<f64>)> {
        self.robots
            .iter()
            .map(|(name, follow)| (name.as_str(), follow.max_lag_s))
    }
}

/// Simulated seconds between the robot's `clock` and the frame of the
/// latest estimate (at `estimate_time_s`); a robot that has stopped sending
/// frames (its `newest_frame_s` behind its clock) leaves nothing to be
/// behind on, however long the simulator runs on.
fn lag_s(clock: f64, newest_frame_s: Option<f64>, estimate_time_s: f64) -> f64 {
    newest_frame_s.map_or(clock, |newest| clock.min(newest)) - estimate_time_s
}

impl Follow {
    /// Records the lag at this tick (never below zero: the robot's clock
    /// is read a moment before the estimate may be).
    fn note_lag(&mut self, lag_s: f64) {
        let lag_s = lag_s.max(0.0);
        self.lag_s = Some(lag_s);
        self.max_lag_s = Some(self.max_lag_s.map_or(lag_s, |m| m.max(lag_s)));
    }
}

/// The line from its figures: each robot as its name and what its
/// localizer last said.
fn format_line(
    now: f64,
    duration: f64,
    frames: u64,
    cells: Option<u64>,
    robots: &[(&str, Follow)],
) -> String {
    let mut line = format!("{now:5.0}/{duration:.0} s");
    // Writing to a String cannot fail.
    let _ = write!(line, " | {frames} frames");
    if let Some(cells) = cells {
        let _ = write!(line, " | map {cells} cells");
    }
    for (robot, follow) in robots {
        let _ = write!(line, " | {robot} ");
        match follow.error {
            Some((metres, converged)) => {
                let flag = if converged { "" } else { "?" };
                let _ = write!(line, "{metres:.2} m{flag}");
                if let Some(lag) = follow.lag_s {
                    let _ = write!(line, " lag {lag:.1} s");
                }
            }
            None => line.push('-'),
        }
    }
    line
}

/// A robot's latest estimate, judged against its frame's true pose.
struct Latest {
    /// The estimate's frame.
    sequence: u64,
    /// That frame's simulated time, seconds.
    time_s: f64,
    /// The position error, metres.
    metres: f64,
    /// Whether the filter called itself converged.
    converged: bool,
}

/// A robot's latest estimate after frame `after`.
async fn latest_error(client: &MapClient, robot: &str, after: u64) -> Option<Latest> {
    let poses = client.read_poses(robot, after + 1, 0).await.ok()?;
    let estimate = poses.iter().rev().find(|p| p.map == MAP)?;
    let frame = client
        .read_frames(robot, estimate.frame_sequence, estimate.frame_sequence)
        .await
        .ok()?;
    let frame = frame.first()?;
    let truth = frame.true_pose?;
    let pose = estimate.pose?;
    Some(Latest {
        sequence: estimate.frame_sequence,
        time_s: frame.time_s,
        metres: (pose.x - truth.x).hypot(pose.y - truth.y),
        converged: estimate.converged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lag_runs_to_the_clock_or_to_the_last_frame_of_a_robot_that_stopped() {
        // Driving: frames come up to the clock.
        assert!((lag_s(100.0, Some(99.95), 99.2) - 0.75).abs() < 1e-9);
        assert!((lag_s(100.0, None, 99.2) - 0.8).abs() < 1e-9);
        // Stopped at 240.3 s, the simulator at 241.2 s: the localizer
        // has estimated the last frame.
        assert!(lag_s(241.2, Some(240.3), 240.3).abs() < 1e-9);
        assert!((lag_s(241.2, Some(240.3), 239.8) - 0.5).abs() < 1e-9);
    }

    #[test]
    fn the_line_names_time_frames_cells_and_each_robots_error_and_lag() {
        let mut behind = Follow {
            cursor: 480,
            frame_time_s: 48.0,
            error: Some((2.5, false)),
            ..Follow::default()
        };
        behind.note_lag(1.3);
        let robots = [
            ("scout-1", Follow::default()),
            (
                "scout-2",
                Follow {
                    cursor: 495,
                    error: Some((0.034, true)),
                    lag_s: Some(0.0),
                    ..Follow::default()
                },
            ),
            ("scout-3", behind),
        ];
        assert_eq!(
            format_line(61.4, 240.0, 1500, Some(12345), &robots),
            "   61/240 s | 1500 frames | map 12345 cells | scout-1 - | scout-2 0.03 m lag 0.0 s \
             | scout-3 2.50 m? lag 1.3 s"
        );
    }

    #[test]
    fn the_largest_lag_is_kept() {
        let mut follow = Follow::default();
        for lag in [0.2, 3.5, 0.1, -0.05] {
            follow.note_lag(lag);
        }
        assert_eq!(follow.lag_s, Some(0.0));
        assert_eq!(follow.max_lag_s, Some(3.5));
    }

    #[test]
    fn a_map_not_yet_there_is_left_out() {
        assert_eq!(
            format_line(0.0, 60.0, 0, None, &[]),
            "    0/60 s | 0 frames"
        );
    }
}
