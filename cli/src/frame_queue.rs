//! A robot's frame stream read into a queue as fast as it comes, so a
//! follower (`deog map`, `deog localize`) can take whatever has arrived at
//! once, and stop when the stream ends or goes quiet.

use std::time::Duration;

use anyhow::{Context, Result};
use deog_proto::v1 as pb;

/// Frames read ahead at most.
const QUEUE_CAPACITY: usize = 1024;

/// Frames read ahead from a `SubscribeFrames` stream.
pub(crate) struct FrameQueue {
    frames: tokio::sync::mpsc::Receiver<pb::SonarFrame>,
    reader: Option<tokio::task::JoinHandle<Result<()>>>,
    idle: Option<Duration>,
}

impl FrameQueue {
    /// Starts reading `stream`; with `idle_exit_s` > 0, [`Self::next`]
    /// ends once no frame has come for that long.
    pub(crate) fn spawn(mut stream: tonic::Streaming<pb::SonarFrame>, idle_exit_s: f64) -> Self {
        let (tx, frames) = tokio::sync::mpsc::channel(QUEUE_CAPACITY);
        let reader = tokio::spawn(async move {
            while let Some(frame) = stream.message().await.context("the frame stream failed")? {
                if tx.send(frame).await.is_err() {
                    break;
                }
            }
            Ok(())
        });
        Self {
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

impl Drop for FrameQueue {
    fn drop(&mut self) {
        if let Some(reader) = &self.reader {
            reader.abort();
        }
    }
}
