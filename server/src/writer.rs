//! The group-commit writer: the one thread that changes the store.
//!
//! Every write (map batches, frames, poses, map admin) is sent here. The
//! writer takes whatever has queued up, applies it in arrival order, writes
//! each touched map once, flushes the store once, and only then answers each
//! request and tells the watchers. One writer makes concurrent updates to a
//! tile atomic and serialisable, makes the exactly-once check race-free, and
//! turns one flush per batch into one flush per group.

use crate::error::StoreError;
use crate::events::{Events, FrameNote, MapEvent};
use crate::store::{
    ClientCursor, FrameWrite, MapRecord, MapWrite, RobotSummary, SequenceCheck, Store, StoredTile,
    Transaction,
};
use deog_grid::{CellBox, CellIndex, LogOdds, Tile, TileDelta, TileKey, TileSize};
use deog_proto::v1::PoseEstimate;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, oneshot, watch};

/// Most requests taken into one group commit.
const MAX_GROUP: usize = 512;
/// How often a writer whose store failed tries to recover it, and how
/// often it looks for writes to refuse meanwhile.
const RECOVERY_INTERVAL: Duration = Duration::from_secs(1);
const REFUSAL_POLL: Duration = Duration::from_millis(20);

/// A batch of tile deltas from one client, decoded and checked.
#[derive(Debug)]
pub struct Batch {
    /// Target map.
    pub map: String,
    /// Sending client.
    pub client_id: String,
    /// The client's sequence number, from 1.
    pub sequence: u64,
    /// Dense deltas per tile, in the map's tile size.
    pub deltas: Vec<TileDelta>,
    /// Shared by the batches of one update stream, set once one of them is
    /// refused or not committed: the later ones are refused too, so that
    /// none is applied past a gap its client will fill by sending again
    /// (the gap's batch would then be out of order for good).
    pub stream_broken: Arc<AtomicBool>,
}

impl Batch {
    fn stream_is_broken(&self) -> bool {
        self.stream_broken.load(Ordering::Acquire)
    }

    fn break_stream(&self) {
        self.stream_broken.store(true, Ordering::Release);
    }
}

/// The answer to a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// False when the batch was a resend and was not applied again.
    pub applied: bool,
    /// The map's version after the batch.
    pub map_version: u64,
}

/// One frame to store.
#[derive(Debug)]
pub struct EncodedFrame {
    /// Robot name.
    pub robot: String,
    /// Sequence.
    pub sequence: u64,
    /// The encoded `SonarFrame`.
    pub bytes: Vec<u8>,
}

type Reply<T> = oneshot::Sender<Result<T, StoreError>>;

enum WriteOp {
    CreateMap(MapRecord, Reply<MapRecord>),
    ClearMap(String, Reply<MapRecord>),
    DeleteMap(String, Reply<()>),
    Apply(Batch, Reply<Ack>),
    Frames(Vec<EncodedFrame>, Reply<(u32, u32)>),
    Pose(Arc<PoseEstimate>, Vec<u8>, Reply<()>),
    /// A read met the store unavailable: look whether it can still write.
    Probe,
    Stop,
}

/// A handle for sending writes; cheap to clone.
#[derive(Clone)]
pub struct WriterHandle {
    sender: mpsc::Sender<WriteOp>,
}

impl std::fmt::Debug for WriterHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WriterHandle").finish_non_exhaustive()
    }
}

/// Whether the store takes writes, as the writer last found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StoreHealth {
    /// The last commit (or recovery) landed.
    Writable,
    /// A commit failed and the store has not recovered yet: writes are
    /// refused with this reason.
    Failing {
        /// The error that made the commit fail.
        reason: String,
    },
}

/// The writer thread.
pub struct Writer {
    handle: WriterHandle,
    thread: Option<JoinHandle<Result<(), StoreError>>>,
    health: watch::Receiver<StoreHealth>,
}

impl std::fmt::Debug for Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Writer").finish_non_exhaustive()
    }
}

impl Writer {
    /// Starts the writer over `store`; at most `queue` requests wait for it.
    pub fn start<S: Store>(
        store: Arc<S>,
        events: Arc<Events>,
        queue: usize,
    ) -> std::io::Result<Self> {
        let (sender, receiver) = mpsc::channel(queue.max(1));
        let (health_sender, health) = watch::channel(StoreHealth::Writable);
        let thread = std::thread::Builder::new()
            .name("deog-writer".into())
            .spawn(move || run(store.as_ref(), &events, receiver, &health_sender))?;
        Ok(Self {
            handle: WriterHandle { sender },
            thread: Some(thread),
            health,
        })
    }

    /// A handle for sending writes.
    pub fn handle(&self) -> WriterHandle {
        self.handle.clone()
    }

