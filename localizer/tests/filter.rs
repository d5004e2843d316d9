//! The particle filter on a synthetic room, with sonar frames cast from the
//! same map by the plain reference (so the map is exact and any error is the
//! filter's): tracking, global localization, kidnapping, determinism, bad
//! input; the cache staying within its budget on a map far larger, and
//! keeping its tables through changes that leave the occupied cells be.

use std::collections::HashSet;

use deog_grid::{Pose2, Resolution, RingFiring, SensorRing, TileKey};
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::LocalMap;
use deog_localizer::range_table::ConeGeometry;

mod common;

use common::*;

#[test]
fn tracking_stays_within_centimetres() {
    let mut map = room();
    let steps = path(240);
    let mut mcl = filter(5_000, 3);
    let start = steps[0].0;
    mcl.start_at(
        Pose2::new(start.x + 0.1, start.y - 0.1, start.theta + 0.05),
        0.2,
        0.1,
    )
    .unwrap();
    let errors = run(&mut mcl, &mut map, &steps);
    let tail = &errors[40..];
    let mean_position = tail.iter().map(|e| e.0).sum::<f64>() / tail.len() as f64;
    let mean_heading = tail.iter().map(|e| e.1).sum::<f64>() / tail.len() as f64;
    assert!(
        mean_position < 0.05,
        "mean position error {mean_position:.3} m"
    );
    assert!(
        mean_heading < 2f64.to_radians(),
        "mean heading error {:.2}°",
        mean_heading.to_degrees()
    );
    // KLD-sampling shrank the set once the pose was certain.
    assert!(
        mcl.particles().len() < 5_000,
        "{} particles",
        mcl.particles().len()
    );
}

#[test]
fn global_localization_converges_and_is_deterministic() {
    let mut map = room();
    let steps = path(200);
    let mut first = filter(30_000, 11);
    first.start_global(&map).unwrap();
    let errors = run(&mut first, &mut map, &steps);
    let (position, heading) = errors[errors.len() - 1];
    assert!(
        position < 0.15 && heading < 0.15,
        "final error {position:.3} m, {heading:.3} rad"
    );
    let estimate = first.estimate(&steps[steps.len() - 1].1).unwrap();
    assert!(estimate.converged, "{estimate:?}");
    // The same seed, the same particles.
    let mut second = filter(30_000, 11);
    second.start_global(&map).unwrap();
    run(&mut second, &mut map, &steps);
    assert_eq!(first.particles(), second.particles());
}

#[test]
fn a_kidnapped_robot_is_found_again() {
    let mut map = room();
    let steps = path(300);
    let mut mcl = filter(20_000, 5);
    let start = steps[0].0;
    mcl.start_at(start, 0.05, 0.05).unwrap();
    run(&mut mcl, &mut map, &steps[..60]);
    // Carried off: the truth jumps to another circle, the odometry goes on
    // as if nothing happened.
    let last_odometry = steps[59].1;
    let kidnapped: Vec<(Pose2, Pose2)> = circle((6.0, 1.6), 1.0, 240)
        .into_iter()
        .map(|(t, o)| (t, last_odometry.compose(&o)))
        .collect();
    let errors = run(&mut mcl, &mut map, &kidnapped);
    let (position, heading) = errors[errors.len() - 1];
    assert!(
        position < 0.25 && heading < 0.25,
        "after the kidnap: {position:.3} m, {heading:.3} rad"
    );
}

#[test]
fn any_number_of_sonars_works() {
    let mut map = room();
    let steps = path(120);
    for count in [5, 24] {
        let ring = SensorRing::uniform(count, 0.2).unwrap();
        let mut settings = FilterSettings {
            ring: ring.clone(),
            seed: 4,
            ..FilterSettings::default()
        };
        settings.kld.max_particles = 3_000;
        let mut mcl = Mcl::new(settings).unwrap();
        mcl.start_at(steps[0].0, 0.1, 0.05).unwrap();
        let mut last = (f64::MAX, f64::MAX);
        for (truth, odometry) in &steps {
            if mcl.predict(odometry).unwrap() {
                let ranges = frame_of(&ring, &map, truth);
                mcl.correct(&mut map, &ranges).unwrap();
            }
            last = error(&mcl.estimate(odometry).unwrap().pose, truth);
        }
        assert!(
            last.0 < 0.1 && last.1 < 0.1,
            "{count} sonars: error {last:?}"
        );
        // A frame of the wrong length is refused.
        assert!(mcl.correct(&mut map, &[1.0; 16]).is_err());
    }
}

