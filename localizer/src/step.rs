//! One frame through the localizer, the same for the `deog localize`
//! process and for `deog bench localize`: apply the map changes the server
//! reported (at most every refresh period), predict, realign a tracked
//! pose the frame no longer fits ([`crate::realign`]), fetch the tiles the
//! frame needs (as its sensor model says: under the particles for a sonar,
//! where the endpoints fall for a likelihood field), correct, evict what
//! the cache cannot hold, refine the estimate where the sensor model
//! does (the likelihood field: [`crate::refine`]), and check a laser's
//! estimate for a rival nearby before calling it converged
//! ([`crate::ambiguity`]).
//!
//! With a CPU budget ([`Localizer::with_step_budget`]) the particles and
//! the global search's slices are fitted to it as the steps run: the
//! filter is any-time, doing less on a busy machine rather than falling
//! behind.
//!
//! The map server is behind [`TileSource`]: the process fetches over the
//! network, the bench from a map in memory. The step itself does no I/O.

use std::collections::HashSet;
use std::time::{Duration, Instant};

use deog_grid::{Pose2, Tile, TileKey, TileMap};

use crate::ambiguity::Ring;
use crate::error::LocalizerError;
use crate::filter::{CarriedEstimate, CorrectionReport, Estimate, Mcl, Realignment};
use crate::local_map::LocalMap;
use crate::searcher::Searcher;

/// A tile as the map server holds it.
#[derive(Debug, Clone)]
pub struct FetchedTile {
    /// Which tile.
    pub key: TileKey,
    /// The server's version of it.
    pub version: u64,
    /// Its cells.
    pub tile: Tile,
}

/// Where the localizer's tiles come from.
pub trait TileSource {
    /// The tiles among `keys` that the map holds. A key left out has no
    /// tile: every cell of it is unknown.
    fn fetch(
        &mut self,
        keys: &[TileKey],
    ) -> Result<Vec<FetchedTile>, Box<dyn std::error::Error + Send + Sync>>;
}

/// A map held in memory serves its tiles, all at version 1 (it does not
/// change while it is read).
impl TileSource for TileMap {
    fn fetch(
        &mut self,
        keys: &[TileKey],
    ) -> Result<Vec<FetchedTile>, Box<dyn std::error::Error + Send + Sync>> {
        Ok(keys
            .iter()
            .filter_map(|&key| {
                self.tile(key).map(|tile| FetchedTile {
                    key,
                    version: 1,
                    tile: tile.clone(),
                })
            })
            .collect())
    }
}

/// What one frame did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepReport {
    /// The sensor update, when the robot had moved enough for one.
    pub correction: Option<CorrectionReport>,
    /// Tiles fetched for this frame (refreshed or missing).
    pub tiles_fetched: usize,
    /// The estimate after the frame, once the filter has one.
    pub estimate: Option<Estimate>,
    /// The tracked pose moved onto where the frame fits, before the
    /// correction ([`Mcl::realign`]).
    pub realigned: Option<Realignment>,
    /// The estimate's ring check ([`Mcl::rival_nearby`]), when one ran:
    /// the best pose nearby, and whether its fit made the estimate
    /// ambiguous.
    pub rival_nearby: Option<(Ring, bool)>,
}

/// A filter on its cached map, kept current with the server's changes.
#[derive(Debug)]
pub struct Localizer {
    mcl: Mcl,
    map: LocalMap,
    /// Least time between two refreshes of changed tiles.
    refresh_every: Duration,
    /// Tiles the server reported changed since the last refresh.
    stale: HashSet<TileKey>,
    /// The server lost track of what changed: everything held is stale.
    resync: bool,
    last_refresh: Instant,
    /// How long the last correction that built tables took.
    last_rebuild: Duration,
    /// Whether slow rebuilds stretch the refresh period.
    stretch_refresh: bool,
    /// The global search beside the filter, when it has one.
    searcher: Option<Searcher>,
    /// The CPU budget per step, when the work is fitted to one.
    budget: Option<StepBudget>,
    /// The last ring check found a rival nearby fitting the frame nearly
    /// as well as the estimate ([`crate::ambiguity`]): not converged
    /// until one finds none.
    ambiguous: bool,
}

