//! Space no robot could have seen: the cells of the view that no path
//! from where a robot stood reaches without crossing a wall the view
//! holds. A specular sonar frees such cells through a face it met at a
//! grazing angle (the face gave no echo, the cone's other rays a farther
//! one); once the faces around them are walls, nothing a sonar heard can
//! have come from inside, so what the view holds free there is wrong: the
//! inside of an obstacle, the space beyond an outer wall.

use deog_grid::{KeyMap, TileKey, TileSize};

use super::{DirectionalTile, UNSEEN};

/// The tiles held, in slots, with each slot's 3 × 3 block of neighbouring
/// slots, so that a cell's neighbours across a tile's edge are a lookup.
struct Slots {
    keys: Vec<TileKey>,
    /// Per slot, the slot of the tile at `(dx, dy)` from it at
    /// `(dy + 1) * 3 + dx + 1`.
    beside: Vec<[Option<usize>; 9]>,
    side: usize,
}

impl Slots {
    fn new(tiles: &KeyMap<TileKey, DirectionalTile>, size: TileSize) -> Self {
        let keys: Vec<TileKey> = tiles.keys().copied().collect();
        let slot_of: KeyMap<TileKey, usize> =
            keys.iter().enumerate().map(|(i, k)| (*k, i)).collect();
        let beside = keys
            .iter()
            .map(|k| {
                std::array::from_fn(|n| {
                    let (dx, dy) = (n as i32 % 3 - 1, n as i32 / 3 - 1);
                    let key = TileKey::new(k.x.wrapping_add(dx), k.y.wrapping_add(dy));
                    slot_of.get(&key).copied()
                })
            })
            .collect();
        Self {
            keys,
            beside,
            side: size.cells() as usize,
        }
    }

    /// The cell `(dx, dy)` (each in -1..=1) from cell `index` of `slot`, if
    /// its tile is held.
    fn step(&self, slot: usize, index: usize, dx: i32, dy: i32) -> Option<(usize, usize)> {
        let side = self.side as i32;
        let (x, y) = (
            (index % self.side) as i32 + dx,
            (index / self.side) as i32 + dy,
        );
        let tx = i32::from(x >= side) - i32::from(x < 0);
        let ty = i32::from(y >= side) - i32::from(y < 0);
        let to = self.beside[slot][((ty + 1) * 3 + tx + 1) as usize]?;
        let (x, y) = (x.rem_euclid(side), y.rem_euclid(side));
        Some((to, (y * side + x) as usize))
    }

    /// The four cells sharing an edge with cell `index` of `slot`.
    fn edge_neighbours(&self, slot: usize, index: usize) -> [Option<(usize, usize)>; 4] {
        [(-1, 0), (1, 0), (0, -1), (0, 1)].map(|(dx, dy)| self.step(slot, index, dx, dy))
    }
}

/// For each tile of `tiles`, which of its cells a flood from the trodden
/// cells reaches. The flood passes observed cells whose belief stays at
/// or below `block`, and unobserved cells near a robot's path (between a
/// robot and where its sensors' cones begin). It keeps to the tiles held:
/// a region joined to a robot's path only through forgotten tiles is not
/// reached, which is why the caller judges only the tiles near the robot.
pub(super) fn reached_from_trodden(
    tiles: &KeyMap<TileKey, DirectionalTile>,
    size: TileSize,
    block: i16,
) -> KeyMap<TileKey, Vec<bool>> {
    let slots = Slots::new(tiles, size);
    let area = size.area();
    let passable: Vec<Vec<bool>> = slots
        .keys
        .iter()
        .map(|key| {
            let tile = &tiles[key];
            (0..area)
                .map(|i| {
                    let belief = tile.leaning[i];
                    if belief == UNSEEN {
                        tile.near_path[i]
                    } else {
                        belief <= block
                    }
                })
                .collect()
        })
        .collect();
    let mut reached: Vec<Vec<bool>> = vec![vec![false; area]; slots.keys.len()];
    let mut stack: Vec<(usize, usize)> = Vec::new();
    for (slot, key) in slots.keys.iter().enumerate() {
        for (index, &trodden) in tiles[key].trodden.iter().enumerate() {
            if trodden {
                reached[slot][index] = true;
                stack.push((slot, index));
            }
        }
    }
    while let Some((slot, index)) = stack.pop() {
        for (s, i) in slots.edge_neighbours(slot, index).into_iter().flatten() {
            if !reached[s][i] && passable[s][i] {
                reached[s][i] = true;
                stack.push((s, i));
            }
        }
    }
    slots.keys.into_iter().zip(reached).collect()
}