#[test]
fn bad_frames_are_errors_not_panics() {
    let mut map = room();
    let mut mcl = filter(1_000, 1);
    // Not started.
    assert!(mcl.correct(&mut map, &[1.0; 16]).is_err());
    mcl.start_at(Pose2::new(2.0, 2.0, 0.0), 0.1, 0.1).unwrap();
    let err = mcl.correct(&mut map, &[1.0; 15]).unwrap_err().to_string();
    assert!(err.contains("15 ranges"), "{err}");
    let mut ranges = vec![1.0; 16];
    ranges[3] = f64::NAN;
    let err = mcl.correct(&mut map, &ranges).unwrap_err().to_string();
    assert!(err.contains("ranges[3]"), "{err}");
    assert!(mcl.predict(&Pose2::new(f64::INFINITY, 0.0, 0.0)).is_err());
    assert!(
        mcl.start_at(Pose2::new(f64::NAN, 0.0, 0.0), 0.1, 0.1)
            .is_err()
    );
    // An empty map has nowhere to put particles.
    let empty = LocalMap::new(settings(1 << 20)).unwrap();
    assert!(filter(1_000, 1).start_global(&empty).is_err());
}

#[test]
fn cache_stays_within_budget_on_a_map_a_hundred_times_larger() {
    // A 40 × 40 tile map (128 × 128 m) whose range tables alone would take
    // about 1.5 GiB, behind a 12 MiB budget, with a robot's particles driven
    // from one corner to the other.
    let budget = 12 << 20;
    let mut map = LocalMap::new(settings(budget)).unwrap();
    let tile_table_bytes = ConeGeometry::default().table_bytes(64 * 64);
    assert!(1600 * tile_table_bytes > 100 * budget);
    let size = map.settings().tile_size;
    let mut mcl = filter(2_000, 2);
    let mut peak = 0;
    for step in 0..40 {
        let p = Pose2::new(
            1.6 + 3.2 * f64::from(step),
            1.6 + 3.2 * f64::from(step),
            0.7,
        );
        mcl.start_at(p, 0.3, 0.3).unwrap();
        let needed = mcl.tiles_needed(&map);
        for key in map.missing_tiles(needed.iter().copied()) {
            // The same room pattern repeated everywhere; far tiles read as unknown.
            let local = TileKey::new(key.x.rem_euclid(3), key.y.rem_euclid(2));
            let tile = room_tile(local);
            assert_eq!(tile.size(), size);
            map.insert_tile(key, 1, Some(&tile)).unwrap();
        }
        let ranges = vec![2.0; 16];
        mcl.correct(&mut map, &ranges).unwrap();
        map.evict_to_budget(&needed.iter().copied().collect::<HashSet<_>>());
        peak = peak.max(map.bytes());
    }
    assert!(
        peak <= budget,
        "the cache held {peak} bytes, budget {budget}"
    );
    assert!(
        map.stats().tables_dropped > 0,
        "nothing was evicted: {:?}",
        map.stats()
    );
}

