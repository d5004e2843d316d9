//! The thesis baseline: the mapper of the thesis's Fig. 7.1 on sled, the
//! store engine the map server uses, over the cells the throughput
//! clients update.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_grid::{LogOdds, TileKey, TileSize};

use super::workload::evidence_pattern;

/// The thesis's mapper commits after this many writes.
const BASELINE_COMMIT_EVERY: u64 = 300;

/// Figures of the thesis's mapper on sled.
pub(super) struct BaselineRun {
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

/// The thesis's Fig. 7.1 on sled: for each cell update, `getdata`, the
/// Bayes update with the sensor's probability (a missing cell starts at
/// 0.5), then `addrows` or `updatedb` (only if the value changed); a commit
/// (flush) after every 300 writes. The cells are the throughput clients':
/// the region's tiles in order, every cell of each, with the same evidence.
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
    let side = size.cells() as i32;
    // The sensor's probability for each cell of each pattern, P(s) = the
    // logistic of the log-odds delta the server gets for that cell.
    let sensor = |delta: i16| LogOdds::from_raw(delta).map_or(0.5, LogOdds::probability);
    let patterns: [Vec<f64>; 2] = [0, 1].map(|visit| {
        evidence_pattern(size, visit)
            .into_iter()
            .map(sensor)
            .collect()
    });
    let (mut updates, mut inserts, mut rewrites, mut flushes, mut pending) =
        (0u64, 0u64, 0u64, 0u64, 0u64);
    let start = Instant::now();
    let deadline = start + duration;
    let mut visit = 0usize;
    'run: loop {
        let key = region[visit % region.len()];
        let pattern = &patterns[(visit / region.len()) % 2];
        for (i, &pemp) in pattern.iter().enumerate() {
            let x = key.x * side + (i as i32 % side);
            let y = key.y * side + (i as i32 / side);
            let cell_key = (((x as u32) << 16).wrapping_add(y as u32)).to_be_bytes();
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
            let both = pemp * old;
            let p = both / ((1.0 - pemp) * (1.0 - old) + both);
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
                    break 'run;
                }
            }
        }
        visit += 1;
    }
    db.flush()?;
    flushes += 1;
    Ok(BaselineRun {
        updates,
        inserts,
        rewrites,
        flushes,
        seconds: start.elapsed().as_secs_f64(),
    })
}
