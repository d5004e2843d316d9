//! The gRPC `MapService`: thin handlers over the store, the writer and the
//! event channels.
//!
//! Streams never buffer without bound. Every response stream is a bounded
//! channel; a watcher that stops reading first fills its channel, then falls
//! behind on the event broadcast, and is then sent one `Resync` (tiles) or
//! re-read from the store (frames, poses, which are kept), never queued.

use crate::convert::{self, Limits};
use crate::error::StoreError;
use crate::events::{Events, MapEvent};
use crate::rigs::RigRegistry;
use crate::store::{MapRecord, Store, TileRange};
use crate::writer::{Batch, EncodedFrame, WriterHandle};
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_server::MapService;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Semaphore, broadcast, mpsc, oneshot};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status, Streaming};

/// Batches one `ApplyUpdates` stream may have waiting for the writer.
const IN_FLIGHT_BATCHES: usize = 64;
/// Frames or poses read from the store per blocking call while catching up.
const CATCH_UP_CHUNK: usize = 256;

type ResponseStream<T> = ReceiverStream<Result<T, Status>>;

/// The map service over store `S`.
pub struct MapServer<S> {
    store: Arc<S>,
    rigs: Arc<RigRegistry>,
    writer: WriterHandle,
    events: Arc<Events>,
    limits: Limits,
    stream_buffer: usize,
    shutdown: CancellationToken,
    reads: ReadStreamLimits,
    /// One per read stream (GetTiles, ReadFrames, ReadPoses) whose
    /// producer holds a blocking thread.
    read_permits: Arc<Semaphore>,
}

/// What the service checks requests against and how it streams replies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServiceSettings {
    /// Request limits.
    pub limits: Limits,
    /// Messages buffered per response stream.
    pub stream_buffer: usize,
    /// Read streams at once, and their stall timeout.
    pub reads: ReadStreamLimits,
}

/// How many read streams may run at once and how long one may wait for a
/// client that does not read. Each runs on a blocking thread while it
/// reads the store; a client that never reads would hold that thread for
/// ever, and enough of them would leave none for anyone else.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadStreamLimits {
    /// Read streams at once; one more is refused with RESOURCE_EXHAUSTED.
    pub max_streams: usize,
    /// How long a read stream waits for its client to take the next
    /// message before it ends.
    pub stalled_timeout: Duration,
}

impl Default for ReadStreamLimits {
    fn default() -> Self {
        Self {
            max_streams: 64,
            stalled_timeout: Duration::from_secs(30),
        }
    }
}

/// What a read stream's producer sends through: waits for a slow client
/// up to the stall timeout, then gives up (false), as for a client gone.
pub(crate) struct ReadSink<T> {
    tx: mpsc::Sender<Result<T, Status>>,
    runtime: tokio::runtime::Handle,
    stalled_timeout: Duration,
}

impl<T> ReadSink<T> {
    /// Sends `item`; false once the client is gone or has not taken a
    /// message for the stall timeout.
    fn send(&self, item: Result<T, Status>) -> bool {
        match self.tx.try_send(item) {
            Ok(()) => true,
            Err(mpsc::error::TrySendError::Closed(_)) => false,
            Err(mpsc::error::TrySendError::Full(item)) => {
                let sent = self.runtime.block_on(tokio::time::timeout(
                    self.stalled_timeout,
                    self.tx.send(item),
                ));
                if sent.is_err() {
                    tracing::debug!(
                        timeout_s = self.stalled_timeout.as_secs_f64(),
                        "read stream ended: its client took nothing for the stall timeout"
                    );
                }
                matches!(sent, Ok(Ok(())))
            }
        }
    }
}

impl<S> std::fmt::Debug for MapServer<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MapServer")
            .field("limits", &self.limits)
            .finish_non_exhaustive()
    }
}

impl<S> Clone for MapServer<S> {
    fn clone(&self) -> Self {
        Self {
            store: self.store.clone(),
            rigs: self.rigs.clone(),
            writer: self.writer.clone(),
            events: self.events.clone(),
            limits: self.limits,
            stream_buffer: self.stream_buffer,
            shutdown: self.shutdown.clone(),
            reads: self.reads,
            read_permits: self.read_permits.clone(),
        }
    }
}

