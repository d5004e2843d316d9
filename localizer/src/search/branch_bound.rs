//! Branch and bound over poses: every heading of a window, every
//! position of a window, scored coarse to fine on the [`SearchGrid`]'s
//! block maxima, so that whole blocks of positions that cannot beat the
//! best found so far are never scored one by one (the search of
//! Hess et al., "Real-time loop closure in 2D LIDAR SLAM", 2016).
//!
//! Unlike a matcher that wants the one best pose, this keeps every pose
//! within a share of the best ([`SearchSettings::keep_ratio`]) and then
//! the best of each region ([`SearchSettings::separation_m`]): a building
//! of look-alike rooms has several poses that explain a scan nearly as
//! well, and the filter must weigh all of them.

use std::cmp::Ordering;

use deog_grid::{Pose2, normalize_angle};

use super::cloud::ScanCloud;
use super::grid::SearchGrid;
use crate::error::{LocalizerError, within};

/// How a search runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSettings {
    /// Poses scoring below this (mean over readings, 0 to 1) are not
    /// hypotheses however they rank.
    pub min_score: f64,
    /// Poses scoring at least this share of the best are kept.
    pub keep_ratio: f64,
    /// Kept poses nearer than this to a better one are the same
    /// hypothesis, metres …
    pub separation_m: f64,
    /// … unless their headings differ by more than this, radians.
    pub separation_rad: f64,
    /// Most hypotheses returned, best first.
    pub max_hypotheses: usize,
    /// Largest heading step, radians; smaller when the scan reaches far
    /// (a step that moves the farthest point by at most a cell).
    pub max_angle_step: f64,
    /// Most point lookups (a candidate scored costs one per point of the
    /// cloud) one search may make past the coarsest level, which is
    /// scored whole (a few thousand blocks for a building): its cost is
    /// bounded whatever the map, about a second per 10⁹ on one core.
    pub budget: u64,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            min_score: 0.35,
            keep_ratio: 0.85,
            separation_m: 0.6,
            separation_rad: 0.5,
            max_hypotheses: 16,
            max_angle_step: 2f64.to_radians(),
            budget: 300_000_000,
        }
    }
}

impl SearchSettings {
    /// The settings if every figure is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        within("search min_score", self.min_score, 0.0, 1.0)?;
        within("search keep_ratio", self.keep_ratio, 0.0, 1.0)?;
        within("search separation_m", self.separation_m, 0.0, 100.0)?;
        within("search separation_rad", self.separation_rad, 0.0, 7.0)?;
        within("search max_angle_step", self.max_angle_step, 1e-4, 1.0)?;
        if self.max_hypotheses == 0 || self.budget == 0 {
            return Err(LocalizerError::Invalid(
                "a search needs at least one hypothesis and a budget above 0".into(),
            ));
        }
        Ok(self)
    }
}

/// Where to look.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SearchWindow {
    /// The whole grid, every heading.
    Global,
    /// Within `linear_m` of `around` in x and y, and `angular_rad` of its
    /// heading.
    Around {
        /// The pose the window is centred on.
        around: Pose2,
        /// Half the window's side, metres.
        linear_m: f64,
        /// Half the window's heading span, radians.
        angular_rad: f64,
    },
}

/// A pose that explains the scan, and how well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hypothesis {
    /// The robot's pose, world frame.
    pub pose: Pose2,
    /// Mean over the scan's readings of the best score of each, 0 to 1.
    pub score: f64,
}

/// What a search found.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchOutcome {
    /// The hypotheses, best first; empty when nothing reached the
    /// minimum score.
    pub hypotheses: Vec<Hypothesis>,
    /// Candidate scorings made.
    pub evaluations: u64,
    /// Point lookups made.
    pub lookups: u64,
    /// Whether the search ran to its end; false when its budget ran out
    /// first (what it found so far is still returned).
    pub complete: bool,
}

impl SearchOutcome {
    /// The best score over the best's: how nearly the runner-up explains
    /// the scan too (0 with fewer than two hypotheses).
    pub fn runner_up_ratio(&self) -> f64 {
        match self.hypotheses.as_slice() {
            [best, second, ..] if best.score > 0.0 => second.score / best.score,
            _ => 0.0,
        }
    }
}

/// The scan's points turned to one heading and put in cells, relative to
/// the cell the robot stands in.
#[derive(Debug, Clone)]
struct Turned {
    theta: f64,
    /// Each point's cell offset.
    cells: Vec<(i64, i64)>,
}

#[derive(Debug, Clone, Copy)]
struct Candidate {
    turn: usize,
    x: i64,
    y: i64,
    bound: f64,
}

/// Searches `grid` for the poses that best explain `cloud` within
/// `window`, to the end (or its budget) at once.
pub fn search(
    grid: &SearchGrid,
    cloud: &ScanCloud,
    window: SearchWindow,
    settings: &SearchSettings,
) -> Result<SearchOutcome, LocalizerError> {
    let mut job = SearchJob::new(grid, cloud.clone(), window, settings)?;
    job.run(grid, u64::MAX);
    Ok(job.finish())
}

