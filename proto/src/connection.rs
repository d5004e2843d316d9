//! The connections a deog server (the map server, the simulator) accepts:
//! bounded in number, given a time to start speaking, paced when the
//! process runs out of file descriptors, and cut when a shutdown's grace
//! period runs out.
//!
//! tonic stops accepting at shutdown but lets open connections run until
//! their clients leave; a client holding a stream open would keep the
//! server's tasks, and so the store, alive after `serve` returns. Each
//! connection here fails its reads and writes once `cut` is cancelled, which
//! makes hyper drop it. hyper waits for a connection's first bytes for ever,
//! so a connection that sends none within the handshake timeout fails the
//! same way; and an accept loop that retried at once on EMFILE would spin a
//! core while every new client times out, so it waits, longer each time.
//!
//! A connection has spoken once it has sent [`SPOKEN_BYTES`] (an HTTP/2
//! preface is 24 bytes, a TLS hello more). Connections that have not yet
//! spoken do not hold the limit against a newcomer: with every place
//! taken, the one that has been silent longest is closed for it. Without
//! that, a client opening a thousand sockets and sending nothing kept
//! every fresh client out for the whole handshake timeout, and could do
//! it again at once.

use std::collections::VecDeque;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio::time::Sleep;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::{CancellationToken, WaitForCancellationFutureOwned};
use tonic::transport::server::{Connected, TcpConnectInfo};

/// Time between keepalive pings on a connection, and how long one may go
/// unanswered before the connection is dropped: a peer that vanished
/// without closing (a robot that lost power) holds its connection
/// otherwise.
pub const KEEPALIVE_INTERVAL: Duration = Duration::from_secs(30);
/// See [`KEEPALIVE_INTERVAL`].
pub const KEEPALIVE_TIMEOUT: Duration = Duration::from_secs(20);

/// HTTP/2 flow-control windows the servers announce: what one stream, and
/// one connection's streams together, may send ahead of what the server
/// has read. h2 closes a connection whose small DATA frames sitting unread
/// cost more than half the connection window (each counted as 256 bytes),
/// so a stream's window must hold few enough of them: 256 KiB of 30-byte
/// frames (a one-cell update batch) costs under 2 MiB of the 4 MiB budget,
/// however late the server's reader runs, where hyper's default of 1 MiB
/// for both got a pipelining client's connection closed within
/// milliseconds.
pub const STREAM_WINDOW_BYTES: u32 = 256 << 10;
/// See [`STREAM_WINDOW_BYTES`].
pub const CONNECTION_WINDOW_BYTES: u32 = 8 << 20;

/// The transport both servers build on: at most `max_streams` calls open
/// per connection, keepalive pings, the flow-control windows above, and TLS
/// with `tls` when given. Made first, so that a bad certificate or key
/// starts nothing.
pub fn server_builder(
    max_streams: u32,
    tls: Option<&crate::tls::TlsIdentity>,
) -> Result<tonic::transport::Server, crate::tls::TlsError> {
    let builder = tonic::transport::Server::builder()
        .max_concurrent_streams(Some(max_streams))
        .initial_stream_window_size(Some(STREAM_WINDOW_BYTES))
        .initial_connection_window_size(Some(CONNECTION_WINDOW_BYTES))
        .http2_keepalive_interval(Some(KEEPALIVE_INTERVAL))
        .http2_keepalive_timeout(Some(KEEPALIVE_TIMEOUT));
    match tls {
        None => Ok(builder),
        Some(identity) => builder
            .tls_config(identity.server_config()?)
            .map_err(|e| crate::tls::TlsError::Setup(crate::tls::error_chain(&e))),
    }
}

/// First and longest wait after an accept failed for want of resources.
const ACCEPT_BACKOFF: (Duration, Duration) = (Duration::from_millis(50), Duration::from_secs(1));

/// How many connections the server holds and how long a new one may stay
/// silent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnectionLimits {
    /// Connections held at once; one more is closed as soon as it is
    /// accepted.
    pub max_connections: usize,
    /// Time a new connection has to send its first bytes (the HTTP/2
    /// preface, or a TLS hello) before it is closed.
    pub handshake_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 1024,
            handshake_timeout: Duration::from_secs(10),
        }
    }
}

