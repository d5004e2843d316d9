//! The likelihood field on the synthetic room, with laser frames cast by
//! marching each ray over the map's cells (so the map is exact and any
//! error is the model's or the filter's): scores peak at the true pose,
//! MCL tracks a laser robot, a frame's tiles are where its endpoints fall
//! (and the step fetches them), fields go when the walls near them move,
//! and the cache keeps to its budget with fields built and evicted; an
//! estimate along a corridor whose ends the laser cannot see is not
//! called converged.

mod common;

use std::cell::RefCell;
use std::collections::HashSet;
use std::time::{Duration, Instant};

use common::*;
use deog_grid::{
    ClampLimits, Occupancy, OccupancyView, Pose2, Resolution, TileKey, TileMap, TileSize,
};
use deog_localizer::distance_field::FieldSpec;
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::LocalMap;
use deog_localizer::refine::RefineParams;
use deog_localizer::sensors::{LikelihoodField, LikelihoodFieldParams, SensorModel};
use deog_localizer::step::{FetchedTile, Localizer, TileSource};
use deog_rig::Rig;

fn laser() -> Rig {
    deog_rig::built_in_rig("laser180").unwrap()
}

fn model() -> LikelihoodField {
    LikelihoodField::new(laser(), LikelihoodFieldParams::default()).unwrap()
}

/// The range along a ray from `(x, y)` heading `theta` to the first
/// occupied cell, in 5 mm steps; `None` past `max_range`.
fn march(map: &impl OccupancyView, x: f64, y: f64, theta: f64, max_range: f64) -> Option<f64> {
    let res = Resolution::DEFAULT;
    let (sin, cos) = theta.sin_cos();
    let mut t = 0.0;
    while t <= max_range {
        let cell = res.cell_of(x + t * cos, y + t * sin).ok()?;
        if map.occupancy(cell) == Occupancy::Occupied {
            return Some(t);
        }
        t += 0.005;
    }
    None
}

/// The frame `rig` reads at `pose` on `map`: no echo as the beam's no-echo
/// range.
fn laser_frame(rig: &Rig, map: &impl OccupancyView, pose: &Pose2) -> Vec<f64> {
    rig.beams()
        .iter()
        .map(|b| {
            let s = pose.compose(&b.mount);
            march(map, s.x, s.y, s.theta, b.max_range).unwrap_or(b.no_echo.at_or_beyond)
        })
        .collect()
}

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

fn laser_filter(max_particles: usize, seed: u64) -> Mcl {
    let mut settings = FilterSettings {
        seed,
        ..FilterSettings::default()
    };
    settings.kld.max_particles = max_particles;
    Mcl::with_sensor(settings, Box::new(model())).unwrap()
}

#[test]
fn the_true_pose_scores_above_poses_a_little_off() {
    let mut map = room();
    let rig = laser();
    let mut field = model();
    for truth in [
        Pose2::new(3.0, 2.5, 0.3),
        Pose2::new(6.2, 1.2, 2.0),
        Pose2::new(1.0, 4.5, -1.2),
    ] {
        let ranges = laser_frame(&rig, &map, &truth);
        let at_truth = field.score_pose(&mut map, &truth, &ranges).unwrap();
        for (dx, dy, dtheta) in [
            (0.3, 0.0, 0.0),
            (-0.3, 0.0, 0.0),
            (0.0, 0.3, 0.0),
            (0.0, -0.3, 0.0),
            (0.0, 0.0, 0.2),
            (0.0, 0.0, -0.2),
        ] {
            let off = Pose2::new(truth.x + dx, truth.y + dy, truth.theta + dtheta);
            let score = field.score_pose(&mut map, &off, &ranges).unwrap();
            assert!(
                score < at_truth,
                "{off:?} scores {score:.3}, the truth {truth:?} {at_truth:.3}"
            );
        }
    }
}