/// A search that runs in slices: [`SearchJob::run`] works through it a
/// number of point lookups at a time, so that a filter beside it keeps
/// its frames' pace while a search of a whole building goes on over
/// several of them. Run on the grid it was made with, it finds what
/// [`search`] finds, however it is sliced.
#[derive(Debug, Clone)]
pub struct SearchJob {
    settings: SearchSettings,
    cloud: ScanCloud,
    turns: Vec<Turned>,
    x_max: i64,
    y_max: i64,
    /// Blocks still to look into, with their level; the best on top.
    stack: Vec<(Candidate, usize)>,
    found: Vec<Hypothesis>,
    best: f64,
    evaluations: u64,
    lookups: u64,
    /// Lookups at which the search stops splitting blocks.
    budget: u64,
    out_of_budget: bool,
}

impl SearchJob {
    /// A search of `grid` for `cloud` within `window`, its coarsest level
    /// scored (the whole of it, whatever the budget: a few thousand
    /// blocks for a building).
    pub fn new(
        grid: &SearchGrid,
        cloud: ScanCloud,
        window: SearchWindow,
        settings: &SearchSettings,
    ) -> Result<Self, LocalizerError> {
        let settings = settings.validate()?;
        let mut job = Self {
            settings,
            cloud,
            turns: Vec::new(),
            x_max: 0,
            y_max: 0,
            stack: Vec::new(),
            found: Vec::new(),
            best: 0.0,
            evaluations: 0,
            lookups: 0,
            budget: u64::MAX,
            out_of_budget: false,
        };
        if job.cloud.groups() == 0 {
            return Ok(job);
        }
        let cell = grid.cell_m();
        let reach = job.cloud.reach().max(cell);
        // A turn that moves the farthest point by at most one cell.
        let step = (1.0 - cell * cell / (2.0 * reach * reach))
            .clamp(-1.0, 1.0)
            .acos()
            .clamp(1e-4, settings.max_angle_step);
        let (width, height) = grid.size();
        let (thetas, x_range, y_range) = match window {
            SearchWindow::Global => {
                let n = (std::f64::consts::TAU / step).ceil() as usize;
                let thetas: Vec<f64> = (0..n)
                    .map(|i| normalize_angle(i as f64 * std::f64::consts::TAU / n as f64))
                    .collect();
                (thetas, (0, width as i64 - 1), (0, height as i64 - 1))
            }
            SearchWindow::Around {
                around,
                linear_m,
                angular_rad,
            } => {
                let around = around.validate("search window centre")?;
                within("search window linear_m", linear_m, 0.0, 1.0e4)?;
                within("search window angular_rad", angular_rad, 0.0, 4.0)?;
                let k = (angular_rad / step).ceil() as i64;
                let thetas = (-k..=k)
                    .map(|i| normalize_angle(around.theta + i as f64 * step))
                    .collect();
                let (cx, cy) = grid.cell_at(around.x, around.y);
                let r = (linear_m / cell).ceil() as i64;
                let x_range = ((cx - r).max(0), (cx + r).min(width as i64 - 1));
                let y_range = ((cy - r).max(0), (cy + r).min(height as i64 - 1));
                (thetas, x_range, y_range)
            }
        };
        if x_range.0 > x_range.1 || y_range.0 > y_range.1 {
            return Ok(job);
        }
        job.x_max = x_range.1;
        job.y_max = y_range.1;
        job.turns = thetas
            .iter()
            .map(|&theta| {
                let (s, c) = theta.sin_cos();
                let turn = |p: &[f64; 2]| {
                    let x = c * p[0] - s * p[1];
                    let y = s * p[0] + c * p[1];
                    // The robot stands at its cell's centre.
                    (
                        (x / cell + 0.5).floor() as i64,
                        (y / cell + 0.5).floor() as i64,
                    )
                };
                Turned {
                    theta,
                    cells: job.cloud.points().iter().map(turn).collect(),
                }
            })
            .collect();
        let top = grid.levels() - 1;
        let side = 1i64 << top;
        let mut candidates = Vec::new();
        for turn in 0..job.turns.len() {
            let mut y = y_range.0;
            while y <= y_range.1 {
                let mut x = x_range.0;
                while x <= x_range.1 {
                    candidates.push(Candidate {
                        turn,
                        x,
                        y,
                        bound: 0.0,
                    });
                    x += side;
                }
                y += side;
            }
        }
        job.bound_all(grid, &mut candidates, top);
        job.budget = job.lookups.saturating_add(settings.budget);
        // Best last: the stack pops it first.
        job.stack = candidates.into_iter().rev().map(|c| (c, top)).collect();
        Ok(job)
    }

