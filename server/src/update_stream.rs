//! One `ApplyUpdates` stream: batches read, checked, handed to the writer
//! and acknowledged in the order they came.
//!
//! The stream is read as fast as the client sends. HTTP/2 (h2) budgets the
//! small DATA frames that sit buffered in the transport unread, and closes
//! the whole connection (GOAWAY `too_many_data_frames`) once they exceed
//! it; a client pipelining one-cell batches, each in a frame of its own,
//! got there within milliseconds while the writer flushed. So the reader
//! takes every message off the transport at once into a queue of its own,
//! bounded in bytes per stream and across the server; only a full queue
//! stops it reading, and the client is then slowed by HTTP/2 flow control.

use crate::error::StoreError;
use crate::service::{MapServer, shutting_down};
use crate::store::Store;
use crate::writer::Ack;
use deog_proto::v1 as pb;
use prost::Message;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc, oneshot};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Status, Streaming};

/// Batches of one stream handed to the writer and not yet acknowledged:
/// as many as the writer takes into one group commit.
const IN_FLIGHT_BATCHES: usize = 512;
/// Bytes of batches one stream may have read and not yet handed to the
/// writer.
pub const STREAM_QUEUE_BYTES: usize = 16 << 20;
/// Bytes of batches all streams together may have read and not yet
/// handed to the writer.
pub const SERVER_QUEUE_BYTES: usize = 256 << 20;
/// What a queued batch costs beyond its encoded size: its decoded
/// structures.
const BATCH_OVERHEAD_BYTES: usize = 256;

/// The server-wide share of queued update bytes.
#[derive(Debug, Clone)]
pub(crate) struct UpdateQueueBudget(Arc<Semaphore>);

impl UpdateQueueBudget {
    pub(crate) fn new() -> Self {
        Self(Arc::new(Semaphore::new(SERVER_QUEUE_BYTES)))
    }
}

/// A message read off the stream, waiting for the writer.
enum Queued {
    /// A batch, with the queue space it holds until the writer has it.
    Batch(pb::UpdateBatch, [OwnedSemaphorePermit; 2]),
    /// The stream could not be read past this point.
    Unreadable(Status),
}

/// A batch handed on, waiting for its acknowledgement.
enum Pending {
    Ack(String, u64, oneshot::Receiver<Result<Ack, StoreError>>),
    Fail(Status),
}

/// Runs one update stream: three tasks (read, submit, acknowledge) joined
/// by bounded queues, so none waits on the next while it could be reading.
/// The returned stream carries the acknowledgements.
pub(crate) fn run<S: Store>(
    server: MapServer<S>,
    inbound: Streaming<pb::UpdateBatch>,
    budget: UpdateQueueBudget,
    reply_buffer: usize,
) -> ReceiverStream<Result<pb::UpdateAck, Status>> {
    // Unbounded as a channel; bounded by the byte permits each batch holds.
    let (queue_tx, queue_rx) = mpsc::unbounded_channel();
    let (pending_tx, pending_rx) = mpsc::channel(IN_FLIGHT_BATCHES);
    let (out_tx, out_rx) = mpsc::channel(reply_buffer);
    tokio::spawn(read(inbound, queue_tx, budget, server.shutdown_token()));
    tokio::spawn(submit(server, queue_rx, pending_tx));
    tokio::spawn(acknowledge(pending_rx, out_tx));
    ReceiverStream::new(out_rx)
}