    /// Follows whether the store takes writes; ends when the writer stops.
    pub fn health(&self) -> watch::Receiver<StoreHealth> {
        self.health.clone()
    }

    /// Finishes every queued write, flushes, and stops the thread. Writes
    /// sent later fail with [`StoreError::ShuttingDown`]. The error is the
    /// final flush's: what was written but not yet flushed is not on disk.
    pub async fn stop(mut self) -> Result<(), StoreError> {
        let _ = self.handle.sender.send(WriteOp::Stop).await;
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        // The thread only ends after its final flush.
        match tokio::task::spawn_blocking(move || thread.join()).await {
            Ok(Ok(flushed)) => flushed,
            _ => Err(StoreError::Backend("the writer thread panicked".into())),
        }
    }
}

impl WriterHandle {
    async fn call<T>(&self, make: impl FnOnce(Reply<T>) -> WriteOp) -> Result<T, StoreError> {
        let (tx, rx) = oneshot::channel();
        self.sender
            .send(make(tx))
            .await
            .map_err(|_| StoreError::ShuttingDown)?;
        rx.await.map_err(|_| StoreError::ShuttingDown)?
    }

    /// Creates a map.
    pub async fn create_map(&self, record: MapRecord) -> Result<MapRecord, StoreError> {
        self.call(|r| WriteOp::CreateMap(record, r)).await
    }

    /// Clears a map.
    pub async fn clear_map(&self, name: String) -> Result<MapRecord, StoreError> {
        self.call(|r| WriteOp::ClearMap(name, r)).await
    }

    /// Deletes a map.
    pub async fn delete_map(&self, name: String) -> Result<(), StoreError> {
        self.call(|r| WriteOp::DeleteMap(name, r)).await
    }

    /// Queues a batch and returns a receiver for its acknowledgement, so a
    /// client's batches can be pipelined while keeping their order.
    pub async fn submit_batch(
        &self,
        batch: Batch,
    ) -> Result<oneshot::Receiver<Result<Ack, StoreError>>, StoreError> {
        let (tx, rx) = oneshot::channel();
        self.sender
            .send(WriteOp::Apply(batch, tx))
            .await
            .map_err(|_| StoreError::ShuttingDown)?;
        Ok(rx)
    }

    /// Stores frames; returns (stored, duplicates).
    pub async fn publish_frames(
        &self,
        frames: Vec<EncodedFrame>,
    ) -> Result<(u32, u32), StoreError> {
        self.call(|r| WriteOp::Frames(frames, r)).await
    }

    /// Says that a read found the store unavailable: the writer then looks
    /// whether it can still write, and if not reports the store failing
    /// (health `NOT_SERVING`) until it recovers, as after a failed commit.
    /// Never waits: with the queue full, the writes queued will find out.
    pub fn store_unavailable(&self) {
        let _ = self.sender.try_send(WriteOp::Probe);
    }

    /// Stores a pose estimate; [`StoreError::MapNotFound`] if the map it
    /// names does not exist.
    pub async fn publish_pose(&self, pose: PoseEstimate) -> Result<(), StoreError> {
        let bytes = prost::Message::encode_to_vec(&pose);
        self.call(|r| WriteOp::Pose(Arc::new(pose), bytes, r)).await
    }
}

/// Applies the writes as they come, a group at a time, until stopped;
/// returns the final flush's outcome. After a failed commit it refuses
/// writes and tries to recover the store until it can write again.
fn run<S: Store>(
    store: &S,
    events: &Events,
    mut receiver: mpsc::Receiver<WriteOp>,
    health: &watch::Sender<StoreHealth>,
) -> Result<(), StoreError> {
    let mut stopping = false;
    while !stopping {
        let Some(first) = receiver.blocking_recv() else {
            break;
        };
        let mut group = vec![first];
        while group.len() < MAX_GROUP {
            match receiver.try_recv() {
                Ok(op) => group.push(op),
                Err(_) => break,
            }
        }
        if let Some(at) = group.iter().position(|op| matches!(op, WriteOp::Stop)) {
            stopping = true;
            group.truncate(at);
        }
        let probed = group.len();
        group.retain(|op| !matches!(op, WriteOp::Probe));
        // A group of writes finds out by committing; probes alone ask.
        let failed = if group.is_empty() && probed > 0 {
            store.check_writable().err().map(|error| {
                let unconfirmed = Unconfirmed {
                    map_events: Vec::new(),
                    frame_events: Vec::new(),
                    pose_events: Vec::new(),
                };
                (GroupFailure::of(&error), unconfirmed)
            })
        } else {
            commit_group(store, group, events)
        };
        if let Some((failure, unconfirmed)) = failed {
            if !stopping {
                stopping = recover(store, events, &mut receiver, health, failure, unconfirmed);
            }
        }
    }
    receiver.close();
    // Anything still queued was never accepted.
    while let Ok(op) = receiver.try_recv() {
        refuse(op, || StoreError::ShuttingDown);
    }
    let flushed = store.flush();
    tracing::debug!("writer stopped");
    flushed
}