#[test]
fn recovery_on_a_map_larger_than_the_cache_stays_within_the_budget() {
    // 13 × 12 tiles of the room pattern behind a 16 MiB budget, which holds
    // range tables for about a dozen of them.
    let budget = 16 << 20;
    let mut map = LocalMap::new(settings(budget)).unwrap();
    for ty in -5..=6 {
        for tx in -5..=7 {
            let key = TileKey::new(tx, ty);
            let local = TileKey::new(key.x.rem_euclid(3), key.y.rem_euclid(2));
            map.insert_tile(key, 1, Some(&room_tile(local))).unwrap();
        }
    }
    let capacity = map.table_capacity();
    assert!(
        map.free_tile_count() > 4 * capacity,
        "{} tiles with free cells, tables for {capacity}",
        map.free_tile_count()
    );
    // Global localization would need every table at once: refused, clearly.
    let err = filter(10_000, 1)
        .start_global(&map)
        .unwrap_err()
        .to_string();
    assert!(err.contains("initial pose"), "{err}");
    // Tracking, then frames that fit nowhere: the filter injects particles,
    // but only where the cache can hold tables, and the cache never grows
    // past its budget, even before eviction.
    let steps = path(120);
    let mut mcl = filter(20_000, 5);
    mcl.start_at(steps[0].0, 0.05, 0.05).unwrap();
    let size = map.settings().tile_size;
    let (mut injected, mut widest) = (0, 0);
    for (i, (truth, odometry)) in steps.iter().enumerate() {
        if !mcl.predict(odometry).unwrap() {
            continue;
        }
        let ranges = if i < 40 {
            frame(&map, truth)
        } else {
            vec![0.5; 16]
        };
        let report = mcl.correct(&mut map, &ranges).unwrap();
        injected += report.injected;
        assert!(
            map.bytes() <= budget,
            "frame {i}: the cache holds {} bytes, budget {budget}",
            map.bytes()
        );
        let tiles: HashSet<TileKey> = mcl
            .particles()
            .iter()
            .map(|p| {
                let cell = Resolution::DEFAULT.cell_of(p.x, p.y).unwrap();
                size.split(cell).0
            })
            .collect();
        widest = widest.max(tiles.len());
    }
    assert!(injected > 0, "the frames that fit nowhere injected nothing");
    // Injected particles come from the tiles nearest the estimate, not
    // from all 156; the motion noise carries a few over their edges.
    assert!(
        widest <= 2 * capacity,
        "the particles covered {widest} tiles, the cache holds tables for {capacity}"
    );
}

#[test]
fn a_changed_tile_keeps_the_tables_while_its_walls_stay_put() {
    let mut map = room();
    let here = TileKey::new(0, 0);
    let next = TileKey::new(1, 0);
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 1);

    // The server reports a change: the tile goes stale, the table stays.
    map.tile_changed(next);
    assert_eq!(map.stale_tiles(), vec![next]);
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 0);

    // Fetched again with other log-odds but the same occupied cells.
    let firmer = tile_of(next, |x, y| {
        let v = room_log_odds(x, y);
        if v == FREE { FREE * 2 } else { v }
    });
    map.insert_tile(next, 2, Some(&firmer)).unwrap();
    assert!(map.stale_tiles().is_empty());
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 0, "table kept");
    assert_eq!(map.version(next), Some(2));

    // The block's edge a cell thicker, as sonar noise makes it: kept.
    map.tile_changed(next);
    let ragged = tile_of(next, |x, y| {
        if (4.95..5.0).contains(&x) && (3.1..3.15).contains(&y) {
            OCCUPIED
        } else {
            room_log_odds(x, y)
        }
    });
    map.insert_tile(next, 3, Some(&ragged)).unwrap();
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 0, "table kept");

    // A new obstacle: the tables that read the tile are rebuilt.
    map.tile_changed(next);
    let with_box = tile_of(next, |x, y| {
        if (4.0..4.2).contains(&x) && (2.0..2.2).contains(&y) {
            OCCUPIED
        } else {
            room_log_odds(x, y)
        }
    });
    map.insert_tile(next, 4, Some(&with_box)).unwrap();
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 1, "table rebuilt");

    // A tile never held that changes drops the tables near it at once.
    let beyond = TileKey::new(4, 0);
    map.tile_changed(beyond);
    assert!(map.stale_tiles().is_empty());
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 1);

    // Lost events: every held tile is stale and every table dropped.
    map.all_changed();
    assert_eq!(map.stale_tiles().len(), 20);
    assert_eq!(map.ensure_tables([here], &[]).unwrap(), 1);
}