/// Takes messages off the transport as they come, into the queue, while it
/// has room.
async fn read(
    mut inbound: Streaming<pb::UpdateBatch>,
    queue: mpsc::UnboundedSender<Queued>,
    budget: UpdateQueueBudget,
    shutdown: tokio_util::sync::CancellationToken,
) {
    let stream_budget = Arc::new(Semaphore::new(STREAM_QUEUE_BYTES));
    let mut read = 0u64;
    loop {
        let message = tokio::select! {
            () = shutdown.cancelled() => {
                let _ = queue.send(Queued::Unreadable(shutting_down()));
                return;
            }
            () = queue.closed() => return,
            message = inbound.message() => message,
        };
        let batch = match message {
            Ok(Some(batch)) => batch,
            Ok(None) => return,
            Err(status) => {
                // Ending with OK here would tell the client that
                // everything it sent was taken.
                let status = unreadable_batch(read, &status);
                tracing::debug!(%status, "update stream unreadable");
                let _ = queue.send(Queued::Unreadable(status));
                return;
            }
        };
        read += 1;
        let cost = (batch.encoded_len() + BATCH_OVERHEAD_BYTES).min(STREAM_QUEUE_BYTES) as u32;
        // The stream's own share first: one stream waiting for room holds
        // none of the server's.
        let permits = tokio::select! {
            () = shutdown.cancelled() => {
                let _ = queue.send(Queued::Unreadable(shutting_down()));
                return;
            }
            () = queue.closed() => return,
            permits = async {
                let own = stream_budget.clone().acquire_many_owned(cost).await.ok()?;
                let shared = budget.0.clone().acquire_many_owned(cost).await.ok()?;
                Some([own, shared])
            } => permits,
        };
        let Some(permits) = permits else { return };
        if queue.send(Queued::Batch(batch, permits)).is_err() {
            return;
        }
    }
}

/// Checks each queued batch and hands it to the writer, in order; stops at
/// the first refused.
async fn submit<S: Store>(
    server: MapServer<S>,
    mut queue: mpsc::UnboundedReceiver<Queued>,
    pending: mpsc::Sender<Pending>,
) {
    let stream_broken = Arc::new(AtomicBool::new(false));
    while let Some(queued) = queue.recv().await {
        let (batch, permits) = match queued {
            Queued::Batch(batch, permits) => (batch, permits),
            Queued::Unreadable(status) => {
                let _ = pending.send(Pending::Fail(status)).await;
                return;
            }
        };
        let (client, sequence) = (batch.client_id.clone(), batch.sequence);
        let submitted = match server.check_batch(batch) {
            Ok(mut batch) => {
                batch.stream_broken = stream_broken.clone();
                server.writer().submit_batch(batch).await
            }
            Err(error) => {
                if matches!(error, StoreError::Unavailable(_)) {
                    server.writer().store_unavailable();
                }
                Err(error)
            }
        };
        // The writer holds the batch now, within its own bounds.
        drop(permits);
        let next = match submitted {
            Ok(ack) => Pending::Ack(client, sequence, ack),
            Err(error) => {
                tracing::debug!(%error, "update batch refused");
                Pending::Fail(error.into())
            }
        };
        let failed = matches!(next, Pending::Fail(_));
        if pending.send(next).await.is_err() || failed {
            return;
        }
    }
}

/// Sends the acknowledgements, in the order the batches came; ends the
/// stream with the first failure.
async fn acknowledge(
    mut pending: mpsc::Receiver<Pending>,
    out: mpsc::Sender<Result<pb::UpdateAck, Status>>,
) {
    while let Some(next) = pending.recv().await {
        let reply = match next {
            Pending::Ack(client_id, sequence, ack) => match ack.await {
                Ok(Ok(ack)) => Ok(pb::UpdateAck {
                    client_id,
                    sequence,
                    applied: ack.applied,
                    map_version: ack.map_version,
                }),
                Ok(Err(error)) => Err(error.into()),
                Err(_) => Err(StoreError::ShuttingDown.into()),
            },
            Pending::Fail(status) => Err(status),
        };
        let failed = reply.is_err();
        if out.send(reply).await.is_err() || failed {
            return;
        }
    }
}

/// The status that ends an update stream whose next batch (after `read`
/// good ones) the transport could not decode. Too large a message is
/// RESOURCE_EXHAUSTED, as the server's own size check answers; any other
/// failure keeps the transport's code.
fn unreadable_batch(read: u64, status: &Status) -> Status {
    let code = match status.code() {
        tonic::Code::OutOfRange => tonic::Code::ResourceExhausted,
        code => code,
    };
    Status::new(
        code,
        format!(
            "update batch {} of this stream could not be read ({read} read before it; \
             none after it is applied): {}",
            read.saturating_add(1),
            status.message()
        ),
    )
}