#[test]
fn mcl_with_the_likelihood_field_tracks_a_laser_robot() {
    let reference = room();
    let rig = laser();
    let steps = path(150);
    let mut source = Counting {
        tiles: room_tiles(),
        asked: RefCell::new(Vec::new()),
    };
    let now = Instant::now();
    let start = steps[0].0;
    let mut mcl = laser_filter(3_000, 4);
    mcl.start_at(
        Pose2::new(start.x + 0.1, start.y - 0.1, start.theta + 0.05),
        0.2,
        0.1,
    )
    .unwrap();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let mut localizer = Localizer::new(mcl, map, Duration::from_secs(5), now);
    let mut errors = Vec::new();
    for (truth, odometry) in &steps {
        let ranges = laser_frame(&rig, &reference, truth);
        let report = localizer.step(odometry, &ranges, now, &mut source).unwrap();
        let estimate = report.estimate.expect("an estimate every frame");
        errors.push(error(&estimate.pose, truth));
    }
    // The field is flat where endpoints fall inside a wall, and this
    // laser sees only ahead: the estimate may sit a few centimetres into
    // the direction of travel (the odometry reads 2 % long), within a
    // cell or two of the truth.
    let tail = &errors[30..];
    let position = tail.iter().map(|e| e.0).sum::<f64>() / tail.len() as f64;
    let heading = tail.iter().map(|e| e.1).sum::<f64>() / tail.len() as f64;
    let worst = tail.iter().map(|e| e.0).fold(0.0, f64::max);
    assert!(position < 0.08, "mean position error {position:.3} m");
    assert!(worst < 0.15, "worst position error {worst:.3} m");
    assert!(
        heading < 2f64.to_radians(),
        "mean heading error {:.2}°",
        heading.to_degrees()
    );
    // Fields only, no range table; every tile fetched once.
    let stats = localizer.map().stats();
    assert!(
        stats.fields_built > 0 && stats.tables_built == 0,
        "{stats:?}"
    );
    let asked = source.asked.borrow();
    let unique: HashSet<&TileKey> = asked.iter().collect();
    assert_eq!(unique.len(), asked.len(), "a tile was fetched twice");
}

#[test]
fn a_frame_needs_the_tiles_its_endpoints_fall_in() {
    let map = room();
    let rig = laser();
    let field = model();
    let truth = Pose2::new(3.0, 2.5, 0.3);
    let mut ranges = laser_frame(&rig, &map, &truth);
    // One echo 30 m ahead, far past the room and any reach.
    let ahead = field.scored_readings()[30];
    ranges[ahead] = 30.0;
    let particles = [truth, Pose2::new(3.3, 2.4, 0.25), Pose2::new(2.8, 2.9, 0.4)];
    let needed: HashSet<TileKey> = field
        .tiles_needed(&map, &particles, &ranges)
        .into_iter()
        .collect();
    let res = map.settings().resolution;
    let mut endpoints = HashSet::new();
    for p in &particles {
        for &i in field.scored_readings() {
            let beam = rig.beams()[i];
            let s = p.compose(&beam.mount);
            let (x, y) = (
                s.x + ranges[i] * s.theta.cos(),
                s.y + ranges[i] * s.theta.sin(),
            );
            endpoints.insert(map.tile_of(res.cell_of(x, y).unwrap()));
        }
    }
    assert_eq!(needed, endpoints);
    let heading = truth.theta + rig.beams()[ahead].mount.theta;
    let far = map.tile_of(
        res.cell_of(3.0 + 30.0 * heading.cos(), 2.5 + 30.0 * heading.sin())
            .unwrap(),
    );
    assert!(needed.contains(&far), "{far:?} not in {needed:?}");
    // The step fetches it, and the tiles the field there reads.
    let mut source = Counting {
        tiles: room_tiles(),
        asked: RefCell::new(Vec::new()),
    };
    let mut mcl = laser_filter(500, 1);
    mcl.start_at(truth, 0.01, 0.01).unwrap();
    let now = Instant::now();
    let mut localizer = Localizer::new(
        mcl,
        LocalMap::new(settings(1 << 30)).unwrap(),
        Duration::from_secs(5),
        now,
    );
    localizer.step(&truth, &ranges, now, &mut source).unwrap();
    let asked: HashSet<TileKey> = source.asked.borrow().iter().copied().collect();
    for key in [far, TileKey::new(far.x + 1, far.y + 1)] {
        assert!(asked.contains(&key), "{key:?} was not fetched");
    }
    assert!(localizer.map().field(far).is_some());
}