#[test]
fn a_new_obstacle_outdates_a_neighbourhood_rebuilt_one_table_a_call() {
    let mut map = room();
    let keys: Vec<TileKey> = (0..3)
        .flat_map(|x| (0..2).map(move |y| TileKey::new(x, y)))
        .collect();
    assert_eq!(map.ensure_tables(keys.iter().copied(), &[]).unwrap(), 6);
    // A sonar at (4.1, 1.2) looking up the room: its expected range in
    // centimetres, as the tables have it.
    let up = std::f64::consts::FRAC_PI_2;
    let forward = |map: &mut LocalMap| {
        map.window(&keys)
            .expected_slot(4.1, 1.2, up, (up.cos(), up.sin()), 2000)
    };
    let before = forward(&mut map);
    // The cone (15° each side) meets the block at (5, 4.6) first.
    assert!((330..355).contains(&before), "{before} cm to the block");

    // A box in front of the robot, in a tile every table reads.
    let boxed = TileKey::new(1, 0);
    map.tile_changed(boxed);
    let with_box = tile_of(boxed, |x, y| {
        if (4.0..4.2).contains(&x) && (2.0..2.2).contains(&y) {
            OCCUPIED
        } else {
            room_log_odds(x, y)
        }
    });
    map.insert_tile(boxed, 2, Some(&with_box)).unwrap();

    // Each call rebuilds one outdated table, and those under a quarter of
    // the particles or more; the others still score. A tile without any
    // table is built at once whatever the count.
    let fresh = TileKey::new(3, 0);
    let mut with_fresh = keys.clone();
    with_fresh.push(fresh);
    let crowd: Vec<Pose2> = (0..100)
        .map(|i| Pose2::new(7.0 + 0.001 * f64::from(i), 4.0, 0.0))
        .chain((0..300).map(|i| Pose2::new(10.0, 0.5 + 0.01 * f64::from(i % 200), 0.0)))
        .collect();
    assert_eq!(map.tile_at(7.0, 4.0).unwrap(), TileKey::new(2, 1));
    assert_eq!(
        map.ensure_tables(with_fresh.iter().copied(), &crowd)
            .unwrap(),
        3,
        "the fresh tile, (2, 1) under a quarter of the particles, and the oldest"
    );
    let mut rebuilt_at = None;
    for call in 2..=5 {
        if rebuilt_at.is_none() && forward(&mut map) != before {
            rebuilt_at = Some(call);
        }
        assert_eq!(
            map.ensure_tables(keys.iter().copied(), &[]).unwrap(),
            1,
            "call {call}"
        );
    }
    assert_eq!(map.ensure_tables(keys.iter().copied(), &[]).unwrap(), 0);
    assert!(
        rebuilt_at.is_some_and(|call| call > 1),
        "the outdated table scored until rebuilt (first seen new at call {rebuilt_at:?})"
    );

    // Rebuilt, the tables see the box: the sonar's expected range shrinks
    // to it.
    let after = forward(&mut map);
    assert!((70..90).contains(&after), "{after} cm to the box");
}

#[test]
fn tables_under_a_pose_are_the_tiles_under_its_sensors_built_once() {
    let mut map = room();
    let ring = SensorRing::scout();
    // On the corner of four tiles (64 cells of 5 cm: 3.2 m), so the
    // sensors stand on more than one of them.
    let pose = Pose2::new(3.2, 3.2, 0.3);
    let keys = map.tables_under(&ring, &pose).unwrap();
    let expected: HashSet<TileKey> = ring
        .sensor_poses(&pose)
        .map(|s| map.tile_at(s.x, s.y).unwrap())
        .collect();
    assert!(expected.len() > 1, "the pose straddles tiles");
    assert_eq!(keys.iter().copied().collect::<HashSet<_>>(), expected);
    assert!(keys.windows(2).all(|w| w[0] < w[1]), "sorted, no repeats");
    // Every table is already built: asking again builds none.
    assert_eq!(map.ensure_tables(keys.iter().copied(), &[]).unwrap(), 0);
    assert_eq!(map.tables_under(&ring, &pose).unwrap(), keys);
}

/// The room with the cells east of `x_seen` never observed: a map still
/// being built.
fn room_seen_west_of(x_seen: f64) -> LocalMap {
    let mut map = LocalMap::new(settings(1 << 30)).unwrap();
    for ty in -1..=2 {
        for tx in -1..=3 {
            let key = TileKey::new(tx, ty);
            let tile = tile_of(key, |x, y| {
                if x > x_seen {
                    i16::MIN
                } else {
                    room_log_odds(x, y)
                }
            });
            map.insert_tile(key, 1, Some(&tile)).unwrap();
        }
    }
    map
}

