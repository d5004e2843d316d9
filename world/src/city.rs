//! A generated city, for runs on a map far larger than any room: rows and
//! columns of solid blocks 6 to 12 m a side between streets 2.5 to 3 m
//! wide, inside an outer wall, drawn as a map_server image. Pure and
//! seeded: a size and a seed give the same city, pixel for pixel.

use deog_grid::Pose2;
use deog_mapfile::{MapImage, Mode};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::WorldError;

/// Cell size of the city map, metres.
pub const RESOLUTION_M: f64 = 0.05;
/// Smallest city side, metres: room for a few blocks.
pub const MIN_SIDE_M: f64 = 30.0;
/// Thickness of the outer wall, metres.
const WALL_M: f64 = 0.3;
/// Side of a block, metres: drawn from this range per row and column.
const BLOCK_M: (f64, f64) = (6.0, 12.0);
/// Width of a street, metres: drawn from this range per street. Wide
/// enough that the wanderer cruises down the middle without slowing for
/// the walls beside it.
const STREET_M: (f64, f64) = (2.5, 3.0);

/// A generated city.
#[derive(Debug, Clone, PartialEq)]
pub struct City {
    /// The city as a trinary map_server map: occupied blocks and outer
    /// wall, free streets; [`RESOLUTION_M`] a cell, origin (0, 0).
    pub image: MapImage,
    /// Where a robot starts: a street crossing near the middle, facing +x;
    /// metres, world frame.
    pub start: Pose2,
    /// Blocks in the city.
    pub blocks: usize,
}

/// A square city `side_px` cells a side at 5 cm: rows and columns of
/// blocks of random sizes between streets of random widths, inside a wall.
/// The origin is (0, 0), so pixel (column, row from the bottom) is cell
/// (column, row) and the tiles line up with the image. The same
/// `side_px` and `seed` give the same city. Errors when `side_px` leaves no
/// room for a block ([`MIN_SIDE_M`] always has room).
pub fn city(side_px: u32, seed: u64) -> Result<City, WorldError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6369_7479);
    let columns = block_spans(side_px, &mut rng);
    let rows = block_spans(side_px, &mut rng);
    if columns.is_empty() || rows.is_empty() {
        return Err(WorldError::CityTooSmall { side_px });
    }
    let n = side_px as usize;
    let wall = px(WALL_M) as usize;
    const FREE: u8 = 254;
    const OCCUPIED: u8 = 0;
    let mut pixels = vec![FREE; n * n];
    // `row` counts from the bottom; the image's first row is the top.
    let mut set = |col: usize, row: usize| pixels[(n - 1 - row) * n + col] = OCCUPIED;
    for row in 0..n {
        for col in 0..n {
            if col < wall || row < wall || col >= n - wall || row >= n - wall {
                set(col, row);
            }
        }
    }
    for &(y0, y1) in &rows {
        for &(x0, x1) in &columns {
            for row in y0..y1 {
                for col in x0..x1 {
                    set(col as usize, row as usize);
                }
            }
        }
    }
    // The street centres between (and around) the blocks; the one nearest
    // the middle on each axis gives the start.
    let middle = |spans: &[(u32, u32)]| -> f64 {
        let mut edges = vec![px(WALL_M)];
        for &(a, b) in spans {
            edges.push(a);
            edges.push(b);
        }
        edges.push(side_px - px(WALL_M));
        edges
            .chunks(2)
            .map(|street| f64::from(street[0] + street[1]) / 2.0)
            .min_by(|a, b| {
                let half = f64::from(side_px) / 2.0;
                (a - half).abs().total_cmp(&(b - half).abs())
            })
            .unwrap_or(f64::from(side_px) / 2.0)
    };
    let start = Pose2::new(
        middle(&columns) * RESOLUTION_M,
        middle(&rows) * RESOLUTION_M,
        0.0,
    );
    Ok(City {
        image: MapImage {
            width: side_px,
            height: side_px,
            resolution: RESOLUTION_M,
            origin: (0.0, 0.0, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: Mode::Trinary,
            pixels,
        },
        start,
        blocks: columns.len() * rows.len(),
    })
}

