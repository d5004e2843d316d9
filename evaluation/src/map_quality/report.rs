//! [`MapQuality`] as markdown tables for people and as JSON for tools
//! ([`MapQualityRecord`], serialised with serde). The JSON names are an
//! interface.

use std::fmt::Write as _;

use serde::Serialize;

use super::{Confusion, FREE_BELOW, MapQuality, OCCUPIED_ABOVE, ratio};
use crate::localization::pretty;

/// [`MapQuality`] as JSON shows it, under the names of the
/// [module docs](super).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[allow(missing_docs)] // Each field is the figure of that name.
pub struct MapQualityRecord {
    pub resolution_m: f64,
    pub robot_radius_m: f64,
    pub seeds_given: u64,
    pub seeds_used: u64,
    pub cells_observed: u64,
    pub cells_correct: u64,
    pub cells_uncertain: u64,
    pub fraction_correct: f64,
    pub map_occupied: u64,
    pub map_occupied_near_truth: u64,
    pub occupied_precision: Option<f64>,
    pub surface_cells: u64,
    pub surface_cells_found: u64,
    pub occupied_recall: Option<f64>,
    pub surface_cells_observed: u64,
    pub surface_cells_observed_found: u64,
    pub observed_occupied_recall: Option<f64>,
    pub reachable_cells: u64,
    pub reachable_cells_free: u64,
    pub coverage: Option<f64>,
    pub confusion: Confusion,
    pub occupied_above: f64,
    pub free_below: f64,
}

impl MapQuality {
    /// One JSON object: every count, and the four fractions (`null` when
    /// undefined), under the names of the module docs
    /// ([`MapQualityRecord`]).
    pub fn to_json(&self) -> String {
        pretty(&self.record())
    }

    /// The figures' JSON form, to be put in a larger document.
    pub fn record(&self) -> MapQualityRecord {
        MapQualityRecord {
            resolution_m: self.resolution_m,
            robot_radius_m: self.robot_radius_m,
            seeds_given: self.seeds_given,
            seeds_used: self.seeds_used,
            cells_observed: self.cells_observed(),
            cells_correct: self.cells_correct(),
            cells_uncertain: self.cells_uncertain(),
            fraction_correct: self.fraction_correct(),
            map_occupied: self.map_occupied,
            map_occupied_near_truth: self.map_occupied_near_truth,
            occupied_precision: self.occupied_precision(),
            surface_cells: self.surface_cells,
            surface_cells_found: self.surface_cells_found,
            occupied_recall: self.occupied_recall(),
            surface_cells_observed: self.surface_cells_observed,
            surface_cells_observed_found: self.surface_cells_observed_found,
            observed_occupied_recall: self.observed_occupied_recall(),
            reachable_cells: self.reachable_cells,
            reachable_cells_free: self.reachable_cells_free,
            coverage: self.coverage(),
            confusion: self.confusion,
            occupied_above: OCCUPIED_ABOVE,
            free_below: FREE_BELOW,
        }
    }

    /// The figures as markdown tables: the summary, then the confusion
    /// counts.
    pub fn table(&self) -> String {
        let observed = self.cells_observed();
        let mut out = String::new();
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "map quality: {} m cells, robot radius {} m, {} of {} seeds used\n",
            self.resolution_m, self.robot_radius_m, self.seeds_used, self.seeds_given
        );
        let _ = writeln!(out, "| figure | value | cells |");
        let _ = writeln!(out, "|---|---:|---:|");
        let _ = writeln!(out, "| cells observed | {observed} | |");
        let rows = [
            (
                "fraction correct",
                Some(self.fraction_correct()),
                self.cells_correct(),
                observed,
            ),
            (
                "uncertain",
                ratio(self.cells_uncertain(), observed),
                self.cells_uncertain(),
                observed,
            ),
            (
                "occupied precision (±1 cell)",
                self.occupied_precision(),
                self.map_occupied_near_truth,
                self.map_occupied,
            ),
            (
                "occupied recall (±1 cell)",
                self.occupied_recall(),
                self.surface_cells_found,
                self.surface_cells,
            ),
            (
                "occupied recall of observed walls (±1 cell)",
                self.observed_occupied_recall(),
                self.surface_cells_observed_found,
                self.surface_cells_observed,
            ),
            (
                "coverage of reachable free space",
                self.coverage(),
                self.reachable_cells_free,
                self.reachable_cells,
            ),
        ];
        for (name, value, part, whole) in rows {
            let value = value.map_or_else(|| "n/a".to_string(), |v| format!("{v:.4}"));
            let _ = writeln!(out, "| {name} | {value} | {part} of {whole} |");
        }
        let c = &self.confusion;
        let _ = writeln!(out, "\n| truth \\ map | free | occupied | uncertain |");
        let _ = writeln!(out, "|---|---:|---:|---:|");
        let _ = writeln!(
            out,
            "| free | {} | {} | {} |",
            c.free_as_free, c.free_as_occupied, c.free_as_uncertain
        );
        let _ = writeln!(
            out,
            "| occupied | {} | {} | {} |",
            c.occupied_as_free, c.occupied_as_occupied, c.occupied_as_uncertain
        );
        out
    }
}