/// After a failed commit: says so through `health`, then until the store
/// recovers refuses every write with the reason and tries to recover it
/// every [`RECOVERY_INTERVAL`]. Once recovered, tells watchers of the
/// failed group's changes that reached the disk after all. Returns true if
/// the server stopped meanwhile.
fn recover<S: Store>(
    store: &S,
    events: &Events,
    receiver: &mut mpsc::Receiver<WriteOp>,
    health: &watch::Sender<StoreHealth>,
    failure: GroupFailure,
    unconfirmed: Unconfirmed,
) -> bool {
    let failed_at = Instant::now();
    let reason = failure.reason;
    health.send_replace(StoreHealth::Failing {
        reason: reason.clone(),
    });
    tracing::error!(%reason, "the store cannot write: writes are refused until it recovers");
    let mut attempts = 0u64;
    let mut next_attempt = failed_at;
    let mut last_error = String::new();
    loop {
        let now = Instant::now();
        if now >= next_attempt {
            attempts += 1;
            match store.recover(&reason) {
                Ok(()) => break,
                Err(error) => {
                    // A line per attempt would flood the log: a line when
                    // the reason changes, and one a minute.
                    let error = error.to_string();
                    if error != last_error || attempts % 60 == 0 {
                        tracing::warn!(%error, attempts, "the store has not recovered yet");
                    }
                    last_error = error;
                    next_attempt = now + RECOVERY_INTERVAL;
                }
            }
        }
        loop {
            match receiver.try_recv() {
                Ok(WriteOp::Stop) | Err(mpsc::error::TryRecvError::Disconnected) => return true,
                Ok(op) => refuse(op, || {
                    StoreError::Unavailable(format!(
                        "the store cannot write ({reason}); the server retries every second"
                    ))
                }),
                Err(mpsc::error::TryRecvError::Empty) => break,
            }
        }
        std::thread::sleep(REFUSAL_POLL);
    }
    unconfirmed.announce_survivors(store, events);
    health.send_replace(StoreHealth::Writable);
    tracing::info!(
        after_s = failed_at.elapsed().as_secs_f64(),
        "the store recovered: writes are taken again"
    );
    false
}

fn refuse(op: WriteOp, error: impl Fn() -> StoreError) {
    match op {
        WriteOp::CreateMap(_, r) | WriteOp::ClearMap(_, r) => {
            let _ = r.send(Err(error()));
        }
        WriteOp::DeleteMap(_, r) | WriteOp::Pose(_, _, r) => {
            let _ = r.send(Err(error()));
        }
        WriteOp::Apply(batch, r) => {
            batch.break_stream();
            let _ = r.send(Err(error()));
        }
        WriteOp::Frames(_, r) => {
            let _ = r.send(Err(error()));
        }
        WriteOp::Probe | WriteOp::Stop => {}
    }
}

/// The changes of a group whose commit failed. Some may have reached the
/// disk all the same (the store writes in pieces); watchers hear of those
/// once the store has recovered.
struct Unconfirmed {
    map_events: Vec<(String, MapEvent)>,
    frame_events: Vec<FrameNote>,
    pose_events: Vec<Arc<PoseEstimate>>,
}

impl Unconfirmed {
    fn announce_survivors<S: Store>(self, store: &S, events: &Events) {
        let mut by_map: BTreeMap<String, Vec<MapEvent>> = BTreeMap::new();
        for (map, event) in self.map_events {
            let record = store.map(&map).ok().flatten();
            let landed = match (&event, &record) {
                (MapEvent::Deleted, record) => record.is_none(),
                // The writer makes none.
                (MapEvent::Resync, _) => false,
                (MapEvent::Cleared { version }, Some(record)) => record.version >= *version,
                (MapEvent::TileChanged { key, version }, Some(record)) => store
                    .tile(record, *key)
                    .ok()
                    .flatten()
                    .is_some_and(|tile| tile.version == *version),
                (_, None) => false,
            };
            if landed {
                by_map.entry(map).or_default().push(event);
            }
        }
        for (map, list) in by_map {
            events.map_changed(&map, list);
        }
        for note in self.frame_events {
            if store.has_frame(&note.robot, note.sequence).unwrap_or(false) {
                events.frame_stored(note);
            }
        }
        for pose in self.pose_events {
            let mut found = false;
            let _ = store.read_poses(
                &pose.robot,
                pose.frame_sequence,
                pose.frame_sequence,
                &mut |_, _| {
                    found = true;
                    false
                },
            );
            if found {
                events.pose_stored(pose);
            }
        }
    }
}

