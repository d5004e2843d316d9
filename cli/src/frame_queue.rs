//! A robot's frame stream read into a queue as fast as it comes, so a
//! follower (`deog map`, `deog localize`) can take whatever has arrived at
//! once, and stop when the stream ends or goes quiet.

use std::collections::VecDeque;
use std::time::Duration;

use anyhow::{Context, Result};
use deog_harness::progress::{Progress, ProgressMode};
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;

/// Frames read ahead at most.
const QUEUE_CAPACITY: usize = 1024;

/// Times in a row a broken frame stream is opened again before the
/// follower gives up.
const REOPEN_TRIES: u32 = 10;

/// The pause before opening a broken stream again, times the failures in
/// a row.
const REOPEN_PAUSE: Duration = Duration::from_millis(500);

/// Frames read ahead from a `SubscribeFrames` stream.
pub(crate) struct FrameQueue {
    /// What the server held of the robot's frames when following began.
    held: Option<pb::RobotFrames>,
    frames: tokio::sync::mpsc::Receiver<pb::SonarFrame>,
    reader: Option<tokio::task::JoinHandle<Result<()>>>,
    idle: Option<Duration>,
}

impl FrameQueue {
    /// Follows `robot`'s frames from sequence `from`, saying whose frames
    /// it waits for (and what the server holds of them), and again when the
    /// first one comes; with `idle_exit_s` > 0, [`Self::next`] ends once no
    /// frame has come for that long.
    pub(crate) async fn follow(
        client: &MapClient,
        robot: &str,
        from: u64,
        idle_exit_s: f64,
    ) -> Result<Self> {
        let held = client
            .robots()
            .await
            .ok()
            .and_then(|robots| robots.into_iter().find(|r| r.robot == robot));
        // Sequence 0 asks for everything: frames are numbered from 1.
        let start = if from == 0 {
            "its first frame".to_string()
        } else {
            format!("sequence {from}")
        };
        match &held {
            Some(r) => tracing::info!(
                "waiting for frames of robot {robot} from {start} (the server holds {} of them, {}..={})",
                r.frame_count,
                r.first_sequence,
                r.last_sequence
            ),
            None => tracing::info!(
                "waiting for frames of robot {robot} from {start}: it has published none yet"
            ),
        }
        let stream = client
            .subscribe_frames(robot, from)
            .await
            .with_context(|| format!("following the frames of robot {robot}"))?;
        let mut queue = Self::spawn(client.clone(), stream, robot.to_string(), idle_exit_s);
        queue.held = held;
        Ok(queue)
    }

    /// The progress of a replay of stored frames from `from` to `to` (0:
    /// the last stored), counted by sequence: shown when the follower ends
    /// by itself (`to` or `idle_exit_s` set), hidden when it follows live
    /// frames until stopped.
    pub(crate) fn replay_progress(
        &self,
        what: &str,
        from: u64,
        to: u64,
        idle_exit_s: f64,
    ) -> ReplayProgress {
        let (first, last) = self
            .held
            .as_ref()
            .map_or((0, 0), |r| (r.first_sequence, r.last_sequence));
        let first = from.max(first).max(1);
        let end = match (to, last) {
            (0, last) => last,
            (to, 0) => to,
            (to, last) => to.min(last),
        };
        let total = if end >= first { end - first + 1 } else { 0 };
        let mode = if to > 0 || idle_exit_s > 0.0 {
            ProgressMode::for_stderr()
        } else {
            ProgressMode::Hidden
        };
        ReplayProgress {
            progress: Progress::with_mode(what, "frames", total, mode),
            first,
        }
    }

