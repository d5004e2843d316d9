//! Everything `deog bench laser-mapping` measured: the table it prints and
//! the JSON `--json` writes.
//!
//! The JSON's keys are stable; `octomap`, `ratio` and `agreement` are
//! `null` (and `octomap_skipped` says why) when OctoMap's side did not run.
//!
//! - `config`: `log`, `laser`, `beams_per_scan`, `echoes_per_pass` (beams
//!   with a return, the points OctoMap gets), `scans_per_pass`, `passes`,
//!   `resolution_m`, `max_range_m` (the rays' cut on both sides), `prob_hit`,
//!   `prob_miss`, `clamp_min`, `clamp_max` (probabilities).
//! - `deog`: `scans`, `cell_updates` (cells touched, one per cell per
//!   scan), `seconds`, `scans_per_s`, `cell_updates_per_s` (integration and
//!   application together: what OctoMap's insertion also does),
//!   `integrate_s`, `integrate_scans_per_s`, `integrate_cell_updates_per_s`,
//!   `apply_s`, `apply_cell_updates_per_s`, `pass_seconds`,
//!   `observed_cells`, `tiles`.
//! - `octomap`: `python`, `numpy`, `octomap` (versions), `scans`,
//!   `seconds` (insertion only), `scans_per_s`, `cell_updates_per_s`
//!   (deog's count of the cells the same scans touch over OctoMap's time:
//!   the API does not count its own updates), `pass_seconds`,
//!   `leaf_cells`, `tree_nodes`, `memory_bytes`.
//! - `ratio`: `scans_per_s` (deog's over OctoMap's, integration and
//!   application against insertion; the cell rates' ratio is the same),
//!   `integrate_scans_per_s` (deog's integration alone over OctoMap's).
//! - `agreement`: `deog_cells`, `octomap_cells`, `both_observed`, `alike`,
//!   `share_alike` (alike over both observed), `occupied_deog`,
//!   `occupied_octomap`, `occupied_both`, `occupied_iou`, `deog_only`,
//!   `octomap_only` (see `agreement`: occupied means log-odds ≥ 0).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use serde::Serialize;

use super::agreement::Agreement;
use super::deog_side::DeogRun;
use crate::octomap::OctomapRun;

/// The settings of a run, as reported.
#[derive(Debug, Clone, Serialize)]
pub(super) struct ConfigRecord {
    pub log: String,
    pub laser: String,
    pub beams_per_scan: usize,
    pub echoes_per_pass: u64,
    pub scans_per_pass: usize,
    pub passes: u32,
    pub resolution_m: f64,
    pub max_range_m: f64,
    pub prob_hit: f64,
    pub prob_miss: f64,
    pub clamp_min: f64,
    pub clamp_max: f64,
}

/// Everything measured in one run.
pub(super) struct LaserMappingFigures {
    /// The settings.
    pub config: ConfigRecord,
    /// deog's side.
    pub deog: DeogRun,
    /// OctoMap's side, or why it did not run.
    pub octomap: Result<OctomapRun, String>,
    /// The maps compared, when both ran.
    pub agreement: Option<Agreement>,
}

#[derive(Serialize)]
struct LaserMappingRecord<'a> {
    config: &'a ConfigRecord,
    deog: DeogRecord,
    octomap: Option<OctomapRecord<'a>>,
    octomap_skipped: Option<&'a str>,
    ratio: Option<RatioRecord>,
    agreement: Option<AgreementRecord>,
}

#[derive(Serialize)]
struct DeogRecord {
    scans: u64,
    cell_updates: u64,
    seconds: f64,
    scans_per_s: f64,
    cell_updates_per_s: f64,
    integrate_s: f64,
    integrate_scans_per_s: f64,
    integrate_cell_updates_per_s: f64,
    apply_s: f64,
    apply_cell_updates_per_s: f64,
    pass_seconds: Vec<f64>,
    observed_cells: u64,
    tiles: u64,
}

