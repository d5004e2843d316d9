//! Read streams (GetTiles, ReadFrames, ReadPoses): each runs on a blocking
//! thread while it reads the store, so their number is capped, and the cap
//! is shared so that no client can hold it.
//!
//! A client that opens read streams and never reads them would otherwise
//! hold every place until the stall timeout, reopen them, and keep every
//! other client refused. Two rules keep places for the others:
//! - one connection holds at most its share of the places;
//! - when every place is taken, a newcomer ends the stream that has waited
//!   longest for its client to take anything (a quarter of a second at
//!   least) and takes its place. A stream whose client reads is never
//!   ended for another; that client's streams end only with their data.
//!
//! A stream that ends early says why, after what it had sent: its client
//! never mistakes a cut stream for a whole answer.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::Status;

/// How long a read stream must have waited for its client before a
/// newcomer, finding every place taken, may end it.
const ENDABLE_AFTER: Duration = Duration::from_millis(250);
/// How long a newcomer waits for a place before it is refused.
const PLACE_WAIT: Duration = Duration::from_secs(1);
/// How often a waiting newcomer looks again for a stream it may end.
const PLACE_POLL: Duration = Duration::from_millis(25);

/// How many read streams may run at once, how many of them one connection
/// may hold, and how long one may wait for a client that does not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadStreamLimits {
    /// Read streams at once; a newcomer finding them all taken, none of
    /// them waiting on its client, is refused with RESOURCE_EXHAUSTED.
    pub max_streams: usize,
    /// Read streams one connection may hold at once; one more is refused
    /// with RESOURCE_EXHAUSTED.
    pub max_streams_per_connection: usize,
    /// How long a read stream waits for its client to take the next
    /// message before it ends.
    pub stalled_timeout: Duration,
}

impl Default for ReadStreamLimits {
    fn default() -> Self {
        Self {
            max_streams: 64,
            max_streams_per_connection: 16,
            stalled_timeout: Duration::from_secs(30),
        }
    }
}

/// The places read streams take, and who holds them.
#[derive(Debug)]
pub(crate) struct ReadStreams {
    limits: ReadStreamLimits,
    permits: Arc<Semaphore>,
    holders: Mutex<Holders>,
}

#[derive(Debug, Default)]
struct Holders {
    next_id: u64,
    open: HashMap<u64, Holder>,
}

#[derive(Debug)]
struct Holder {
    connection: Option<SocketAddr>,
    /// Since when the stream has waited for its client, if it is waiting.
    waiting_since: Option<Instant>,
    /// Cancelled to end the stream for a newcomer.
    end: CancellationToken,
}

impl Holders {
    fn held_by(&self, connection: SocketAddr) -> usize {
        self.open
            .values()
            .filter(|h| h.connection == Some(connection))
            .count()
    }

    /// Ends the stream that has waited longest for its client, if one has
    /// waited long enough and is not ending already.
    fn end_longest_waiting(&mut self, now: Instant) -> bool {
        let longest = self
            .open
            .values()
            .filter(|h| !h.end.is_cancelled())
            .filter_map(|h| h.waiting_since.map(|since| (since, h)))
            .filter(|(since, _)| now.duration_since(*since) >= ENDABLE_AFTER)
            .min_by_key(|(since, _)| *since);
        match longest {
            Some((_, holder)) => {
                holder.end.cancel();
                true
            }
            None => false,
        }
    }
}

impl ReadStreams {
    pub(crate) fn new(limits: ReadStreamLimits) -> Self {
        Self {
            limits,
            permits: Arc::new(Semaphore::new(limits.max_streams)),
            holders: Mutex::default(),
        }
    }

