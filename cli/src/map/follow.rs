//! The frame loop of `deog map`: frames taken in batches of those waiting,
//! each turned into tile deltas by its rig's cartographer (its view of the
//! map read where the frame needs it, and anew every refresh period), the
//! deltas sent as one update batch numbered by the last frame it holds.

use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::ops::ControlFlow::{self, Break, Continue};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::{FrameMotion, TileDelta, TileKey, TileSize};
use deog_mapping::{FrameInput, MapView, MappingError};
use deog_proto::v1 as pb;
use deog_robot_client::convert::{pose_from_wire, pose_or_origin};
use deog_robot_client::{AckState, MapClient, UpdateSender};

use super::by_rig::CartographerByRig;
use super::estimates::EstimateFollower;

/// Tiles pending in the sender at which a batch is sent before the frames
/// taken together are all mapped: a batch stays well under the server's
/// request limit.
const MAX_BATCH_TILES: usize = 256;

/// Where the frame loop's frames go, and how it takes them.
pub(super) struct MappingEnds<'a> {
    pub client: &'a MapClient,
    pub map: &'a str,
    pub tile_size: TileSize,
    pub cartographers: CartographerByRig,
    pub sender: UpdateSender,
    /// `--ack-log`: a line per batch sent, once acknowledged.
    pub ack_log: Option<BufWriter<File>>,
    /// With `--pose estimate`, the localizer's estimates followed.
    pub estimates: Option<EstimateFollower>,
    /// The first frame to map and the last (0: no end).
    pub start: u64,
    pub to: u64,
    /// How often the cartographer's view of the map is read anew.
    pub view_refresh: Duration,
}

/// The frame loop's state: its ends and what it counted.
pub(super) struct Mapping<'a> {
    ends: MappingEnds<'a>,
    view_read: Instant,
    frame_motion: FrameMotion,
    deltas: Vec<TileDelta>,
    /// Frames mapped, cell updates made and the last frame taken.
    pub integrated: u64,
    pub cells: u64,
    pub last: u64,
    /// Frames skipped because their values cannot be mapped.
    pub unusable: u64,
}

impl<'a> Mapping<'a> {
    /// A loop that has mapped nothing yet.
    pub(super) fn new(ends: MappingEnds<'a>) -> Self {
        Self {
            ends,
            view_read: Instant::now(),
            frame_motion: FrameMotion::default(),
            deltas: Vec::new(),
            integrated: 0,
            cells: 0,
            last: 0,
            unusable: 0,
        }
    }

    /// The estimates followed, with their counts, once the loop is over.
    pub(super) fn take_estimates(&mut self) -> Option<EstimateFollower> {
        self.ends.estimates.take()
    }
}

