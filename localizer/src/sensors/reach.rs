//! The tiles under the particles' sensors: what a sensor whose tables are
//! looked up where the sensor sits (the sonar's range tables) needs for a
//! frame, whatever the frame reads.

use deog_grid::{Pose2, TileKey};

use crate::cluster::{BinMap, BinSet};
use crate::local_map::LocalMap;
use crate::numeric::floor_i64;

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
    // Spread particles: only the tiles under them, found as the range
    // window finds a sensor's tile (its cell by one multiply, the tile by a
    // shift): the same tile at a cell's edge, and no division per corner.
    let inv_res = 1.0 / res.metres();
    let shift = map.settings().tile_size.cells().trailing_zeros();
    let tile_at = |(x, y): (f64, f64)| -> Option<TileKey> {
        let (cx, cy) = (floor_i64(x * inv_res), floor_i64(y * inv_res));
        Some(TileKey::new(
            i32::try_from(cx >> shift).ok()?,
            i32::try_from(cy >> shift).ok()?,
        ))
    };
    let mut keys: BinSet<TileKey> = BinSet::default();
    let mut last = None;
    for p in particles {
        for key in reach_corners(p, reach).into_iter().filter_map(tile_at) {
            if last != Some(key) {
                keys.insert(key);
                last = Some(key);
            }
        }
    }
    if keys.len() > capacity {
        // More tables than the cache holds: those under the most
        // particles' sonars.
        let mut uses: BinMap<TileKey, usize> = BinMap::default();
        for p in particles {
            for key in reach_corners(p, reach).into_iter().filter_map(tile_at) {
                *uses.entry(key).or_default() += 1;
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
