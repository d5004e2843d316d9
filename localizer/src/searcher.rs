//! The global search as the localizer runs it ([`crate::search`]): when
//! to search, and what the filter does with what it finds.
//!
//! - **A global start** waits until the robot has driven far enough for
//!   its recent echoes to outline where it is (one scan for a laser, a
//!   metre or two of sonar frames), searches the whole map, and starts
//!   the filter with particles around each hypothesis: a few thousand
//!   particles whatever the map's size, where a uniform start spreads the
//!   most allowed over every free cell.
//! - **A lost filter** (its frames fit far worse than they did,
//!   [`Mcl::injection_share`] at least the search share) searches again,
//!   at most every [`SearcherSettings::research_every_m`] driven, and its
//!   injected particles are drawn around the hypotheses.
//! - **Convergence is verified**: a filter that calls itself settled is
//!   believed only once a search over its recent echoes finds no pose
//!   far from its estimate that explains them as well
//!   ([`SearcherSettings::rival_margin`], by the filter's own model over
//!   the frames kept) and the echoes fit the map at
//!   the estimate ([`SearchSettings::min_score`]). Look-alike rooms are
//!   ambiguity, not convergence: the rivals found go into the filter as
//!   modes of their own, to be weighed against its pose frame by frame.
//!   The check is made again every [`SearcherSettings::verify_every_m`];
//!   an estimate that jumps to another mode loses its confirmation, and
//!   a check cut short by its budget, or whose list of hypotheses is full
//!   (a corridor's look-alikes along it), confirms nothing.
//!   A filter started at a given pose is checked too, more leniently:
//!   one check confirms it, a rival must explain the frames better, and
//!   rivals are not added to it.
//! - **Searches run in slices** ([`SearchJob`]): each frame advances the
//!   search under way by [`Searcher::slice_lookups`] point lookups, so a
//!   building's search goes on over several frames while the filter
//!   keeps their pace; the search ends on the grid it began with, however
//!   the map changes meanwhile.

use deog_grid::{Pose2, normalize_angle};
use deog_rig::rig::{Beam, BeamShape};

use crate::error::{LocalizerError, within};
use crate::filter::{Estimate, Mcl};
use crate::local_map::LocalMap;
use crate::motion::OdometryMove;
use crate::search::{
    Hypothesis, RecentFrames, ScanCloud, SearchGrid, SearchJob, SearchOutcome, SearchSettings,
    SearchWindow, score_pose,
};

/// How the localizer searches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearcherSettings {
    /// The search itself.
    pub search: SearchSettings,
    /// Map cells a search cell spans along each side.
    pub cell_factor: u32,
    /// σ of the search's score around a wall, metres.
    pub sigma_m: f64,
    /// Block sizes of the search grid (level `d`: `2^d` cells).
    pub levels: usize,
    /// Frames kept for the cloud …
    pub frames: usize,
    /// … over at most this path, metres.
    pub span_m: f64,
    /// A frame is kept once the robot has moved this far from the last
    /// one kept, metres (or turned a tenth of a radian).
    pub frame_spacing_m: f64,
    /// A global start searches once the frames kept span this path,
    /// metres, and hold at least `min_frames`.
    pub min_driven_m: f64,
    /// Fewest frames kept before a search.
    pub min_frames: usize,
    /// Echoes at or past this range are left out of the cloud, metres.
    pub max_range: f64,
    /// Most readings of the cloud searched, evenly spread (0: all).
    pub max_groups: usize,
    /// Particles around each hypothesis …
    pub particles_per_hypothesis: usize,
    /// … spread this much, metres …
    pub std_xy: f64,
    /// … and radians.
    pub std_theta: f64,
    /// A settled filter is confirmed only by frames spanning at least
    /// this path, metres: a short stretch of a building repeats.
    pub min_verify_m: f64,
    /// Checks in a row, each at least [`Self::research_every_m`] of path
    /// after the one before, that must find no rival before the filter's
    /// pose is believed.
    pub confirmations: u32,
    /// A lost filter searches again at most every this many metres.
    pub research_every_m: f64,
    /// A settled filter is checked again every this many metres.
    pub verify_every_m: f64,
    /// A hypothesis away from the estimate whose frames' tempered
    /// log-likelihood ([`Mcl::path_score`]) comes within this of the
    /// estimate's is a rival: the estimate is not converged (2: the pose
    /// must be about 7 times likelier than any other).
    pub rival_margin: f64,
    /// Point lookups a search makes per frame ([`SearchJob::run`]): a
    /// search of a building goes on over several frames while the filter
    /// keeps their pace. A CPU budget sets it anew
    /// ([`Searcher::set_slice_lookups`]); this is the figure without one,
    /// the same on any machine.
    pub slice_lookups: u64,
}

