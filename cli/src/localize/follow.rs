//! The frame loop of `deog localize`: the robot's frames taken in turn
//! (or, following a live robot faster than the filter, the newest within
//! reach, the ones passed over given the last estimate carried by their
//! odometry), the map's changes noted, the localizer stepped, its estimate
//! published.

use std::future::Future;
use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use deog_grid::{Pose2, normalize_angle};
use deog_localizer::error::LocalizerError;
use deog_localizer::searcher::{Searcher, SearcherStats};
use deog_localizer::step::Localizer;
use deog_proto::rig::frame_rig_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_from_wire;
use deog_robot_client::{TileChange, TileWatch};

use super::carry::{Carrier, worth_carrying};
use super::server::{EstimateSink, ServerTiles, log_estimate};
use crate::frame_queue::{CatchUp, FrameQueue, ReplayProgress};

/// A sensor update that takes this long is logged with what it did: the
/// robot's frames come ten a second.
const SLOW_STEP: Duration = Duration::from_millis(100);

/// How the loop takes the frames, from `deog localize`'s flags.
pub(super) struct FollowSettings {
    /// Take the newest frame within reach when more wait (a live robot).
    pub keep_up: bool,
    /// The last frame to take; 0: no end.
    pub to: u64,
    /// Most seconds of frames skipped at once to keep up.
    pub max_skip_s: f64,
    /// Particles sent with an estimate for viewers; 0: none.
    pub particle_sample: usize,
    /// Least seconds of the frames' time between two such samples.
    pub particle_sample_every_s: f64,
}

/// What the loop reads from and writes to.
pub(super) struct Ends<'a> {
    pub runtime: &'a tokio::runtime::Runtime,
    /// The robot's frames.
    pub queue: FrameQueue,
    /// The map's tiles, and what changed in them.
    pub tiles: ServerTiles<'a>,
    pub changes: TileWatch,
    /// Where the estimates go, and the thread that carries the last one to
    /// frames arriving during a slow step.
    pub sink: EstimateSink<'a>,
    pub carrier: Carrier<'a>,
    pub progress: ReplayProgress,
}

/// What the loop did, for the summary line.
pub(super) struct Followed {
    pub processed: u64,
    pub corrections: u64,
    /// Corrections whose tracked pose was first realigned to the frame.
    pub realigned: u64,
    /// Corrections whose estimate a rival nearby made ambiguous.
    pub ambiguous: u64,
    /// Frames skipped to keep up.
    pub skipped: u64,
    /// Frames skipped for values the filter cannot use.
    pub unusable: u64,
    /// The most seconds of frames that came while one step ran: how far
    /// the filter's evidence fell behind.
    pub filter_lag_s: f64,
}

/// The loop's state between frames.
struct Following<'a> {
    settings: FollowSettings,
    ends: Ends<'a>,
    /// The rig field of the first frame: later frames must name the same.
    rig_field: String,
    processed: u64,
    /// Frames skipped for values the filter cannot use.
    unusable: u64,
    corrections: u64,
    realigned: u64,
    ambiguous: u64,
    last_sequence: u64,
    /// Frame time of the last estimate sent with particles.
    sampled_at: Option<f64>,
    catch_up: CatchUp,
    /// How long the last step took.
    last_took: Duration,
    filter_lag_s: f64,
}

/// The next frame of `queue`, or `None` at its end or once `shutdown`
/// fires.
pub(super) fn next_frame(
    runtime: &tokio::runtime::Runtime,
    queue: &mut FrameQueue,
    shutdown: &mut (impl Future<Output = ()> + Unpin),
) -> Result<Option<pb::SonarFrame>> {
    runtime.block_on(async {
        tokio::select! {
            () = shutdown => Ok(None),
            frame = queue.next() => frame,
        }
    })
}

/// Localizes `first` and every frame after it with `localizer` until the
/// frames end, the last frame `settings.to` is done or `shutdown` fires.
pub(super) fn follow(
    localizer: &mut Localizer,
    first: pb::SonarFrame,
    ends: Ends<'_>,
    settings: FollowSettings,
    shutdown: &mut (impl Future<Output = ()> + Unpin),
) -> Result<Followed> {
    let mut following = Following {
        catch_up: CatchUp::new(settings.max_skip_s),
        settings,
        ends,
        rig_field: first.rig.clone(),
        processed: 0,
        unusable: 0,
        corrections: 0,
        realigned: 0,
        ambiguous: 0,
        last_sequence: 0,
        sampled_at: None,
        last_took: Duration::ZERO,
        filter_lag_s: 0.0,
    };
    let mut first = Some(first);
    loop {
        let next = match first.take().or_else(|| following.catch_up.next_waiting()) {
            Some(frame) => Some(frame),
            None => next_frame(following.ends.runtime, &mut following.ends.queue, shutdown)?,
        };
        let Some(frame) = next else { break };
        if following.take(frame, localizer)?.is_break() {
            break;
        }
    }
    following.ends.progress.finish();
    Ok(Followed {
        processed: following.processed,
        corrections: following.corrections,
        realigned: following.realigned,
        ambiguous: following.ambiguous,
        skipped: following.catch_up.skipped(),
        unusable: following.unusable,
        filter_lag_s: following.filter_lag_s,
    })
}