    /// Starts reading `stream` of `robot`'s frames. A stream that breaks
    /// (the connection dropped, the server restarted) is opened again from
    /// the frame after the last one read, with a log line, up to
    /// [`REOPEN_TRIES`] times in a row: a follower is not lost because its
    /// connection was.
    fn spawn(
        client: MapClient,
        mut stream: tonic::Streaming<pb::SonarFrame>,
        robot: String,
        idle_exit_s: f64,
    ) -> Self {
        let (tx, frames) = tokio::sync::mpsc::channel(QUEUE_CAPACITY);
        let reader = tokio::spawn(async move {
            let mut last: Option<u64> = None;
            let mut failures = 0u32;
            loop {
                match stream.message().await {
                    Ok(Some(frame)) => {
                        if last.is_none() {
                            tracing::info!(
                                "first frame of robot {robot} arrived: sequence {}",
                                frame.sequence
                            );
                        }
                        failures = 0;
                        // A reopened stream may repeat what was read.
                        if last.is_some_and(|l| frame.sequence <= l) {
                            continue;
                        }
                        last = Some(frame.sequence);
                        if tx.send(frame).await.is_err() {
                            return Ok(());
                        }
                    }
                    Ok(None) => return Ok(()),
                    Err(status) => {
                        let from = last.map_or(0, |l| l + 1);
                        tracing::warn!(
                            robot = %robot,
                            from,
                            error = %status,
                            "the frame stream broke; opening it again"
                        );
                        loop {
                            failures += 1;
                            if failures > REOPEN_TRIES {
                                return Err(anyhow::Error::new(status).context(format!(
                                    "the frame stream of robot {robot} broke and could not be opened again in {REOPEN_TRIES} tries"
                                )));
                            }
                            tokio::time::sleep(REOPEN_PAUSE * failures).await;
                            match client.subscribe_frames(&robot, from).await {
                                Ok(reopened) => {
                                    tracing::info!(robot = %robot, from, "the frame stream is open again");
                                    stream = reopened;
                                    break;
                                }
                                Err(e) => tracing::warn!(
                                    robot = %robot,
                                    error = %e,
                                    "the frame stream could not be opened again yet"
                                ),
                            }
                        }
                    }
                }
            }
        });
        Self {
            held: None,
            frames,
            reader: Some(reader),
            idle: (idle_exit_s > 0.0).then(|| Duration::from_secs_f64(idle_exit_s)),
        }
    }

    /// The next frame; `None` when the stream has ended or no frame came
    /// within the idle time; the stream's error if it failed.
    pub(crate) async fn next(&mut self) -> Result<Option<pb::SonarFrame>> {
        let frame = match self.idle {
            Some(idle) => match tokio::time::timeout(idle, self.frames.recv()).await {
                Ok(frame) => frame,
                Err(_) => {
                    tracing::info!("no frame for {:.1} s; stopping", idle.as_secs_f64());
                    return Ok(None);
                }
            },
            None => self.frames.recv().await,
        };
        if frame.is_none()
            && let Some(reader) = self.reader.take()
        {
            reader.await.context("the frame reader panicked")??;
        }
        Ok(frame)
    }

    /// A frame that has already arrived, if any.
    pub(crate) fn try_next(&mut self) -> Option<pb::SonarFrame> {
        self.frames.try_recv().ok()
    }

    /// The frames that have arrived, oldest first, once the reader has
    /// caught up with what the connection already holds: the runtime is
    /// given a few turns until one brings nothing new. At most the
    /// queue's capacity.
    pub(crate) async fn ready(&mut self) -> Vec<pb::SonarFrame> {
        const QUIET_TURNS: usize = 3;
        let mut frames = Vec::new();
        let mut quiet = 0;
        while quiet < QUIET_TURNS && frames.len() < QUEUE_CAPACITY {
            tokio::task::yield_now().await;
            let before = frames.len();
            while let Ok(frame) = self.frames.try_recv() {
                frames.push(frame);
            }
            quiet = if frames.len() == before { quiet + 1 } else { 0 };
        }
        frames
    }
}

/// A replay's progress, by frame sequence.
pub(crate) struct ReplayProgress {
    progress: Progress,
    /// The first sequence of the replay.
    first: u64,
}

impl ReplayProgress {
    /// Frames up to `sequence` are done.
    pub(crate) fn reached(&self, sequence: u64) {
        self.progress
            .set_done((sequence + 1).saturating_sub(self.first));
    }