/// Point lookups per frame without a CPU budget: about a tenth of a
/// second of one core.
pub const DEFAULT_SLICE_LOOKUPS: u64 = 40_000_000;

/// Hypotheses nearer than this to a better one are one at a check,
/// metres.
const CHECK_SEPARATION_M: f64 = 2.0;
/// Most hypotheses a check lists.
const CHECK_HYPOTHESES: usize = 32;

/// Rivals a check weighs per frame once its search has ended.
const RIVALS_PER_FRAME: usize = 4;

/// Most lookups of a whole search, over all its slices: several times a
/// single search's default, since slices keep each frame short.
const SEARCH_BUDGET: u64 = 1_500_000_000;

impl SearcherSettings {
    /// The settings for frames from `beams`: one scan for a laser, two
    /// metres of frames for sonars (whose cones say little each).
    pub fn for_beams(beams: &[Beam]) -> Self {
        let sonar = beams
            .iter()
            .any(|b| matches!(b.shape, BeamShape::Cone { .. }));
        if sonar {
            Self {
                search: SearchSettings {
                    keep_ratio: 0.7,
                    max_hypotheses: 24,
                    budget: SEARCH_BUDGET,
                    ..SearchSettings::default()
                },
                cell_factor: 4,
                sigma_m: 0.2,
                levels: 6,
                frames: 20,
                span_m: 3.0,
                frame_spacing_m: 0.15,
                min_driven_m: 1.5,
                min_frames: 10,
                max_range: 5.0,
                max_groups: 0,
                particles_per_hypothesis: 600,
                min_verify_m: 1.5,
                confirmations: 3,
                std_xy: 0.2,
                std_theta: 0.12,
                research_every_m: 1.0,
                verify_every_m: 2.0,
                rival_margin: 2.0,
                slice_lookups: DEFAULT_SLICE_LOOKUPS,
            }
        } else {
            Self {
                search: SearchSettings {
                    budget: SEARCH_BUDGET,
                    ..SearchSettings::default()
                },
                cell_factor: 2,
                sigma_m: 0.1,
                levels: 7,
                frames: 3,
                span_m: 1.0,
                frame_spacing_m: 0.2,
                min_driven_m: 0.0,
                min_frames: 1,
                max_range: 30.0,
                max_groups: 90,
                particles_per_hypothesis: 300,
                min_verify_m: 0.0,
                confirmations: 3,
                std_xy: 0.15,
                std_theta: 0.06,
                research_every_m: 1.0,
                verify_every_m: 2.0,
                rival_margin: 2.0,
                slice_lookups: DEFAULT_SLICE_LOOKUPS,
            }
        }
    }

    /// The settings if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        self.search.validate()?;
        within("search sigma_m", self.sigma_m, 0.001, 10.0)?;
        within("search span_m", self.span_m, 0.0, 1000.0)?;
        within("search frame_spacing_m", self.frame_spacing_m, 0.0, 100.0)?;
        within("search min_driven_m", self.min_driven_m, 0.0, 1000.0)?;
        within("search max_range", self.max_range, 0.0, 1000.0)?;
        within("search std_xy", self.std_xy, 0.0, 100.0)?;
        within("search std_theta", self.std_theta, 0.0, 10.0)?;
        within(
            "search research_every_m",
            self.research_every_m,
            0.0,
            1000.0,
        )?;
        within("search verify_every_m", self.verify_every_m, 0.0, 1000.0)?;
        within("search rival_margin", self.rival_margin, 0.0, 1000.0)?;
        if self.cell_factor == 0
            || self.frames == 0
            || self.particles_per_hypothesis == 0
            || self.slice_lookups == 0
        {
            return Err(LocalizerError::Invalid(
                "the search needs a cell factor, frames, particles and lookups per frame above 0"
                    .into(),
            ));
        }
        Ok(self)
    }
}