#[test]
fn a_field_goes_when_walls_near_it_move_and_stays_for_ragged_edges() {
    let mut map = room();
    let spec = FieldSpec { max_distance: 2.0 };
    let key = TileKey::new(1, 0);
    map.ensure_fields(&[key], &spec).unwrap();
    let before = map.field(key).unwrap().clone();
    // A new box in the neighbouring tile (0, 0): within 2 m of tile (1, 0).
    let boxed = |x: f64, y: f64| {
        if (2.6..3.0).contains(&x) && (0.8..1.2).contains(&y) {
            OCCUPIED
        } else {
            room_log_odds(x, y)
        }
    };
    let neighbour = TileKey::new(0, 0);
    map.insert_tile(neighbour, 2, Some(&tile_of(neighbour, boxed)))
        .unwrap();
    assert!(map.field(key).is_none(), "the field outlived a new wall");
    assert_eq!(map.ensure_fields(&[key], &spec).unwrap(), 1);
    assert_ne!(map.field(key).unwrap(), &before);
    // A wall one cell thicker at its edge, two tiles away: kept.
    let far_key = TileKey::new(3, 0);
    let ragged = |x: f64, y: f64| {
        if (7.85..7.9).contains(&x) {
            OCCUPIED
        } else {
            room_log_odds(x, y)
        }
    };
    let far = TileKey::new(2, 0);
    map.ensure_fields(&[far_key], &spec).unwrap();
    map.insert_tile(far, 2, Some(&tile_of(far, ragged)))
        .unwrap();
    assert!(map.field(key).is_some());
    assert!(map.field(far_key).is_some());
    // Another spec rebuilds every field.
    let wider = FieldSpec { max_distance: 3.0 };
    assert_eq!(map.missing_field_tiles(&[key], &wider), Vec::new());
    map.ensure_fields(&[key], &wider).unwrap();
    assert_eq!(map.field_spec(), Some(wider));
    assert!(map.field(far_key).is_none());
}

#[test]
fn the_cache_keeps_its_budget_with_fields_built_and_evicted() {
    // The room pattern repeated over a 40 × 40 tile map behind a 4 MiB
    // budget; particles driven from one corner to the other, a laser
    // reading 20 m on every beam, so each frame needs a ring of tiles.
    let budget = 4 << 20;
    let mut map = LocalMap::new(settings(budget)).unwrap();
    let mut mcl = laser_filter(2_000, 2);
    let ranges = vec![20.0; 180];
    let mut peak = 0;
    for step in 0..40 {
        let p = Pose2::new(
            1.6 + 3.2 * f64::from(step),
            1.6 + 3.2 * f64::from(step),
            0.7,
        );
        mcl.start_at(p, 0.3, 0.3).unwrap();
        let needed = mcl.tiles_for_frame(&map, &ranges);
        assert!(needed.len() <= map.field_capacity());
        for key in mcl.missing_tiles(&map, &needed) {
            let local = TileKey::new(key.x.rem_euclid(3), key.y.rem_euclid(2));
            map.insert_tile(key, 1, Some(&room_tile(local))).unwrap();
        }
        mcl.correct(&mut map, &ranges).unwrap();
        for key in &needed {
            assert!(map.field(*key).is_some(), "no field for {key:?}");
        }
        map.evict_to_budget(&needed.iter().copied().collect::<HashSet<_>>());
        peak = peak.max(map.bytes());
    }
    assert!(
        peak <= budget,
        "the cache held {peak} bytes, budget {budget}"
    );
    let stats = map.stats();
    assert!(
        stats.fields_dropped > 0 && stats.tiles_evicted > 0,
        "{stats:?}"
    );
}