#[test]
fn tracking_at_the_edge_of_a_map_being_built_keeps_its_pose() {
    // The robot circles across the edge of what the map has seen, its
    // sonars hearing walls in the unseen half; the frames are cast in the
    // whole room.
    let whole = room();
    let mut seen = room_seen_west_of(2.5);
    let steps = path(240);
    let mut mcl = filter(5_000, 5);
    let start = steps[0].0;
    mcl.start_at(start, 0.1, 0.05).unwrap();
    let mut errors = Vec::new();
    for (truth, odometry) in &steps {
        if mcl.predict(odometry).unwrap() {
            let ranges = frame(&whole, truth);
            mcl.correct(&mut seen, &ranges).unwrap();
        }
        errors.push(error(&mcl.estimate(odometry).unwrap().pose, truth));
    }
    let worst = errors.iter().map(|e| e.0).fold(0.0, f64::max);
    let mean = errors.iter().map(|e| e.0).sum::<f64>() / errors.len() as f64;
    assert!(
        worst < 0.25,
        "worst position error {worst:.3} m, mean {mean:.3} m"
    );
    assert!(mean < 0.08, "mean position error {mean:.3} m");
}

/// The heading, within 0.2 rad of `truth`'s, at which `mcl` scores
/// `ranges` best.
fn best_heading(mcl: &mut Mcl, map: &mut LocalMap, truth: &Pose2, ranges: &[f64]) -> f64 {
    let mut best = (f64::NEG_INFINITY, truth.theta);
    for i in -40..=40 {
        let theta = truth.theta + 0.005 * f64::from(i);
        let score = mcl
            .score_pose(map, &Pose2::new(truth.x, truth.y, theta), ranges)
            .unwrap();
        if score > best.0 {
            best = (score, theta);
        }
    }
    best.1
}

#[test]
fn a_ring_fired_in_turn_is_scored_where_each_sonar_fired() {
    let mut map = room();
    // Turning on the spot at 1.5 rad/s while the ring fires in turn over
    // 0.1 s: the first sonar fired 0.14 rad before the frame's heading.
    let firing = RingFiring::over(0.1).unwrap();
    let back = Pose2::new(0.0, 0.0, -1.5);
    let at = firing.robot_at_readings(16, Some(&back)).unwrap();
    let ring = SensorRing::scout().as_fired(&at);
    let mut plain = filter(1000, 1);
    let mut fired = filter(1000, 1);
    fired.set_firing(firing);
    // The odometry turned 0.15 rad in the 0.1 s between two frames.
    fired.note_frame(&Pose2::new(1.0, 1.0, 0.0), 10.0);
    fired.note_frame(&Pose2::new(1.0, 1.0, 0.15), 10.1);
    let mut misses = (0.0, 0.0);
    for (x, y, theta) in [(3.5, 3.0, 0.3), (1.0, 4.0, -2.0), (6.5, 1.5, 2.5)] {
        let truth = Pose2::new(x, y, theta);
        let ranges = frame_of(&ring, &map, &truth);
        misses.0 += (best_heading(&mut plain, &mut map, &truth, &ranges) - theta).abs();
        misses.1 += (best_heading(&mut fired, &mut map, &truth, &ranges) - theta).abs();
    }
    assert!(
        misses.1 <= 0.015,
        "placed where they fired, the readings fit the true heading: {misses:?}"
    );
    assert!(
        misses.0 >= 2.0 * misses.1 + 0.03,
        "as if fired together, they fit a heading behind: {misses:?}"
    );
    // The particles are scored as a pose alone is.
    let truth = Pose2::new(3.5, 3.0, 0.3);
    let ranges = frame_of(&ring, &map, &truth);
    fired.start_at(truth, 0.05, 0.05).unwrap();
    fired.score(&mut map, &ranges).unwrap();
    let (particles, scores) = (fired.particles().to_vec(), fired.scores().to_vec());
    for (p, s) in particles.iter().zip(&scores).take(20) {
        let alone = fired.score_pose(&mut map, p, &ranges).unwrap();
        assert!((alone - s).abs() < 1e-9, "{alone} against {s}");
    }
    // A gap between frames gives no pace: read as fired together.
    fired.note_frame(&Pose2::new(1.0, 1.0, 0.3), 15.0);
    let truth = Pose2::new(3.5, 3.0, 0.3);
    let ranges = frame_of(&ring, &map, &truth);
    assert_eq!(
        best_heading(&mut fired, &mut map, &truth, &ranges),
        best_heading(&mut plain, &mut map, &truth, &ranges)
    );
}
