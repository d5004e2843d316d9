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
//!   The check is made again every [`SearcherSettings::verify_every_m`].
//!   A filter started at a given pose is checked too, more leniently:
//!   one check confirms it, a rival must explain the frames better, and
//!   rivals are not added to it.

use deog_grid::{Pose2, normalize_angle};
use deog_rig::rig::{Beam, BeamShape};

use crate::error::{LocalizerError, within};
use crate::filter::{Estimate, Mcl};
use crate::local_map::LocalMap;
use crate::motion::OdometryMove;
use crate::search::{
    Hypothesis, RecentFrames, ScanCloud, SearchGrid, SearchSettings, SearchWindow, score_pose,
    search,
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
}

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
            }
        } else {
            Self {
                search: SearchSettings::default(),
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
        if self.cell_factor == 0 || self.frames == 0 || self.particles_per_hypothesis == 0 {
            return Err(LocalizerError::Invalid(
                "the search needs a cell factor, frames and particles above 0".into(),
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

/// Counts of what the searcher did, for logs and benches.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SearcherStats {
    /// Searches made.
    pub searches: u64,
    /// Of those, stopped by their budget.
    pub incomplete: u64,
    /// Checks of a settled estimate that found a rival or a bad fit.
    pub vetoes: u64,
    /// Checks that confirmed it.
    pub confirmations: u64,
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
    /// the map changed.
    grid: Option<SearchGrid>,
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
            last_kept: None,
            driven_m: 0.0,
            last_odometry: None,
            searched_at_m: None,
            verified_at_m: None,
            verified: false,
            streak: 0,
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

    /// A global start: the filter waits for the first search.
    pub fn start_global(&mut self) {
        self.phase = Phase::Starting;
        self.tracking = false;
        self.verified = false;
        self.streak = 0;
        self.found = None;
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

    /// The map changed: the grid is built again at the next search.
    pub fn map_changed(&mut self) {
        self.grid = None;
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

    /// Whether the filter's pose stands confirmed: always, for a
    /// searcher that is off; else since the last check found no rival.
    pub fn confirmed(&self) -> bool {
        self.phase == Phase::Off || self.verified
    }

    /// Searches the map for the kept frames' cloud, at the odometry of
    /// the latest one ([`Self::last_kept`]).
    fn search(
        &mut self,
        map: &LocalMap,
        window: SearchWindow,
    ) -> Result<Option<(ScanCloud, Vec<Hypothesis>)>, LocalizerError> {
        if self.grid.is_none() {
            let Some(cells) = map.search_cells(self.settings.cell_factor)? else {
                return Ok(None);
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
            return Ok(None);
        };
        let cloud = self
            .recent
            .cloud(&self.beams, self.settings.max_range)
            .thinned(self.settings.max_groups);
        let outcome = search(grid, &cloud, window, &self.settings.search)?;
        self.stats.searches += 1;
        if !outcome.complete {
            self.stats.incomplete += 1;
        }
        self.searched_at_m = Some(self.driven_m);
        Ok(Some((cloud, outcome.hypotheses)))
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
                if !self.ready() {
                    return Ok(false);
                }
                let due = self
                    .searched_at_m
                    .is_none_or(|at| self.driven_m - at >= self.settings.research_every_m);
                if !due {
                    return Ok(false);
                }
                let Some((_, hypotheses)) = self.search(map, SearchWindow::Global)? else {
                    return Ok(false);
                };
                if hypotheses.is_empty() {
                    return Ok(false);
                }
                let poses: Vec<Pose2> = hypotheses.iter().map(|h| h.pose).collect();
                // The hypotheses are of the robot at the last frame kept.
                let kept = self.last_kept.unwrap_or(*odometry);
                let step = OdometryMove::between(&kept, odometry);
                let poses: Vec<Pose2> = poses.iter().map(|p| step.apply(p)).collect();
                mcl.start_hypotheses(
                    &poses,
                    self.settings.particles_per_hypothesis,
                    self.settings.std_xy,
                    self.settings.std_theta,
                )?;
                self.found = Some(Found {
                    odometry: kept,
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
                    let due = self
                        .searched_at_m
                        .is_none_or(|at| self.driven_m - at >= self.settings.research_every_m);
                    if due
                        && self.ready()
                        && let Some((_, hypotheses)) = self.search(map, SearchWindow::Global)?
                    {
                        self.found = Some(Found {
                            odometry: self.last_kept.unwrap_or(*odometry),
                            hypotheses,
                        });
                    }
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
        if !estimate.converged || estimate.lost_score > 0.0 {
            self.verified = false;
            self.streak = 0;
            return Ok(false);
        }
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
        let Some((cloud, hypotheses)) = self.search(map, SearchWindow::Global)? else {
            return Ok(false);
        };
        let grid = self.grid.as_ref().ok_or(LocalizerError::NoFreeSpace)?;
        // The cloud is of the robot at the last frame kept: the estimate
        // is carried back there, the hypotheses forward to now.
        let kept = self.last_kept.unwrap_or(*odometry);
        let forward = OdometryMove::between(&kept, odometry);
        let pose = estimate.pose;
        let own_cloud = score_pose(
            grid,
            &cloud,
            &OdometryMove::between(odometry, &kept).apply(&pose),
        );
        let separated = |p: &Pose2| {
            (p.x - pose.x).hypot(p.y - pose.y) > self.settings.search.separation_m
                || normalize_angle(p.theta - pose.theta).abs() > self.settings.search.separation_rad
        };
        // The search ranks by one blurred cloud; the filter's own model
        // over the frames kept is what weighs a rival against the pose.
        let own = mcl.path_score(map, odometry, &pose, self.recent.frames())?;
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
        let mut rivals = Vec::new();
        for h in &hypotheses {
            let at = forward.apply(&h.pose);
            if !separated(&at) {
                continue;
            }
            let score = mcl.path_score(map, odometry, &at, self.recent.frames())?;
            if score >= own - margin {
                rivals.push(at);
            }
        }
        let fits = own_cloud >= self.settings.search.min_score;
        let passed = fits && rivals.is_empty();
        self.streak = if passed { self.streak + 1 } else { 0 };
        self.verified = self.streak >= needed;
        if passed {
            self.stats.confirmations += 1;
        } else {
            self.stats.vetoes += 1;
        }
        if !passed && !self.tracking {
            mcl.add_rivals(
                &rivals,
                self.settings.particles_per_hypothesis,
                self.settings.std_xy,
                self.settings.std_theta,
            )?;
        }
        self.found = Some(Found {
            odometry: kept,
            hypotheses,
        });
        Ok(self.verified)
    }
}