#[test]
fn bad_parameters_and_frames_are_refused_by_name() {
    let bad = |params: LikelihoodFieldParams, name: &str| {
        let err = LikelihoodField::new(laser(), params)
            .unwrap_err()
            .to_string();
        assert!(err.contains(name), "{err}");
    };
    let d = LikelihoodFieldParams::default();
    bad(LikelihoodFieldParams { z_hit: 1.5, ..d }, "z_hit");
    bad(LikelihoodFieldParams { z_rand: 0.0, ..d }, "z_rand");
    bad(
        LikelihoodFieldParams {
            sigma_hit: -0.1,
            ..d
        },
        "sigma_hit",
    );
    bad(
        LikelihoodFieldParams {
            max_distance: f64::NAN,
            ..d
        },
        "max_distance",
    );
    bad(LikelihoodFieldParams { max_beams: 0, ..d }, "max_beams");
    bad(
        LikelihoodFieldParams {
            tempering: 2.0,
            ..d
        },
        "tempering",
    );
    bad(
        LikelihoodFieldParams {
            unknown_distance: 3.0,
            ..d
        },
        "unknown_distance",
    );
    bad(
        LikelihoodFieldParams {
            search_tempering: Some(0.0),
            ..d
        },
        "search_tempering",
    );
    bad(
        LikelihoodFieldParams {
            refine: Some(RefineParams {
                inlier_distance: -1.0,
                ..RefineParams::default()
            }),
            ..d
        },
        "inlier_distance",
    );
    let field = model();
    assert_eq!(field.scored_readings().len(), 60);
    assert_eq!(field.scored_readings()[0], 0);
    assert_eq!(field.scored_readings()[59], 179);
    let err = field.check_frame(&[1.0; 16]).unwrap_err().to_string();
    assert!(err.contains("180"), "{err}");
    let mut frame = vec![1.0; 180];
    frame[7] = f64::NAN;
    let err = field.check_frame(&frame).unwrap_err().to_string();
    assert!(err.contains("ranges[7]"), "{err}");
}

#[test]
fn unknown_space_is_neutral_between_a_hit_and_a_miss() {
    // One endpoint straight ahead, on a wall, in known free space far from
    // any wall, and in a tile the server does not have.
    let mut map = room();
    let rig = laser();
    let params = LikelihoodFieldParams {
        max_beams: 180,
        ..LikelihoodFieldParams::default()
    };
    let mut field = LikelihoodField::new(rig, params).unwrap();
    let pose = Pose2::new(4.0, 2.2, 0.0);
    let mut score_at = |range: f64| {
        let mut ranges = vec![50.0; 180];
        ranges[90] = range;
        field.score_pose(&mut map, &pose, &ranges).unwrap()
    };
    // The wall at x = 7.9..8; the block (5, 3)..(5.5, 5) is > 0.8 m off.
    let hit = score_at(3.9);
    let miss = score_at(1.2);
    let unknown = score_at(30.0);
    assert!(hit > unknown && unknown > miss, "{hit} {unknown} {miss}");
    let tau = params.tempering;
    let expected = params.log_likelihood(params.unknown_distance, 50.0) * tau;
    assert!(
        (unknown - expected).abs() < 1e-3 * tau,
        "{unknown} vs {expected}"
    );
}

/// As [`laser_frame`], but each echo from the middle of the ray's chord
/// through the first occupied cell, as a map built from such echoes holds
/// them (a cell is marked where echoes fall, on average its middle),
/// rather than from the cell's face.
fn laser_frame_mid_cell(rig: &Rig, map: &impl OccupancyView, pose: &Pose2) -> Vec<f64> {
    let res = Resolution::DEFAULT;
    rig.beams()
        .iter()
        .map(|b| {
            let s = pose.compose(&b.mount);
            let Some(face) = march(map, s.x, s.y, s.theta, b.max_range) else {
                return b.no_echo.at_or_beyond;
            };
            let (sin, cos) = s.theta.sin_cos();
            let cell = res.cell_of(s.x + face * cos, s.y + face * sin).ok();
            let mut t = face;
            while res.cell_of(s.x + t * cos, s.y + t * sin).ok() == cell {
                t += 0.001;
            }
            (face + t) / 2.0
        })
        .collect()
}

/// Mean position error of a tracking run on the room's path with `params`.
fn tracking_error(params: LikelihoodFieldParams) -> f64 {
    let reference = room();
    let rig = laser();
    let steps = path(150);
    let now = Instant::now();
    let start = steps[0].0;
    let filter = FilterSettings {
        seed: 4,
        ..FilterSettings::default()
    };
    let field = LikelihoodField::new(rig.clone(), params).unwrap();
    let mut mcl = Mcl::with_sensor(filter, Box::new(field)).unwrap();
    mcl.start_at(
        Pose2::new(start.x + 0.1, start.y - 0.1, start.theta + 0.05),
        0.2,
        0.1,
    )
    .unwrap();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let mut localizer = Localizer::new(mcl, map, Duration::from_secs(5), now);
    let mut source = room_tiles();
    let mut errors = Vec::new();
    for (truth, odometry) in &steps {
        let ranges = laser_frame_mid_cell(&rig, &reference, truth);
        let report = localizer.step(odometry, &ranges, now, &mut source).unwrap();
        errors.push(error(&report.estimate.expect("an estimate").pose, truth).0);
    }
    let tail = &errors[30..];
    tail.iter().sum::<f64>() / tail.len() as f64
}

