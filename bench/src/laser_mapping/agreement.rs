//! How alike the two final maps are: over the cells both observed, the
//! share both call occupied or both call free.
//!
//! Both are judged by OctoMap's own rule (`isNodeOccupied` with its
//! default threshold 0.5): a cell is occupied when its log-odds is at
//! least 0, free otherwise. Free cells far outnumber occupied ones, so the
//! overlap of the occupied cells (intersection over union) is given too:
//! it is the figure the walls decide.

use std::collections::HashMap;

use deog_grid::{CellOffset, TileMap};

use crate::octomap::cell_list::ExportedCell;

/// The two maps compared, cell by cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) struct Agreement {
    /// Cells deog's map observed.
    pub deog_cells: u64,
    /// Cells of OctoMap's z = 0 layer.
    pub octomap_cells: u64,
    /// Cells both observed.
    pub both_observed: u64,
    /// Of those, the cells both classify alike.
    pub alike: u64,
    /// Of those both observed, the cells deog calls occupied.
    pub occupied_deog: u64,
    /// Of those both observed, the cells OctoMap calls occupied.
    pub occupied_octomap: u64,
    /// Of those both observed, the cells both call occupied.
    pub occupied_both: u64,
}

impl Agreement {
    /// The share of the cells both observed that they classify alike;
    /// `None` when they share no cell.
    pub fn share_alike(&self) -> Option<f64> {
        (self.both_observed > 0).then(|| self.alike as f64 / self.both_observed as f64)
    }

    /// Occupied cells both call occupied over those either does, among the
    /// cells both observed; `None` when neither calls any occupied.
    pub fn occupied_iou(&self) -> Option<f64> {
        let either = self.occupied_deog + self.occupied_octomap - self.occupied_both;
        (either > 0).then(|| self.occupied_both as f64 / either as f64)
    }

    /// Cells only deog observed.
    pub fn deog_only(&self) -> u64 {
        self.deog_cells - self.both_observed
    }

    /// Cells only OctoMap observed.
    pub fn octomap_only(&self) -> u64 {
        self.octomap_cells - self.both_observed
    }
}

/// Compares deog's `map` with OctoMap's exported `cells` (same resolution,
/// same cell indices).
pub(super) fn compare(map: &TileMap, cells: &[ExportedCell]) -> Agreement {
    let octomap: HashMap<(i32, i32), bool> = cells
        .iter()
        .map(|c| ((c.x, c.y), c.log_odds >= 0.0))
        .collect();
    let size = map.tile_size();
    let mut out = Agreement {
        octomap_cells: octomap.len() as u64,
        ..Agreement::default()
    };
    for (key, tile) in map.tiles() {
        for (index, _) in tile.raw_cells().iter().enumerate() {
            let offset = CellOffset::from_index(index, size);
            let Some(belief) = tile.get(offset) else {
                continue;
            };
            out.deog_cells += 1;
            // Every offset of a tile of the map's size has a cell index.
            let Ok(cell) = size.join(*key, offset) else {
                continue;
            };
            let Some(&octomap_occupied) = octomap.get(&(cell.x, cell.y)) else {
                continue;
            };
            let deog_occupied = belief.raw() >= 0;
            out.both_observed += 1;
            out.alike += u64::from(deog_occupied == octomap_occupied);
            out.occupied_deog += u64::from(deog_occupied);
            out.occupied_octomap += u64::from(octomap_occupied);
            out.occupied_both += u64::from(deog_occupied && octomap_occupied);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use approx::assert_relative_eq;
    use deog_grid::{ClampLimits, Resolution, TileDelta, TileKey, TileSize};

    use super::*;

    fn cell(x: i32, y: i32, log_odds: f32) -> ExportedCell {
        ExportedCell { x, y, log_odds }
    }

    #[test]
    fn cells_are_matched_by_index_and_judged_at_even_odds() {
        let size = TileSize::new(8).expect("size");
        let mut map = TileMap::new(Resolution::DEFAULT, size, ClampLimits::default());
        // Tile (-1, 0) holds cells x -8..-1, y 0..7.
        let key = TileKey::new(-1, 0);
        let mut delta = TileDelta::zero(key, size);
        let put = |d: &mut TileDelta, x: i32, y: i32, v: i16| {
            let (k, offset) = size.split(deog_grid::CellIndex::new(x, y));
            assert_eq!(k, key);
            d.raw_mut()[offset.index(size)] = v;
        };
        put(&mut delta, -1, 0, 847); // occupied
        put(&mut delta, -2, 0, -405); // free
        put(&mut delta, -3, 0, 847); // occupied, OctoMap says free
        put(&mut delta, -4, 5, -405); // deog only
        map.apply(&delta).expect("apply");

        let octomap = [
            cell(-1, 0, 0.85),
            cell(-2, 0, -0.4),
            cell(-3, 0, -0.4),
            cell(10, 10, 0.85), // OctoMap only
        ];
        let a = compare(&map, &octomap);
        assert_eq!(
            a,
            Agreement {
                deog_cells: 4,
                octomap_cells: 4,
                both_observed: 3,
                alike: 2,
                occupied_deog: 2,
                occupied_octomap: 1,
                occupied_both: 1,
            }
        );
        assert_relative_eq!(a.share_alike().expect("shared"), 2.0 / 3.0);
        assert_relative_eq!(a.occupied_iou().expect("occupied"), 0.5);
        assert_eq!((a.deog_only(), a.octomap_only()), (1, 1));
    }

    #[test]
    fn maps_without_common_cells_have_no_share() {
        let map = TileMap::new(
            Resolution::DEFAULT,
            TileSize::DEFAULT,
            ClampLimits::default(),
        );
        let a = compare(&map, &[cell(0, 0, 1.0)]);
        assert_eq!(a.share_alike(), None);
        assert_eq!(a.occupied_iou(), None);
        assert_eq!(a.octomap_only(), 1);
    }
}