/// Shares of a step's budget: the filter's update, and a search's slice;
/// the rest is left for the refinement, the tiles and the publishing.
const FILTER_SHARE: f64 = 0.5;
const SEARCH_SHARE: f64 = 0.3;

/// How much of each new measure the running figures take …
const MEASURE_WEIGHT: f64 = 0.25;
/// … and of one that says the work got dearer: most of it, so that a
/// spread set is not sized by a tight one's cost, but not all, so that
/// one update held up by the machine does not cut the set to its fewest.
const RISE_WEIGHT: f64 = 0.6;

/// A wall-clock budget per step and what the machine has been measured
/// to do within it.
#[derive(Debug, Clone, Copy)]
struct StepBudget {
    per_step: Duration,
    /// Seconds a sensor update took per particle, running mean.
    per_particle_s: Option<f64>,
    /// Point lookups the search made per second, running mean.
    lookups_per_s: Option<f64>,
}

/// An update that built more than a table per this many particles is
/// not timed for the particles' cost.
const PARTICLES_PER_TABLE: usize = 500;

impl StepBudget {
    /// A running figure: a cost that rose is taken mostly (a spread set
    /// costs many times a tight one per particle), one that fell in part.
    fn measure_cost(running: &mut Option<f64>, value: f64) {
        if value.is_finite() && value > 0.0 {
            *running = Some(match *running {
                Some(r) if value < r => r + MEASURE_WEIGHT * (value - r),
                Some(r) => r + RISE_WEIGHT * (value - r),
                None => value,
            });
        }
    }

    /// A running rate: a rate that fell is taken mostly, one that rose in
    /// part.
    fn measure_rate(running: &mut Option<f64>, value: f64) {
        if value.is_finite() && value > 0.0 {
            *running = Some(match *running {
                Some(r) if value > r => r + MEASURE_WEIGHT * (value - r),
                Some(r) => r + RISE_WEIGHT * (value - r),
                None => value,
            });
        }
    }
}

impl Localizer {
    /// A localizer that refreshes reported changes at most every
    /// `refresh_every` (longer while rebuilds are slow, see
    /// [`Self::step`]), counting from `now`.
    pub fn new(mcl: Mcl, map: LocalMap, refresh_every: Duration, now: Instant) -> Self {
        Self {
            mcl,
            map,
            refresh_every,
            stale: HashSet::new(),
            resync: false,
            last_refresh: now,
            last_rebuild: Duration::ZERO,
            stretch_refresh: true,
            searcher: None,
            budget: None,
            ambiguous: false,
        }
    }

    /// Fits each step's work to `per_step` of wall-clock time, as an
    /// any-time filter: the particles to what the machine updates within
    /// half of it, a search's slice to what it looks up within a third
    /// (a search then runs over more frames). Both are measured as the
    /// steps run, so a loaded machine gets fewer particles and longer
    /// searches: it converges later, and the checks of its flag are the
    /// same. Without a budget the work is the settings', the same on any
    /// machine (for runs that must repeat).
    pub fn with_step_budget(mut self, per_step: Duration) -> Self {
        self.budget = Some(StepBudget {
            per_step,
            per_particle_s: None,
            lookups_per_s: None,
        });
        self
    }

    /// The most particles the budget affords now, and the search's
    /// lookups per frame; `None` without a budget.
    pub fn budget_fit(&self) -> Option<(usize, Option<u64>)> {
        self.budget?;
        Some((
            self.mcl.most_particles(),
            self.searcher.as_ref().map(Searcher::slice_lookups),
        ))
    }

    /// Gives the filter a global search ([`crate::searcher`]): a global
    /// start then starts from its hypotheses, a lost filter searches, and
    /// a settled one is believed only once a search confirms it. A filter
    /// already started at a pose is checked from its first frame.
    pub fn with_searcher(mut self, mut searcher: Searcher) -> Self {
        if !self.mcl.particles().is_empty() {
            searcher.start_tracking();
        }
        self.searcher = Some(searcher);
        self
    }