impl<S: Store> MapServer<S> {
    /// The service; `shutdown` ends its long-lived streams.
    pub fn new(
        store: Arc<S>,
        rigs: Arc<RigRegistry>,
        writer: WriterHandle,
        events: Arc<Events>,
        settings: ServiceSettings,
        shutdown: CancellationToken,
    ) -> Self {
        Self {
            store,
            rigs,
            writer,
            events,
            limits: settings.limits,
            stream_buffer: settings.stream_buffer.max(1),
            shutdown,
            reads: settings.reads,
            read_permits: Arc::new(Semaphore::new(settings.reads.max_streams)),
        }
    }

    fn record(&self, name: &str) -> Result<MapRecord, StoreError> {
        self.store
            .map(name)?
            .ok_or_else(|| StoreError::MapNotFound(name.to_string()))
    }

    fn check_batch(&self, batch: pb::UpdateBatch) -> Result<Batch, StoreError> {
        self.limits.check_size("UpdateBatch", &batch)?;
        let map = convert::map_name("map", &batch.map)?;
        let client_id = convert::client_id("client_id", &batch.client_id)?;
        convert::sequence("sequence", batch.sequence)?;
        if batch.tiles.len() > self.limits.max_tiles_per_batch {
            return Err(StoreError::TooLarge {
                field: "tiles".into(),
                reason: format!(
                    "{} tiles exceed the server's limit of {} per batch",
                    batch.tiles.len(),
                    self.limits.max_tiles_per_batch
                ),
            });
        }
        let record = self.record(&map)?;
        let size = record.settings.tile_size;
        let deltas = batch
            .tiles
            .iter()
            .enumerate()
            .map(|(i, t)| convert::tile_delta(&format!("tiles[{i}]"), t, size, &self.limits))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Batch {
            map,
            client_id,
            sequence: batch.sequence,
            deltas,
            stream_broken: Arc::default(),
        })
    }

    /// Refuses a frame whose rig is unknown or reads another count of
    /// ranges.
    fn check_rig(&self, field: &str, frame: &pb::SonarFrame) -> Result<(), StoreError> {
        let name = deog_proto::rig::frame_rig_name(&frame.rig);
        let rig =
            self.rigs
                .find(self.store.as_ref(), name)?
                .ok_or_else(|| StoreError::UnknownRig {
                    field: format!("{field}.rig"),
                    rig: name.to_owned(),
                })?;
        if rig.readings() != frame.ranges.len() {
            return Err(StoreError::invalid(
                format!("{field}.ranges"),
                format!(
                    "rig {} reads {} ranges per frame, the frame has {}",
                    rig.name(),
                    rig.readings(),
                    frame.ranges.len()
                ),
            ));
        }
        Ok(())
    }

    /// Runs `produce` on a blocking thread, streaming what it sends; one of
    /// at most [`ReadStreamLimits::max_streams`] at once.
    fn blocking_stream<T: Send + 'static>(
        &self,
        produce: impl FnOnce(&ReadSink<T>) -> Result<(), StoreError> + Send + 'static,
    ) -> Result<ResponseStream<T>, Status> {
        let permit = self.read_permits.clone().try_acquire_owned().map_err(|_| {
            Status::resource_exhausted(format!(
                "{} read streams are open, the most the map server allows (--max-read-streams): \
                 retry when one has ended",
                self.reads.max_streams
            ))
        })?;
        let (tx, rx) = mpsc::channel(self.stream_buffer);
        let sink = ReadSink {
            tx,
            runtime: tokio::runtime::Handle::current(),
            stalled_timeout: self.reads.stalled_timeout,
        };
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            if let Err(error) = produce(&sink) {
                sink.send(Err(error.into()));
            }
        });
        Ok(ReceiverStream::new(rx))
    }

    /// [`Self::blocking_stream`] of the records `read` visits in the store,
    /// each decoded as `T` (`what` names it in the error), `limit` at most;
    /// one that does not decode ends the stream with that error.
    fn decoded_stream<T: prost::Message + Default + Send + 'static>(
        &self,
        what: &'static str,
        limit: usize,
        read: impl FnOnce(&mut dyn FnMut(u64, &[u8]) -> bool) -> Result<(), StoreError> + Send + 'static,
    ) -> Result<ResponseStream<T>, Status> {
        self.blocking_stream(move |tx| {
            let mut sent = 0usize;
            let mut failure = None;
            read(&mut |_, bytes| match decode::<T>(bytes, what) {
                Ok(record) => {
                    sent += 1;
                    tx.send(Ok(record)) && sent < limit
                }
                Err(e) => {
                    failure = Some(e);
                    false
                }
            })?;
            failure.map_or(Ok(()), Err)
        })
    }
}

