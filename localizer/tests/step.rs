//! One localizer step per frame on a map behind a tile source: what it
//! fetches and when, what a failing source does, and the sensor seam (a
//! sensor the filter has never heard of, plugged in without touching it).

mod common;

use std::cell::RefCell;
use std::time::{Duration, Instant};

use common::*;
use deog_grid::{ClampLimits, Pose2, Resolution, TileKey, TileMap, TileSize};
use deog_localizer::error::LocalizerError;
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::LocalMap;
use deog_localizer::searcher::{Searcher, SearcherSettings};
use deog_localizer::sensors::SensorModel;
use deog_localizer::step::{FetchedTile, Localizer, TileSource};

/// The room as a map server would hold it.
fn room_tiles() -> TileMap {
    let mut tiles = TileMap::new(
        Resolution::DEFAULT,
        TileSize::new(64).unwrap(),
        ClampLimits::default(),
    );
    for ty in -1..=2 {
        for tx in -1..=3 {
            let key = TileKey::new(tx, ty);
            tiles.insert(key, room_tile(key)).unwrap();
        }
    }
    tiles
}

/// A tile source that records every key asked for.
struct Counting {
    tiles: TileMap,
    asked: RefCell<Vec<TileKey>>,
}

impl TileSource for Counting {
    fn fetch(
        &mut self,
        keys: &[TileKey],
    ) -> Result<Vec<FetchedTile>, Box<dyn std::error::Error + Send + Sync>> {
        self.asked.borrow_mut().extend_from_slice(keys);
        self.tiles.fetch(keys)
    }
}

fn tracking_localizer(start: Pose2, now: Instant, refresh: Duration) -> Localizer {
    let mut mcl = filter(3_000, 5);
    mcl.start_at(start, 0.1, 0.05).unwrap();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    Localizer::new(mcl, map, refresh, now)
}

#[test]
fn the_step_fetches_the_tiles_the_particles_need_and_tracks() {
    let reference = room();
    let steps = path(120);
    let mut source = Counting {
        tiles: room_tiles(),
        asked: RefCell::new(Vec::new()),
    };
    let now = Instant::now();
    let mut localizer = tracking_localizer(steps[0].0, now, Duration::from_secs(5));
    let mut errors = Vec::new();
    for (truth, odometry) in &steps {
        let ranges = frame(&reference, truth);
        let report = localizer.step(odometry, &ranges, now, &mut source).unwrap();
        let estimate = report.estimate.expect("an estimate every frame");
        errors.push(error(&estimate.pose, truth).0);
    }
    let asked = source.asked.borrow();
    assert!(!asked.is_empty(), "no tile was fetched");
    // Each tile is fetched once: the cache's budget holds the whole room.
    let mut unique = asked.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), asked.len(), "a tile was fetched twice");
    let tail = &errors[20..];
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    assert!(mean < 0.06, "mean position error {mean:.3} m");
}

#[test]
fn reported_changes_are_fetched_again_once_the_refresh_period_passed() {
    let reference = room();
    let (truth, odometry) = path(1)[0];
    let ranges = frame(&reference, &truth);
    let mut source = Counting {
        tiles: room_tiles(),
        asked: RefCell::new(Vec::new()),
    };
    let start = Instant::now();
    let mut localizer = tracking_localizer(truth, start, Duration::from_secs(5));
    localizer
        .step(&odometry, &ranges, start, &mut source)
        .unwrap();
    let held = TileKey::new(1, 1);
    assert!(
        localizer.map().version(held).is_some(),
        "the robot's tile is held"
    );
    source.asked.borrow_mut().clear();

    // The robot stands still, so only the refresh fetches.
    localizer.tile_changed(held);
    localizer
        .step(
            &odometry,
            &ranges,
            start + Duration::from_secs(1),
            &mut source,
        )
        .unwrap();
    assert!(
        source.asked.borrow().is_empty(),
        "refreshed before its period"
    );
    let report = localizer
        .step(
            &odometry,
            &ranges,
            start + Duration::from_secs(6),
            &mut source,
        )
        .unwrap();
    assert_eq!(*source.asked.borrow(), vec![held]);
    assert_eq!(report.tiles_fetched, 1);
    assert!(report.correction.is_none(), "the robot did not move");
}

#[test]
fn a_failing_source_is_an_error_not_a_panic() {
    struct Down;
    impl TileSource for Down {
        fn fetch(
            &mut self,
            _: &[TileKey],
        ) -> Result<Vec<FetchedTile>, Box<dyn std::error::Error + Send + Sync>> {
            Err("connection refused".into())
        }
    }
    let reference = room();
    let (truth, odometry) = path(1)[0];
    let now = Instant::now();
    let mut localizer = tracking_localizer(truth, now, Duration::from_secs(5));
    let error = localizer
        .step(&odometry, &frame(&reference, &truth), now, &mut Down)
        .unwrap_err();
    assert!(matches!(error, LocalizerError::Fetch(_)), "{error:?}");
    let chain = format!("{error}: {}", std::error::Error::source(&error).unwrap());
    assert_eq!(chain, "fetching tiles: connection refused");
}