    /// The global search, when the filter has one.
    pub fn searcher(&self) -> Option<&Searcher> {
        self.searcher.as_ref()
    }

    /// The estimate for a frame at `odometry`, converged only where the
    /// search confirmed it ([`Mcl::estimate`] otherwise).
    pub fn estimate(&self, odometry: &Pose2) -> Option<Estimate> {
        let mut estimate = self.mcl.estimate(odometry)?;
        estimate.converged &= self.confirmed() && !self.ambiguous;
        Some(estimate)
    }

    /// What [`Self::estimate`] needs apart from the localizer, to carry
    /// it to frames that come while a step runs.
    pub fn carried(&self) -> Option<CarriedEstimate> {
        let carried = self.mcl.carried()?;
        Some(if self.confirmed() && !self.ambiguous {
            carried
        } else {
            carried.unconfirmed()
        })
    }

    fn confirmed(&self) -> bool {
        self.searcher.as_ref().is_none_or(Searcher::confirmed)
    }

    /// Refreshes at exactly the period, however long table rebuilds take:
    /// for runs in simulated time that must repeat whatever the machine's
    /// load (the stretch measures the rebuilds by the wall clock).
    pub fn with_steady_refresh(mut self) -> Self {
        self.stretch_refresh = false;
        self
    }

    /// The filter.
    pub fn mcl(&self) -> &Mcl {
        &self.mcl
    }

    /// The filter, to start it or to score poses for diagnostics.
    pub fn mcl_mut(&mut self) -> &mut Mcl {
        &mut self.mcl
    }

    /// The cached map.
    pub fn map(&self) -> &LocalMap {
        &self.map
    }

    /// The filter and the cached map at once.
    pub fn parts_mut(&mut self) -> (&mut Mcl, &mut LocalMap) {
        (&mut self.mcl, &mut self.map)
    }

    /// The cached map, for another run on it.
    pub fn into_map(self) -> LocalMap {
        self.map
    }

    /// Notes the next frame's odometry and time before its step, for a
    /// ring that fires in turn ([`Mcl::note_frame`]).
    pub fn note_frame(&mut self, odometry: &Pose2, time_s: f64) {
        self.mcl.note_frame(odometry, time_s);
    }

    /// Global localization: `tiles` (the whole map) go into the cache and
    /// the particles are spread over their known-free cells.
    pub fn start_global(
        &mut self,
        tiles: impl IntoIterator<Item = FetchedTile>,
    ) -> Result<(), LocalizerError> {
        for t in tiles {
            self.map.insert_tile(t.key, t.version, Some(&t.tile))?;
        }
        match &mut self.searcher {
            Some(searcher) => {
                searcher.start_global();
                Ok(())
            }
            None => self.mcl.start_global(&self.map),
        }
    }

    /// Fetches the tiles and builds the tables (or fields) a frame like
    /// `readings` needs with the particles where they are, without
    /// weighing them: a process calls it once started, before it takes
    /// the frame to correct with, so that a global start's tables (all
    /// of the map's) are not built while frames wait. Returns how many
    /// tiles it fetched.
    pub fn prepare(
        &mut self,
        readings: &[f64],
        tiles: &mut impl TileSource,
    ) -> Result<usize, LocalizerError> {
        if self.searcher.as_ref().is_some_and(Searcher::waiting) {
            // No particle yet: the search places them.
            return Ok(0);
        }
        let needed = self.mcl.tiles_for_frame(&self.map, readings);
        let missing = self.mcl.missing_tiles(&self.map, &needed);
        let fetched = fetch_into(tiles, &missing, &mut self.map)?;
        self.mcl.score(&mut self.map, readings)?;
        Ok(fetched)
    }

    /// The server reported that tile `key` changed: it is fetched again at
    /// the next refresh.
    pub fn tile_changed(&mut self, key: TileKey) {
        self.stale.insert(key);
    }

    /// The server's changes were lost (or the map cleared): every held
    /// tile is fetched again at the next refresh.
    pub fn all_changed(&mut self) {
        self.resync = true;
    }

