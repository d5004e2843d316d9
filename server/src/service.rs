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
use crate::read_streams::{ReadResponse, ReadSink, ReadStreamLimits, ReadStreams};
use crate::rigs::RigRegistry;
use crate::store::{MapRecord, Store, TileRange};
use crate::update_stream::{self, UpdateQueueBudget};
use crate::writer::{Batch, EncodedFrame, WriterHandle};
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_server::MapService;
use std::sync::Arc;
use tokio::sync::{broadcast, mpsc};
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::sync::CancellationToken;
use tonic::{Request, Response, Status, Streaming};

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
    /// The places of read streams (GetTiles, ReadFrames, ReadPoses),
    /// whose producers hold a blocking thread each.
    read_streams: Arc<ReadStreams>,
    /// Bytes of update batches read and not yet handed to the writer.
    update_queue: UpdateQueueBudget,
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
            read_streams: self.read_streams.clone(),
            update_queue: self.update_queue.clone(),
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
            read_streams: Arc::new(ReadStreams::new(settings.reads)),
            update_queue: UpdateQueueBudget::new(),
        }
    }

    /// The writer the service hands its writes to.
    pub(crate) fn writer(&self) -> &WriterHandle {
        &self.writer
    }

    /// Cancelled when the server shuts down.
    pub(crate) fn shutdown_token(&self) -> CancellationToken {
        self.shutdown.clone()
    }

    fn record(&self, name: &str) -> Result<MapRecord, StoreError> {
        self.store
            .map(name)?
            .ok_or_else(|| StoreError::MapNotFound(name.to_string()))
    }

    /// Checks a batch against the limits and its map.
    pub(crate) fn check_batch(&self, batch: pb::UpdateBatch) -> Result<Batch, StoreError> {
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

    /// Runs `produce` on a blocking thread, streaming what it sends, once
    /// the client on `connection` has a place among the read streams.
    async fn blocking_stream<T: Send + 'static>(
        &self,
        connection: Option<std::net::SocketAddr>,
        produce: impl FnOnce(&ReadSink<T>) -> Result<(), StoreError> + Send + 'static,
    ) -> Result<ReadResponse<T>, Status> {
        let place = self.read_streams.admit(connection).await?;
        let (sink, response) = ReadSink::new(place, self.stream_buffer);
        tokio::task::spawn_blocking(move || {
            if let Err(error) = produce(&sink) {
                sink.fail(error.into());
            }
        });
        Ok(response)
    }

    /// [`Self::blocking_stream`] of the records `read` visits in the store,
    /// each decoded as `T` (`what` names it in the error), `limit` at most;
    /// one that does not decode ends the stream with that error.
    async fn decoded_stream<T: prost::Message + Default + Send + 'static>(
        &self,
        connection: Option<std::net::SocketAddr>,
        what: &'static str,
        limit: usize,
        read: impl FnOnce(&mut dyn FnMut(u64, &[u8]) -> bool) -> Result<(), StoreError> + Send + 'static,
    ) -> Result<ReadResponse<T>, Status> {
        self.blocking_stream(connection, move |tx| {
            let mut sent = 0usize;
            let mut failure = None;
            read(&mut |_, bytes| match decode::<T>(bytes, what) {
                Ok(record) => {
                    sent += 1;
                    tx.send(record) && sent < limit
                }
                Err(e) => {
                    failure = Some(e);
                    false
                }
            })?;
            failure.map_or(Ok(()), Err)
        })
        .await
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
pub(crate) fn shutting_down() -> Status {
    Status::unavailable("the map server is shutting down")
}

fn decode<T: prost::Message + Default>(bytes: &[u8], what: &str) -> Result<T, StoreError> {
    T::decode(bytes).map_err(|e| StoreError::Corrupt {
        what: what.to_string(),
        reason: e.to_string(),
    })
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
        Ok(Response::new(update_stream::run(
            self.clone(),
            request.into_inner(),
            self.update_queue.clone(),
            self.stream_buffer,
        )))
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

    type GetTilesStream = ReadResponse<pb::Tile>;

    async fn get_tiles(
        &self,
        request: Request<pb::TileQuery>,
    ) -> Result<Response<Self::GetTilesStream>, Status> {
        let connection = request.remote_addr();
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
                self.blocking_stream(connection, move |tx| {
                    store.tiles_in(&record, TileRange { min, max }, &mut |key, stored| {
                        tx.send(wire(key, &stored))
                    })
                })
                .await?
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
                self.blocking_stream(connection, move |tx| {
                    for key in keys {
                        if let Some(stored) = store.tile(&record, key)?
                            && !tx.send(wire(key, &stored))
                        {
                            break;
                        }
                    }
                    Ok(())
                })
                .await?
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

    type ReadFramesStream = ReadResponse<pb::SonarFrame>;

    async fn read_frames(
        &self,
        request: Request<pb::ReadFramesRequest>,
    ) -> Result<Response<Self::ReadFramesStream>, Status> {
        let connection = request.remote_addr();
        let request = request.into_inner();
        let robot = convert::robot_name("robot", &request.robot)?;
        let (from, to) = convert::sequence_range(request.from_sequence, request.to_sequence)?;
        let limit = if request.limit == 0 {
            usize::MAX
        } else {
            request.limit as usize
        };
        let store = self.store.clone();
        Ok(Response::new(
            self.decoded_stream(connection, "frame", limit, move |visit| {
                store.read_frames(&robot, from, to, visit)
            })
            .await?,
        ))
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

    type ReadPosesStream = ReadResponse<pb::PoseEstimate>;

    async fn read_poses(
        &self,
        request: Request<pb::ReadPosesRequest>,
    ) -> Result<Response<Self::ReadPosesStream>, Status> {
        let connection = request.remote_addr();
        let request = request.into_inner();
        let robot = convert::robot_name("robot", &request.robot)?;
        let (from, to) = convert::sequence_range(request.from_sequence, request.to_sequence)?;
        let store = self.store.clone();
        Ok(Response::new(
            self.decoded_stream(connection, "pose", usize::MAX, move |visit| {
                store.read_poses(&robot, from, to, visit)
            })
            .await?,
        ))
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