    /// The replay is over.
    pub(crate) fn finish(&self) {
        self.progress.finish();
    }
}

/// Frames kept waiting at most while catching up (at 10 a second, 100 s of
/// them); older ones are skipped.
const MOST_PENDING: usize = 1024;

/// A follower's rule for frames that waited while it worked: correct with
/// the newest within `max_skip_s` of the one in hand (the odometry carries
/// the particles over those skipped); keep the rest for the next turn.
pub(crate) struct CatchUp {
    pending: VecDeque<pb::SonarFrame>,
    max_skip_s: f64,
    skipped: u64,
}

impl CatchUp {
    pub(crate) fn new(max_skip_s: f64) -> Self {
        Self {
            pending: VecDeque::new(),
            max_skip_s,
            skipped: 0,
        }
    }

    /// Keeps `frames` (which came after those kept) for later turns.
    pub(crate) fn hold(&mut self, frames: Vec<pb::SonarFrame>) {
        self.pending.extend(frames);
    }

    /// The oldest frame kept from an earlier turn.
    pub(crate) fn next_waiting(&mut self) -> Option<pb::SonarFrame> {
        self.pending.pop_front()
    }

    /// Takes `waiting` behind the kept frames and returns the frame to use
    /// in place of `frame`: the newest within reach, or with `first` (a
    /// filter that has seen no frame has no odometry to carry) the newest
    /// of all; beside it the newest frame passed over, if any. A follower
    /// far slower than its robot keeps only the newest [`MOST_PENDING`].
    pub(crate) fn newest_within_reach(
        &mut self,
        mut frame: pb::SonarFrame,
        waiting: Vec<pb::SonarFrame>,
        first: bool,
    ) -> (pb::SonarFrame, Option<pb::SonarFrame>) {
        self.pending.extend(waiting);
        let reach = if first {
            f64::INFINITY
        } else {
            frame.time_s + self.max_skip_s
        };
        let mut passed = None;
        while self
            .pending
            .front()
            .is_some_and(|next| next.time_s <= reach)
        {
            if let Some(next) = self.pending.pop_front() {
                passed = Some(std::mem::replace(&mut frame, next));
                self.skipped += 1;
            }
        }
        while self.pending.len() > MOST_PENDING {
            self.pending.pop_front();
            self.skipped += 1;
        }
        (frame, passed)
    }

    /// Frames passed over so far.
    pub(crate) fn skipped(&self) -> u64 {
        self.skipped
    }
}

impl Drop for FrameQueue {
    fn drop(&mut self) {
        if let Some(reader) = &self.reader {
            reader.abort();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(sequence: u64) -> pb::SonarFrame {
        pb::SonarFrame {
            sequence,
            time_s: sequence as f64 * 0.1,
            ..Default::default()
        }
    }

    #[test]
    fn catching_up_skips_at_most_the_reach_and_keeps_the_rest() {
        let mut catch_up = CatchUp::new(1.0);
        // The first frame goes straight to the newest.
        let waiting: Vec<_> = (2..=40).map(frame).collect();
        let (newest, passed) = catch_up.newest_within_reach(frame(1), waiting, true);
        assert_eq!(newest.sequence, 40);
        assert_eq!(passed.map(|f| f.sequence), Some(39));
        assert_eq!(catch_up.skipped(), 39);
        // Later, at most a second (10 frames) beyond the one in hand.
        let waiting: Vec<_> = (42..=70).map(frame).collect();
        let (newest, passed) = catch_up.newest_within_reach(frame(41), waiting, false);
        assert_eq!(newest.sequence, 51);
        assert_eq!(passed.map(|f| f.sequence), Some(50));
        assert_eq!(catch_up.next_waiting().map(|f| f.sequence), Some(52));
        assert_eq!(catch_up.skipped(), 49);
        // Nothing waiting: the frame in hand, nothing passed over.
        let (newest, passed) = CatchUp::new(1.0).newest_within_reach(frame(5), Vec::new(), false);
        assert_eq!((newest.sequence, passed), (5, None));
    }
}