impl<S> MapServer<S> {
    /// A watcher's stream of the events `events` carries that it `keeps`,
    /// until it hangs up or the server shuts down. A watcher that falls
    /// behind skips to the newest event (`what` names them in the log):
    /// the events relayed this way are stored, and can be read again.
    fn relay<T: Clone + Send + Sync + 'static>(
        &self,
        mut events: broadcast::Receiver<Arc<T>>,
        what: &'static str,
        keeps: impl Fn(&T) -> bool + Send + 'static,
    ) -> ResponseStream<T> {
        let (tx, rx) = mpsc::channel(self.stream_buffer);
        let shutdown = self.shutdown.clone();
        tokio::spawn(async move {
            loop {
                let event = tokio::select! {
                    () = shutdown.cancelled() => {
                        let _ = tx.send(Err(shutting_down())).await;
                        break;
                    }
                    () = tx.closed() => break,
                    event = events.recv() => event,
                };
                match event {
                    Ok(event) => {
                        if keeps(&event) && tx.send(Ok((*event).clone())).await.is_err() {
                            break;
                        }
                    }
                    Err(broadcast::error::RecvError::Lagged(missed)) => {
                        tracing::debug!(missed, what, "a watcher fell behind");
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                }
            }
        });
        ReceiverStream::new(rx)
    }
}

/// What ends a stream when the server shuts down.
fn shutting_down() -> Status {
    Status::unavailable("the map server is shutting down")
}