impl Mapping<'_> {
    /// Maps `batch`, frames taken together, and sends what they changed as
    /// one update batch (or more, past [`MAX_BATCH_TILES`]). Breaks after
    /// the last frame asked for.
    pub(super) async fn batch(
        &mut self,
        batch: impl IntoIterator<Item = pb::SonarFrame>,
    ) -> Result<ControlFlow<()>> {
        let mut flow = Continue(());
        for frame in batch {
            flow = self.frame(frame).await?;
            if flow.is_break() {
                break;
            }
        }
        if self.last > 0 {
            self.send().await?;
        }
        Ok(flow)
    }

    /// Maps one frame into the sender's pending batch.
    async fn frame(&mut self, frame: pb::SonarFrame) -> Result<ControlFlow<()>> {
        if frame.sequence < self.ends.start || frame.sequence <= self.last {
            return Ok(Continue(()));
        }
        if self.ends.to > 0 && frame.sequence > self.ends.to {
            return Ok(Break(()));
        }
        self.deltas.clear();
        let estimate = match &mut self.ends.estimates {
            Some(follower) => match follower.pose_for(frame.sequence).await? {
                Some(pose) => Some(pose),
                // Stopping while the frame waited: left for the next run.
                None if follower.stopping() => return Ok(Break(())),
                None => {
                    // No converged estimate for it: not mapped.
                    self.last = frame.sequence;
                    return Ok(Continue(()));
                }
            },
            None => None,
        };
        let odometry = pose_or_origin(frame.odometry);
        let pace = self.frame_motion.observe(&odometry, frame.time_s);
        let input = FrameInput {
            sequence: frame.sequence,
            pace,
            true_pose: frame.true_pose.map(pose_from_wire),
            odometry,
            reference_pose: frame.reference_pose.map(pose_from_wire),
            estimate,
            ranges: &frame.ranges,
        };
        let cartographer = self
            .ends
            .cartographers
            .for_frame(&frame.rig, frame.sequence)
            .await?;
        if let Some(view) = cartographer.view_mut() {
            if self.view_read.elapsed() >= self.ends.view_refresh {
                // Read again what other writers changed.
                view.clear();
                self.view_read = Instant::now();
            }
        }
        let missing = match cartographer.missing_tiles(&input) {
            Err(MappingError::UnusableFrame { sequence, reason }) => {
                return Ok(self.skip_unusable(sequence, &reason));
            }
            other => other?,
        };
        if let (false, Some(view)) = (missing.is_empty(), cartographer.view_mut()) {
            fill_view(
                self.ends.client,
                self.ends.map,
                self.ends.tile_size,
                view,
                &missing,
            )
            .await?;
        }
        self.cells += match cartographer.integrate(&input, &mut self.deltas) {
            Err(MappingError::UnusableFrame { sequence, reason }) => {
                self.deltas.clear();
                return Ok(self.skip_unusable(sequence, &reason));
            }
            other => other? as u64,
        };
        for delta in self.deltas.drain(..) {
            self.ends.sender.push(delta).await?;
        }
        self.last = frame.sequence;
        self.integrated += 1;
        if self.ends.sender.pending_tiles() >= MAX_BATCH_TILES {
            self.send().await?;
        }
        Ok(if self.ends.to > 0 && frame.sequence >= self.ends.to {
            Break(())
        } else {
            Continue(())
        })
    }

    /// A frame whose values cannot be mapped: skipped with a warning that
    /// names it, and the mapping goes on.
    fn skip_unusable(&mut self, sequence: u64, reason: &str) -> ControlFlow<()> {
        tracing::warn!(frame = sequence, reason, "frame cannot be mapped: skipped");
        self.unusable += 1;
        self.last = sequence;
        if self.ends.to > 0 && sequence >= self.ends.to {
            Break(())
        } else {
            Continue(())
        }
    }

    /// Sends the pending deltas as one batch numbered by the last frame
    /// taken; with `--ack-log`, waits for its acknowledgement and logs it.
    async fn send(&mut self) -> Result<()> {
        if self.ends.sender.pending_tiles() == 0 {
            return Ok(());
        }
        // Read before sending: the acknowledgement may arrive at once.
        let before = self.ends.sender.acks();
        self.ends.sender.send_batch_as(self.last).await?;
        if let Some(log) = &mut self.ends.ack_log {
            let after = self.ends.sender.flush().await?;
            writeln!(
                log,
                "{} {} {}",
                after.last_acked,
                after.map_version,
                after.applied > before.applied
            )
            .context("writing the ack log")?;
            log.flush().context("writing the ack log")?;
        }
        Ok(())
    }

    /// Sends what is left and waits for every acknowledgement.
    pub(super) async fn close(self) -> Result<AckState> {
        Ok(self.ends.sender.close().await?)
    }
}

/// Reads `keys`, tiles of `map`, into `view`; a tile the server does not
/// hold is held as unknown.
async fn fill_view(
    client: &MapClient,
    map: &str,
    tile_size: TileSize,
    view: &mut MapView,
    keys: &[TileKey],
) -> Result<()> {
    let tiles = client
        .tiles_by_key(map, tile_size, keys)
        .await
        .with_context(|| format!("reading {} tiles of map {map} around the robot", keys.len()))?;
    let mut found = std::collections::HashSet::with_capacity(tiles.len());
    for (key, _, tile) in tiles {
        found.insert(key);
        view.insert(key, tile)?;
    }
    for &key in keys.iter().filter(|key| !found.contains(key)) {
        view.insert_unknown(key)?;
    }
    Ok(())
}