/// Why a group was not committed: the first error, worded, whether its
/// cause passes, and whether it was a concurrent write (the group is then
/// applied again).
#[derive(Debug, Clone)]
struct GroupFailure {
    reason: String,
    transient: bool,
    conflict: bool,
}

impl GroupFailure {
    fn of(error: &StoreError) -> Self {
        Self {
            reason: error.to_string(),
            transient: error.is_transient(),
            conflict: matches!(error, StoreError::Conflict(_)),
        }
    }
}

/// How many times a group that met a concurrent write through another
/// server is applied; the database resolved the clash by rolling it back.
const CONFLICT_ATTEMPTS: u32 = 8;

/// Applies `ops` in one transaction, again while it meets concurrent
/// writes, then answers them and tells the watchers; if the commit failed,
/// returns why with the changes it held.
fn commit_group<S: Store>(
    store: &S,
    ops: Vec<WriteOp>,
    events: &Events,
) -> Option<(GroupFailure, Unconfirmed)> {
    let mut attempt = 1;
    let applied = loop {
        let applied = Group::apply_all(store, &ops);
        match &applied.failure {
            Some(failure) if failure.conflict && attempt < CONFLICT_ATTEMPTS => {
                tracing::debug!(attempt, reason = %failure.reason, "group met a concurrent write; applying it again");
                // Back off a little longer each time, so the two sides part.
                std::thread::sleep(Duration::from_millis(u64::from(attempt) * 3));
                attempt += 1;
            }
            _ => break applied,
        }
    };
    applied.finish(ops, events)
}

/// What applying one request gave, to be answered once the group's fate
/// is known.
enum Outcome {
    Map(Result<MapRecord, StoreError>),
    Unit(Result<(), StoreError>),
    Ack(Result<Ack, StoreError>),
    Frames(Result<(u32, u32), StoreError>),
    /// The request was never applied (the transaction could not begin).
    Skipped,
}

/// Answers `op` with its outcome, or with the group's failure.
fn respond(op: WriteOp, outcome: Outcome, failure: Option<&GroupFailure>) {
    fn send<T>(reply: Reply<T>, value: Result<T, StoreError>, failure: Option<&GroupFailure>) {
        let result = match failure {
            Some(failure) => Err(StoreError::NotCommitted {
                reason: failure.reason.clone(),
                transient: failure.transient,
            }),
            None => value,
        };
        let _ = reply.send(result);
    }
    fn skipped<T>() -> Result<T, StoreError> {
        Err(StoreError::Backend("the write was not applied".into()))
    }
    match (op, outcome) {
        (WriteOp::CreateMap(_, r) | WriteOp::ClearMap(_, r), Outcome::Map(value)) => {
            send(r, value, failure)
        }
        (WriteOp::CreateMap(_, r) | WriteOp::ClearMap(_, r), _) => send(r, skipped(), failure),
        (WriteOp::DeleteMap(_, r) | WriteOp::Pose(_, _, r), Outcome::Unit(value)) => {
            send(r, value, failure)
        }
        (WriteOp::DeleteMap(_, r) | WriteOp::Pose(_, _, r), _) => send(r, skipped(), failure),
        (WriteOp::Apply(batch, r), Outcome::Ack(value)) => {
            if failure.is_some() || value.is_err() {
                batch.break_stream();
            }
            send(r, value, failure)
        }
        (WriteOp::Apply(batch, r), _) => {
            batch.break_stream();
            send(r, skipped(), failure)
        }
        (WriteOp::Frames(_, r), Outcome::Frames(value)) => send(r, value, failure),
        (WriteOp::Frames(_, r), _) => send(r, skipped(), failure),
        (WriteOp::Probe | WriteOp::Stop, _) => {}
    }
}

/// A group after its transaction ended.
struct Applied {
    outcomes: Vec<Outcome>,
    failure: Option<GroupFailure>,
    map_events: Vec<(String, MapEvent)>,
    frame_events: Vec<FrameNote>,
    pose_events: Vec<Arc<PoseEstimate>>,
}

impl Applied {
    fn failed(failure: GroupFailure) -> Self {
        Self {
            outcomes: Vec::new(),
            failure: Some(failure),
            map_events: Vec::new(),
            frame_events: Vec::new(),
            pose_events: Vec::new(),
        }
    }