fn decode<T: prost::Message + Default>(bytes: &[u8], what: &str) -> Result<T, StoreError> {
    T::decode(bytes).map_err(|e| StoreError::Corrupt {
        what: what.to_string(),
        reason: e.to_string(),
    })
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

/// Reads a robot's stored frames after sequence `after`, in chunks, sending
/// each; returns the last sequence sent (or `after`), or None once the
/// client is gone. Nothing follows `u64::MAX`: counting past it would wrap
/// to 0 and replay the robot's whole history.
async fn send_frames_after<S: Store>(
    store: &Arc<S>,
    robot: &str,
    mut after: u64,
    tx: &mpsc::Sender<Result<pb::SonarFrame, Status>>,
) -> Option<u64> {
    loop {
        let Some(next) = after.checked_add(1) else {
            return Some(after);
        };
        let (store, name) = (store.clone(), robot.to_string());
        let chunk = tokio::task::spawn_blocking(move || {
            let mut out = Vec::new();
            let mut failure = None;
            let read = store.read_frames(&name, next, u64::MAX, &mut |seq, bytes| {
                match decode::<pb::SonarFrame>(bytes, "frame") {
                    Ok(frame) => out.push((seq, frame)),
                    Err(e) => failure = Some(e),
                }
                failure.is_none() && out.len() < CATCH_UP_CHUNK
            });
            match (read, failure) {
                (Err(e), _) | (Ok(()), Some(e)) => Err(e),
                (Ok(()), None) => Ok(out),
            }
        })
        .await;
        let chunk = match chunk {
            Ok(Ok(chunk)) => chunk,
            Ok(Err(error)) => {
                let _ = tx.send(Err(error.into())).await;
                return None;
            }
            Err(_) => {
                let _ = tx.send(Err(Status::internal("frame reader failed"))).await;
                return None;
            }
        };
        let full = chunk.len() == CATCH_UP_CHUNK;
        for (seq, frame) in chunk {
            tx.send(Ok(frame)).await.ok()?;
            after = seq;
        }
        if !full {
            return Some(after);
        }
    }
}

#[tonic::async_trait]
impl<S: Store> MapService for MapServer<S> {
    async fn create_map(
        &self,
        request: Request<pb::CreateMapRequest>,
    ) -> Result<Response<pb::MapInfo>, Status> {
        let request = request.into_inner();
        self.limits.check_size("CreateMapRequest", &request)?;
        let name = convert::map_name("name", &request.name)?;
        let settings = convert::map_settings(&request)?;
        let record = self
            .writer
            .create_map(MapRecord::new(name, settings))
            .await?;
        tracing::info!(map = %record.name, "map created");
        Ok(Response::new(convert::map_info(&record)))
    }

    async fn list_maps(
        &self,
        _request: Request<pb::ListMapsRequest>,
    ) -> Result<Response<pb::ListMapsResponse>, Status> {
        let maps = self.store.maps()?.iter().map(convert::map_info).collect();
        Ok(Response::new(pb::ListMapsResponse { maps }))
    }

    async fn get_map_info(
        &self,
        request: Request<pb::MapRef>,
    ) -> Result<Response<pb::MapInfo>, Status> {
        let name = convert::map_name("name", &request.get_ref().name)?;
        Ok(Response::new(convert::map_info(&self.record(&name)?)))
    }

    async fn clear_map(
        &self,
        request: Request<pb::MapRef>,
    ) -> Result<Response<pb::MapInfo>, Status> {
        let name = convert::map_name("name", &request.get_ref().name)?;
        let record = self.writer.clear_map(name).await?;
        tracing::info!(map = %record.name, version = record.version, "map cleared");
        Ok(Response::new(convert::map_info(&record)))
    }

    async fn delete_map(
        &self,
        request: Request<pb::MapRef>,
    ) -> Result<Response<pb::DeleteMapResponse>, Status> {
        let name = convert::map_name("name", &request.get_ref().name)?;
        self.writer.delete_map(name.clone()).await?;
        tracing::info!(map = %name, "map deleted");
        Ok(Response::new(pb::DeleteMapResponse {}))
    }

    type ApplyUpdatesStream = ResponseStream<pb::UpdateAck>;

    async fn apply_updates(
        &self,
        request: Request<Streaming<pb::UpdateBatch>>,
    ) -> Result<Response<Self::ApplyUpdatesStream>, Status> {
        enum Pending {
            Ack(
                String,
                u64,
                oneshot::Receiver<Result<crate::writer::Ack, StoreError>>,
            ),
            Fail(Status),
        }
        let mut inbound = request.into_inner();
        let (out_tx, out_rx) = mpsc::channel(self.stream_buffer);
        let (pending_tx, mut pending_rx) = mpsc::channel::<Pending>(IN_FLIGHT_BATCHES);
        let server = self.clone();
        let stream_broken = Arc::new(std::sync::atomic::AtomicBool::new(false));
        // Reads batches and hands them to the writer, in order.
        tokio::spawn(async move {
            let mut read = 0u64;
            loop {
                let message = tokio::select! {
                    () = server.shutdown.cancelled() => {
                        let _ = pending_tx.send(Pending::Fail(shutting_down())).await;
                        break;
                    }
                    message = inbound.message() => message,
                };
                let batch = match message {
                    Ok(Some(batch)) => batch,
                    Ok(None) => break,
                    Err(status) => {
                        // Ending with OK here would tell the client that
                        // everything it sent was taken.
                        let status = unreadable_batch(read, &status);
                        tracing::debug!(%status, "update stream unreadable");
                        let _ = pending_tx.send(Pending::Fail(status)).await;
                        break;
                    }
                };
                read += 1;
                let (client, sequence) = (batch.client_id.clone(), batch.sequence);
                let submitted = match server.check_batch(batch) {
                    Ok(mut batch) => {
                        batch.stream_broken = stream_broken.clone();
                        server.writer.submit_batch(batch).await
                    }
                    Err(error) => {
                        if matches!(error, StoreError::Unavailable(_)) {
                            server.writer.store_unavailable();
                        }
                        Err(error)
                    }
                };
                let pending = match submitted {
                    Ok(ack) => Pending::Ack(client, sequence, ack),
                    Err(error) => {
                        tracing::debug!(%error, "update batch refused");
                        Pending::Fail(error.into())
                    }
                };
                let failed = matches!(pending, Pending::Fail(_));
                if pending_tx.send(pending).await.is_err() || failed {
                    break;
                }
            }
        });
        // Sends acknowledgements, in the order the batches came.
        tokio::spawn(async move {
            while let Some(pending) = pending_rx.recv().await {
                let reply = match pending {
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
                if out_tx.send(reply).await.is_err() || failed {
                    break;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(out_rx)))
    }

    async fn get_update_cursor(
        &self,
        request: Request<pb::UpdateCursorRequest>,
    ) -> Result<Response<pb::UpdateCursor>, Status> {
        let request = request.into_inner();
        let map = convert::map_name("map", &request.map)?;
        let client = convert::client_id("client_id", &request.client_id)?;
        self.record(&map)?;
        let last_sequence = self.store.cursor(&map, &client)?.last;
        Ok(Response::new(pb::UpdateCursor { last_sequence }))
    }

    async fn list_update_cursors(
        &self,
        request: Request<pb::MapRef>,
    ) -> Result<Response<pb::ListUpdateCursorsResponse>, Status> {
        let map = convert::map_name("name", &request.into_inner().name)?;
        self.record(&map)?;
        let cursors = self
            .store
            .cursors(&map)?
            .into_iter()
            .map(|(client_id, cursor)| pb::ClientUpdateCursor {
                client_id,
                last_sequence: cursor.last,
            })
            .collect();
        Ok(Response::new(pb::ListUpdateCursorsResponse { cursors }))
    }

    type GetTilesStream = ResponseStream<pb::Tile>;

    async fn get_tiles(
        &self,
        request: Request<pb::TileQuery>,
    ) -> Result<Response<Self::GetTilesStream>, Status> {
        let request = request.into_inner();
        self.limits.check_size("TileQuery", &request)?;
        let map = convert::map_name("map", &request.map)?;
        let record = self.record(&map)?;
        let size = record.settings.tile_size;
        let newer_than = request.newer_than_version;
        let wire = move |key, stored: &crate::store::StoredTile| {
            convert::tile_to_wire(
                key,
                stored.version,
                (stored.version > newer_than).then_some(&stored.tile),
            )
        };
        let store = self.store.clone();
        let stream = match request.selection {
            Some(pb::tile_query::Selection::Region(region)) => {
                let region = convert::cell_box("region", Some(&region))?;
                let (min, max) = size.tiles_covering(&region);
                self.blocking_stream(move |tx| {
                    store.tiles_in(&record, TileRange { min, max }, &mut |key, stored| {
                        tx.send(Ok(wire(key, &stored)))
                    })
                })?
            }
            Some(pb::tile_query::Selection::Keys(keys)) => {
                let keys = keys
                    .keys
                    .iter()
                    .enumerate()
                    .map(|(i, k)| {
                        convert::tile_key(&format!("keys.keys[{i}]"), Some(k), size, &self.limits)
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                self.blocking_stream(move |tx| {
                    for key in keys {
                        if let Some(stored) = store.tile(&record, key)?
                            && !tx.send(Ok(wire(key, &stored)))
                        {
                            break;
                        }
                    }
                    Ok(())
                })?
            }
            None => return Err(StoreError::invalid("selection", "give a region or keys").into()),
        };
        Ok(Response::new(stream))
    }

    type WatchTilesStream = ResponseStream<pb::TileEvent>;

    async fn watch_tiles(
        &self,
        request: Request<pb::WatchTilesRequest>,
    ) -> Result<Response<Self::WatchTilesStream>, Status> {
        let request = request.into_inner();
        let map = convert::map_name("map", &request.map)?;
        let region = convert::cell_box("region", request.region.as_ref())?;
        let record = self.record(&map)?;
        let (min, max) = record.settings.tile_size.tiles_covering(&region);
        let range = TileRange { min, max };
        let mut events = self.events.watch_map(&map);
        let (tx, rx) = mpsc::channel(self.stream_buffer);
        let server = self.clone();
        let include_cells = request.include_cells;
        tokio::spawn(async move {
            use pb::tile_event::Event;
            loop {
                let event = tokio::select! {
                    () = server.shutdown.cancelled() => {
                        let _ = tx.send(Err(shutting_down())).await;
                        break;
                    }
                    () = tx.closed() => break,
                    event = events.recv() => event,
                };
                let event = match event {
                    Ok(MapEvent::TileChanged { key, version }) => {
                        if !range.contains(key) {
                            continue;
                        }
                        if !include_cells {
                            Event::Changed(convert::tile_to_wire(key, version, None))
                        } else {
                            match server.store.tile(&record, key) {
                                Ok(Some(stored)) => Event::Changed(convert::tile_to_wire(
                                    key,
                                    stored.version,
                                    Some(&stored.tile),
                                )),
                                Ok(None) => continue,
                                Err(error) => {
                                    let _ = tx.send(Err(error.into())).await;
                                    break;
                                }
                            }
                        }
                    }
                    Ok(MapEvent::Cleared { version }) => Event::Cleared(pb::MapCleared {
                        map_version: version,
                    }),
                    Ok(MapEvent::Deleted) => {
                        let _ = tx
                            .send(Err(StoreError::MapNotFound(map.clone()).into()))
                            .await;
                        break;
                    }
                    Ok(MapEvent::Resync) => {
                        let map_version = server
                            .store
                            .map(&map)
                            .ok()
                            .flatten()
                            .map_or(0, |r| r.version);
                        tracing::debug!(map = %map, "changes through another server may have been missed; sending resync");
                        Event::Resync(pb::Resync {
                            map_version,
                            reason: "changes made through another map server may have been missed"
                                .into(),
                        })
                    }
                    Err(broadcast::error::RecvError::Lagged(missed)) => {
                        let map_version = server
                            .store
                            .map(&map)
                            .ok()
                            .flatten()
                            .map_or(0, |r| r.version);
                        tracing::debug!(map = %map, missed, "tile watcher fell behind; sending resync");
                        Event::Resync(pb::Resync {
                            map_version,
                            reason: format!(
                                "{missed} tile events dropped because the subscriber fell behind"
                            ),
                        })
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                };
                if tx
                    .send(Ok(pb::TileEvent { event: Some(event) }))
                    .await
                    .is_err()
                {
                    break;
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn publish_frames(
        &self,
        request: Request<pb::PublishFramesRequest>,
    ) -> Result<Response<pb::PublishFramesResponse>, Status> {
        let request = request.into_inner();
        self.limits.check_size("PublishFramesRequest", &request)?;
        if request.frames.len() > self.limits.max_frames_per_request {
            return Err(StoreError::TooLarge {
                field: "frames".into(),
                reason: format!(
                    "{} frames exceed the server's limit of {} per request",
                    request.frames.len(),
                    self.limits.max_frames_per_request
                ),
            }
            .into());
        }
        let mut inputs = Vec::with_capacity(request.frames.len());
        for (i, frame) in request.frames.iter().enumerate() {
            let field = format!("frames[{i}]");
            convert::sonar_frame(&field, frame, &self.limits)?;
            self.check_rig(&field, frame)?;
            inputs.push(EncodedFrame {
                robot: frame.robot.clone(),
                sequence: frame.sequence,
                bytes: prost::Message::encode_to_vec(frame),
            });
        }
        let (stored, duplicates) = self.writer.publish_frames(inputs).await?;
        Ok(Response::new(pb::PublishFramesResponse {
            stored,
            duplicates,
        }))
    }

    type ReadFramesStream = ResponseStream<pb::SonarFrame>;

    async fn read_frames(
        &self,
        request: Request<pb::ReadFramesRequest>,
    ) -> Result<Response<Self::ReadFramesStream>, Status> {
        let request = request.into_inner();
        let robot = convert::robot_name("robot", &request.robot)?;
        let (from, to) = convert::sequence_range(request.from_sequence, request.to_sequence)?;
        let limit = if request.limit == 0 {
            usize::MAX
        } else {
            request.limit as usize
        };
        let store = self.store.clone();
        Ok(Response::new(self.decoded_stream(
            "frame",
            limit,
            move |visit| store.read_frames(&robot, from, to, visit),
        )?))
    }

    type SubscribeFramesStream = ResponseStream<pb::SonarFrame>;

    async fn subscribe_frames(
        &self,
        request: Request<pb::SubscribeFramesRequest>,
    ) -> Result<Response<Self::SubscribeFramesStream>, Status> {
        let request = request.into_inner();
        let robot = convert::robot_name("robot", &request.robot)?;
        // Subscribe before reading the store, so no frame falls in between.
        let mut notes = self.events.watch_frames();
        // The last sequence sent: the subscriber wants only later ones.
        let mut after = match request.from_sequence {
            0 => self.store.robot(&robot)?.map_or(0, |s| s.last_sequence),
            from => from - 1,
        };
        let (tx, rx) = mpsc::channel(self.stream_buffer);
        let server = self.clone();
        tokio::spawn(async move {
            let mut catch_up = true;
            loop {
                if catch_up {
                    match send_frames_after(&server.store, &robot, after, &tx).await {
                        Some(sent) => after = sent,
                        None => break,
                    }
                }
                let note = tokio::select! {
                    () = server.shutdown.cancelled() => {
                        let _ = tx.send(Err(shutting_down())).await;
                        break;
                    }
                    () = tx.closed() => break,
                    note = notes.recv() => note,
                };
                catch_up = match note {
                    Ok(note) => &*note.robot == robot.as_str() && note.sequence > after,
                    // Frames are stored: a subscriber that fell behind re-reads them.
                    Err(broadcast::error::RecvError::Lagged(_)) => true,
                    Err(broadcast::error::RecvError::Closed) => break,
                };
            }
        });
        Ok(Response::new(ReceiverStream::new(rx)))
    }

    async fn list_robots(
        &self,
        _request: Request<pb::ListRobotsRequest>,
    ) -> Result<Response<pb::ListRobotsResponse>, Status> {
        let robots = self
            .store
            .robots()?
            .into_iter()
            .map(|(robot, s)| pb::RobotFrames {
                robot,
                first_sequence: s.first_sequence,
                last_sequence: s.last_sequence,
                frame_count: s.frame_count,
            })
            .collect();
        Ok(Response::new(pb::ListRobotsResponse { robots }))
    }

    async fn put_rig(&self, request: Request<pb::Rig>) -> Result<Response<pb::Rig>, Status> {
        let wire = request.into_inner();
        self.limits.check_size("Rig", &wire)?;
        let (store, rigs) = (self.store.clone(), self.rigs.clone());
        let rig = tokio::task::spawn_blocking(move || rigs.put(store.as_ref(), &wire))
            .await
            .map_err(|_| Status::internal("rig writer failed"))??;
        Ok(Response::new(deog_proto::rig::rig_to_wire(&rig)))
    }

    async fn get_rig(&self, request: Request<pb::RigRef>) -> Result<Response<pb::Rig>, Status> {
        let name = request.into_inner().name;
        let rig = self
            .rigs
            .find(self.store.as_ref(), &name)?
            .ok_or(StoreError::RigNotFound(name))?;
        Ok(Response::new(deog_proto::rig::rig_to_wire(&rig)))
    }

    async fn list_rigs(
        &self,
        _request: Request<pb::ListRigsRequest>,
    ) -> Result<Response<pb::ListRigsResponse>, Status> {
        self.rigs.refresh(self.store.as_ref())?;
        let rigs = self
            .rigs
            .list()
            .iter()
            .map(|rig| deog_proto::rig::rig_to_wire(rig))
            .collect();
        Ok(Response::new(pb::ListRigsResponse { rigs }))
    }

    async fn publish_pose(
        &self,
        request: Request<pb::PoseEstimate>,
    ) -> Result<Response<pb::PublishPoseResponse>, Status> {
        let estimate = request.into_inner();
        self.limits.check_size("PoseEstimate", &estimate)?;
        convert::pose_estimate(&estimate)?;
        self.writer.publish_pose(estimate).await?;
        Ok(Response::new(pb::PublishPoseResponse {}))
    }

    type ReadPosesStream = ResponseStream<pb::PoseEstimate>;

    async fn read_poses(
        &self,
        request: Request<pb::ReadPosesRequest>,
    ) -> Result<Response<Self::ReadPosesStream>, Status> {
        let request = request.into_inner();
        let robot = convert::robot_name("robot", &request.robot)?;
        let (from, to) = convert::sequence_range(request.from_sequence, request.to_sequence)?;
        let store = self.store.clone();
        Ok(Response::new(self.decoded_stream(
            "pose",
            usize::MAX,
            move |visit| store.read_poses(&robot, from, to, visit),
        )?))
    }

    type WatchPosesStream = ResponseStream<pb::PoseEstimate>;

    async fn watch_poses(
        &self,
        request: Request<pb::WatchPosesRequest>,
    ) -> Result<Response<Self::WatchPosesStream>, Status> {
        let request = request.into_inner();
        let robot = match request.robot.as_str() {
            "" => None,
            name => Some(convert::robot_name("robot", name)?),
        };
        // Estimates are stored; a watcher that fell behind skips to the
        // newest and can read the gap with ReadPoses.
        let poses = self.relay(self.events.watch_poses(), "pose", move |pose| {
            robot.as_ref().is_none_or(|r| *r == pose.robot)
        });
        Ok(Response::new(poses))
    }

    async fn publish_goal(
        &self,
        request: Request<pb::ExplorationGoal>,
    ) -> Result<Response<pb::PublishGoalResponse>, Status> {
        let goal = request.into_inner();
        self.limits.check_size("ExplorationGoal", &goal)?;
        convert::exploration_goal(&goal)?;
        let store = self.store.clone();
        let (map, robot, bytes) = (
            goal.map.clone(),
            goal.robot.clone(),
            prost::Message::encode_to_vec(&goal),
        );
        tokio::task::spawn_blocking(move || store.put_goal(&map, &robot, bytes))
            .await
            .map_err(|_| Status::internal("goal writer failed"))??;
        self.events.goal_stored(Arc::new(goal));
        Ok(Response::new(pb::PublishGoalResponse {}))
    }

    async fn list_goals(
        &self,
        request: Request<pb::ListGoalsRequest>,
    ) -> Result<Response<pb::ListGoalsResponse>, Status> {
        let map = convert::map_name("map", &request.into_inner().map)?;
        let store = self.store.clone();
        let stored = tokio::task::spawn_blocking(move || store.goals(&map))
            .await
            .map_err(|_| Status::internal("goal reader failed"))??;
        let goals = stored
            .iter()
            .map(|(_, bytes)| decode::<pb::ExplorationGoal>(bytes, "goal"))
            .collect::<Result<_, _>>()?;
        Ok(Response::new(pb::ListGoalsResponse { goals }))
    }

    type WatchGoalsStream = ResponseStream<pb::ExplorationGoal>;

    async fn watch_goals(
        &self,
        request: Request<pb::ListGoalsRequest>,
    ) -> Result<Response<Self::WatchGoalsStream>, Status> {
        let map = convert::map_name("map", &request.into_inner().map)?;
        // Goals are stored: ListGoals has what a lagging watcher skipped.
        let goals = self.relay(self.events.watch_goals(), "goal", move |goal| {
            goal.map == map
        });
        Ok(Response::new(goals))
    }
}
