//! [`UpdateSender`]: batched, pipelined, exactly-once tile updates.
//!
//! Deltas are gathered per tile into a batch; a full batch goes to a
//! background task that keeps one `ApplyUpdates` stream open, sends up to a
//! window of batches ahead of their acknowledgements, and keeps every
//! unacknowledged batch. When the stream breaks (the server restarts, the
//! network drops) it reconnects with backoff and resends them with their
//! original sequence numbers; the server applies each sequence once.

use crate::client::MapClient;
use crate::connect::RetryPolicy;
use crate::convert::encode_delta;
use crate::error::{ClientError, is_transient};
use deog_grid::{TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use std::collections::{HashMap, VecDeque};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio_stream::wrappers::ReceiverStream;

/// How an [`UpdateSender`] batches and pipelines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UpdateSenderConfig {
    /// Tiles per batch before it is sent.
    pub max_batch_tiles: usize,
    /// Batches sent ahead of their acknowledgements; pushing waits beyond it.
    pub window: usize,
}

impl Default for UpdateSenderConfig {
    fn default() -> Self {
        Self {
            max_batch_tiles: 64,
            window: 32,
        }
    }
}

/// What the server has acknowledged so far.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AckState {
    /// Highest acknowledged sequence.
    pub last_acked: u64,
    /// Map version after it.
    pub map_version: u64,
    /// Batches the server applied.
    pub applied: u64,
    /// Batches acknowledged as already applied (resends).
    pub duplicates: u64,
    /// Times the stream was reopened.
    pub reconnects: u64,
    /// Set when the stream failed for good.
    pub failure: Option<String>,
}

/// Sends tile deltas to one map as one client, exactly once.
#[derive(Debug)]
pub struct UpdateSender {
    map: String,
    client_id: String,
    tile_size: TileSize,
    config: UpdateSenderConfig,
    current: Vec<TileDelta>,
    index: HashMap<TileKey, usize>,
    next_sequence: u64,
    inbox: Option<mpsc::Sender<pb::UpdateBatch>>,
    acks: watch::Receiver<AckState>,
    task: Option<JoinHandle<()>>,
}

impl UpdateSender {
    pub(crate) fn start(
        client: MapClient,
        info: pb::MapInfo,
        client_id: String,
        first_sequence: u64,
        config: UpdateSenderConfig,
    ) -> Result<Self, ClientError> {
        let tile_size = TileSize::new(info.tile_size)?;
        let config = UpdateSenderConfig {
            max_batch_tiles: config.max_batch_tiles.max(1),
            window: config.window.max(1),
        };
        let (inbox_tx, inbox_rx) = mpsc::channel(1);
        let (acks_tx, acks_rx) = watch::channel(AckState {
            last_acked: first_sequence - 1,
            ..AckState::default()
        });
        let retry = client.config().retry;
        let task = tokio::spawn(run_stream(client, inbox_rx, acks_tx, config.window, retry));
        Ok(Self {
            map: info.name,
            client_id,
            tile_size,
            config,
            current: Vec::new(),
            index: HashMap::new(),
            next_sequence: first_sequence,
            inbox: Some(inbox_tx),
            acks: acks_rx,
            task: Some(task),
        })
    }

    /// Cells per tile side of the map.
    pub fn tile_size(&self) -> TileSize {
        self.tile_size
    }

    /// The sequence the next batch will carry.
    pub fn next_sequence(&self) -> u64 {
        self.next_sequence
    }

    /// What the server has acknowledged.
    pub fn acks(&self) -> AckState {
        self.acks.borrow().clone()
    }

    /// Adds a tile's deltas to the current batch (summed with any earlier
    /// deltas for the same tile), sending the batch once it is full.
    pub async fn push(&mut self, delta: TileDelta) -> Result<(), ClientError> {
        match self.index.get(&delta.key) {
            Some(&i) => self.current[i].accumulate(&delta)?,
            None => {
                if delta.raw().len() != self.tile_size.area() {
                    return Err(ClientError::Config(format!(
                        "delta for tile ({}, {}) has {} cells; the map's tiles have {}",
                        delta.key.x,
                        delta.key.y,
                        delta.raw().len(),
                        self.tile_size.area()
                    )));
                }
                self.index.insert(delta.key, self.current.len());
                self.current.push(delta);
            }
        }
        if self.current.len() >= self.config.max_batch_tiles {
            self.send_batch().await?;
        }
        Ok(())
    }

    /// Tiles in the batch being filled.
    pub fn pending_tiles(&self) -> usize {
        self.current.len()
    }

    /// Sends the current batch, if it holds anything, without waiting for
    /// its acknowledgement.
    pub async fn send_batch(&mut self) -> Result<(), ClientError> {
        self.send_batch_as(self.next_sequence).await
    }