    /// Answers every request and tells the watchers what landed.
    fn finish(self, ops: Vec<WriteOp>, events: &Events) -> Option<(GroupFailure, Unconfirmed)> {
        if let Some(failure) = &self.failure {
            tracing::error!(failure = %failure.reason, "group commit failed");
        }
        let failure = self.failure.as_ref();
        let outcomes = self
            .outcomes
            .into_iter()
            .chain(std::iter::repeat_with(|| Outcome::Skipped));
        for (op, outcome) in ops.into_iter().zip(outcomes) {
            respond(op, outcome, failure);
        }
        if let Some(failure) = self.failure {
            let unconfirmed = Unconfirmed {
                map_events: self.map_events,
                frame_events: self.frame_events,
                pose_events: self.pose_events,
            };
            return Some((failure, unconfirmed));
        }
        let mut by_map: BTreeMap<String, Vec<MapEvent>> = BTreeMap::new();
        for (map, event) in self.map_events {
            by_map.entry(map).or_default().push(event);
        }
        for (map, list) in by_map {
            events.map_changed(&map, list);
        }
        for note in self.frame_events {
            events.frame_stored(note);
        }
        for pose in self.pose_events {
            events.pose_stored(pose);
        }
        None
    }
}

/// A map's state while a group is being applied.
struct PendingMap {
    record: MapRecord,
    tiles: HashMap<TileKey, StoredTile>,
    /// Keys read from the store (stored or not), so each is read once.
    read_tiles: HashSet<TileKey>,
    /// Tiles changed in this group, with the version of their last change.
    dirty: BTreeMap<TileKey, u64>,
    cursors: HashMap<String, ClientCursor>,
    dirty_cursors: HashSet<String>,
    record_dirty: bool,
}

impl PendingMap {
    /// Reads the tiles among `keys` not read yet.
    fn read_tiles(
        &mut self,
        txn: &mut dyn Transaction,
        keys: impl Iterator<Item = TileKey>,
    ) -> Result<(), StoreError> {
        let missing: Vec<TileKey> = keys.filter(|k| !self.read_tiles.contains(k)).collect();
        if missing.is_empty() {
            return Ok(());
        }
        for (key, tile) in txn.tiles(&self.record, &missing)? {
            self.tiles.insert(key, tile);
        }
        self.read_tiles.extend(missing);
        Ok(())
    }
}

/// A robot's summary, the sequences it has stored among those this group
/// brings, and the frames (sequence, encoded frame) added in this group.
struct PendingRobot {
    summary: RobotSummary,
    stored: HashSet<u64>,
    frames: Vec<(u64, Vec<u8>)>,
}

/// What a group will touch, gathered before it is applied, so the store
/// is read in a few large reads and locked in one order.
#[derive(Default)]
struct Wanted {
    /// Per map: tile keys and client ids its batches name.
    maps: BTreeMap<String, (BTreeSet<TileKey>, BTreeSet<String>)>,
    /// Per robot: the frame sequences the group brings.
    robots: BTreeMap<String, BTreeSet<u64>>,
}

impl Wanted {
    fn of(ops: &[WriteOp]) -> Self {
        let mut wanted = Self::default();
        for op in ops {
            match op {
                WriteOp::Apply(batch, _) => {
                    let (keys, clients) = wanted.maps.entry(batch.map.clone()).or_default();
                    keys.extend(batch.deltas.iter().map(|d| d.key));
                    clients.insert(batch.client_id.clone());
                }
                WriteOp::ClearMap(name, _) | WriteOp::DeleteMap(name, _) => {
                    wanted.maps.entry(name.clone()).or_default();
                }
                WriteOp::Frames(frames, _) => {
                    for frame in frames {
                        wanted
                            .robots
                            .entry(frame.robot.clone())
                            .or_default()
                            .insert(frame.sequence);
                    }
                }
                WriteOp::CreateMap(..) | WriteOp::Pose(..) | WriteOp::Probe | WriteOp::Stop => {}
            }
        }
        wanted
    }
}

struct Group<'t> {
    txn: Box<dyn Transaction + 't>,
    wanted: Wanted,
    /// Streams one of whose batches failed in this attempt (their flags
    /// are set only once the group's fate is known: an attempt that met a
    /// concurrent write is made again).
    broken_here: Vec<Arc<AtomicBool>>,
    maps: HashMap<String, PendingMap>,
    robots: BTreeMap<String, PendingRobot>,
    poses: Vec<(String, u64, Vec<u8>)>,
    map_events: Vec<(String, MapEvent)>,
    frame_events: Vec<FrameNote>,
    pose_events: Vec<Arc<PoseEstimate>>,
    failure: Option<GroupFailure>,
}

