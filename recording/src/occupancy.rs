//! A map's tiles as one `nav_msgs/OccupancyGrid`: the box of its observed
//! cells, each 0 to 100 from its log-odds, -1 where never observed.

use deog_grid::{CellIndex, Pose2, TileKey, TileMap};

use crate::error::RecordingError;
use crate::messages::{Header, MapMetaData, OccupancyGrid, Pose, Time};

/// The most cells one grid message may hold (its bytes travel as one
/// message; ROS tools load it whole).
pub const MAX_GRID_CELLS: u64 = 64 * 1024 * 1024;

/// The occupancy of every cell in the box of `map`'s observed cells, at
/// `stamp` in frame `frame_id`.
pub fn occupancy_grid(
    map: &TileMap,
    stamp: Time,
    frame_id: &str,
) -> Result<OccupancyGrid, RecordingError> {
    let size = map.tile_size();
    let observed = |key: &TileKey, index: usize| -> Option<CellIndex> {
        let offset = deog_grid::CellOffset::from_index(index, size);
        size.join(*key, offset).ok()
    };
    let mut bounds: Option<(CellIndex, CellIndex)> = None;
    for (key, tile) in map.tiles() {
        for (index, &raw) in tile.raw_cells().iter().enumerate() {
            if raw == deog_grid::LogOdds::UNKNOWN_RAW {
                continue;
            }
            let Some(cell) = observed(key, index) else {
                continue;
            };
            bounds = Some(match bounds {
                None => (cell, cell),
                Some((lo, hi)) => (
                    CellIndex::new(lo.x.min(cell.x), lo.y.min(cell.y)),
                    CellIndex::new(hi.x.max(cell.x), hi.y.max(cell.y)),
                ),
            });
        }
    }
    let Some((lo, hi)) = bounds else {
        return Err(RecordingError::Empty(
            "the map has no observed cell to record".into(),
        ));
    };
    let width = (i64::from(hi.x) - i64::from(lo.x) + 1) as u64;
    let height = (i64::from(hi.y) - i64::from(lo.y) + 1) as u64;
    if width * height > MAX_GRID_CELLS {
        return Err(RecordingError::Unrecordable(format!(
            "the map's observed cells span {width} x {height} cells, more than {MAX_GRID_CELLS} in one grid"
        )));
    }
    let mut data = vec![-1i8; (width * height) as usize];
    for y in lo.y..=hi.y {
        for x in lo.x..=hi.x {
            if let Some(belief) = map.get(CellIndex::new(x, y)) {
                let row = (y - lo.y) as usize;
                let column = (x - lo.x) as usize;
                data[row * width as usize + column] =
                    (belief.probability() * 100.0).round().clamp(0.0, 100.0) as i8;
            }
        }
    }
    let resolution = map.resolution();
    let (corner_x, corner_y) = resolution.cell_corner(lo);
    Ok(OccupancyGrid {
        header: Header::new(stamp, frame_id),
        info: MapMetaData {
            map_load_time: stamp,
            resolution: resolution.metres() as f32,
            width: width as u32,
            height: height as u32,
            origin: Pose::from_planar(Pose2::new(corner_x, corner_y, 0.0)),
        },
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::{ClampLimits, LogOdds, Resolution, Tile, TileSize};

    #[test]
    fn cells_become_percentages_in_the_box_of_the_observed_ones() {
        let size = TileSize::new(8).unwrap();
        let mut map = TileMap::new(Resolution::new(0.5).unwrap(), size, ClampLimits::NONE);
        let mut cells = [LogOdds::UNKNOWN_RAW; 64];
        // Tile (-1, 0): its cell (-8 + 7, 0 + 1) = (-1, 1) is occupied,
        // (-1 + 0, 0 + 3) free.
        cells[8 + 7] = LogOdds::from_probability(0.9).unwrap().raw();
        cells[3 * 8 + 7] = LogOdds::from_probability(0.2).unwrap().raw();
        let bytes: Vec<u8> = cells.iter().flat_map(|c| c.to_le_bytes()).collect();
        map.insert(
            TileKey::new(-1, 0),
            Tile::from_dense_bytes(size, &bytes).unwrap(),
        )
        .unwrap();
        let mut cells = [LogOdds::UNKNOWN_RAW; 64];
        // Tile (0, 0): its first cell is (0, 0), even odds.
        cells[0] = LogOdds::EVEN.raw();
        let bytes: Vec<u8> = cells.iter().flat_map(|c| c.to_le_bytes()).collect();
        map.insert(
            TileKey::new(0, 0),
            Tile::from_dense_bytes(size, &bytes).unwrap(),
        )
        .unwrap();
        let grid = occupancy_grid(&map, Time::default(), "map").unwrap();
        // Cells x -1..=0, y 0..=3.
        assert_eq!((grid.info.width, grid.info.height), (2, 4));
        assert_eq!(grid.info.origin.position.x, -0.5);
        assert_eq!(grid.info.origin.position.y, 0.0);
        assert_eq!(grid.data[0], -1); // (-1, 0)
        assert_eq!(grid.data[1], 50); // (0, 0)
        assert_eq!(grid.data[2], 90); // (-1, 1)
        assert_eq!(grid.data[6], 20); // (-1, 3)
        assert_eq!(grid.data.iter().filter(|&&v| v >= 0).count(), 3);
    }

    #[test]
    fn an_empty_map_is_an_error() {
        let map = TileMap::new(
            Resolution::new(0.1).unwrap(),
            TileSize::new(8).unwrap(),
            ClampLimits::NONE,
        );
        assert!(occupancy_grid(&map, Time::default(), "map").is_err());
    }
}