    /// Works through the search for about `lookups` point lookups more
    /// (at least one block's split), on the grid it was made with.
    /// Returns whether it is done: run to its end, or out of its budget.
    pub fn run(&mut self, grid: &SearchGrid, lookups: u64) -> bool {
        let stop_at = self.lookups.saturating_add(lookups);
        while let Some((candidate, level)) = self.stack.pop() {
            if self.out_of_budget {
                break;
            }
            let threshold = self.threshold();
            if candidate.bound < threshold {
                // Every block below it on the stack was bounded before
                // the best grew: it is either lower (its siblings) or was
                // checked against a lower threshold; look at each.
                continue;
            }
            if level == 0 {
                // A leaf: its bound is its score, for a free cell.
                let (x, y) = grid.centre(candidate.x, candidate.y);
                self.best = self.best.max(candidate.bound);
                self.found.push(Hypothesis {
                    pose: Pose2::new(x, y, self.turns[candidate.turn].theta),
                    score: candidate.bound,
                });
                continue;
            }
            let half = 1i64 << (level - 1);
            let mut children = Vec::with_capacity(4);
            for (dx, dy) in [(0, 0), (half, 0), (0, half), (half, half)] {
                let (x, y) = (candidate.x + dx, candidate.y + dy);
                if x > self.x_max || y > self.y_max {
                    continue;
                }
                children.push(Candidate {
                    x,
                    y,
                    bound: 0.0,
                    ..candidate
                });
            }
            self.bound_all(grid, &mut children, level - 1);
            if self.out_of_budget {
                break;
            }
            self.stack
                .extend(children.into_iter().rev().map(|c| (c, level - 1)));
            if self.lookups >= stop_at {
                break;
            }
        }
        self.done()
    }

    /// Whether the search is over: nothing left to look into, or its
    /// budget spent.
    pub fn done(&self) -> bool {
        self.out_of_budget || self.stack.is_empty()
    }

    /// Point lookups made so far.
    pub fn lookups(&self) -> u64 {
        self.lookups
    }

    /// The cloud searched for.
    pub fn cloud(&self) -> &ScanCloud {
        &self.cloud
    }

    /// What the search found; called before it is done, what it found so
    /// far, as incomplete.
    pub fn finish(self) -> SearchOutcome {
        let settings = self.settings;
        let mut outcome = SearchOutcome {
            hypotheses: Vec::new(),
            evaluations: self.evaluations,
            lookups: self.lookups,
            complete: !self.out_of_budget && self.stack.is_empty(),
        };
        let threshold = self.threshold();
        let mut found = self.found;
        found.retain(|h| h.score >= threshold);
        found.sort_by(|a, b| b.score.partial_cmp(&a.score).unwrap_or(Ordering::Equal));
        for h in found {
            if outcome.hypotheses.len() >= settings.max_hypotheses {
                break;
            }
            let apart = outcome.hypotheses.iter().all(|kept| {
                let d = (kept.pose.x - h.pose.x).hypot(kept.pose.y - h.pose.y);
                d > settings.separation_m
                    || normalize_angle(kept.pose.theta - h.pose.theta).abs()
                        > settings.separation_rad
            });
            if apart {
                outcome.hypotheses.push(h);
            }
        }
        outcome
    }

    fn threshold(&self) -> f64 {
        self.settings
            .min_score
            .max(self.best * self.settings.keep_ratio)
    }

    /// The candidate's bound at `level`: the mean over readings of each
    /// reading's best block maximum; 0 for a block with no free cell.
    fn bound(&mut self, grid: &SearchGrid, c: &Candidate, level: usize) -> f64 {
        self.evaluations += 1;
        self.lookups += self.cloud.points().len() as u64;
        if self.lookups > self.budget {
            self.out_of_budget = true;
        }
        if !grid.any_free(level, c.x, c.y) {
            return 0.0;
        }
        let cells = &self.turns[c.turn].cells;
        let mut total = 0u64;
        for group in self.cloud.group_ranges() {
            let mut best = 0u8;
            for &(dx, dy) in &cells[group] {
                best = best.max(grid.score(level, c.x + dx, c.y + dy));
            }
            total += u64::from(best);
        }
        total as f64 / (255.0 * self.cloud.groups() as f64)
    }

    /// Bounds every candidate at `level` and sorts them best first.
    fn bound_all(&mut self, grid: &SearchGrid, candidates: &mut [Candidate], level: usize) {
        for c in candidates.iter_mut() {
            c.bound = self.bound(grid, c, level);
        }
        candidates.sort_by(|a, b| b.bound.partial_cmp(&a.bound).unwrap_or(Ordering::Equal));
    }
}

/// Scores `pose` as the search would at its finest level: the mean over
/// the cloud's readings of each reading's best point score, 0 to 1.
pub fn score_pose(grid: &SearchGrid, cloud: &ScanCloud, pose: &Pose2) -> f64 {
    if cloud.groups() == 0 {
        return 0.0;
    }
    let (s, c) = pose.theta.sin_cos();
    let cell_of = |p: &[f64; 2]| {
        let x = pose.x + c * p[0] - s * p[1];
        let y = pose.y + s * p[0] + c * p[1];
        grid.cell_at(x, y)
    };
    let mut total = 0u64;
    for group in cloud.group_ranges() {
        let best = cloud.points()[group]
            .iter()
            .map(|p| {
                let (x, y) = cell_of(p);
                grid.score(0, x, y)
            })
            .max()
            .unwrap_or(0);
        total += u64::from(best);
    }
    total as f64 / (255.0 * cloud.groups() as f64)
}
