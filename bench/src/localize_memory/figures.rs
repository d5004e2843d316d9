//! Everything `deog bench localize-memory` measured, and the figures
//! derived from it that the table and the JSON share.

use std::path::PathBuf;

use deog_evaluation::localization::LocalizationReport;
use deog_evaluation::tracking::Tracking;
use deog_grid::Pose2;

use super::log::LocalizerSummary;
use super::sampling::{BeyondCache, MemorySamples};
use super::server_reads::FilterFigures;

/// The figures of one run, with the settings it ran with.
pub(super) struct LocalizerMemoryFigures {
    /// `--cache-mb`.
    pub cache_mb: usize,
    /// `--max-particles`.
    pub max_particles: usize,
    /// The cache budget, bytes.
    pub budget_bytes: usize,
    /// Pixels (cells) a side of the city.
    pub side_px: u32,
    /// The city's blocks.
    pub blocks: usize,
    /// The map's tiles, as the server holds them.
    pub tiles: u64,
    /// Bytes one tile costs the localizer.
    pub tile_bytes: usize,
    /// The robot's start pose, world frame.
    pub start: Pose2,
    /// `--duration`, simulated seconds.
    pub duration_s: f64,
    /// `--speed`, simulated seconds per wall-clock second.
    pub speed: f64,
    /// `--robot-speed`, m/s.
    pub robot_speed: f64,
    /// `--seed`.
    pub seed: u64,
    /// The localizer's memory as sampled.
    pub memory: MemorySamples,
    /// Its resident set beyond the cache it logged.
    pub beyond_cache: BeyondCache,
    /// Its resident set once it had built its first tables, kB.
    pub baseline_kb: u64,
    /// The simulated time of the frame the baseline was taken at.
    pub baseline_time_s: f64,
    /// Tiles the robot's true path crossed.
    pub tiles_crossed: usize,
    /// Tiles crossed up to the frame of the localizer's last estimate.
    pub tiles_estimated: usize,
    /// Metres the robot drove.
    pub distance_m: f64,
    /// The robot's frames with a true pose on the server.
    pub frames_on_server: usize,
    /// The localizer's last line; `None` when it was given up on.
    pub summary: Option<LocalizerSummary>,
    /// Why the localizer was given up on, if it was.
    pub gave_up: Option<String>,
    /// What the estimates say of the filter.
    pub filter: FilterFigures,
    /// The largest cache size the localizer logged, MiB, if it logged any.
    pub logged_cache_max_mib: Option<f64>,
    /// The most frames the localizer was behind the robot.
    pub max_lag_frames: u64,
    /// The estimates judged as `deog eval localize` judges them.
    pub report: LocalizationReport,
    /// Every estimate against the truth, lapses included.
    pub tracking: Tracking,
    /// Wall-clock seconds of the whole run.
    pub wall_s: f64,
    /// The work folder, when it is kept (--out).
    pub work: Option<PathBuf>,
    /// The command line of every process started, in order.
    pub commands: Vec<String>,
}

/// kB as MiB.
pub(super) fn mib(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

impl LocalizerMemoryFigures {
    /// The map held whole in the localizer, bytes.
    pub fn map_bytes(&self) -> u64 {
        self.tiles * self.tile_bytes as u64
    }

    /// The map held whole in the localizer against the cache budget.
    pub fn ratio(&self) -> f64 {
        self.map_bytes() as f64 / self.budget_bytes as f64
    }

    /// The localizer's peak: `VmHWM`, or a larger sampled `VmRSS`.
    pub fn peak_kb(&self) -> u64 {
        self.memory.hwm_kb.max(self.memory.peak_rss_kb)
    }

    /// Baseline plus budget, kB.
    pub fn allowed_kb(&self) -> u64 {
        self.baseline_kb + (self.budget_bytes / 1024) as u64
    }

    /// Whether the peak stayed within baseline plus budget.
    pub fn within(&self) -> bool {
        self.peak_kb() <= self.allowed_kb()
    }
}
