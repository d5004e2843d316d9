//! The thesis baseline: the mapper of the thesis's Fig. 7.1 on sled, the
//! store engine the map server uses by default, over the cells the
//! throughput clients update. The same mapper on PostgreSQL is in
//! `baseline_postgres`; both take their cells from [`ThesisCells`].

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::{LogOdds, TileKey, TileSize};

use super::workload::evidence_pattern;

/// The thesis's mapper commits after this many writes.
pub(super) const BASELINE_COMMIT_EVERY: u64 = 300;

/// Figures of the thesis's mapper on one store engine.
pub(super) struct BaselineRun {
    /// The engine it ran on: `sled` or `postgres`.
    pub engine: &'static str,
    /// Cell updates done.
    pub updates: u64,
    /// Of which the first write of a cell.
    pub inserts: u64,
    /// Of which a cell's value changed and was written again.
    pub rewrites: u64,
    /// Commits (flushes to disk).
    pub flushes: u64,
    /// Wall-clock seconds it ran.
    pub seconds: f64,
}

impl BaselineRun {
    /// Cell updates a second.
    pub fn cells_per_s(&self) -> f64 {
        self.updates as f64 / self.seconds
    }
}

/// The cell updates the thesis's mapper makes, for ever: the region's
/// tiles in order, every cell of each, with the evidence the throughput
/// clients send, as the thesis's key `(x << 16) + y` and the sensor's
/// probability `P(s)` (the logistic of the log-odds delta the server gets
/// for that cell).
pub(super) struct ThesisCells<'a> {
    region: &'a [TileKey],
    side: i32,
    patterns: [Vec<f64>; 2],
    visit: usize,
    cell: usize,
}

impl<'a> ThesisCells<'a> {
    /// The cells of `region`'s tiles of `size`.
    pub fn new(size: TileSize, region: &'a [TileKey]) -> Self {
        let sensor = |delta: i16| LogOdds::from_raw(delta).map_or(0.5, LogOdds::probability);
        Self {
            region,
            side: size.cells() as i32,
            patterns: [0, 1].map(|visit| {
                evidence_pattern(size, visit)
                    .into_iter()
                    .map(sensor)
                    .collect()
            }),
            visit: 0,
            cell: 0,
        }
    }
}

impl Iterator for ThesisCells<'_> {
    type Item = (u32, f64);

    fn next(&mut self) -> Option<(u32, f64)> {
        let key = *self.region.get(self.visit % self.region.len().max(1))?;
        let pattern = &self.patterns[(self.visit / self.region.len()) % 2];
        let pemp = *pattern.get(self.cell)?;
        let x = key.x * self.side + (self.cell as i32 % self.side);
        let y = key.y * self.side + (self.cell as i32 / self.side);
        self.cell += 1;
        if self.cell == pattern.len() {
            self.cell = 0;
            self.visit += 1;
        }
        Some((((x as u32) << 16).wrapping_add(y as u32), pemp))
    }
}

/// The thesis's Bayes update of a cell's probability `old` with the
/// sensor's probability `pemp`.
pub(super) fn bayes(pemp: f64, old: f64) -> f64 {
    let both = pemp * old;
    both / ((1.0 - pemp) * (1.0 - old) + both)
}

/// The thesis's Fig. 7.1 on sled: for each cell update, `getdata`, the
/// Bayes update with the sensor's probability (a missing cell starts at
/// 0.5), then `addrows` or `updatedb` (only if the value changed); a commit
/// (flush) after every 300 writes. The cells are [`ThesisCells`].
pub(super) fn thesis_baseline(
    duration: Duration,
    size: TileSize,
    region: &[TileKey],
) -> Result<BaselineRun> {
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let db = sled::Config::new()
        .path(dir.path())
        .cache_capacity(64 << 20)
        .open()
        .context("opening the baseline's sled database")?;
    let (mut updates, mut inserts, mut rewrites, mut flushes, mut pending) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    let deadline = start + duration;
    for (key, pemp) in ThesisCells::new(size, region) {
        let cell_key = key.to_be_bytes();
        let stored = db.get(cell_key)?;
        let old = match &stored {
            Some(bytes) => f64::from_be_bytes(
                bytes
                    .as_ref()
                    .try_into()
                    .context("baseline value is not 8 bytes")?,
            ),
            None => 0.5,
        };
        let p = bayes(pemp, old);
        if stored.is_none() {
            db.insert(cell_key, &p.to_be_bytes())?;
            inserts += 1;
            pending += 1;
        } else if p != old {
            db.insert(cell_key, &p.to_be_bytes())?;
            rewrites += 1;
            pending += 1;
        }
        updates += 1;
        if pending >= BASELINE_COMMIT_EVERY {
            db.flush()?;
            flushes += 1;
            pending = 0;
            if Instant::now() >= deadline {
                break;
            }
        }
    }
    db.flush()?;
    flushes += 1;
    Ok(BaselineRun {
        engine: "sled",
        updates,
        inserts,
        rewrites,
        flushes,
        seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map_server::workload::region_tiles;

    #[test]
    fn the_cells_walk_every_cell_of_each_tile_then_the_next_tile() {
        let size = TileSize::new(8).expect("size");
        let region = region_tiles(2);
        let cells: Vec<(u32, f64)> = ThesisCells::new(size, &region).take(65).collect();
        // Tile (0, 0): x 0..8, y 0..8, row by row.
        assert_eq!(cells[0].0, 0);
        assert_eq!(cells[1].0, 1 << 16);
        assert_eq!(cells[8].0, 1);
        // Then tile (1, 0) starts at x = 8.
        assert_eq!(cells[64].0, 8 << 16);
        // The evidence alternates along a row.
        assert!(cells[0].1 > 0.5 && cells[1].1 < 0.5);
        approx::assert_relative_eq!(bayes(0.5, 0.7), 0.7);
    }
}