impl<'t> Group<'t> {
    /// Applies `ops` in one transaction of `store` and commits it.
    fn apply_all<S: Store>(store: &'t S, ops: &[WriteOp]) -> Applied {
        let txn = match store.begin() {
            Ok(txn) => txn,
            Err(error) => return Applied::failed(GroupFailure::of(&error)),
        };
        let mut group = Group {
            txn,
            wanted: Wanted::of(ops),
            broken_here: Vec::new(),
            maps: HashMap::new(),
            robots: BTreeMap::new(),
            poses: Vec::new(),
            map_events: Vec::new(),
            frame_events: Vec::new(),
            pose_events: Vec::new(),
            failure: None,
        };
        let outcomes = match group.lock() {
            Ok(()) => ops.iter().map(|op| group.apply(op)).collect(),
            Err(error) => {
                group.fail(&error);
                Vec::new()
            }
        };
        group.write_maps();
        group.write_rest();
        let Group {
            txn,
            mut failure,
            map_events,
            frame_events,
            pose_events,
            ..
        } = group;
        if failure.is_none() {
            failure = txn.commit().err().map(|error| GroupFailure::of(&error));
        }
        Applied {
            outcomes,
            failure,
            map_events,
            frame_events,
            pose_events,
        }
    }

    /// Locks what the group writes, maps before robots, each in name order.
    fn lock(&mut self) -> Result<(), StoreError> {
        let maps: Vec<&str> = self.wanted.maps.keys().map(String::as_str).collect();
        self.txn.lock_maps(&maps)?;
        let robots: Vec<&str> = self.wanted.robots.keys().map(String::as_str).collect();
        self.txn.lock_robots(&robots)
    }

    /// Records the first failure of the store itself: the whole group
    /// fails with it.
    fn fail(&mut self, error: &StoreError) {
        self.failure.get_or_insert_with(|| GroupFailure::of(error));
    }

    /// Passes a request's result on, failing the group if the store failed.
    fn check<T>(&mut self, result: Result<T, StoreError>) -> Result<T, StoreError> {
        if let Err(error) = &result
            && error.is_backend()
        {
            self.fail(error);
        }
        result
    }

    fn apply(&mut self, op: &WriteOp) -> Outcome {
        match op {
            WriteOp::CreateMap(record, _) => {
                self.write_maps();
                let result = self.txn.create_map(record).map(|()| record.clone());
                Outcome::Map(self.check(result))
            }
            WriteOp::ClearMap(name, _) => {
                self.write_maps();
                let result = self.clear(name);
                Outcome::Map(self.check(result))
            }
            WriteOp::DeleteMap(name, _) => {
                self.write_maps();
                let result = self.txn.delete_map(name);
                if result.is_ok() {
                    self.map_events.push((name.clone(), MapEvent::Deleted));
                }
                Outcome::Unit(self.check(result))
            }
            WriteOp::Apply(batch, _) => {
                let broken = batch.stream_is_broken()
                    || self
                        .broken_here
                        .iter()
                        .any(|flag| Arc::ptr_eq(flag, &batch.stream_broken));
                let result = if broken {
                    Err(StoreError::Unavailable(format!(
                        "an earlier batch of this update stream was not applied; send again \
                         from it (batch {} of client {:?} was not applied)",
                        batch.sequence, batch.client_id
                    )))
                } else {
                    self.apply_batch(batch)
                };
                if result.is_err() {
                    self.broken_here.push(batch.stream_broken.clone());
                }
                Outcome::Ack(self.check(result))
            }
            WriteOp::Frames(frames, _) => {
                let result = self.add_frames(frames);
                Outcome::Frames(self.check(result))
            }
            WriteOp::Pose(pose, bytes, _) => {
                // Checked here rather than in the handler, so that a map
                // deleted meanwhile cannot slip in between.
                let result = if self.maps.contains_key(&pose.map) {
                    Ok(())
                } else {
                    match self.txn.map(&pose.map) {
                        Ok(Some(_)) => Ok(()),
                        Ok(None) => Err(StoreError::MapNotFound(pose.map.clone())),
                        Err(error) => Err(error),
                    }
                };
                if result.is_ok() {
                    self.poses
                        .push((pose.robot.clone(), pose.frame_sequence, bytes.clone()));
                    self.pose_events.push(pose.clone());
                }
                Outcome::Unit(self.check(result))
            }
            WriteOp::Probe | WriteOp::Stop => Outcome::Skipped,
        }
    }

    fn clear(&mut self, name: &str) -> Result<MapRecord, StoreError> {
        let mut record = self
            .txn
            .map(name)?
            .ok_or_else(|| StoreError::MapNotFound(name.to_string()))?;
        record.version += 1;
        record.tile_count = 0;
        record.cell_count = 0;
        record.bounds = None;
        self.txn.write_map(
            name,
            MapWrite {
                record: Some(record.clone()),
                clear_tiles: true,
                ..MapWrite::default()
            },
        )?;
        self.map_events.push((
            name.to_string(),
            MapEvent::Cleared {
                version: record.version,
            },
        ));
        Ok(record)
    }

