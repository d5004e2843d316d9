//! Copying what one store holds into another: maps (record, tiles, client
//! cursors), robots' frames, pose estimates and rigs, through the [`Store`]
//! contract alone, so any two backends can be copied between.
//!
//! A copy can be interrupted and run again: tiles, frames and poses the
//! destination already holds as the source does are skipped, and a map's
//! record (its version, counts and bounds) is written last, so a map whose
//! record matches the source's was copied whole. Each map is then checked:
//! its tile count and a checksum of its tiles on both sides.

use super::{FrameWrite, MapRecord, MapWrite, RobotSummary, Store, StoredTile, TileRange};
use crate::error::StoreError;
use deog_grid::TileKey;

/// Tiles, frames or poses written per store call.
const CHUNK: usize = 256;

/// What a copy did to one map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MapCopied {
    /// The map.
    pub name: String,
    /// Tiles it holds (on both sides, once checked).
    pub tiles: u64,
    /// Tiles written by this run (the rest were there already).
    pub tiles_written: u64,
    /// FNV-1a over every tile's key, version and cells, in key order: the
    /// same on both sides.
    pub checksum: u64,
    /// The map's version.
    pub version: u64,
}

/// What a whole copy did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CopyReport {
    /// Each map copied, by name.
    pub maps: Vec<MapCopied>,
    /// Robots whose frames were copied, and frames written by this run.
    pub robots: u64,
    /// Frames written by this run (the rest were there already).
    pub frames_written: u64,
    /// Pose estimates copied.
    pub poses: u64,
    /// Rigs copied.
    pub rigs: u64,
}

/// What a copy tells its caller as it goes, so the caller can show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CopyProgress<'a> {
    /// The items to go through in all: the tiles of the maps copied and
    /// the frames of every robot, as the source's records count them.
    Total(u64),
    /// This many more items gone through (written, or found already there).
    Advanced(u64),
    /// A step finished, in words.
    Step(&'a str),
}

/// Why a copy stopped.
#[derive(Debug, thiserror::Error)]
pub enum CopyError {
    /// A store failed; `what` says which side and doing what.
    #[error("{what}: {error}")]
    Store {
        /// Where it failed.
        what: String,
        /// The store's error, worded into this one (not a separate cause,
        /// which would print it twice).
        error: StoreError,
    },
    /// A map asked for is not in the source.
    #[error("the source holds no map {0:?}")]
    NoSuchMap(String),
    /// The destination holds a map of the same name with other settings.
    #[error(
        "the destination's map {0:?} has other settings (resolution, tile size or clamp) than the source's: delete it there or copy to another store"
    )]
    OtherSettings(String),
    /// The destination holds a different rig of the same name.
    #[error("the destination holds a different rig called {0:?}")]
    OtherRig(String),
    /// A map came out different from its source.
    #[error(
        "map {name:?} does not match after the copy: source {source_tiles} tiles (checksum {source_sum:016x}), destination {copy_tiles} (checksum {copy_sum:016x})"
    )]
    Mismatch {
        /// The map.
        name: String,
        /// Tiles in the source.
        source_tiles: u64,
        /// Its checksum.
        source_sum: u64,
        /// Tiles in the destination.
        copy_tiles: u64,
        /// Its checksum.
        copy_sum: u64,
    },
}

fn at<T>(what: impl FnOnce() -> String, result: Result<T, StoreError>) -> Result<T, CopyError> {
    result.map_err(|error| CopyError::Store {
        what: what(),
        error,
    })
}

/// Every tile key.
const EVERYWHERE: TileRange = TileRange {
    min: TileKey {
        x: i32::MIN,
        y: i32::MIN,
    },
    max: TileKey {
        x: i32::MAX,
        y: i32::MAX,
    },
};

