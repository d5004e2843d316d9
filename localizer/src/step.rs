//! One frame through the localizer, the same for the `deog localize`
//! process and for `deog bench localize`: apply the map changes the server
//! reported (at most every refresh period), predict, fetch the tiles the
//! frame needs (as its sensor model says: under the particles for a sonar,
//! where the endpoints fall for a likelihood field), correct, evict what
//! the cache cannot hold, and refine the estimate where the sensor model
//! does (the likelihood field: [`crate::refine`]).
//!
//! The map server is behind [`TileSource`]: the process fetches over the
//! network, the bench from a map in memory. The step itself does no I/O.

use std::collections::HashSet;
use std::time::{Duration, Instant};

use deog_grid::{Pose2, Tile, TileKey, TileMap};

use crate::error::LocalizerError;
use crate::filter::{CarriedEstimate, CorrectionReport, Estimate, Mcl};
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
        }
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
        estimate.converged &= self.confirmed();
        Some(estimate)
    }

    /// What [`Self::estimate`] needs apart from the localizer, to carry
    /// it to frames that come while a step runs.
    pub fn carried(&self) -> Option<CarriedEstimate> {
        let carried = self.mcl.carried()?;
        Some(if self.confirmed() {
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
        if let Some(searcher) = &mut self.searcher {
            searcher.note_frame(odometry, readings);
            if !searcher.before_step(&mut self.mcl, &self.map, odometry)? {
                return Ok(report);
            }
        }
        if self.mcl.predict(odometry)? {
            let needed = self.mcl.tiles_for_frame(&self.map, readings);
            let missing = self.mcl.missing_tiles(&self.map, &needed);
            report.tiles_fetched += fetch_into(tiles, &missing, &mut self.map)?;
            let started = Instant::now();
            let correction = self.mcl.correct(&mut self.map, readings)?;
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
        if let (Some(searcher), Some(estimate)) = (&mut self.searcher, &mut report.estimate) {
            estimate.converged =
                searcher.verify(&mut self.mcl, &mut self.map, estimate, odometry)?;
        }
        Ok(report)
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