    /// Reads map `name` into the group, with the tiles and cursors its
    /// batches in this group name, unless it is there already.
    fn pend(&mut self, name: &str) -> Result<(), StoreError> {
        if self.maps.contains_key(name) {
            return Ok(());
        }
        let record = self
            .txn
            .map(name)?
            .ok_or_else(|| StoreError::MapNotFound(name.to_string()))?;
        let mut map = PendingMap {
            record,
            tiles: HashMap::new(),
            read_tiles: HashSet::new(),
            dirty: BTreeMap::new(),
            cursors: HashMap::new(),
            dirty_cursors: HashSet::new(),
            record_dirty: false,
        };
        if let Some((keys, clients)) = self.wanted.maps.get(name) {
            map.read_tiles(self.txn.as_mut(), keys.iter().copied())?;
            let clients: Vec<&str> = clients.iter().map(String::as_str).collect();
            map.cursors = self.txn.cursors(name, &clients)?.into_iter().collect();
            for client in clients {
                map.cursors.entry(client.to_string()).or_default();
            }
        }
        self.maps.insert(name.to_string(), map);
        Ok(())
    }

    fn apply_batch(&mut self, batch: &Batch) -> Result<Ack, StoreError> {
        self.pend(&batch.map)?;
        let Group { maps, txn, .. } = self;
        let map = maps
            .get_mut(&batch.map)
            .ok_or_else(|| StoreError::MapNotFound(batch.map.clone()))?;
        if !map.cursors.contains_key(&batch.client_id) {
            let read = txn.cursors(&batch.map, &[batch.client_id.as_str()])?;
            let cursor = read.into_iter().next().map(|(_, c)| c).unwrap_or_default();
            map.cursors.insert(batch.client_id.clone(), cursor);
        }
        let cursor = map
            .cursors
            .get(&batch.client_id)
            .cloned()
            .unwrap_or_default();
        match cursor.check(batch.sequence) {
            SequenceCheck::Next => {}
            // Below the kept sequences a batch out of order cannot be told
            // from a resend; a resend is the likelier, and the safe answer.
            SequenceCheck::Applied | SequenceCheck::Unknown => {
                return Ok(Ack {
                    applied: false,
                    map_version: map.record.version,
                });
            }
            SequenceCheck::NeverApplied => {
                return Err(StoreError::SequenceOutOfOrder {
                    map: batch.map.clone(),
                    client: batch.client_id.clone(),
                    sequence: batch.sequence,
                    last: cursor.last,
                });
            }
        }
        let size = map.record.settings.tile_size;
        if let Some(delta) = batch.deltas.iter().find(|d| d.raw().len() != size.area()) {
            return Err(StoreError::invalid(
                "tiles.cells",
                format!(
                    "tile ({}, {}) has the wrong number of cells",
                    delta.key.x, delta.key.y
                ),
            ));
        }
        map.read_tiles(txn.as_mut(), batch.deltas.iter().map(|d| d.key))?;
        let version = map.record.version + 1;
        for delta in &batch.deltas {
            let is_new = !map.tiles.contains_key(&delta.key);
            let newly_observed = delta
                .raw()
                .iter()
                .zip(
                    map.tiles
                        .get(&delta.key)
                        .map(|t| t.tile.raw_cells())
                        .unwrap_or(&[]),
                )
                .filter(|&(&d, &c)| d != 0 && c == LogOdds::UNKNOWN_RAW)
                .count()
                + if is_new { delta.nonzero_count() } else { 0 };
            if is_new && newly_observed == 0 {
                // No evidence for an unstored tile: nothing to store.
                continue;
            }
            let stored = map.tiles.entry(delta.key).or_insert_with(|| StoredTile {
                version,
                tile: Tile::unknown(size),
            });
            stored
                .tile
                .apply(delta, map.record.settings.clamp)
                .map_err(|e| StoreError::grid("tiles.cells", e))?;
            stored.version = version;
            map.dirty.insert(delta.key, version);
            if is_new {
                map.record.tile_count += 1;
            }
            map.record.cell_count += newly_observed as u64;
            if newly_observed > 0
                && let Some(cells) = evidence_box(size, delta)
            {
                map.record.bounds = Some(match map.record.bounds {
                    Some(b) => b.union(&cells),
                    None => cells,
                });
            }
        }
        map.record.version = version;
        map.record_dirty = true;
        if let Some(cursor) = map.cursors.get_mut(&batch.client_id) {
            cursor.applied(batch.sequence);
        }
        map.dirty_cursors.insert(batch.client_id.clone());
        Ok(Ack {
            applied: true,
            map_version: version,
        })
    }