/// Bytes a connection must send before it counts as speaking: an HTTP/2
/// client preface's length (a TLS client hello is longer).
pub const SPOKEN_BYTES: usize = 24;

/// A connection's place, shared between it and the accept loop: the loop
/// takes it from a silent connection it closes and gives it to the
/// newcomer at once (a newcomer waiting for the closed connection's task
/// to let go lost the place to connections arriving meanwhile).
type Place = Arc<Mutex<Option<OwnedSemaphorePermit>>>;

/// A connection that has not yet spoken, as the accept loop sees it: the
/// token that closes it alone, whether it has since spoken (or gone), and
/// its place.
struct Silent {
    cut: CancellationToken,
    done: Arc<AtomicBool>,
    place: Place,
}

/// The connections that have not yet spoken, oldest first. Entries of
/// those that have since spoken or gone are dropped as they are met.
#[derive(Default)]
struct SilentQueue {
    queue: Mutex<VecDeque<Silent>>,
}

impl SilentQueue {
    fn push(&self, silent: Silent, most: usize) {
        let mut queue = lock(&self.queue);
        if queue.len() >= most {
            queue.retain(|s| !s.done.load(Ordering::Acquire));
        }
        queue.push_back(silent);
    }

    /// Closes the connection silent longest and returns its place; `None`
    /// when no connection is silent.
    fn close_oldest(&self) -> Option<OwnedSemaphorePermit> {
        let mut queue = lock(&self.queue);
        while let Some(silent) = queue.pop_front() {
            if !silent.done.swap(true, Ordering::AcqRel) {
                silent.cut.cancel();
                if let Some(place) = lock(&silent.place).take() {
                    return Some(place);
                }
            }
        }
        None
    }
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|e| e.into_inner())
}

/// A TCP connection that errors once its token is cancelled.
/// It also errors if it has not spoken ([`SPOKEN_BYTES`]) within the
/// handshake timeout, and holds one of the server's connection places
/// until it goes or the accept loop takes it back.
pub struct CuttableStream {
    inner: TcpStream,
    cut: Pin<Box<WaitForCancellationFutureOwned>>,
    /// Until it has spoken: when the connection gives up on it, the bytes
    /// read so far, and its flag in the accept loop's [`SilentQueue`].
    handshake: Option<Handshake>,
    place: Place,
}

struct Handshake {
    deadline: Pin<Box<Sleep>>,
    read: usize,
    done: Arc<AtomicBool>,
}

impl CuttableStream {
    fn new(
        inner: TcpStream,
        cut: CancellationToken,
        handshake_timeout: Duration,
        place: Place,
        done: Arc<AtomicBool>,
    ) -> Self {
        Self {
            inner,
            cut: Box::pin(cut.cancelled_owned()),
            handshake: Some(Handshake {
                deadline: Box::pin(tokio::time::sleep(handshake_timeout)),
                read: 0,
                done,
            }),
            place,
        }
    }

    /// Ready with an error once cut; registers the waker otherwise.
    fn poll_cut(&mut self, cx: &mut Context<'_>) -> Poll<io::Error> {
        self.cut.as_mut().poll(cx).map(|()| {
            io::Error::new(
                io::ErrorKind::ConnectionAborted,
                "the server closed the connection (shutting down, or its place given to a newcomer)",
            )
        })
    }
}

use std::future::Future as _;

impl AsyncRead for CuttableStream {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        if let Poll::Ready(error) = this.poll_cut(cx) {
            return Poll::Ready(Err(error));
        }
        if let Some(handshake) = &mut this.handshake
            && handshake.deadline.as_mut().poll(cx).is_ready()
        {
            return Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the connection did not speak within the handshake timeout",
            )));
        }
        let filled = buf.filled().len();
        let read = Pin::new(&mut this.inner).poll_read(cx, buf);
        if let Some(handshake) = &mut this.handshake {
            handshake.read += buf.filled().len() - filled;
            // Once it has spoken it is no longer closed for a newcomer; if
            // the accept loop closed it first, the cut says so next poll.
            if handshake.read >= SPOKEN_BYTES {
                handshake.done.store(true, Ordering::Release);
                this.handshake = None;
            }
        }
        read
    }
}