/// Where the searcher stands.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Not searching: the filter was started otherwise.
    Off,
    /// A global start waiting for its first hypotheses.
    Starting,
    /// The filter runs.
    Running,
}

/// What the last search found, at the odometry it was made at.
#[derive(Debug, Clone)]
struct Found {
    odometry: Pose2,
    hypotheses: Vec<Hypothesis>,
}

/// Why a search runs, and so what its end does.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Purpose {
    /// A global start: the filter starts from what it finds.
    Start,
    /// A lost filter: it injects around what it finds.
    Lost,
    /// A settled filter: what it finds may be a rival.
    Verify,
}

/// A search under way, over the frames to come.
#[derive(Debug)]
struct Pending {
    job: SearchJob,
    purpose: Purpose,
    /// The odometry of the frame its cloud is of.
    kept: Pose2,
    /// A check's estimate at that frame, when the check began.
    estimate_at_kept: Option<Pose2>,
}

/// A check whose search has ended, weighing its rivals frame by frame.
#[derive(Debug)]
struct Judging {
    /// Whether the frames' cloud fits the map at the estimate.
    fits: bool,
    /// Whether the search ran to its end with room in its list.
    complete: bool,
    /// The odometry the poses below are of.
    odometry: Pose2,
    /// Hypotheses apart from the estimate still to weigh, best last.
    left: Vec<Pose2>,
    /// Those weighed that explain the frames nearly as well.
    rivals: Vec<Pose2>,
}

/// A search at its end.
struct Ended {
    outcome: SearchOutcome,
    cloud: ScanCloud,
    kept: Pose2,
    estimate_at_kept: Option<Pose2>,
}

/// Counts of what the searcher did, for logs and benches.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SearcherStats {
    /// Searches begun.
    pub searches: u64,
    /// Of those, ended (run to their end or out of budget).
    pub ended: u64,
    /// Point lookups made by every search.
    pub lookups: u64,
    /// Of those, stopped by their budget.
    pub incomplete: u64,
    /// Checks of a settled estimate that found a rival or a bad fit.
    pub vetoes: u64,
    /// Of those, the vetoes for a bad fit: the estimate's own echoes
    /// scored below the search's least score, rival or none.
    pub unfit: u64,
    /// Checks that confirmed it.
    pub confirmations: u64,
    /// Checks that ended with neither: their search cut short or their
    /// list of hypotheses full.
    pub undecided: u64,
    /// Checks dropped because the estimate stopped being settled while
    /// they ran.
    pub dropped: u64,
    /// Standing checks (a streak or a confirmation) undone because the
    /// filter stopped calling itself settled …
    pub unsettled: u64,
    /// … because its frames fit worse than they did …
    pub fits_worse: u64,
    /// … or because its estimate jumped to another mode.
    pub jumps: u64,
}

/// What [`Searcher::probe`] tells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Probe {
    /// The cloud's score at the pose asked about.
    pub score: f64,
    /// The latest frame's alone.
    pub latest_score: f64,
    /// The last search's best hypothesis, carried to now.
    pub best: Option<Hypothesis>,
    /// Hypotheses the last search kept.
    pub hypotheses: usize,
    /// Points in the cloud.
    pub points: usize,
}