    fn holders(&self) -> std::sync::MutexGuard<'_, Holders> {
        // A panic while holding the lock leaves only counts behind.
        self.holders
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A place for a read stream of a client on `connection` (None when
    /// the transport does not say): at once, or after ending a stream
    /// whose client does not read, or RESOURCE_EXHAUSTED after
    /// [`PLACE_WAIT`].
    pub(crate) async fn admit(
        self: &Arc<Self>,
        connection: Option<SocketAddr>,
    ) -> Result<ReadPlace, Status> {
        let deadline = tokio::time::Instant::now() + PLACE_WAIT;
        loop {
            let ended_one = {
                let mut holders = self.holders();
                if let Some(connection) = connection {
                    let held = holders.held_by(connection);
                    if held >= self.limits.max_streams_per_connection {
                        return Err(Status::resource_exhausted(format!(
                            "this connection holds {held} read streams, its share of the map \
                             server's (--max-read-streams-per-connection): read them or end \
                             one first"
                        )));
                    }
                }
                if let Ok(permit) = self.permits.clone().try_acquire_owned() {
                    return Ok(self.register(&mut holders, connection, permit));
                }
                holders.end_longest_waiting(Instant::now())
            };
            if ended_one {
                // Its thread lets the place go as soon as it sees the end.
                return match tokio::time::timeout_at(deadline, self.permits.clone().acquire_owned())
                    .await
                {
                    Ok(Ok(permit)) => Ok(self.register(&mut self.holders(), connection, permit)),
                    _ => Err(self.all_taken()),
                };
            }
            if tokio::time::Instant::now() + PLACE_POLL > deadline {
                return Err(self.all_taken());
            }
            tokio::time::sleep(PLACE_POLL).await;
        }
    }

    fn all_taken(&self) -> Status {
        Status::resource_exhausted(format!(
            "{} read streams are open and being read, the most the map server allows \
             (--max-read-streams): retry when one has ended",
            self.limits.max_streams
        ))
    }

    fn register(
        self: &Arc<Self>,
        holders: &mut Holders,
        connection: Option<SocketAddr>,
        permit: OwnedSemaphorePermit,
    ) -> ReadPlace {
        let id = holders.next_id;
        holders.next_id += 1;
        let end = CancellationToken::new();
        holders.open.insert(
            id,
            Holder {
                connection,
                waiting_since: None,
                end: end.clone(),
            },
        );
        ReadPlace {
            streams: self.clone(),
            id,
            end,
            _permit: permit,
        }
    }

    fn set_waiting(&self, id: u64, since: Option<Instant>) {
        if let Some(holder) = self.holders().open.get_mut(&id) {
            holder.waiting_since = since;
        }
    }
}

/// One read stream's place; let go when dropped.
#[derive(Debug)]
pub(crate) struct ReadPlace {
    streams: Arc<ReadStreams>,
    id: u64,
    end: CancellationToken,
    _permit: OwnedSemaphorePermit,
}

impl Drop for ReadPlace {
    fn drop(&mut self) {
        self.streams.holders().open.remove(&self.id);
    }
}

/// Why a read stream ended before its data did, told after what it sent.
type Ending = Arc<Mutex<Option<Status>>>;

/// What a read stream's producer sends through, on its blocking thread:
/// waits for a slow client up to the stall timeout, or until a newcomer
/// ends the stream, then gives up (false), as for a client gone.
pub(crate) struct ReadSink<T> {
    tx: mpsc::Sender<Result<T, Status>>,
    runtime: tokio::runtime::Handle,
    place: ReadPlace,
    ending: Ending,
}

impl<T> ReadSink<T> {
    /// A sink and the stream its client reads, `buffer` messages apart.
    pub(crate) fn new(place: ReadPlace, buffer: usize) -> (Self, ReadResponse<T>) {
        let (tx, rx) = mpsc::channel(buffer);
        let ending = Ending::default();
        let sink = Self {
            tx,
            runtime: tokio::runtime::Handle::current(),
            place,
            ending: ending.clone(),
        };
        let response = ReadResponse {
            messages: ReceiverStream::new(rx),
            ending,
            finished: false,
        };
        (sink, response)
    }

    /// Sends `item`; false once the client is gone, has not taken a
    /// message for the stall timeout, or the stream was ended for another.
    pub(crate) fn send(&self, item: T) -> bool {
        let item = match self.tx.try_send(Ok(item)) {
            Ok(()) => return true,
            Err(mpsc::error::TrySendError::Closed(_)) => return false,
            Err(mpsc::error::TrySendError::Full(item)) => item,
        };
        let streams = &self.place.streams;
        let since = Instant::now();
        streams.set_waiting(self.place.id, Some(since));
        let stalled_timeout = streams.limits.stalled_timeout;
        let sent = self.runtime.block_on(async {
            tokio::select! {
                sent = tokio::time::timeout(stalled_timeout, self.tx.send(item)) => match sent {
                    Ok(Ok(())) => Ok(true),
                    Ok(Err(_)) => Ok(false),
                    Err(_) => Err(Status::deadline_exceeded(format!(
                        "read stream ended: its client took nothing for {:.1} s \
                         (--stalled-read-timeout-s); read again from where it stopped",
                        stalled_timeout.as_secs_f64()
                    ))),
                },
                () = self.place.end.cancelled() => Err(Status::resource_exhausted(format!(
                    "read stream ended to make room for another reader: every read stream \
                     was in use and its client had taken nothing for {:.1} s; read again \
                     from where it stopped",
                    since.elapsed().as_secs_f64()
                ))),
            }
        });
        streams.set_waiting(self.place.id, None);
        match sent {
            Ok(sent) => sent,
            Err(status) => {
                tracing::debug!(%status, "read stream ended early");
                self.fail(status);
                false
            }
        }
    }

    /// Ends the stream with `status`, after what was sent.
    pub(crate) fn fail(&self, status: Status) {
        let mut ending = self
            .ending
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        ending.get_or_insert(status);
    }
}

/// The stream a read's client receives: the producer's messages, then the
/// reason it ended early, if it did.
pub struct ReadResponse<T> {
    messages: ReceiverStream<Result<T, Status>>,
    ending: Ending,
    finished: bool,
}

impl<T> Stream for ReadResponse<T> {
    type Item = Result<T, Status>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        if self.finished {
            return Poll::Ready(None);
        }
        match Pin::new(&mut self.messages).poll_next(cx) {
            Poll::Ready(None) => {
                self.finished = true;
                // The producer sets the ending before it lets its sender
                // go, so it is there once the channel has closed.
                let ending = self
                    .ending
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .take();
                Poll::Ready(ending.map(Err))
            }
            other => other,
        }
    }
}