    /// One frame: its odometry pose and readings, at time `now`.
    ///
    /// Reported changes are applied at most every refresh period, longer
    /// (up to four periods) while the table rebuilds a refresh causes take
    /// more than a fifth of the time: with particles spread over the whole
    /// map (global localization, a kidnap) a rebuild covers every tile, and
    /// a map still being built would otherwise keep the filter rebuilding.
    pub fn step(
        &mut self,
        odometry: &Pose2,
        readings: &[f64],
        now: Instant,
        tiles: &mut impl TileSource,
    ) -> Result<StepReport, LocalizerError> {
        let mut report = StepReport::default();
        let every = self.refresh_every;
        let interval = every.max(
            self.last_rebuild
                .saturating_mul(4)
                .min(every.saturating_mul(4)),
        );
        if (self.resync || !self.stale.is_empty())
            && now.saturating_duration_since(self.last_refresh) >= interval
        {
            if self.resync {
                self.map.all_changed();
            } else {
                for key in self.stale.drain() {
                    self.map.tile_changed(key);
                }
            }
            self.stale.clear();
            self.resync = false;
            self.last_refresh = now;
            // Held tiles are fetched again now; a tile whose occupied cells
            // did not change keeps its range tables.
            let refetch = self.map.stale_tiles();
            report.tiles_fetched += fetch_into(tiles, &refetch, &mut self.map)?;
            if let Some(searcher) = &mut self.searcher {
                searcher.map_changed();
            }
        }
        let mut searched = SearchTime::default();
        if let Some(searcher) = &mut self.searcher {
            searcher.note_frame(odometry, readings);
            let proceed = searched.time(searcher, |searcher| {
                searcher.before_step(&mut self.mcl, &self.map, odometry)
            })?;
            if !proceed {
                self.fit_budget(None, searched);
                return Ok(report);
            }
        }
        let mut updated = None;
        if self.mcl.predict(odometry)? {
            let realign = self.mcl.tiles_for_realign(&self.map, readings);
            if !realign.is_empty() {
                let missing = self.mcl.missing_tiles(&self.map, &realign);
                report.tiles_fetched += fetch_into(tiles, &missing, &mut self.map)?;
                report.realigned = self.mcl.realign(&mut self.map, &realign, readings)?;
            }
            let needed = self.mcl.tiles_for_frame(&self.map, readings);
            let missing = self.mcl.missing_tiles(&self.map, &needed);
            report.tiles_fetched += fetch_into(tiles, &missing, &mut self.map)?;
            let started = Instant::now();
            let particles = self.mcl.particles().len();
            let correction = self.mcl.correct(&mut self.map, readings)?;
            // Table builds are the map's cost, not the particles': an
            // update that built many for its particles says little of
            // what a particle costs.
            if correction.tables_built.saturating_mul(PARTICLES_PER_TABLE) <= particles {
                updated = Some((particles, started.elapsed()));
            }
            if correction.tables_built > 0 && self.stretch_refresh {
                self.last_rebuild = started.elapsed();
            }
            self.map.evict_to_budget(&needed.into_iter().collect());
            report.correction = Some(correction);
        }
        report.estimate = match self.mcl.estimate(odometry) {
            Some(estimate) if self.mcl.refines() => {
                let needed = self.mcl.tiles_for_pose(&self.map, &estimate.pose, readings);
                let missing = self.mcl.missing_tiles(&self.map, &needed);
                report.tiles_fetched += fetch_into(tiles, &missing, &mut self.map)?;
                Some(
                    self.mcl
                        .refine(&mut self.map, &needed, estimate, readings)?,
                )
            }
            other => other,
        };
        if report.correction.is_none()
            && let Some(estimate) = &mut report.estimate
            && estimate.converged
            && !self
                .mcl
                .still_fits(&mut self.map, &estimate.pose, readings)?
        {
            estimate.converged = false;
        }
        // The ring check, on each correction of an estimate that is
        // otherwise converged; its verdict holds for the frames between.
        if let Some(estimate) = &report.estimate {
            if !estimate.converged {
                self.ambiguous = false;
            } else if report.correction.is_some() {
                let needed = self.mcl.tiles_for_ring(&self.map, &estimate.pose, readings);
                if !needed.is_empty() {
                    let missing = self.mcl.missing_tiles(&self.map, &needed);
                    report.tiles_fetched += fetch_into(tiles, &missing, &mut self.map)?;
                    report.rival_nearby =
                        self.mcl
                            .rival_nearby(&mut self.map, &needed, &estimate.pose, readings)?;
                    self.ambiguous = report.rival_nearby.is_some_and(|(_, ambiguous)| ambiguous);
                }
            }
        }
        if let (Some(searcher), Some(estimate)) = (&mut self.searcher, &mut report.estimate) {
            let (mcl, map) = (&mut self.mcl, &mut self.map);
            estimate.converged = searched.time(searcher, |searcher| {
                searcher.verify(mcl, map, estimate, odometry)
            })?;
        }
        if let Some(estimate) = &mut report.estimate {
            estimate.converged &= !self.ambiguous;
        }
        self.fit_budget(updated, searched);
        Ok(report)
    }