/// The global search beside a filter.
#[derive(Debug)]
pub struct Searcher {
    settings: SearcherSettings,
    beams: Vec<Beam>,
    recent: RecentFrames,
    phase: Phase,
    /// The grid, built from the map when first needed and again after
    /// the map changed (once no search is under way on it).
    grid: Option<SearchGrid>,
    grid_stale: bool,
    /// The map's count of tiles added when the grid was built: a filter
    /// tracking a given pose holds the tiles near its path only, and
    /// the grid must grow with them.
    grid_tiles_added: u64,
    pending: Option<Pending>,
    judging: Option<Judging>,
    slice_lookups: u64,
    last_kept: Option<Pose2>,
    /// Odometry path driven since the searcher began, metres.
    driven_m: f64,
    last_odometry: Option<Pose2>,
    /// `driven_m` at the last search, and at the last verification.
    searched_at_m: Option<f64>,
    verified_at_m: Option<f64>,
    /// Whether the checks confirmed the filter's pose.
    verified: bool,
    /// Checks in a row that found no rival.
    streak: u32,
    /// The estimate at the last frame while checks stand (a streak or a
    /// confirmation), with its odometry: a filter whose estimate jumps to
    /// another mode has had that mode checked by nothing.
    checked: Option<(Pose2, Pose2)>,
    /// Started at a given pose ([`Self::start_tracking`]).
    tracking: bool,
    found: Option<Found>,
    stats: SearcherStats,
}