    /// Sends the current batch under `sequence`, which must not be below
    /// [`UpdateSender::next_sequence`]; later batches follow it. A client
    /// whose batches stand for numbered inputs (the cartographer: a batch
    /// per run of frames, numbered by its last frame) can then resume from
    /// the server's cursor. Sequences may skip numbers; they run from 1 to
    /// `u64::MAX - 1`, as the server takes them.
    pub async fn send_batch_as(&mut self, sequence: u64) -> Result<(), ClientError> {
        if self.current.is_empty() {
            return Ok(());
        }
        if sequence == u64::MAX {
            return Err(ClientError::Config(format!(
                "batch sequence {sequence} (u64::MAX) is not allowed: no later batch could \
                 follow it; sequences run from 1 to u64::MAX - 1"
            )));
        }
        if sequence < self.next_sequence {
            return Err(ClientError::Config(format!(
                "batch sequence {sequence} is below the next free one, {}",
                self.next_sequence
            )));
        }
        self.next_sequence = sequence;
        self.check_failure()?;
        self.index.clear();
        let tiles = std::mem::take(&mut self.current)
            .iter()
            .map(encode_delta)
            .collect();
        let batch = pb::UpdateBatch {
            map: self.map.clone(),
            client_id: self.client_id.clone(),
            sequence: self.next_sequence,
            tiles,
        };
        // Below u64::MAX, checked above.
        self.next_sequence += 1;
        let inbox = self
            .inbox
            .as_ref()
            .ok_or_else(|| ClientError::Updates("the sender is closed".into()))?;
        if inbox.send(batch).await.is_err() {
            self.check_failure()?;
            return Err(ClientError::Updates("the update task ended".into()));
        }
        Ok(())
    }

    /// Sends the current batch and waits until every batch sent is
    /// acknowledged (durable on the server).
    pub async fn flush(&mut self) -> Result<AckState, ClientError> {
        self.send_batch().await?;
        let target = self.next_sequence - 1;
        let state = self
            .acks
            .wait_for(|s| s.last_acked >= target || s.failure.is_some())
            .await
            .map_err(|_| ClientError::Updates("the update task ended".into()))?
            .clone();
        match state.failure {
            Some(failure) => Err(ClientError::Updates(failure)),
            None => Ok(state),
        }
    }

    /// Flushes, then closes the stream.
    pub async fn close(mut self) -> Result<AckState, ClientError> {
        let state = self.flush().await?;
        self.inbox = None;
        if let Some(task) = self.task.take() {
            let _ = task.await;
        }
        Ok(state)
    }

    fn check_failure(&self) -> Result<(), ClientError> {
        match &self.acks.borrow().failure {
            Some(failure) => Err(ClientError::Updates(failure.clone())),
            None => Ok(()),
        }
    }
}

impl Drop for UpdateSender {
    fn drop(&mut self) {
        // Unflushed batches are abandoned with the sender; a restarted client
        // resumes from the server's cursor.
        if let Some(task) = self.task.take() {
            task.abort();
        }
    }
}

async fn run_stream(
    client: MapClient,
    mut inbox: mpsc::Receiver<pb::UpdateBatch>,
    acks: watch::Sender<AckState>,
    window: usize,
    retry: RetryPolicy,
) {
    let mut unacked: VecDeque<pb::UpdateBatch> = VecDeque::new();
    let mut inbox_open = true;
    let mut failures = 0u32;
    let fail = |acks: &watch::Sender<AckState>, why: String| {
        tracing::warn!(%why, "update stream failed");
        acks.send_modify(|s| s.failure = Some(why));
    };
    let mut first = true;
    'connect: loop {
        if !inbox_open && unacked.is_empty() {
            return;
        }
        if !first {
            failures += 1;
            if !retry.allows(failures + 1) {
                fail(
                    &acks,
                    format!("gave up after {failures} failed attempts to reach the map server"),
                );
                return;
            }
            tokio::time::sleep(retry.delay(failures + 1)).await;
            acks.send_modify(|s| s.reconnects += 1);
        }
        first = false;
        let (request_tx, request_rx) = mpsc::channel(window + 1);
        for batch in &unacked {
            // The channel holds a whole window and unacked never exceeds it.
            let _ = request_tx.try_send(batch.clone());
        }
        let mut responses = match client
            .raw()
            .apply_updates(ReceiverStream::new(request_rx))
            .await
        {
            Ok(response) => response.into_inner(),
            Err(status) if is_transient(&status) => {
                tracing::debug!(%status, "cannot open the update stream; retrying");
                continue 'connect;
            }
            Err(status) => {
                fail(&acks, status.to_string());
                return;
            }
        };
        loop {
            tokio::select! {
                batch = inbox.recv(), if inbox_open && unacked.len() < window => match batch {
                    Some(batch) => {
                        unacked.push_back(batch.clone());
                        if request_tx.send(batch).await.is_err() {
                            continue 'connect;
                        }
                    }
                    None => {
                        inbox_open = false;
                        if unacked.is_empty() {
                            return;
                        }
                    }
                },
                message = responses.message() => match message {
                    Ok(Some(ack)) => {
                        failures = 0;
                        while unacked.front().is_some_and(|b| b.sequence <= ack.sequence) {
                            unacked.pop_front();
                        }
                        acks.send_modify(|s| {
                            s.last_acked = s.last_acked.max(ack.sequence);
                            s.map_version = s.map_version.max(ack.map_version);
                            if ack.applied { s.applied += 1 } else { s.duplicates += 1 }
                        });
                        if !inbox_open && unacked.is_empty() {
                            return;
                        }
                    }
                    Ok(None) => continue 'connect,
                    Err(status) if is_transient(&status) => {
                        tracing::debug!(%status, unacked = unacked.len(), "update stream broke; reconnecting");
                        continue 'connect;
                    }
                    Err(status) => {
                        fail(&acks, status.to_string());
                        return;
                    }
                },
            }
        }
    }
}