    /// Measures the step's update (particles, time) and search slices,
    /// and fits the next steps' work to the budget.
    fn fit_budget(&mut self, updated: Option<(usize, Duration)>, searched: SearchTime) {
        let Some(budget) = &mut self.budget else {
            return;
        };
        if let Some((particles, took)) = updated
            && particles > 0
        {
            StepBudget::measure_cost(
                &mut budget.per_particle_s,
                took.as_secs_f64() / particles as f64,
            );
        }
        // Slices too short to time say little of the rate.
        if searched.lookups >= MIN_TIMED_LOOKUPS {
            StepBudget::measure_rate(
                &mut budget.lookups_per_s,
                searched.lookups as f64 / searched.took.as_secs_f64().max(1e-6),
            );
        }
        let seconds = budget.per_step.as_secs_f64();
        if let Some(per_particle) = budget.per_particle_s {
            let most = (seconds * FILTER_SHARE / per_particle).min(usize::MAX as f64);
            self.mcl.set_most_particles(most as usize);
        }
        if let (Some(rate), Some(searcher)) = (budget.lookups_per_s, &mut self.searcher) {
            searcher.set_slice_lookups((seconds * SEARCH_SHARE * rate).min(u64::MAX as f64) as u64);
        }
    }
}

/// Fewest lookups of a step's slices that time the search's rate.
const MIN_TIMED_LOOKUPS: u64 = 1_000_000;

/// The search's share of a step: lookups made, and the time it took.
#[derive(Debug, Clone, Copy, Default)]
struct SearchTime {
    lookups: u64,
    took: Duration,
}

impl SearchTime {
    /// Runs `work` on the searcher, adding its lookups and time.
    fn time<T>(
        &mut self,
        searcher: &mut Searcher,
        work: impl FnOnce(&mut Searcher) -> Result<T, LocalizerError>,
    ) -> Result<T, LocalizerError> {
        let (before, started) = (searcher.stats().lookups, Instant::now());
        let out = work(searcher);
        self.lookups += searcher.stats().lookups - before;
        self.took += started.elapsed();
        out
    }
}

/// Fetches `keys` into `map`; keys the source has no tile for are held as
/// all unknown. Returns how many keys were asked for.
fn fetch_into(
    source: &mut impl TileSource,
    keys: &[TileKey],
    map: &mut LocalMap,
) -> Result<usize, LocalizerError> {
    if keys.is_empty() {
        return Ok(0);
    }
    let fetched = source.fetch(keys).map_err(LocalizerError::Fetch)?;
    let mut found = HashSet::with_capacity(fetched.len());
    for t in &fetched {
        map.insert_tile(t.key, t.version, Some(&t.tile))?;
        found.insert(t.key);
    }
    for key in keys {
        if !found.contains(key) {
            map.insert_tile(*key, 0, None)?;
        }
    }
    Ok(keys.len())
}