    /// Writes every pending map (within the transaction), before an admin
    /// operation or at the end of the group.
    fn write_maps(&mut self) {
        for (name, map) in std::mem::take(&mut self.maps) {
            if !map.record_dirty {
                continue;
            }
            let tiles: Vec<(TileKey, StoredTile)> = map
                .dirty
                .keys()
                .filter_map(|k| map.tiles.get(k).map(|t| (*k, t.clone())))
                .collect();
            let cursors = map
                .dirty_cursors
                .iter()
                .filter_map(|c| map.cursors.get(c).map(|s| (c.clone(), s.clone())))
                .collect();
            let write = MapWrite {
                record: Some(map.record),
                clear_tiles: false,
                tiles,
                cursors,
            };
            if let Err(error) = self.txn.write_map(&name, write) {
                self.fail(&error);
                continue;
            }
            for (key, version) in map.dirty {
                self.map_events
                    .push((name.clone(), MapEvent::TileChanged { key, version }));
            }
        }
    }

    fn add_frames(&mut self, frames: &[EncodedFrame]) -> Result<(u32, u32), StoreError> {
        let (mut stored, mut duplicates) = (0u32, 0u32);
        for frame in frames {
            if !self.robots.contains_key(&frame.robot) {
                let summary = self.txn.robot(&frame.robot)?.unwrap_or_default();
                let sequences: Vec<u64> = self
                    .wanted
                    .robots
                    .get(&frame.robot)
                    .map(|s| s.iter().copied().collect())
                    .unwrap_or_default();
                let known = self.txn.stored_frames(&frame.robot, &sequences)?;
                self.robots.insert(
                    frame.robot.clone(),
                    PendingRobot {
                        summary,
                        stored: known.into_iter().collect(),
                        frames: Vec::new(),
                    },
                );
            }
            let Some(robot) = self.robots.get_mut(&frame.robot) else {
                continue;
            };
            if robot.stored.contains(&frame.sequence) {
                duplicates += 1;
                continue;
            }
            robot.stored.insert(frame.sequence);
            robot.summary = robot.summary.with(frame.sequence);
            robot.frames.push((frame.sequence, frame.bytes.clone()));
            self.frame_events.push(FrameNote {
                robot: Arc::from(frame.robot.as_str()),
                sequence: frame.sequence,
            });
            stored += 1;
        }
        Ok((stored, duplicates))
    }

    fn write_rest(&mut self) {
        let writes: Vec<FrameWrite> = std::mem::take(&mut self.robots)
            .into_iter()
            .filter(|(_, robot)| !robot.frames.is_empty())
            .map(|(name, robot)| FrameWrite {
                robot: name,
                summary: robot.summary,
                frames: robot.frames,
            })
            .collect();
        if !writes.is_empty()
            && let Err(error) = self.txn.write_frames(writes)
        {
            self.fail(&error);
        }
        let poses = std::mem::take(&mut self.poses);
        if !poses.is_empty()
            && let Err(error) = self.txn.write_poses(poses)
        {
            self.fail(&error);
        }
    }
}

/// The box of cells with evidence in `delta`.
fn evidence_box(size: TileSize, delta: &TileDelta) -> Option<CellBox> {
    let side = size.cells() as usize;
    let (mut min_x, mut min_y, mut max_x, mut max_y) = (usize::MAX, usize::MAX, 0, 0);
    for (row, cells) in delta.raw().chunks_exact(side).enumerate() {
        let Some(first) = cells.iter().position(|&d| d != 0) else {
            continue;
        };
        let last = cells.iter().rposition(|&d| d != 0).unwrap_or(first);
        min_x = min_x.min(first);
        max_x = max_x.max(last);
        min_y = min_y.min(row);
        max_y = row;
    }
    if min_x == usize::MAX {
        return None;
    }
    let origin = size.origin(delta.key).ok()?;
    CellBox::new(
        CellIndex::new(origin.x + min_x as i32, origin.y + min_y as i32),
        CellIndex::new(origin.x + max_x as i32, origin.y + max_y as i32),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_commit_reaches_each_write_worded_once() {
        let (reply, answer) = oneshot::channel::<Result<(), StoreError>>();
        let failure = GroupFailure::of(&StoreError::Backend("disk full".into()));
        respond(
            WriteOp::DeleteMap("m".into(), reply),
            Outcome::Unit(Ok(())),
            Some(&failure),
        );
        let error = answer.blocking_recv().unwrap().unwrap_err();
        assert_eq!(error.to_string(), "storage failure: disk full");
        assert_eq!(tonic::Status::from(error).code(), tonic::Code::Internal);
    }
}