impl Following<'_> {
    /// Localizes `frame` (or the newest frame within reach, keeping up)
    /// and publishes the estimate. Breaks after the last frame asked for.
    fn take(
        &mut self,
        frame: pb::SonarFrame,
        localizer: &mut Localizer,
    ) -> Result<std::ops::ControlFlow<()>> {
        use std::ops::ControlFlow::{Break, Continue};
        let frame = if self.settings.keep_up {
            self.newest_within_reach(frame, localizer)?
        } else {
            frame
        };
        if frame.rig != self.rig_field {
            bail!(
                "frame {} comes from rig {}, the robot's earlier frames from {}: restart the localizer for the new rig",
                frame.sequence,
                frame_rig_name(&frame.rig),
                frame_rig_name(&self.rig_field)
            );
        }
        let to = self.settings.to;
        if frame.sequence <= self.last_sequence {
            return Ok(Continue(()));
        }
        if to > 0 && frame.sequence > to {
            return Ok(Break(()));
        }
        self.last_sequence = frame.sequence;
        while let Some(change) = self.ends.changes.try_next() {
            match change {
                TileChange::Tile(key) => localizer.tile_changed(key),
                TileChange::All => localizer.all_changed(),
            }
        }
        self.step(&frame, localizer)?;
        self.ends.progress.reached(frame.sequence);
        Ok(if to > 0 && frame.sequence >= to {
            Break(())
        } else {
            Continue(())
        })
    }

    /// Keeping up: the newest frame within reach of `frame` and those
    /// waiting. While the step with it runs, the newest frame passed over
    /// gets the estimate of now: the last step's, carried by that frame's
    /// odometry (as amcl's pose follows odometry between its filter
    /// updates).
    fn newest_within_reach(
        &mut self,
        frame: pb::SonarFrame,
        localizer: &Localizer,
    ) -> Result<pb::SonarFrame> {
        let waiting = self.ends.runtime.block_on(self.ends.queue.ready());
        let (newest, passed) =
            self.catch_up
                .newest_within_reach(frame, waiting, self.processed == 0);
        let passed = passed.filter(|p| self.processed > 0 && p.sequence > self.last_sequence);
        if let Some(passed) = passed {
            let estimate = passed
                .odometry
                .map(pose_from_wire)
                .and_then(|odometry| localizer.estimate(&odometry));
            if let Some(estimate) = estimate {
                self.ends.sink.publish(&passed, &estimate, &[])?;
            }
        }
        Ok(newest)
    }

    /// One localizer step with `frame`, its estimate published.
    fn step(&mut self, frame: &pb::SonarFrame, localizer: &mut Localizer) -> Result<()> {
        let Some(odometry) = frame.odometry.map(pose_from_wire) else {
            tracing::warn!(
                frame = frame.sequence,
                "frame cannot be localized: it has no odometry pose; skipped"
            );
            self.unusable += 1;
            return Ok(());
        };
        localizer.note_frame(&odometry, frame.time_s);
        let particles = localizer.mcl().particles().len();
        let searched_before = localizer.searcher().map(|s| search_events(&s.stats()));
        let started = Instant::now();
        let carried = localizer
            .carried()
            .filter(|_| self.settings.keep_up && worth_carrying(particles, self.last_took));
        let ends = &mut self.ends;
        let report = match carried {
            Some(carried) => {
                // The frames that come meanwhile get the estimate of now
                // from a thread beside the step, then wait their turn.
                let (report, arrived) = ends.carrier.beside(
                    ends.runtime,
                    &mut ends.queue,
                    carried,
                    frame.sequence,
                    || localizer.step(&odometry, &frame.ranges, started, &mut ends.tiles),
                )?;
                if let Some(newest) = arrived.last() {
                    self.filter_lag_s = self.filter_lag_s.max(newest.time_s - frame.time_s);
                }
                self.catch_up.hold(arrived);
                report
            }
            None => localizer.step(&odometry, &frame.ranges, started, &mut ends.tiles),
        };
        let report = match report {
            Ok(report) => report,
            // What is wrong is this frame's: the next may do.
            Err(error @ (LocalizerError::Invalid(_) | LocalizerError::Grid(_))) => {
                tracing::warn!(frame = frame.sequence, %error, "frame cannot be localized: skipped");
                self.unusable += 1;
                return Ok(());
            }
            Err(error) => {
                return Err(anyhow::Error::new(error).context(format!("frame {}", frame.sequence)));
            }
        };
        let took = started.elapsed();
        self.last_took = took;
        if let Some(searcher) = localizer.searcher()
            && Some(search_events(&searcher.stats())) != searched_before
        {
            let stats = searcher.stats();
            tracing::info!(
                frame = frame.sequence,
                ms = took.as_millis() as u64,
                searches = stats.searches,
                ended = stats.ended,
                cut_short = stats.incomplete,
                confirmations = stats.confirmations,
                vetoes = stats.vetoes,
                unfit = stats.unfit,
                undecided = stats.undecided,
                dropped = stats.dropped,
                unsettled = stats.unsettled,
                fits_worse = stats.fits_worse,
                jumps = stats.jumps,
                lookups_per_frame = searcher.slice_lookups(),
                particles = localizer.mcl().particles().len(),
                most_particles = localizer.mcl().most_particles(),
                "global search"
            );
            if tracing::enabled!(tracing::Level::DEBUG)
                && searched_before.is_some_and(|before| before[1] != stats.ended)
            {
                log_hypotheses(frame, &odometry, searcher);
            }
        }
        if let Some(moved) = &report.realigned {
            self.realigned += 1;
            tracing::info!(
                frame = frame.sequence,
                from_x = format!("{:.3}", moved.from.x),
                from_y = format!("{:.3}", moved.from.y),
                to_x = format!("{:.3}", moved.to.x),
                to_y = format!("{:.3}", moved.to.y),
                turned_deg = format!(
                    "{:.2}",
                    normalize_angle(moved.to.theta - moved.from.theta).to_degrees()
                ),
                fit_before = format!("{:.3}", moved.fit_before),
                fit_after = format!("{:.3}", moved.fit_after),
                "tracked pose realigned to the frame"
            );
        }
        if let Some((ring, ambiguous)) = &report.rival_nearby {
            if *ambiguous {
                self.ambiguous += 1;
            }
            let at = report.estimate.map(|e| e.pose).unwrap_or_default();
            tracing::debug!(
                frame = frame.sequence,
                x = format!("{:.3}", at.x),
                y = format!("{:.3}", at.y),
                rival_x = format!("{:.3}", ring.rival.x),
                rival_y = format!("{:.3}", ring.rival.y),
                rival_share = format!("{:.3}", ring.rival_share()),
                ambiguous,
                "ring check"
            );
        }
        if let Some(correction) = &report.correction {
            self.corrections += 1;
            if took >= SLOW_STEP {
                tracing::info!(
                    frame = frame.sequence,
                    ms = took.as_millis() as u64,
                    particles,
                    injected = correction.injected,
                    tables_built = correction.tables_built,
                    tiles_fetched = report.tiles_fetched,
                    "slow sensor update"
                );
            }
        }
        self.processed += 1;
        if let Some(estimate) = report.estimate {
            let every = self.settings.particle_sample_every_s;
            let sample = if self.settings.particle_sample > 0
                && self.sampled_at.is_none_or(|at| frame.time_s - at >= every)
            {
                self.sampled_at = Some(frame.time_s);
                localizer
                    .mcl()
                    .sample(self.settings.particle_sample, &odometry)
            } else {
                Vec::new()
            };
            self.ends.sink.publish(frame, &estimate, &sample)?;
            log_estimate(frame, &estimate, self.processed, localizer.map().bytes());
        }
        Ok(())
    }
}