#[test]
fn the_refined_estimate_tracks_nearer_than_the_filters_own() {
    let refined = tracking_error(LikelihoodFieldParams::default());
    let plain = tracking_error(LikelihoodFieldParams {
        refine: None,
        ..LikelihoodFieldParams::default()
    });
    assert!(
        refined < 0.6 * plain && refined < 0.03,
        "refined {refined:.4} m, the filter's own {plain:.4} m"
    );
}

#[test]
fn a_searching_filter_scores_with_the_search_tempering() {
    let mut map = room();
    let rig = laser();
    let truth = Pose2::new(3.0, 2.5, 0.3);
    let ranges = laser_frame(&rig, &map, &truth);
    let off = Pose2::new(3.3, 2.4, 0.4);
    let mut field = LikelihoodField::new(
        rig,
        LikelihoodFieldParams {
            tempering: 0.5,
            search_tempering: Some(0.05),
            ..LikelihoodFieldParams::default()
        },
    )
    .unwrap();
    let settled = field.score_pose(&mut map, &off, &ranges).unwrap();
    assert_eq!(field.tempering(), 0.5);
    field.set_searching(true);
    let searching = field.score_pose(&mut map, &off, &ranges).unwrap();
    assert_eq!(field.tempering(), 0.05);
    assert!(settled.abs() > 1.0, "{settled}");
    assert!(
        (searching / settled - 0.1).abs() < 1e-9,
        "searching {searching}, settled {settled}"
    );
}

/// The room's circle, with wheels that slip from frame 60 to 71: the
/// odometry reads each of those steps backwards (5 cm back where the
/// robot drove 5 cm on), as the Freiburg 079 log's do for a stretch.
fn slipping_path() -> Vec<(Pose2, Pose2)> {
    let steps = path(150);
    let mut out = Vec::with_capacity(steps.len());
    let mut odometry = steps[0].1;
    out.push(steps[0]);
    for (k, pair) in steps.windows(2).enumerate() {
        let (from, to) = (pair[0].1, pair[1].1);
        let mut step = to.relative_to(&from);
        if (60..72).contains(&(k + 1)) {
            step.x = -step.x;
            step.y = -step.y;
        }
        odometry = odometry.compose(&step);
        out.push((pair[1].0, odometry));
    }
    out
}

/// A laser filter tracking [`slipping_path`], realigning or not: the
/// worst position error from frame 30 on, the realignments whose estimate
/// was called converged, and whether the last estimate is.
fn worst_error_through_slipping_wheels(realign: bool) -> (f64, usize, bool) {
    let reference = room();
    let rig = laser();
    let steps = slipping_path();
    let now = Instant::now();
    let mut filter = FilterSettings {
        seed: 4,
        ..FilterSettings::default()
    };
    filter.kld.max_particles = 3_000;
    if !realign {
        filter.realign = None;
    }
    let mut mcl = Mcl::with_sensor(filter, Box::new(model())).unwrap();
    mcl.start_at(steps[0].0, 0.05, 0.05).unwrap();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let mut localizer = Localizer::new(mcl, map, Duration::from_secs(5), now);
    let mut source = room_tiles();
    let mut worst: f64 = 0.0;
    let (mut realigned, mut sure_on_one_scan, mut converged_at_end) = (0, 0, false);
    for (k, (truth, odometry)) in steps.iter().enumerate() {
        let ranges = laser_frame_mid_cell(&rig, &reference, truth);
        let report = localizer.step(odometry, &ranges, now, &mut source).unwrap();
        let estimate = report.estimate.expect("an estimate");
        realigned += usize::from(report.realigned.is_some());
        sure_on_one_scan += usize::from(report.realigned.is_some() && estimate.converged);
        converged_at_end = estimate.converged;
        if k >= 30 {
            worst = worst.max(error(&estimate.pose, truth).0);
        }
    }
    assert_eq!(realigned > 0, realign, "{realigned} realignments");
    (worst, sure_on_one_scan, converged_at_end)
}

