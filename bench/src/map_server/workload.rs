//! What the clients send: the square region of tiles they update and the
//! evidence each visit of a tile carries.

use deog_grid::{TileKey, TileSize};
use deog_proto::v1 as pb;

/// Cells per tile side of every benchmark map.
pub(super) const TILE_SIDE: u32 = 64;
/// Log-odds deltas (1/1000 nat) of the two kinds of evidence sent: a cell
/// gets them in turn on successive visits, so beliefs move both ways.
const EVIDENCE: (i16, i16) = (400, -300);

/// The tiles of a `side` × `side` square from tile (0, 0), row by row.
pub(super) fn region_tiles(side: i32) -> Vec<TileKey> {
    (0..side)
        .flat_map(|y| (0..side).map(move |x| TileKey::new(x, y)))
        .collect()
}

/// The deltas a tile gets on its `visit`-th visit: every cell nonzero,
/// alternating between the two kinds of evidence along a row and from one
/// visit to the next.
pub(super) fn evidence_pattern(size: TileSize, visit: usize) -> Vec<i16> {
    (0..size.area())
        .map(|i| {
            if (i + visit) % 2 == 0 {
                EVIDENCE.0
            } else {
                EVIDENCE.1
            }
        })
        .collect()
}

/// The request that creates a benchmark map named `name`.
pub(super) fn create_map_request(name: &str) -> pb::CreateMapRequest {
    pb::CreateMapRequest {
        name: name.into(),
        tile_size: TILE_SIDE,
        ..Default::default()
    }
}
