//! The localizer's memory as it runs: its resident set and peak from
//! `/proc`, its baseline once it has built its first tables, and what it
//! holds beyond the cache it logs.

use std::time::Instant;

use anyhow::{Context, Result};
use deog_grid::Pose2;
use deog_harness::proc_stats;
use deog_robot_client::MapClient;

use super::{MAP, ROBOT};

/// The baseline is taken once the localizer has estimated a frame this
/// far, metres, from the start: it has moved, run sensor updates, fetched
/// its first tiles and built their tables by then.
pub(super) const BASELINE_MOVE_M: f64 = 0.5;

/// The localizer's memory, read from `/proc` as it runs.
#[derive(Debug, Default)]
pub(super) struct MemorySamples {
    /// Readings of `VmRSS` that succeeded.
    pub samples: u64,
    /// The largest `VmRSS` read, kB.
    pub peak_rss_kb: u64,
    /// The last `VmRSS` read, kB.
    pub last_rss_kb: u64,
    /// The last `VmHWM` read, kB: the peak of the whole process life up
    /// to then. The process is idle (waiting out --idle-exit) between the
    /// last reading and its exit, so this is its final peak.
    pub hwm_kb: u64,
    /// Resident set per second of the run: (wall seconds, kB).
    pub series: Vec<(f64, u64)>,
    /// User plus system CPU seconds the process had used at the last
    /// reading.
    pub cpu_s: f64,
}

impl MemorySamples {
    /// Reads the process's memory once; a process that has exited (its
    /// status no longer has the fields) leaves the figures as they were.
    pub fn sample(&mut self, pid: u32, since: Instant) {
        let Ok(rss) = proc_stats::status_kb(pid, "VmRSS") else {
            return;
        };
        if let Ok(hwm) = proc_stats::status_kb(pid, "VmHWM") {
            self.hwm_kb = hwm;
        }
        if let Ok(cpu) = proc_stats::cpu_seconds(pid) {
            self.cpu_s = cpu;
        }
        self.samples += 1;
        self.peak_rss_kb = self.peak_rss_kb.max(rss);
        self.last_rss_kb = rss;
        let t = since.elapsed().as_secs_f64();
        if self.series.last().is_none_or(|(last, _)| t - last >= 1.0) {
            self.series.push((t, rss));
        }
    }
}

/// The localizer's resident set beyond its cache: at each of its periodic
/// info lines (every 100 frames, carrying `cache_mb`), the resident set
/// read right after the line less that cache.
#[derive(Debug, Default)]
pub(super) struct BeyondCache {
    /// Lines seen.
    pub count: u64,
    /// At the first line: (resident set kB, cache MiB).
    pub first: Option<(u64, f64)>,
    /// The largest resident set less cache, kB.
    pub max_kb: u64,
}

impl BeyondCache {
    /// Notes a resident set read right after a line logging `cache_mib`.
    pub fn note(&mut self, rss_kb: u64, cache_mib: f64) {
        let beyond = rss_kb.saturating_sub((cache_mib * 1024.0) as u64);
        self.count += 1;
        self.first.get_or_insert((rss_kb, cache_mib));
        self.max_kb = self.max_kb.max(beyond);
    }

    /// The resident set less cache at the first line, kB.
    pub fn first_kb(&self) -> Option<u64> {
        self.first
            .map(|(rss, cache)| rss.saturating_sub((cache * 1024.0) as u64))
    }
}

/// Finding the baseline: the first frame past [`BASELINE_MOVE_M`] from the
/// start, then the localizer's estimate of it.
#[derive(Debug)]
pub(super) enum Baseline {
    /// Reading frames after this sequence for one far enough out.
    FindFrame { after: u64 },
    /// Waiting for the estimate of this frame.
    AwaitEstimate { sequence: u64 },
    /// The resident set then, kB, and the simulated time of that frame.
    Taken { rss_kb: u64, time_s: f64 },
}

impl Baseline {
    /// One step towards the baseline; takes it when the localizer (process
    /// `pid`) has estimated the first frame past [`BASELINE_MOVE_M`] from
    /// `start`.
    pub async fn step(self, client: &MapClient, start: Pose2, pid: u32) -> Result<Self> {
        Ok(match self {
            Baseline::FindFrame { after } => {
                let frames = client
                    .read_frames(ROBOT, after + 1, 0)
                    .await
                    .context("reading the robot's frames")?;
                let far = frames.iter().find(|f| {
                    f.true_pose
                        .is_some_and(|p| (p.x - start.x).hypot(p.y - start.y) >= BASELINE_MOVE_M)
                });
                match far {
                    Some(frame) => Baseline::AwaitEstimate {
                        sequence: frame.sequence,
                    },
                    None => Baseline::FindFrame {
                        after: frames.last().map_or(after, |f| f.sequence),
                    },
                }
            }
            Baseline::AwaitEstimate { sequence } => {
                let poses = client
                    .read_poses(ROBOT, sequence, 0)
                    .await
                    .context("reading the localizer's estimates")?;
                match poses.iter().find(|p| p.map == MAP) {
                    Some(estimate) => Baseline::Taken {
                        rss_kb: proc_stats::status_kb(pid, "VmRSS")?,
                        time_s: estimate.time_s,
                    },
                    None => Baseline::AwaitEstimate { sequence },
                }
            }
            taken @ Baseline::Taken { .. } => taken,
        })
    }
}