/// Logs a search's hypotheses at debug level, each beside the
/// simulator's true pose or the log's reference when the frame has one.
fn log_hypotheses(frame: &pb::SonarFrame, odometry: &Pose2, searcher: &Searcher) {
    let truth = frame.true_pose.or(frame.reference_pose).map(pose_from_wire);
    if let Some(probe) = truth.and_then(|t| searcher.probe(&t, odometry)) {
        tracing::debug!(
            frame = frame.sequence,
            score = format!("{:.3}", probe.score),
            latest_score = format!("{:.3}", probe.latest_score),
            points = probe.points,
            "the search's cloud at the true or reference pose"
        );
    }
    let hypotheses = searcher.hypotheses_now(odometry);
    for (rank, h) in hypotheses.iter().enumerate() {
        let off = truth.map(|t| {
            format!(
                "{:.2} m, {:.1} deg",
                (h.pose.x - t.x).hypot(h.pose.y - t.y),
                normalize_angle(h.pose.theta - t.theta).abs().to_degrees()
            )
        });
        tracing::debug!(
            frame = frame.sequence,
            rank,
            x = format!("{:.3}", h.pose.x),
            y = format!("{:.3}", h.pose.y),
            theta = format!("{:.3}", h.pose.theta),
            score = format!("{:.3}", h.score),
            off = off.as_deref().unwrap_or("-"),
            "search hypothesis"
        );
    }
}

/// What a search log line is written for: a search begun or ended, a
/// check's verdict (not the lookups each frame's slice makes).
fn search_events(stats: &SearcherStats) -> [u64; 4] {
    [
        stats.searches,
        stats.ended,
        stats.confirmations,
        stats.vetoes,
    ]
}
