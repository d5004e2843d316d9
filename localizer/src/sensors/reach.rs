//! The tiles under the particles' sensors: what a sensor whose tables are
//! looked up where the sensor sits (the sonar's range tables) needs for a
//! frame, whatever the frame reads.

use deog_grid::{Pose2, TileKey};

use crate::cluster::BinMap;
use crate::local_map::LocalMap;
use crate::numeric::floor_i64;

/// Up to this many tiles, a correction reads every tile of the particles'
/// bounding box rather than finding the tiles under each particle. A
/// tracking filter's box is a few tiles; a spread one's covers tiles with
/// no particle in them (walls, the unknown beyond them), whose range
/// tables would cost more to build than finding the tiles does.
const BOUNDING_BOX_TILES: i64 = 4;

/// Up to this many tiles in the particles' bounding box, the particles
/// under each tile are counted in a dense array over the box (4 MiB at
/// most); beyond it, in a hash map.
const DENSE_BOX_TILES: i64 = 1 << 20;

/// The tiles within `reach` metres (a square about each particle) of
/// `particles`, sorted; when they are more than `capacity`, the
/// `capacity` of them under the most particles' sensors (particles
/// elsewhere then read as inside a wall and die out at the next
/// resampling). A point's tile is found as the range window finds a
/// sensor's (its cell by one multiply, the tile by a shift), so a sensor
/// at a cell's edge reads a tile this returns.
pub fn tiles_within_reach(
    map: &LocalMap,
    particles: &[Pose2],
    reach: f64,
    capacity: usize,
) -> Vec<TileKey> {
    if particles.is_empty() {
        return Vec::new();
    }
    let inv_res = 1.0 / map.settings().resolution.metres();
    let shift = map.settings().tile_size.cells().trailing_zeros();
    let tile_of = |v: f64| floor_i64(v * inv_res) >> shift;
    let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in particles {
        lo_x = lo_x.min(p.x);
        lo_y = lo_y.min(p.y);
        hi_x = hi_x.max(p.x);
        hi_y = hi_y.max(p.y);
    }
    let (ax, ay) = (tile_of(lo_x - reach), tile_of(lo_y - reach));
    let (bx, by) = (tile_of(hi_x + reach), tile_of(hi_y + reach));
    let key = |x: i64, y: i64| Some(TileKey::new(i32::try_from(x).ok()?, i32::try_from(y).ok()?));
    let (width, height) = (bx.saturating_sub(ax) + 1, by.saturating_sub(ay) + 1);
    let area = width.saturating_mul(height);
    // Usually the particles' bounding box is small: take its tiles.
    if area <= BOUNDING_BOX_TILES {
        let mut keys: Vec<TileKey> = (ay..=by)
            .flat_map(|y| (ax..=bx).filter_map(move |x| key(x, y)))
            .collect();
        keys.sort();
        return keys;
    }
    // Spread particles: only the tiles under them, each with the number of
    // particles whose square reaches it. A square is a fraction of a tile,
    // so it covers one to four tiles: four floors a particle.
    let spans = particles.iter().map(|p| {
        (
            (tile_of(p.x - reach), tile_of(p.x + reach)),
            (tile_of(p.y - reach), tile_of(p.y + reach)),
        )
    });
    let mut under: Vec<(usize, TileKey)> = if area <= DENSE_BOX_TILES {
        let mut counts = vec![0usize; area as usize];
        for ((x0, x1), (y0, y1)) in spans {
            for y in y0..=y1 {
                let row = (y - ay) * width;
                for x in x0..=x1 {
                    counts[(row + x - ax) as usize] += 1;
                }
            }
        }
        counts
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .filter_map(|(i, &n)| Some((n, key(ax + i as i64 % width, ay + i as i64 / width)?)))
            .collect()
    } else {
        let mut counts: BinMap<TileKey, usize> = BinMap::default();
        for ((x0, x1), (y0, y1)) in spans {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if let Some(k) = key(x, y) {
                        *counts.entry(k).or_default() += 1;
                    }
                }
            }
        }
        counts.into_iter().map(|(k, n)| (n, k)).collect()
    };
    if under.len() > capacity {
        // More tables than the cache holds: those under the most
        // particles' sonars.
        under.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        under.truncate(capacity);
    }
    let mut keys: Vec<TileKey> = under.into_iter().map(|(_, k)| k).collect();
    keys.sort();
    keys
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn map() -> LocalMap {
        LocalMap::empty_for_tests(1 << 26)
    }

    /// The tile the range window reads for a sensor at `(x, y)`.
    fn window_tile(map: &LocalMap, x: f64, y: f64) -> TileKey {
        let inv = 1.0 / map.settings().resolution.metres();
        let shift = map.settings().tile_size.cells().trailing_zeros();
        TileKey::new(
            ((x * inv).floor() as i64 >> shift) as i32,
            ((y * inv).floor() as i64 >> shift) as i32,
        )
    }

    fn particles() -> impl Strategy<Value = Vec<Pose2>> {
        prop::collection::vec(
            (-40.0f64..40.0, -40.0f64..40.0).prop_map(|(x, y)| Pose2::new(x, y, 0.0)),
            1..60,
        )
    }

    proptest! {
        #[test]
        fn every_point_within_reach_lies_in_a_tile_given(
            particles in particles(),
            reach in 0.01f64..1.5,
            fractions in prop::collection::vec((0.0f64..=1.0, 0.0f64..=1.0), 8),
        ) {
            let map = map();
            let tiles = tiles_within_reach(&map, &particles, reach, usize::MAX);
            prop_assert!(tiles.windows(2).all(|w| w[0] < w[1]), "sorted, no repeats");
            for p in &particles {
                let corners = [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0), (0.5, 0.5)];
                for (fx, fy) in corners.into_iter().chain(fractions.iter().copied()) {
                    let (x, y) = (p.x - reach + 2.0 * reach * fx, p.y - reach + 2.0 * reach * fy);
                    let tile = window_tile(&map, x, y);
                    prop_assert!(tiles.binary_search(&tile).is_ok(), "{tile:?} under ({x}, {y}) missing");
                }
            }
        }

        #[test]
        fn spread_particles_get_only_the_tiles_under_them(
            particles in particles(),
            reach in 0.01f64..1.5,
        ) {
            let map = map();
            let tiles = tiles_within_reach(&map, &particles, reach, usize::MAX);
            prop_assume!(tiles.len() > BOUNDING_BOX_TILES as usize);
            for tile in &tiles {
                let under = particles.iter().any(|p| {
                    let lo = window_tile(&map, p.x - reach, p.y - reach);
                    let hi = window_tile(&map, p.x + reach, p.y + reach);
                    (lo.x..=hi.x).contains(&tile.x) && (lo.y..=hi.y).contains(&tile.y)
                });
                prop_assert!(under, "{tile:?} lies under no particle");
            }
        }
    }

    #[test]
    fn over_capacity_the_tiles_under_the_most_particles_are_kept() {
        let map = map();
        // Tiles are 3.2 m: three crowds in three tiles far apart.
        let crowd = |x: f64, y: f64, n: usize| (0..n).map(move |_| Pose2::new(x, y, 0.0));
        let particles: Vec<Pose2> = crowd(1.6, 1.6, 30)
            .chain(crowd(17.6, 1.6, 10))
            .chain(crowd(1.6, 17.6, 20))
            .collect();
        let all = tiles_within_reach(&map, &particles, 0.3, usize::MAX);
        assert_eq!(
            all,
            vec![TileKey::new(0, 0), TileKey::new(5, 0), TileKey::new(0, 5)]
                .into_iter()
                .collect::<std::collections::BTreeSet<_>>()
                .into_iter()
                .collect::<Vec<_>>()
        );
        let kept = tiles_within_reach(&map, &particles, 0.3, 2);
        assert_eq!(kept, vec![TileKey::new(0, 0), TileKey::new(0, 5)]);
        assert!(tiles_within_reach(&map, &[], 0.3, 2).is_empty());
    }
}