/// Copies `maps` (every map when empty), and every robot's frames and
/// poses and every rig, from `source` into `destination`, then checks each
/// map; `progress` hears the items to go through, each chunk gone through
/// and a line per step.
pub fn copy_store<A: Store + ?Sized, B: Store + ?Sized>(
    source: &A,
    destination: &B,
    maps: &[String],
    progress: &mut dyn FnMut(CopyProgress<'_>),
) -> Result<CopyReport, CopyError> {
    let mut report = CopyReport::default();
    let records = at(|| "listing the source's maps".into(), source.maps())?;
    let wanted: Vec<MapRecord> = if maps.is_empty() {
        records
    } else {
        maps.iter()
            .map(|name| {
                records
                    .iter()
                    .find(|r| &r.name == name)
                    .cloned()
                    .ok_or_else(|| CopyError::NoSuchMap(name.clone()))
            })
            .collect::<Result<_, _>>()?
    };
    let robots = at(|| "listing the source's robots".into(), source.robots())?;
    let tiles: u64 = wanted.iter().map(|r| r.tile_count).sum();
    let frames: u64 = robots.iter().map(|(_, s)| s.frame_count).sum();
    progress(CopyProgress::Total(tiles + frames));
    copy_rigs(source, destination, &mut report)?;
    for record in wanted {
        let copied = copy_map(source, destination, &record, progress)?;
        progress(CopyProgress::Step(&format!(
            "map {}: {} tiles ({} written), version {}, checksum {:016x}",
            copied.name, copied.tiles, copied.tiles_written, copied.version, copied.checksum
        )));
        report.maps.push(copied);
    }
    copy_frames_and_poses(source, destination, &robots, &mut report, progress)?;
    progress(CopyProgress::Step(&format!(
        "{} robots: {} frames written, {} pose estimates, {} rigs",
        report.robots, report.frames_written, report.poses, report.rigs
    )));
    at(|| "flushing the destination".into(), destination.flush())?;
    Ok(report)
}

fn copy_rigs<A: Store + ?Sized, B: Store + ?Sized>(
    source: &A,
    destination: &B,
    report: &mut CopyReport,
) -> Result<(), CopyError> {
    let there = at(
        || "listing the destination's rigs".into(),
        destination.rigs(),
    )?;
    for (name, bytes) in at(|| "listing the source's rigs".into(), source.rigs())? {
        match there.iter().find(|(n, _)| *n == name) {
            Some((_, held)) if *held == bytes => {}
            Some(_) => return Err(CopyError::OtherRig(name)),
            None => {
                at(
                    || format!("writing rig {name}"),
                    destination.put_rig(&name, bytes),
                )?;
                report.rigs += 1;
            }
        }
    }
    Ok(())
}

fn copy_map<A: Store + ?Sized, B: Store + ?Sized>(
    source: &A,
    destination: &B,
    record: &MapRecord,
    progress: &mut dyn FnMut(CopyProgress<'_>),
) -> Result<MapCopied, CopyError> {
    let name = &record.name;
    let existing = at(
        || format!("reading map {name} at the destination"),
        destination.map(name),
    )?;
    let target = match existing {
        Some(there) if there.settings != record.settings => {
            return Err(CopyError::OtherSettings(name.clone()));
        }
        Some(there) => there,
        None => {
            // Counts and version come with the last write: a map whose
            // record matches the source's was copied whole.
            let fresh = MapRecord::new(name.clone(), record.settings);
            at(
                || format!("creating map {name} at the destination"),
                destination.create_map(&fresh),
            )?;
            fresh
        }
    };
    let mut tiles = Vec::new();
    let mut written = 0u64;
    let mut failure = None;
    let mut seen = 0u64;
    let mut visit = |key: TileKey, tile: StoredTile| {
        seen += 1;
        if seen % CHUNK as u64 == 0 {
            progress(CopyProgress::Advanced(CHUNK as u64));
        }
        let held = match destination.tile(&target, key) {
            Ok(held) => held,
            Err(error) => {
                failure = Some(error);
                return false;
            }
        };
        if held.is_some_and(|h| h == tile) {
            return true;
        }
        tiles.push((key, tile));
        if tiles.len() >= CHUNK {
            written += tiles.len() as u64;
            let write = MapWrite {
                tiles: std::mem::take(&mut tiles),
                ..MapWrite::default()
            };
            if let Err(error) = destination.write_map(name, write) {
                failure = Some(error);
                return false;
            }
        }
        true
    };
    at(
        || format!("reading map {name}'s tiles"),
        source.tiles_in(record, EVERYWHERE, &mut visit),
    )?;
    if let Some(error) = failure {
        return Err(CopyError::Store {
            what: format!("copying map {name}'s tiles"),
            error,
        });
    }
    progress(CopyProgress::Advanced(seen % CHUNK as u64));
    written += tiles.len() as u64;
    let cursors = at(
        || format!("reading map {name}'s cursors"),
        source.cursors(name),
    )?;
    at(
        || format!("writing map {name}'s last tiles, cursors and record"),
        destination.write_map(
            name,
            MapWrite {
                record: Some(record.clone()),
                clear_tiles: false,
                tiles,
                cursors,
            },
        ),
    )?;
    let (source_tiles, source_sum) = at(
        || format!("checking map {name} at the source"),
        summarise(source, record),
    )?;
    let (copy_tiles, copy_sum) = at(
        || format!("checking map {name} at the destination"),
        summarise(destination, record),
    )?;
    if (source_tiles, source_sum) != (copy_tiles, copy_sum) {
        return Err(CopyError::Mismatch {
            name: name.clone(),
            source_tiles,
            source_sum,
            copy_tiles,
            copy_sum,
        });
    }
    Ok(MapCopied {
        name: name.clone(),
        tiles: source_tiles,
        tiles_written: written,
        checksum: source_sum,
        version: record.version,
    })
}

/// A map's tile count and checksum.
fn summarise<S: Store + ?Sized>(store: &S, record: &MapRecord) -> Result<(u64, u64), StoreError> {
    let mut sum = Fnv::new();
    let mut count = 0u64;
    store.tiles_in(record, EVERYWHERE, &mut |key, tile| {
        count += 1;
        sum.add(&key.to_store_bytes());
        sum.add(&tile.encode());
        true
    })?;
    Ok((count, sum.value()))
}

fn copy_frames_and_poses<A: Store + ?Sized, B: Store + ?Sized>(
    source: &A,
    destination: &B,
    robots: &[(String, RobotSummary)],
    report: &mut CopyReport,
    progress: &mut dyn FnMut(CopyProgress<'_>),
) -> Result<(), CopyError> {
    for (robot, _) in robots {
        report.robots += 1;
        let mut summary = at(
            || format!("reading robot {robot} at the destination"),
            destination.robot(robot),
        )?
        .unwrap_or_default();
        let mut frames: Vec<(u64, Vec<u8>)> = Vec::new();
        let mut failure = None;
        let mut seen = 0u64;
        let flush = |frames: &mut Vec<(u64, Vec<u8>)>, summary: RobotSummary| {
            destination.write_frames(vec![FrameWrite {
                robot: robot.clone(),
                summary,
                frames: std::mem::take(frames),
            }])
        };
        at(
            || format!("reading robot {robot}'s frames"),
            source.read_frames(robot, 0, u64::MAX, &mut |sequence, bytes| {
                seen += 1;
                if seen % CHUNK as u64 == 0 {
                    progress(CopyProgress::Advanced(CHUNK as u64));
                }
                match destination.has_frame(robot, sequence) {
                    Ok(true) => return true,
                    Ok(false) => {}
                    Err(error) => {
                        failure = Some(error);
                        return false;
                    }
                }
                summary = summary.with(sequence);
                frames.push((sequence, bytes.to_vec()));
                report.frames_written += 1;
                if frames.len() >= CHUNK
                    && let Err(error) = flush(&mut frames, summary)
                {
                    failure = Some(error);
                    return false;
                }
                true
            }),
        )?;
        progress(CopyProgress::Advanced(seen % CHUNK as u64));
        if let Some(error) = failure {
            return Err(CopyError::Store {
                what: format!("copying robot {robot}'s frames"),
                error,
            });
        }
        if !frames.is_empty() {
            at(
                || format!("copying robot {robot}'s frames"),
                flush(&mut frames, summary),
            )?;
        }
        let mut poses = Vec::new();
        at(
            || format!("reading robot {robot}'s pose estimates"),
            source.read_poses(robot, 0, u64::MAX, &mut |sequence, bytes| {
                poses.push((robot.clone(), sequence, bytes.to_vec()));
                true
            }),
        )?;
        report.poses += poses.len() as u64;
        for chunk in poses.chunks(CHUNK) {
            at(
                || format!("copying robot {robot}'s pose estimates"),
                destination.write_poses(chunk.to_vec()),
            )?;
        }
    }
    Ok(())
}

/// 64-bit FNV-1a: a checksum both sides compute alike, not a defence
/// against anyone.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn add(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    fn value(&self) -> u64 {
        self.0
    }
}