/// A sensor the filter knows nothing of: the distances to three beacons,
/// each judged with a Gaussian of 5 cm. It reads no map.
#[derive(Debug)]
struct Beacons([(f64, f64); 3]);

impl Beacons {
    fn read(&self, pose: &Pose2) -> Vec<f64> {
        self.0
            .iter()
            .map(|b| (b.0 - pose.x).hypot(b.1 - pose.y))
            .collect()
    }
}

impl SensorModel for Beacons {
    fn readings(&self) -> usize {
        3
    }
    fn reach(&self) -> f64 {
        0.0
    }
    fn observations(&self) -> f64 {
        3.0
    }
    fn score_particles(
        &mut self,
        _: &mut LocalMap,
        _: &[TileKey],
        particles: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError> {
        out.extend(particles.iter().map(|p| {
            self.read(p)
                .iter()
                .zip(readings)
                .map(|(expected, z)| -((expected - z) / 0.05).powi(2) / 2.0)
                .sum::<f64>()
        }));
        Ok(0)
    }
    fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<f64, LocalizerError> {
        let mut out = Vec::new();
        self.score_particles(map, &[], std::slice::from_ref(pose), readings, &mut out)?;
        Ok(out[0])
    }
}

#[test]
fn a_new_sensor_plugs_into_the_filter_unchanged() {
    let beacons = Beacons([(0.5, 0.5), (7.5, 0.5), (4.0, 5.5)]);
    let mut map = room();
    let steps = path(150);
    let mut mcl = Mcl::with_sensor(
        FilterSettings {
            seed: 9,
            ..FilterSettings::default()
        },
        Box::new(Beacons(beacons.0)),
    )
    .unwrap();
    // Half a metre and 30° off, spread wide.
    let start = steps[0].0;
    mcl.start_at(
        Pose2::new(start.x + 0.5, start.y - 0.3, start.theta + 0.5),
        0.6,
        0.6,
    )
    .unwrap();
    let mut last = f64::INFINITY;
    for (truth, odometry) in &steps {
        if mcl.predict(odometry).unwrap() {
            mcl.correct(&mut map, &beacons.read(truth)).unwrap();
        }
        last = error(&mcl.estimate(odometry).unwrap().pose, truth).0;
    }
    assert!(last < 0.1, "position error {last:.3} m after 150 frames");
    // The frame check is the sensor's: three readings, not sixteen.
    assert!(mcl.correct(&mut map, &[1.0; 16]).is_err());
}

#[test]
fn prepared_global_start_builds_every_table_so_the_first_correction_builds_none() {
    let reference = room();
    let steps = path(20);
    let ranges = frame(&reference, &steps[0].0);
    let mut source = room_tiles();
    let now = Instant::now();
    let mcl = filter(20_000, 7);
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let mut localizer = Localizer::new(mcl, map, Duration::from_secs(5), now);
    let keys: Vec<TileKey> = source.tiles().map(|(key, _)| *key).collect();
    let whole = source.fetch(&keys).unwrap();
    localizer.start_global(whole).unwrap();
    let before: Vec<Pose2> = localizer.mcl().particles().to_vec();
    localizer.prepare(&ranges, &mut source).unwrap();
    assert!(
        localizer.map().stats().tables_built > 0,
        "preparing built no table"
    );
    assert_eq!(
        localizer.mcl().particles(),
        before.as_slice(),
        "preparing moved the particles"
    );
    let first = steps
        .iter()
        .find_map(|(truth, odometry)| {
            let ranges = frame(&reference, truth);
            let report = localizer.step(odometry, &ranges, now, &mut source).unwrap();
            report.correction
        })
        .expect("no correction in 20 frames");
    assert_eq!(first.tables_built, 0, "the first correction built tables");
}

#[test]
fn slow_rebuilds_stretch_the_refresh_period_unless_it_is_kept_steady() {
    let reference = room();
    let (truth, odometry) = path(1)[0];
    let ranges = frame(&reference, &truth);
    // A period far shorter than building any table: the first step's
    // rebuild stretches it to four periods, unless kept steady.
    let period = Duration::from_micros(1);
    for steady in [false, true] {
        let mut source = Counting {
            tiles: room_tiles(),
            asked: RefCell::new(Vec::new()),
        };
        let start = Instant::now();
        let mut localizer = tracking_localizer(truth, start, period);
        if steady {
            localizer = localizer.with_steady_refresh();
        }
        let first = localizer
            .step(&odometry, &ranges, start, &mut source)
            .unwrap();
        assert!(first.correction.is_some_and(|c| c.tables_built > 0));
        source.asked.borrow_mut().clear();
        let held = TileKey::new(1, 1);
        localizer.tile_changed(held);
        localizer
            .step(&odometry, &ranges, start + 2 * period, &mut source)
            .unwrap();
        assert_eq!(
            source.asked.borrow().contains(&held),
            steady,
            "steady {steady}"
        );
    }
}

#[test]
fn a_searching_global_start_finds_the_robot_and_claims_only_what_is_right() {
    let reference = room();
    let steps = path(300);
    let mut tiles = room_tiles();
    let beams = deog_rig::builtin::scout().beams().to_vec();
    let searcher = Searcher::new(beams.clone(), SearcherSettings::for_beams(&beams)).unwrap();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let now = Instant::now();
    let mut localizer =
        Localizer::new(filter(100_000, 3), map, Duration::MAX, now).with_searcher(searcher);
    let keys: Vec<TileKey> = tiles.tiles().map(|(k, _)| *k).collect();
    localizer.start_global(tiles.fetch(&keys).unwrap()).unwrap();
    let (mut waited, mut most, mut claimed, mut last) = (0, 0, 0, None);
    for (truth, odometry) in &steps {
        let ranges = frame(&reference, truth);
        let report = localizer.step(odometry, &ranges, now, &mut tiles).unwrap();
        let Some(estimate) = report.estimate else {
            assert!(localizer.searcher().unwrap().waiting());
            waited += 1;
            continue;
        };
        most = most.max(estimate.particle_count);
        let (metres, radians) = error(&estimate.pose, truth);
        if estimate.converged {
            claimed += 1;
            assert!(
                metres <= 0.5 && radians <= 0.25,
                "converged {metres} m, {radians} rad off"
            );
        }
        last = Some((estimate.converged, metres, radians));
    }
    // It waited for the frames to outline the room, then started from a
    // few hypotheses: never the most particles allowed.
    assert!(waited > 5, "waited {waited} frames");
    assert!(most < 30_000, "{most} particles");
    let (converged, metres, radians) = last.expect("estimates");
    assert!(converged && claimed > 50, "claimed {claimed}");
    assert!(metres < 0.15 && radians < 0.1, "{metres} m, {radians} rad");
    let stats = localizer.searcher().unwrap().stats();
    assert!(stats.searches >= 1 && stats.confirmations >= 2, "{stats:?}");
}

#[test]
fn a_step_budget_fits_the_particles_and_the_search_to_the_machine() {
    let reference = room();
    let steps = path(300);
    let beams = deog_rig::builtin::scout().beams().to_vec();
    // (budget, converges): a microsecond affords the fewest particles and
    // a search of a block a frame, a minute everything the settings allow.
    for (budget, generous) in [
        (Duration::from_micros(1), false),
        (Duration::from_secs(60), true),
    ] {
        let mut tiles = room_tiles();
        let searcher = Searcher::new(beams.clone(), SearcherSettings::for_beams(&beams)).unwrap();
        let map = LocalMap::new(settings(1 << 30)).unwrap();
        let now = Instant::now();
        let mut localizer = Localizer::new(filter(100_000, 3), map, Duration::MAX, now)
            .with_searcher(searcher)
            .with_step_budget(budget);
        let keys: Vec<TileKey> = tiles.tiles().map(|(k, _)| *k).collect();
        localizer.start_global(tiles.fetch(&keys).unwrap()).unwrap();
        let mut last = None;
        for (truth, odometry) in &steps {
            let ranges = frame(&reference, truth);
            let report = localizer.step(odometry, &ranges, now, &mut tiles).unwrap();
            if let Some(estimate) = report.estimate {
                let (metres, radians) = error(&estimate.pose, truth);
                assert!(
                    !estimate.converged || (metres <= 0.5 && radians <= 0.25),
                    "budget {budget:?}: converged {metres} m, {radians} rad off"
                );
                last = Some(estimate.converged);
            }
        }
        let (most, slice) = localizer.budget_fit().expect("a budget");
        let slice = slice.expect("a searcher");
        let fewest = localizer.mcl().settings().kld.min_particles;
        if generous {
            assert_eq!(most, 100_000);
            assert!(slice > 10_000_000, "{slice} lookups a frame");
            assert_eq!(last, Some(true), "a minute a step converges");
        } else {
            assert_eq!(most, fewest);
            assert!(slice < 1_000_000, "{slice} lookups a frame");
            let stats = localizer.searcher().unwrap().stats();
            assert!(stats.searches >= 1, "{stats:?}");
        }
    }
}