#[derive(Serialize)]
struct OctomapRecord<'a> {
    python: &'a str,
    numpy: &'a str,
    octomap: &'a str,
    scans: u64,
    seconds: f64,
    scans_per_s: f64,
    cell_updates_per_s: f64,
    pass_seconds: Vec<f64>,
    leaf_cells: u64,
    tree_nodes: u64,
    memory_bytes: u64,
}

#[derive(Serialize)]
struct RatioRecord {
    scans_per_s: f64,
    integrate_scans_per_s: f64,
}

#[derive(Serialize)]
struct AgreementRecord {
    deog_cells: u64,
    octomap_cells: u64,
    both_observed: u64,
    alike: u64,
    share_alike: Option<f64>,
    occupied_deog: u64,
    occupied_octomap: u64,
    occupied_both: u64,
    occupied_iou: Option<f64>,
    deog_only: u64,
    octomap_only: u64,
}

/// `n / seconds`, 0 for no time.
fn rate(n: u64, seconds: f64) -> f64 {
    if seconds > 0.0 {
        n as f64 / seconds
    } else {
        0.0
    }
}

/// `x` rounded to `decimals` places.
fn round(x: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (x * scale).round() / scale
}

/// `x` in millions, as the table shows cell rates.
fn millions(x: f64) -> String {
    format!("{:.2} M", x / 1e6)
}

impl LaserMappingFigures {
    fn deog_scans_per_s(&self) -> f64 {
        rate(self.deog.scans, self.deog.seconds())
    }

    fn deog_integrate_scans_per_s(&self) -> f64 {
        rate(self.deog.scans, self.deog.integrate_s)
    }

    fn octomap_scans_per_s(run: &OctomapRun) -> f64 {
        rate(run.report.scans, run.report.seconds)
    }