impl AsyncWrite for CuttableStream {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if let Poll::Ready(error) = this.poll_cut(cx) {
            return Poll::Ready(Err(error));
        }
        Pin::new(&mut this.inner).poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        if let Poll::Ready(error) = this.poll_cut(cx) {
            return Poll::Ready(Err(error));
        }
        Pin::new(&mut this.inner).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_shutdown(cx)
    }
}

impl Drop for CuttableStream {
    fn drop(&mut self) {
        if let Some(handshake) = &self.handshake {
            handshake.done.store(true, Ordering::Release);
        }
        // The accept loop's entry shares the place: let it go now.
        drop(lock(&self.place).take());
    }
}

impl Connected for CuttableStream {
    type ConnectInfo = TcpConnectInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.inner.connect_info()
    }
}

/// The listener's connections, each cut when `cut` is cancelled, at most
/// `limits.max_connections` at once; with every place taken, a newcomer
/// takes the place of the connection silent longest, if one is.
/// Accepting runs in a task of its own that ends, letting the listener
/// go, once the server drops the stream.
pub fn incoming(
    listener: TcpListener,
    cut: CancellationToken,
    limits: ConnectionLimits,
) -> impl Stream<Item = io::Result<CuttableStream>> {
    let (tx, rx) = mpsc::channel(16);
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let silent = Arc::new(SilentQueue::default());
    tokio::spawn(async move {
        let mut backoff = ACCEPT_BACKOFF.0;
        let mut last_refusal_logged: Option<Instant> = None;
        loop {
            let accepted = tokio::select! {
                () = tx.closed() => break,
                accepted = listener.accept() => accepted,
            };
            match accepted {
                Ok((stream, peer)) => {
                    backoff = ACCEPT_BACKOFF.0;
                    // Small messages (acks) should not wait for Nagle.
                    let _ = stream.set_nodelay(true);
                    let place = permits
                        .clone()
                        .try_acquire_owned()
                        .ok()
                        .or_else(|| silent.close_oldest());
                    if let Some(permit) = place {
                        let stream = admit(stream, permit, &cut, &silent, limits);
                        if tx.send(Ok(stream)).await.is_err() {
                            break;
                        }
                        continue;
                    }
                    // Logged at most once a second: a flood would
                    // otherwise fill the log as fast as it connects.
                    if last_refusal_logged.is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
                        tracing::warn!(
                            %peer,
                            max_connections = limits.max_connections,
                            "connection closed: the server holds as many connections as --max-connections allows"
                        );
                        last_refusal_logged = Some(Instant::now());
                    }
                    drop(stream);
                }
                Err(error) if out_of_resources(&error) => {
                    tracing::warn!(
                        %error,
                        wait_ms = backoff.as_millis() as u64,
                        "cannot accept connections: the process is out of file descriptors or memory; waiting"
                    );
                    tokio::time::sleep(backoff).await;
                    backoff = (backoff * 2).min(ACCEPT_BACKOFF.1);
                }
                // A connection that failed between the peer's connect and
                // the accept: nothing to do but take the next.
                Err(error) => tracing::debug!(%error, "accept failed"),
            }
        }
    });
    ReceiverStream::new(rx)
}

/// An accepted connection given its place: cut with `cut` or alone, and
/// listed among the silent until it speaks.
fn admit(
    stream: TcpStream,
    permit: OwnedSemaphorePermit,
    cut: &CancellationToken,
    silent: &SilentQueue,
    limits: ConnectionLimits,
) -> CuttableStream {
    let (cut, done) = (cut.child_token(), Arc::new(AtomicBool::new(false)));
    let place = Arc::new(Mutex::new(Some(permit)));
    silent.push(
        Silent {
            cut: cut.clone(),
            done: done.clone(),
            place: place.clone(),
        },
        limits.max_connections,
    );
    CuttableStream::new(stream, cut, limits.handshake_timeout, place, done)
}

/// Whether an accept failed for want of resources (EMFILE, ENFILE,
/// ENOBUFS, ENOMEM), which retrying at once cannot cure.
fn out_of_resources(error: &io::Error) -> bool {
    const EMFILE: i32 = 24;
    const ENFILE: i32 = 23;
    const ENOBUFS: i32 = 105;
    const ENOMEM: i32 = 12;
    matches!(
        error.raw_os_error(),
        Some(EMFILE | ENFILE | ENOBUFS | ENOMEM)
    ) || error.kind() == io::ErrorKind::OutOfMemory
}
