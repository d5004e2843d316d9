//! The tiles under the particles' sensors: what a sensor whose tables are
//! looked up where the sensor sits (the sonar's range tables) needs for a
//! frame, whatever the frame reads.

use std::collections::{HashMap, HashSet};

use deog_grid::{Pose2, TileKey};

use crate::local_map::LocalMap;

/// Up to this many tiles, a correction reads every tile of the particles'
/// bounding box rather than finding the tiles under each particle. A
/// tracking filter's box is a few tiles; a spread one's covers tiles with
/// no particle in them (walls, the unknown beyond them), whose range
/// tables would cost more to build than finding the tiles does.
const BOUNDING_BOX_TILES: i64 = 4;

/// The tiles within `reach` metres (a square about each particle) of
/// `particles`, sorted; when they are more than `capacity`, the
/// `capacity` of them under the most particles' sensors (particles
/// elsewhere then read as inside a wall and die out at the next
/// resampling).
pub fn tiles_within_reach(
    map: &LocalMap,
    particles: &[Pose2],
    reach: f64,
    capacity: usize,
) -> Vec<TileKey> {
    let res = map.settings().resolution;
    // Usually the particles' bounding box is small: take its tiles.
    let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in particles {
        lo_x = lo_x.min(p.x);
        lo_y = lo_y.min(p.y);
        hi_x = hi_x.max(p.x);
        hi_y = hi_y.max(p.y);
    }
    if let (Ok(lo), Ok(hi)) = (
        res.cell_of(lo_x - reach, lo_y - reach),
        res.cell_of(hi_x + reach, hi_y + reach),
    ) {
        let (a, b) = (map.tile_of(lo), map.tile_of(hi));
        let count = (i64::from(b.x) - i64::from(a.x) + 1) * (i64::from(b.y) - i64::from(a.y) + 1);
        if count <= BOUNDING_BOX_TILES {
            return (a.y..=b.y)
                .flat_map(|y| (a.x..=b.x).map(move |x| TileKey::new(x, y)))
                .collect();
        }
    }
    // Spread particles: only the tiles under them.
    let mut keys = HashSet::new();
    let mut last = None;
    for p in particles {
        for (x, y) in reach_corners(p, reach) {
            if let Ok(cell) = res.cell_of(x, y) {
                let key = map.tile_of(cell);
                if last != Some(key) {
                    keys.insert(key);
                    last = Some(key);
                }
            }
        }
    }
    if keys.len() > capacity {
        // More tables than the cache holds: those under the most
        // particles' sonars.
        let mut uses: HashMap<TileKey, usize> = HashMap::with_capacity(keys.len());
        for p in particles {
            for (x, y) in reach_corners(p, reach) {
                if let Ok(cell) = res.cell_of(x, y) {
                    *uses.entry(map.tile_of(cell)).or_default() += 1;
                }
            }
        }
        let mut ranked: Vec<(usize, TileKey)> = uses.into_iter().map(|(k, n)| (n, k)).collect();
        ranked.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        keys = ranked.into_iter().take(capacity).map(|(_, k)| k).collect();
    }
    let mut keys: Vec<TileKey> = keys.into_iter().collect();
    keys.sort();
    keys
}

/// The corners of the square of half-side `reach` about a particle: every
/// sonar sits inside it.
fn reach_corners(p: &Pose2, reach: f64) -> [(f64, f64); 4] {
    [
        (p.x - reach, p.y - reach),
        (p.x + reach, p.y + reach),
        (p.x - reach, p.y + reach),
        (p.x + reach, p.y - reach),
    ]
}