    /// The figures as a Markdown table, a line on the settings first and
    /// the maps' agreement after.
    pub fn table(&self) -> String {
        let c = &self.config;
        let d = &self.deog;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "\nlaser mapping: {}, {} {} scans x {} pass(es), {} beams ({} with a return per pass), {} m cells, rays cut at {} m, hit {} miss {}, clamp {}..{}",
            c.log,
            c.scans_per_pass,
            c.laser,
            c.passes,
            c.beams_per_scan,
            c.echoes_per_pass,
            c.resolution_m,
            c.max_range_m,
            c.prob_hit,
            c.prob_miss,
            c.clamp_min,
            c.clamp_max
        );
        let _ = writeln!(
            out,
            "\n| side | scans/s | cell updates/s | seconds | scans |"
        );
        let _ = writeln!(out, "|---|---|---|---|---|");
        let _ = writeln!(
            out,
            "| deog: integrate + apply, 1 thread | {:.1} | {} | {:.3} | {} |",
            self.deog_scans_per_s(),
            millions(rate(d.cell_updates, d.seconds())),
            d.seconds(),
            d.scans
        );
        let _ = writeln!(
            out,
            "| deog: integrate only | {:.1} | {} | {:.3} | {} |",
            self.deog_integrate_scans_per_s(),
            millions(rate(d.cell_updates, d.integrate_s)),
            d.integrate_s,
            d.scans
        );
        let _ = writeln!(
            out,
            "| deog: apply only | {:.1} | {} | {:.3} | {} |",
            rate(d.scans, d.apply_s),
            millions(rate(d.cell_updates, d.apply_s)),
            d.apply_s,
            d.scans
        );
        match &self.octomap {
            Ok(o) => {
                let r = &o.report;
                let _ = writeln!(
                    out,
                    "| OctoMap {} insertPointCloud (Python {}) | {:.1} | {} | {:.3} | {} |",
                    r.versions.octomap,
                    r.versions.python,
                    Self::octomap_scans_per_s(o),
                    millions(rate(d.cell_updates, r.seconds)),
                    r.seconds,
                    r.scans
                );
                let _ = writeln!(
                    out,
                    "\ndeog / OctoMap: {:.2}x scans/s (integration alone: {:.2}x); OctoMap's cell rate is deog's count of the cells the same scans touch over OctoMap's time",
                    self.deog_scans_per_s() / Self::octomap_scans_per_s(o),
                    self.deog_integrate_scans_per_s() / Self::octomap_scans_per_s(o)
                );
                let _ = writeln!(
                    out,
                    "OctoMap's tree: {} leaves, {} nodes, {:.1} MB; deog's map: {} cells observed in {} tiles",
                    r.leaf_cells,
                    r.tree_nodes,
                    r.memory_bytes as f64 / 1e6,
                    d.map.observed_count(),
                    d.map.tile_count()
                );
            }
            Err(reason) => {
                let _ = writeln!(out, "\nOctoMap: not run: {reason}");
            }
        }
        if let Some(a) = &self.agreement {
            let percent =
                |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{:.2} %", x * 100.0));
            let _ = writeln!(
                out,
                "map agreement: {} cells both observed, {} classified alike (occupied: deog {}, OctoMap {}, both {}, overlap {}); deog only {}, OctoMap only {}",
                a.both_observed,
                percent(a.share_alike()),
                a.occupied_deog,
                a.occupied_octomap,
                a.occupied_both,
                percent(a.occupied_iou()),
                a.deog_only(),
                a.octomap_only()
            );
        }
        out
    }

    /// The figures as pretty JSON (keys in the module docs).
    pub fn json(&self) -> Result<String> {
        let d = &self.deog;
        let octomap = self.octomap.as_ref().ok();
        let record = LaserMappingRecord {
            config: &self.config,
            deog: DeogRecord {
                scans: d.scans,
                cell_updates: d.cell_updates,
                seconds: round(d.seconds(), 6),
                scans_per_s: round(self.deog_scans_per_s(), 1),
                cell_updates_per_s: round(rate(d.cell_updates, d.seconds()), 0),
                integrate_s: round(d.integrate_s, 6),
                integrate_scans_per_s: round(self.deog_integrate_scans_per_s(), 1),
                integrate_cell_updates_per_s: round(rate(d.cell_updates, d.integrate_s), 0),
                apply_s: round(d.apply_s, 6),
                apply_cell_updates_per_s: round(rate(d.cell_updates, d.apply_s), 0),
                pass_seconds: d.pass_seconds.iter().map(|&s| round(s, 6)).collect(),
                observed_cells: d.map.observed_count() as u64,
                tiles: d.map.tile_count() as u64,
            },
            octomap: octomap.map(|o| OctomapRecord {
                python: &o.report.versions.python,
                numpy: &o.report.versions.numpy,
                octomap: &o.report.versions.octomap,
                scans: o.report.scans,
                seconds: round(o.report.seconds, 6),
                scans_per_s: round(Self::octomap_scans_per_s(o), 1),
                cell_updates_per_s: round(rate(d.cell_updates, o.report.seconds), 0),
                pass_seconds: o.report.pass_seconds.iter().map(|&s| round(s, 6)).collect(),
                leaf_cells: o.report.leaf_cells,
                tree_nodes: o.report.tree_nodes,
                memory_bytes: o.report.memory_bytes,
            }),
            octomap_skipped: self.octomap.as_ref().err().map(String::as_str),
            ratio: octomap.map(|o| RatioRecord {
                scans_per_s: round(self.deog_scans_per_s() / Self::octomap_scans_per_s(o), 3),
                integrate_scans_per_s: round(
                    self.deog_integrate_scans_per_s() / Self::octomap_scans_per_s(o),
                    3,
                ),
            }),
            agreement: self.agreement.map(|a| AgreementRecord {
                deog_cells: a.deog_cells,
                octomap_cells: a.octomap_cells,
                both_observed: a.both_observed,
                alike: a.alike,
                share_alike: a.share_alike().map(|x| round(x, 6)),
                occupied_deog: a.occupied_deog,
                occupied_octomap: a.occupied_octomap,
                occupied_both: a.occupied_both,
                occupied_iou: a.occupied_iou().map(|x| round(x, 6)),
                deog_only: a.deog_only(),
                octomap_only: a.octomap_only(),
            }),
        };
        serde_json::to_string_pretty(&record).context("writing the figures as JSON")
    }
}