#[test]
fn a_laser_filter_follows_the_scans_where_the_wheels_slip() {
    let (followed, sure_on_one_scan, converged_at_end) = worst_error_through_slipping_wheels(true);
    let (wheels_alone, _, _) = worst_error_through_slipping_wheels(false);
    assert!(
        followed < 0.25 && wheels_alone > 1.0,
        "worst error realigning {followed:.3} m, following the wheels alone {wheels_alone:.3} m"
    );
    // A pose that rests on one scan's match is not called converged; once
    // the scans fit it again, it is.
    assert_eq!(sure_on_one_scan, 0, "realignments called converged");
    assert!(converged_at_end, "not converged again after the slip");
}

#[test]
fn the_cache_counts_tiles_newly_held_not_those_fetched_again() {
    // What a search grid of the held tiles checks to grow with them.
    let mut map = LocalMap::new(settings(1 << 30)).unwrap();
    let (a, b) = (TileKey::new(0, 0), TileKey::new(1, 0));
    map.insert_tile(a, 1, Some(&room_tile(a))).unwrap();
    assert_eq!(map.stats().tiles_added, 1);
    map.insert_tile(a, 2, Some(&room_tile(a))).unwrap();
    assert_eq!(map.stats().tiles_added, 1);
    map.insert_tile(b, 1, None).unwrap();
    assert_eq!(map.stats().tiles_added, 2);
}

/// A corridor 1.8 m wide along x from -60 m to `end`, closed there.
fn corridor_tiles(end: f64) -> TileMap {
    let log_odds = move |x: f64, y: f64| {
        if !(-60.0..=end + 0.2).contains(&x) || y.abs() > 1.1 {
            i16::MIN
        } else if y.abs() >= 0.9 || x >= end {
            OCCUPIED
        } else {
            FREE
        }
    };
    let mut tiles = TileMap::new(
        Resolution::DEFAULT,
        TileSize::new(64).unwrap(),
        ClampLimits::default(),
    );
    let side: f64 = 64.0 * Resolution::DEFAULT.metres();
    for tx in (-60.0 / side).floor() as i32..=((end + 0.2) / side).floor() as i32 {
        for ty in -1..=0 {
            let key = TileKey::new(tx, ty);
            tiles.insert(key, tile_of(key, log_odds)).unwrap();
        }
    }
    tiles
}

/// A laser filter tracking a robot that drives 2 m along the corridor of
/// [`corridor_tiles`] to x = 0, from its true pose: whether its last
/// estimate is called converged, and its error.
fn converged_in_corridor(end: f64) -> (bool, f64) {
    let mut source = corridor_tiles(end);
    let rig = laser();
    let mut filter = FilterSettings {
        seed: 3,
        ..FilterSettings::default()
    };
    filter.kld.max_particles = 2_000;
    let mut mcl = Mcl::with_sensor(filter, Box::new(model())).unwrap();
    let start = Pose2::new(-2.0, 0.0, 0.0);
    mcl.start_at(start, 0.02, 0.02).unwrap();
    let now = Instant::now();
    let map = LocalMap::new(settings(1 << 30)).unwrap();
    let mut localizer = Localizer::new(mcl, map, Duration::from_secs(5), now);
    let mut last = None;
    for k in 0..=20 {
        let truth = Pose2::new(-2.0 + 0.1 * f64::from(k), 0.0, 0.0);
        let ranges = laser_frame(&rig, &source, &truth);
        let report = localizer.step(&truth, &ranges, now, &mut source).unwrap();
        last = report
            .estimate
            .map(|e| (e.converged, error(&e.pose, &truth).0));
    }
    last.expect("an estimate")
}

#[test]
fn an_estimate_along_a_corridor_whose_ends_the_laser_cannot_see_is_not_converged() {
    // The far end 60 m ahead, past the laser's 50 m: every pose along the
    // corridor explains the scan as well.
    let (open, open_error) = converged_in_corridor(60.0);
    // The end 3 m ahead pins the pose along it.
    let (closed, closed_error) = converged_in_corridor(3.0);
    assert!(
        closed_error < 0.1 && open_error < 0.3,
        "errors {closed_error:.3} m (closed), {open_error:.3} m (open)"
    );
    assert!(closed, "not converged with the corridor's end in sight");
    assert!(!open, "converged where the scan does not pin the pose");
}