/// Metres to whole cells.
fn px(metres: f64) -> u32 {
    (metres / RESOLUTION_M).round() as u32
}

/// The blocks along one axis, `[start, end)` in cells: a street, a block,
/// a street, ... up to the wall; the last block takes up what would be too
/// little for another, so no street is wider than the widest drawn.
fn block_spans(side_px: u32, rng: &mut impl Rng) -> Vec<(u32, u32)> {
    let (block_min, block_max) = (px(BLOCK_M.0), px(BLOCK_M.1));
    let (street_min, street_max) = (px(STREET_M.0), px(STREET_M.1));
    let end = side_px.saturating_sub(px(WALL_M));
    let mut spans = Vec::new();
    let mut pos = px(WALL_M) + rng.random_range(street_min..=street_max);
    while end.saturating_sub(pos) >= block_min + street_min {
        let left = end - pos;
        let street = rng
            .random_range(street_min..=street_max)
            .min(left - block_min);
        let mut block = rng.random_range(block_min..=block_max);
        if left < block + street + block_min + street_min {
            block = left - street;
        }
        spans.push((pos, pos + block));
        pos += block + street;
    }
    spans
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streets_are_as_wide_as_drawn_and_blocks_fill_the_rest() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for side in [px(MIN_SIDE_M), 2688, 5000] {
            let spans = block_spans(side, &mut rng);
            assert!(!spans.is_empty());
            let mut edge = px(WALL_M);
            for &(a, b) in &spans {
                let street = a - edge;
                assert!(
                    (px(STREET_M.0)..=px(STREET_M.1)).contains(&street),
                    "{street}"
                );
                assert!(b - a >= px(BLOCK_M.0));
                edge = b;
            }
            let last = side - px(WALL_M) - edge;
            assert!((px(STREET_M.0)..=px(STREET_M.1)).contains(&last), "{last}");
        }
    }

    #[test]
    fn the_start_is_on_a_street() {
        let city = city(1280, 3).unwrap();
        let (col, row) = (
            (city.start.x / RESOLUTION_M) as usize,
            (city.start.y / RESOLUTION_M) as usize,
        );
        let n = city.image.width as usize;
        // A robot radius around it is free.
        for dy in -4i64..=4 {
            for dx in -4i64..=4 {
                let (c, r) = ((col as i64 + dx) as usize, (row as i64 + dy) as usize);
                assert_eq!(city.image.pixels[(n - 1 - r) * n + c], 254);
            }
        }
    }

    #[test]
    fn too_small_a_city_is_an_error_naming_its_side() {
        for side in [0, 1, 100, px(MIN_SIDE_M) / 3] {
            let e = city(side, 1).expect_err("no room");
            assert_eq!(
                e.to_string(),
                format!("a city {side} cells a side has no room for a block")
            );
        }
        assert!(city(px(MIN_SIDE_M), u64::MAX).is_ok());
    }

    /// FNV-1a of the pixels: enough to notice a changed draw.
    fn fingerprint(pixels: &[u8]) -> u64 {
        pixels.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        })
    }

    #[test]
    fn a_seed_gives_the_city_it_always_gave() {
        // Recorded before the generator moved here from `deog bench
        // localize-memory`: the figures in BENCHMARKS.md are for its cities.
        let expected = [
            (
                600,
                1,
                0x826f_8099_3d44_d625,
                4,
                (11.025, 14.700000000000001),
            ),
            (1280, 3, 0x6010_9275_ef67_7325, 16, (29.0, 26.425)),
            (2688, 1, 0xd4b6_3182_a409_3fdb, 121, (70.575, 72.175)),
        ];
        for (side, seed, pixels, blocks, (x, y)) in expected {
            let c = city(side, seed).unwrap();
            assert_eq!(fingerprint(&c.image.pixels), pixels, "{side} {seed}");
            assert_eq!(c.blocks, blocks, "{side} {seed}");
            assert_eq!((c.start.x, c.start.y, c.start.theta), (x, y, 0.0));
            assert_eq!(c, city(side, seed).unwrap());
        }
    }
}