impl Searcher {
    /// A searcher of frames from `beams` (the rig's, in frame order).
    pub fn new(beams: Vec<Beam>, settings: SearcherSettings) -> Result<Self, LocalizerError> {
        let settings = settings.validate()?;
        Ok(Self {
            recent: RecentFrames::new(settings.frames, settings.span_m),
            settings,
            beams,
            phase: Phase::Off,
            grid: None,
            grid_stale: false,
            grid_tiles_added: 0,
            pending: None,
            judging: None,
            slice_lookups: settings.slice_lookups,
            last_kept: None,
            driven_m: 0.0,
            last_odometry: None,
            searched_at_m: None,
            verified_at_m: None,
            verified: false,
            streak: 0,
            checked: None,
            tracking: false,
            found: None,
            stats: SearcherStats::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &SearcherSettings {
        &self.settings
    }

    /// What it did so far.
    pub fn stats(&self) -> SearcherStats {
        self.stats
    }

    /// Sets the point lookups a search makes per frame: what a CPU
    /// budget affords at the rate the machine makes them.
    pub fn set_slice_lookups(&mut self, lookups: u64) {
        self.slice_lookups = lookups.max(1);
    }

    /// The point lookups a search makes per frame.
    pub fn slice_lookups(&self) -> u64 {
        self.slice_lookups
    }

    /// Whether a search, or the weighing of its rivals, is under way.
    pub fn searching(&self) -> bool {
        self.pending.is_some() || self.judging.is_some()
    }

    /// A global start: the filter waits for the first search.
    pub fn start_global(&mut self) {
        self.phase = Phase::Starting;
        self.tracking = false;
        self.verified = false;
        self.streak = 0;
        self.checked = None;
        self.found = None;
        self.pending = None;
        self.judging = None;
    }

    /// The filter was started at a given pose: its flag is checked as
    /// any, but the rivals a check finds are not added to it (a pose
    /// given is a prior the search does not overrule).
    pub fn start_tracking(&mut self) {
        self.phase = Phase::Running;
        self.tracking = true;
        self.verified = false;
        self.streak = 0;
    }

    /// Whether a global start still waits for its hypotheses: the filter
    /// has no particles to step.
    pub fn waiting(&self) -> bool {
        self.phase == Phase::Starting
    }

    /// The map changed: the grid is built again at the next search (a
    /// search under way ends on the grid it began with).
    pub fn map_changed(&mut self) {
        self.grid_stale = true;
    }

    /// Notes a frame, keeping it for the cloud if the robot has moved
    /// since the last one kept.
    pub fn note_frame(&mut self, odometry: &Pose2, readings: &[f64]) {
        if let Some(last) = self.last_odometry {
            self.driven_m += (odometry.x - last.x).hypot(odometry.y - last.y);
        }
        self.last_odometry = Some(*odometry);
        let moved = self.last_kept.is_none_or(|k| {
            (odometry.x - k.x).hypot(odometry.y - k.y) >= self.settings.frame_spacing_m
                || normalize_angle(odometry.theta - k.theta).abs() >= 0.1
        });
        if moved {
            self.recent.push(*odometry, readings);
            self.last_kept = Some(*odometry);
        }
    }

    fn ready(&self) -> bool {
        self.recent.len() >= self.settings.min_frames
            && self.recent.driven_m() >= self.settings.min_driven_m
    }

    /// For diagnostics: how the kept frames' cloud scores at `pose` (the
    /// robot's now, at `odometry`), and the last search's best
    /// hypothesis carried to now; `None` before the grid is built.
    pub fn probe(&self, pose: &Pose2, odometry: &Pose2) -> Option<Probe> {
        let grid = self.grid.as_ref()?;
        let kept = self.last_kept.unwrap_or(*odometry);
        let cloud = self.recent.cloud(&self.beams, self.settings.max_range);
        let at_kept = OdometryMove::between(odometry, &kept).apply(pose);
        let best = self.found.as_ref().and_then(|f| {
            let step = OdometryMove::between(&f.odometry, odometry);
            f.hypotheses.first().map(|h| Hypothesis {
                pose: step.apply(&h.pose),
                score: h.score,
            })
        });
        let mut latest = ScanCloud::new();
        if let Some((_, ranges)) = self.recent.frames().last() {
            latest.add_frame(
                &self.beams,
                ranges,
                &Pose2::new(0.0, 0.0, 0.0),
                self.settings.max_range,
            );
        }
        Some(Probe {
            score: score_pose(grid, &cloud, &at_kept),
            latest_score: score_pose(grid, &latest, &at_kept),
            best,
            hypotheses: self.found.as_ref().map_or(0, |f| f.hypotheses.len()),
            points: cloud.points().len(),
        })
    }

    /// The last search's hypotheses (a global start's, a lost filter's
    /// or a check's), best first, carried to the robot's pose now at
    /// `odometry`; empty before the first search ends.
    pub fn hypotheses_now(&self, odometry: &Pose2) -> Vec<Hypothesis> {
        self.found.as_ref().map_or_else(Vec::new, |f| {
            let step = OdometryMove::between(&f.odometry, odometry);
            f.hypotheses
                .iter()
                .map(|h| Hypothesis {
                    pose: step.apply(&h.pose),
                    score: h.score,
                })
                .collect()
        })
    }

    /// Whether the filter's pose stands confirmed: always, for a
    /// searcher that is off; else since the last check found no rival.
    pub fn confirmed(&self) -> bool {
        self.phase == Phase::Off || self.verified
    }

    /// Begins a search of the map for the kept frames' cloud, at the
    /// odometry of the latest one; false when the map has no free space
    /// to search yet.
    fn begin(
        &mut self,
        map: &LocalMap,
        purpose: Purpose,
        odometry: &Pose2,
    ) -> Result<bool, LocalizerError> {
        let added = map.stats().tiles_added;
        if self.grid.is_none() || self.grid_stale || added != self.grid_tiles_added {
            self.grid = None;
            self.grid_stale = false;
            self.grid_tiles_added = added;
            let Some(cells) = map.search_cells(self.settings.cell_factor)? else {
                return Ok(false);
            };
            self.grid = Some(SearchGrid::new(
                cells.origin,
                cells.cell_m,
                cells.width,
                cells.height,
                &cells.cells,
                self.settings.sigma_m,
                self.settings.levels,
            )?);
        }
        let Some(grid) = &self.grid else {
            return Ok(false);
        };
        let cloud = self
            .recent
            .cloud(&self.beams, self.settings.max_range)
            .thinned(self.settings.max_groups);
        // A check lists rivals apart: look-alikes along one corridor are one
        // ambiguity, and a list full of them would leave out the rest.
        let settings = match purpose {
            Purpose::Verify => SearchSettings {
                separation_m: self.settings.search.separation_m.max(CHECK_SEPARATION_M),
                max_hypotheses: self.settings.search.max_hypotheses.max(CHECK_HYPOTHESES),
                ..self.settings.search
            },
            Purpose::Start | Purpose::Lost => self.settings.search,
        };
        let job = SearchJob::new(grid, cloud, SearchWindow::Global, &settings)?;
        self.stats.searches += 1;
        self.stats.lookups += job.lookups();
        self.searched_at_m = Some(self.driven_m);
        self.pending = Some(Pending {
            job,
            purpose,
            kept: self.last_kept.unwrap_or(*odometry),
            estimate_at_kept: None,
        });
        Ok(true)
    }

    /// Runs the search under way for one frame's slice; returns it once
    /// it has ended. A search of another purpose is left as it is.
    fn advance(&mut self, purpose: Purpose) -> Option<Ended> {
        let grid = self.grid.as_ref()?;
        let pending = self.pending.as_mut().filter(|p| p.purpose == purpose)?;
        let before = pending.job.lookups();
        let done = pending.job.run(grid, self.slice_lookups);
        self.stats.lookups += pending.job.lookups() - before;
        if !done {
            return None;
        }
        let Pending {
            job,
            kept,
            estimate_at_kept,
            ..
        } = self.pending.take()?;
        let cloud = job.cloud().clone();
        let outcome = job.finish();
        self.stats.ended += 1;
        if !outcome.complete {
            self.stats.incomplete += 1;
        }
        Some(Ended {
            outcome,
            cloud,
            kept,
            estimate_at_kept,
        })
    }

    /// Drops a search of `purpose` under way.
    fn abandon(&mut self, purpose: Purpose) {
        if self.pending.as_ref().is_some_and(|p| p.purpose == purpose) {
            self.pending = None;
        }
    }

    fn research_due(&self) -> bool {
        self.searched_at_m
            .is_none_or(|at| self.driven_m - at >= self.settings.research_every_m)
    }

    /// Before the filter's step on a frame at `odometry`: a waiting
    /// global start searches and, once it finds hypotheses, starts the
    /// filter on them (returns true when the filter may step); a lost
    /// filter searches again and injects around what it finds.
    pub fn before_step(
        &mut self,
        mcl: &mut Mcl,
        map: &LocalMap,
        odometry: &Pose2,
    ) -> Result<bool, LocalizerError> {
        match self.phase {
            Phase::Off => Ok(true),
            Phase::Starting => {
                if self.pending.is_none() {
                    if !self.ready() || !self.research_due() {
                        return Ok(false);
                    }
                    if !self.begin(map, Purpose::Start, odometry)? {
                        return Ok(false);
                    }
                }
                let Some(ended) = self.advance(Purpose::Start) else {
                    return Ok(false);
                };
                let hypotheses = ended.outcome.hypotheses;
                if hypotheses.is_empty() {
                    return Ok(false);
                }
                // The hypotheses are of the robot at the frame the cloud
                // is of: carried to now by the odometry since.
                let step = OdometryMove::between(&ended.kept, odometry);
                let poses: Vec<Pose2> = hypotheses.iter().map(|h| step.apply(&h.pose)).collect();
                mcl.start_hypotheses(
                    &poses,
                    self.settings.particles_per_hypothesis,
                    self.settings.std_xy,
                    self.settings.std_theta,
                )?;
                self.found = Some(Found {
                    odometry: ended.kept,
                    hypotheses,
                });
                self.phase = Phase::Running;
                self.verified = false;
                self.streak = 0;
                Ok(true)
            }
            Phase::Running => {
                let lost = mcl.injection_share() >= mcl.settings().search_share;
                if lost {
                    self.verified = false;
                    self.streak = 0;
                    self.abandon(Purpose::Verify);
                    self.judging = None;
                    if self.pending.is_none() && self.research_due() && self.ready() {
                        self.begin(map, Purpose::Lost, odometry)?;
                    }
                }
                if let Some(ended) = self.advance(Purpose::Lost) {
                    self.found = Some(Found {
                        odometry: ended.kept,
                        hypotheses: ended.outcome.hypotheses,
                    });
                }
                // A lost filter's injections go around the last hypotheses
                // carried to now by the odometry; a filter that is not lost
                // trickles over free space as it always has (drawn around
                // poses a check found, the trickle would pull a tracking
                // filter towards them).
                let carried = self.found.as_ref().filter(|_| lost).map(|f| {
                    let step = OdometryMove::between(&f.odometry, odometry);
                    f.hypotheses
                        .iter()
                        .map(|h| step.apply(&h.pose))
                        .collect::<Vec<_>>()
                });
                mcl.set_injection_poses(carried, self.settings.std_xy, self.settings.std_theta);
                Ok(true)
            }
        }
    }

    /// After the filter's step: a settled filter's estimate is checked
    /// against a search when due; returns whether the estimate may be
    /// called converged.
    pub fn verify(
        &mut self,
        mcl: &mut Mcl,
        map: &mut LocalMap,
        estimate: &Estimate,
        odometry: &Pose2,
    ) -> Result<bool, LocalizerError> {
        if self.phase == Phase::Off {
            return Ok(estimate.converged);
        }
        // Frames fitting worse than they did (the filter injecting at all)
        // are not a filter sure of its pose: a kidnapped robot's filter
        // keeps its old, tight cluster until the fit has fallen.
        let jumped = self.jumped(estimate, odometry);
        if !estimate.converged || estimate.lost_score > 0.0 || jumped {
            if self.streak > 0 || self.verified {
                if !estimate.converged {
                    self.stats.unsettled += 1;
                } else if jumped {
                    self.stats.jumps += 1;
                } else {
                    self.stats.fits_worse += 1;
                }
            }
            self.verified = false;
            self.streak = 0;
            self.checked = None;
            // A check under way goes on (a flag that flickers would
            // otherwise have every check begun and dropped), but what it
            // finds is of an estimate no longer settled: no verdict.
            if self.advance(Purpose::Verify).is_some() {
                self.stats.dropped += 1;
            }
            if self.judging.take().is_some() {
                self.stats.dropped += 1;
            }
            return Ok(false);
        }
        if self.streak > 0 {
            self.checked = Some((*odometry, estimate.pose));
        }
        if self.pending.is_none() && self.judging.is_none() {
            let due = !self.verified
                || self
                    .verified_at_m
                    .is_none_or(|at| self.driven_m - at >= self.settings.verify_every_m);
            if !due {
                return Ok(true);
            }
            if !self.ready() || self.recent.driven_m() < self.settings.min_verify_m {
                return Ok(false);
            }
            // Not more often than the search's own pace while unconfirmed.
            if !self.verified
                && self
                    .verified_at_m
                    .is_some_and(|at| self.driven_m - at < self.settings.research_every_m)
            {
                return Ok(false);
            }
            self.verified_at_m = Some(self.driven_m);
            if !self.begin(map, Purpose::Verify, odometry)? {
                return Ok(false);
            }
            // A tracked filter's estimate at the cloud's frame, carried
            // the short way back now: carried at the check's end, it would
            // cross every frame the search took, and a real robot's
            // odometry drifts. (A global start's estimate may change mode
            // while its check runs, and is carried at the end.)
            if self.tracking
                && let Some(pending) = &mut self.pending
            {
                pending.estimate_at_kept =
                    Some(OdometryMove::between(odometry, &pending.kept).apply(&estimate.pose));
            }
        }
        // A check under way keeps the flag as the last one left it.
        if self.judging.is_none() {
            let Some(ended) = self.advance(Purpose::Verify) else {
                return Ok(self.verified);
            };
            self.begin_judging(estimate, odometry, ended);
        }
        self.judge(mcl, map, estimate, odometry)
    }

    /// Whether the estimate left the pose the checks stand for, carried
    /// by the odometry: by more than the search tells hypotheses apart.
    fn jumped(&self, estimate: &Estimate, odometry: &Pose2) -> bool {
        let Some((then, pose)) = self.checked else {
            return false;
        };
        let carried = OdometryMove::between(&then, odometry).apply(&pose);
        apart(&carried, &estimate.pose, &self.settings.search)
    }

    /// A check's search has ended: the estimate's fit to its cloud, and
    /// the hypotheses apart from the estimate to weigh as rivals over the
    /// frames to come.
    fn begin_judging(&mut self, estimate: &Estimate, odometry: &Pose2, ended: Ended) {
        let Ended {
            outcome,
            cloud,
            kept,
            estimate_at_kept,
        } = ended;
        let pose = estimate.pose;
        // The cloud is of the robot at the frame it was made at: a
        // tracked estimate is judged as it was there, and the hypotheses
        // are carried to now as the estimate moved since. Any other, or
        // one that has left the mode it was in when the check began, is
        // judged carried back by the odometry, the hypotheses forward.
        let search = &self.settings.search;
        let forward = OdometryMove::between(&kept, odometry);
        let same_mode = estimate_at_kept.filter(|then| !apart(&forward.apply(then), &pose, search));
        let at_kept =
            same_mode.unwrap_or_else(|| OdometryMove::between(odometry, &kept).apply(&pose));
        let own_cloud = self
            .grid
            .as_ref()
            .map_or(0.0, |grid| score_pose(grid, &cloud, &at_kept));
        let left = outcome
            .hypotheses
            .iter()
            .map(|h| match same_mode {
                Some(then) => pose.compose(&h.pose.relative_to(&then)),
                None => forward.apply(&h.pose),
            })
            .filter(|p| apart(p, &pose, search))
            // Weighed from the last: the best first.
            .rev()
            .collect();
        // A search whose list of hypotheses is full may have left out a
        // rival (a corridor fills it with look-alikes along itself): like
        // one cut short, it confirms nothing.
        let whole = outcome.complete
            && outcome.hypotheses.len() < search.max_hypotheses.max(CHECK_HYPOTHESES);
        let fits = own_cloud >= search.min_score;
        self.found = Some(Found {
            odometry: kept,
            hypotheses: outcome.hypotheses,
        });
        self.judging = Some(Judging {
            fits,
            complete: whole,
            odometry: *odometry,
            left,
            rivals: Vec::new(),
        });
    }

    /// Weighs a few more of the check's rivals against the estimate, by
    /// the filter's own model over the frames kept (each costs the
    /// tables its tiles need, so a building's two dozen are spread over
    /// frames); once all are weighed, the verdict.
    fn judge(
        &mut self,
        mcl: &mut Mcl,
        map: &mut LocalMap,
        estimate: &Estimate,
        odometry: &Pose2,
    ) -> Result<bool, LocalizerError> {
        let Some(judging) = &mut self.judging else {
            return Ok(self.verified);
        };
        // Poses found frames ago are carried to now by the odometry.
        let step = OdometryMove::between(&judging.odometry, odometry);
        for p in judging.left.iter_mut().chain(judging.rivals.iter_mut()) {
            *p = step.apply(p);
        }
        judging.odometry = *odometry;
        // A pose given at the start is a prior the search does not
        // overrule: there a rival must explain the frames better, and one
        // check confirms.
        let (margin, needed) = if self.tracking {
            (0.0, 1)
        } else {
            (
                self.settings.rival_margin,
                self.settings.confirmations.max(1),
            )
        };
        let pose = estimate.pose;
        if !judging.left.is_empty() {
            let own = mcl.path_score(map, odometry, &pose, self.recent.frames())?;
            for _ in 0..RIVALS_PER_FRAME {
                let Some(at) = judging.left.pop() else {
                    break;
                };
                let score = mcl.path_score(map, odometry, &at, self.recent.frames())?;
                if score >= own - margin {
                    judging.rivals.push(at);
                }
            }
            if !judging.left.is_empty() {
                return Ok(self.verified);
            }
        }
        let Some(Judging {
            fits,
            complete,
            rivals,
            ..
        }) = self.judging.take()
        else {
            return Ok(self.verified);
        };
        // A search cut short by its budget may have missed a rival: it
        // confirms nothing, though a rival it found still counts.
        let passed = fits && rivals.is_empty() && complete;
        let vetoed = !fits || !rivals.is_empty();
        if passed {
            self.streak += 1;
            self.stats.confirmations += 1;
            self.checked = Some((*odometry, pose));
        } else if vetoed {
            self.streak = 0;
            self.checked = None;
            self.stats.vetoes += 1;
            self.stats.unfit += u64::from(!fits);
        } else {
            self.stats.undecided += 1;
        }
        self.verified = self.streak >= needed;
        if vetoed && !self.tracking {
            mcl.add_rivals(
                &rivals,
                self.settings.particles_per_hypothesis,
                self.settings.std_xy,
                self.settings.std_theta,
            )?;
        }
        Ok(self.verified)
    }
}

/// Whether two poses are different hypotheses: farther apart than the
/// search tells them apart, in position or heading.
fn apart(a: &Pose2, b: &Pose2, search: &SearchSettings) -> bool {
    (a.x - b.x).hypot(a.y - b.y) > search.separation_m
        || normalize_angle(a.theta - b.theta).abs() > search.separation_rad
}
