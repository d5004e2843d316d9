//! The inverse sensor model of a ray (a laser's beam): the cells the ray
//! crossed on its way to the echo are probably empty, the cell it ended in
//! probably occupied.
//!
//! Every cell the segment from the sensor to the echo passes through
//! ([`SegmentCells`], no gaps, no cell twice) gets the miss delta, except
//! the last, the echo's own cell, which gets the hit delta. The deltas are
//! constants, as in OctoMap: `ln(p / (1 − p))` of the hit and miss
//! probabilities, 0.7 and 0.4 by default (OctoMap's figures). A laser's
//! beam is narrow, so one reading's evidence does not fade across the beam
//! as a sonar's does.
//!
//! A reading at or past the maximum range is no echo: nothing was hit
//! within range. It marks its ray empty out to `no_echo_free_range` only,
//! and adds no hit; set it to 0 to ignore such readings (as OctoMap does
//! with a missing return).
//!
//! Any ray can be cut at `max_mapped_range`: an echo farther than that
//! marks its ray empty out to it and adds no hit, and cells beyond are left
//! alone. A long ray spends most of its cells far out, where a small
//! heading error moves it most.

use crate::cell::{CellBox, CellIndex, Resolution};
use crate::error::{GridError, within};
use crate::log_odds::{LOG_ODDS_SCALE, logit};
use crate::pose::Pose2;
use crate::segment_walk::SegmentCells;

/// Every figure of the ray model; the defaults are OctoMap's probabilities
/// and a SICK LMS 200's ranges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayModelParams {
    /// The largest range the sensor reports, metres.
    pub max_range: f64,
    /// The smallest range the sensor reports, metres; shorter echoes are
    /// taken as this.
    pub min_range: f64,
    /// `P(occupied)` one echo gives the cell it ended in (OctoMap's
    /// `prob_hit`, 0.7).
    pub hit_probability: f64,
    /// `P(occupied)` one reading gives each cell its ray crossed
    /// (OctoMap's `prob_miss`, 0.4).
    pub miss_probability: f64,
    /// How far a no-echo reading marks its ray empty, metres; 0 ignores
    /// no-echo readings.
    pub no_echo_free_range: f64,
    /// How far any reading's ray reaches, metres: cells farther than this
    /// are left alone, and an echo beyond it adds no hit. The maximum
    /// range reaches all.
    pub max_mapped_range: f64,
}

impl Default for RayModelParams {
    fn default() -> Self {
        Self {
            max_range: 50.0,
            min_range: 0.02,
            hit_probability: 0.7,
            miss_probability: 0.4,
            no_echo_free_range: 0.0,
            max_mapped_range: 50.0,
        }
    }
}

impl RayModelParams {
    /// Checks every figure is finite and sensible.
    pub fn validate(&self) -> Result<Self, GridError> {
        within("max_range", self.max_range, 0.01, 1000.0)?;
        within("min_range", self.min_range, 0.0, self.max_range)?;
        within("hit_probability", self.hit_probability, 0.5, 0.9999)?;
        within("miss_probability", self.miss_probability, 0.0001, 0.5)?;
        within(
            "no_echo_free_range",
            self.no_echo_free_range,
            0.0,
            self.max_range,
        )?;
        within(
            "max_mapped_range",
            self.max_mapped_range,
            0.0,
            self.max_range,
        )?;
        Ok(*self)
    }
}

/// A validated reading, ready to walk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayReading {
    /// How far the ray is walked, metres.
    pub extent: f64,
    /// Whether the cell at the end of the walk is the echo's (a hit);
    /// otherwise every cell walked is a miss.
    pub hit: bool,
}

/// The ray model with its deltas computed.
#[derive(Debug, Clone, PartialEq)]
pub struct RayModel {
    params: RayModelParams,
    hit: i16,
    miss: i16,
}

impl RayModel {
    /// The model for validated parameters.
    pub fn new(params: RayModelParams) -> Result<Self, GridError> {
        let params = params.validate()?;
        let delta = |p: f64| (logit(p) * LOG_ODDS_SCALE).round() as i16;
        Ok(Self {
            params,
            hit: delta(params.hit_probability),
            miss: delta(params.miss_probability),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &RayModelParams {
        &self.params
    }

    /// The fixed-point log-odds delta of the echo's cell (positive).
    pub fn hit_delta(&self) -> i16 {
        self.hit
    }

    /// The fixed-point log-odds delta of each cell the ray crossed
    /// (negative).
    pub fn miss_delta(&self) -> i16 {
        self.miss
    }

    /// Judges a raw range: at or past the maximum range, no echo; else an
    /// echo there (see [`Self::echo`]).
    pub fn reading(&self, range: f64) -> Result<RayReading, GridError> {
        let range = within("range", range, 0.0, f64::MAX)?;
        if range >= self.params.max_range {
            Ok(self.no_echo())
        } else {
            self.echo(range)
        }
    }

    /// An echo at `range` metres, raised to the minimum range and lowered
    /// to the maximum; the hit is kept only within the mapped range.
    pub fn echo(&self, range: f64) -> Result<RayReading, GridError> {
        let p = &self.params;
        let range = within("range", range, 0.0, f64::MAX)?.clamp(p.min_range, p.max_range);
        Ok(if range > p.max_mapped_range {
            RayReading {
                extent: p.max_mapped_range,
                hit: false,
            }
        } else {
            RayReading {
                extent: range,
                hit: true,
            }
        })
    }

    /// A reading that heard nothing: empty out to the no-echo range.
    pub fn no_echo(&self) -> RayReading {
        RayReading {
            extent: self
                .params
                .no_echo_free_range
                .min(self.params.max_mapped_range),
            hit: false,
        }
    }

    /// Whether a reading changes any cell.
    pub fn is_empty(&self, reading: &RayReading) -> bool {
        !reading.hit && (reading.extent <= 0.0 || self.miss == 0)
    }

    /// The walk of `reading`'s ray from a sensor at `sensor` (world frame)
    /// and the box of cells it stays in. Fails for coordinates beyond the
    /// grid.
    pub fn walk(
        &self,
        sensor: &Pose2,
        reading: &RayReading,
        res: Resolution,
    ) -> Result<(SegmentCells, CellBox), GridError> {
        let (sin, cos) = sensor.theta.sin_cos();
        let (x1, y1) = (
            sensor.x + reading.extent * cos,
            sensor.y + reading.extent * sin,
        );
        let start = res.cell_of(sensor.x, sensor.y)?;
        let end = res.cell_of(x1, y1)?;
        let bounds = CellBox {
            min: CellIndex::new(start.x.min(end.x), start.y.min(end.y)),
            max: CellIndex::new(start.x.max(end.x), start.y.max(end.y)),
        };
        Ok((SegmentCells::new(res, sensor.x, sensor.y, x1, y1)?, bounds))
    }

    /// Calls `visit(cell, delta)` for every cell of a walk of `reading`,
    /// once each, with its nonzero delta.
    #[inline]
    pub fn visit_walk(
        &self,
        cells: SegmentCells,
        reading: &RayReading,
        mut visit: impl FnMut(CellIndex, i16),
    ) {
        self.visit_runs(cells, reading, |run, delta| {
            for cell in run {
                visit(cell, delta);
            }
        });
    }

    /// The walk of `reading` as runs of cells sharing a delta: the free
    /// cells with the miss delta, then the echo's cell with the hit delta;
    /// `run(cells, delta)` is called for each with a nonzero delta. For
    /// callers that do better with a run than a cell at a time.
    #[inline]
    pub fn visit_runs(
        &self,
        mut cells: SegmentCells,
        reading: &RayReading,
        mut run: impl FnMut(std::iter::Take<&mut SegmentCells>, i16),
    ) {
        // A walk holds at least its start cell, so a hit always has its cell.
        let free = cells.len() - usize::from(reading.hit);
        if self.miss != 0 {
            run(cells.by_ref().take(free), self.miss);
        } else if free > 0 {
            cells.nth(free - 1);
        }
        if reading.hit && self.hit != 0 {
            run(cells.by_ref().take(1), self.hit);
        }
    }

    /// Calls `visit(cell, delta)` for every cell a reading `range` taken by
    /// a sensor at `sensor` (world frame) changes, once each, with its
    /// nonzero log-odds delta. Fails, visiting nothing, on a non-finite
    /// pose or range, or coordinates beyond the grid.
    pub fn for_each_cell(
        &self,
        sensor: &Pose2,
        range: f64,
        res: Resolution,
        visit: impl FnMut(CellIndex, i16),
    ) -> Result<(), GridError> {
        let sensor = sensor.validate("sensor pose")?;
        let reading = self.reading(range)?;
        if self.is_empty(&reading) {
            return Ok(());
        }
        let (cells, _) = self.walk(&sensor, &reading, res)?;
        self.visit_walk(cells, &reading, visit);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    const RES: Resolution = Resolution::DEFAULT;

    fn model() -> RayModel {
        RayModel::new(RayModelParams::default()).unwrap()
    }

    fn cells(model: &RayModel, pose: Pose2, range: f64) -> HashMap<CellIndex, i16> {
        let mut out = HashMap::new();
        model
            .for_each_cell(&pose, range, RES, |cell, delta| {
                assert!(out.insert(cell, delta).is_none(), "{cell:?} twice");
            })
            .unwrap();
        out
    }

    #[test]
    fn defaults_are_octomaps_probabilities() {
        let m = model();
        assert_eq!(m.hit_delta(), (logit(0.7) * 1000.0).round() as i16);
        assert_eq!(m.hit_delta(), 847);
        assert_eq!(m.miss_delta(), -405);
    }

    #[test]
    fn an_echo_frees_the_ray_and_hits_its_cell() {
        let m = model();
        let got = cells(&m, Pose2::new(0.01, 0.01, 0.0), 2.0);
        // 2.01 m lies in cell 40; cells 0 to 39 were crossed.
        assert_eq!(got.len(), 41);
        assert_eq!(got[&CellIndex::new(40, 0)], m.hit_delta());
        for x in 0..40 {
            assert_eq!(got[&CellIndex::new(x, 0)], m.miss_delta(), "cell {x}");
        }
    }

    #[test]
    fn no_echo_frees_out_to_its_limit_or_nothing() {
        let ignoring = model();
        assert!(cells(&ignoring, Pose2::default(), 50.0).is_empty());
        let freeing = RayModel::new(RayModelParams {
            no_echo_free_range: 3.0,
            ..RayModelParams::default()
        })
        .unwrap();
        let got = cells(&freeing, Pose2::new(0.01, 0.01, 0.0), 60.0);
        assert!(got.values().all(|&d| d == freeing.miss_delta()));
        assert_eq!(got.keys().map(|c| c.x).max(), Some(60));
        assert_eq!(got.len(), 61);
    }

    #[test]
    fn echoes_beyond_the_mapped_range_free_up_to_it() {
        let near = RayModel::new(RayModelParams {
            max_mapped_range: 5.0,
            ..RayModelParams::default()
        })
        .unwrap();
        let pose = Pose2::new(0.01, 0.01, 0.0);
        let far = cells(&near, pose, 8.0);
        assert!(far.values().all(|&d| d < 0));
        assert_eq!(far.keys().map(|c| c.x).max(), Some(100));
        assert_eq!(cells(&near, pose, 3.0), cells(&model(), pose, 3.0));
    }

    #[test]
    fn short_echoes_count_as_the_minimum_range() {
        let m = RayModel::new(RayModelParams {
            min_range: 0.5,
            ..RayModelParams::default()
        })
        .unwrap();
        let got = cells(&m, Pose2::new(0.01, 0.01, 0.0), 0.1);
        assert_eq!(got[&CellIndex::new(10, 0)], m.hit_delta());
        assert_eq!(got.len(), 11);
    }

    #[test]
    fn bad_readings_and_parameters_are_errors() {
        let m = model();
        for range in [f64::NAN, f64::INFINITY, -0.5] {
            assert!(
                m.for_each_cell(&Pose2::default(), range, RES, |_, _| {})
                    .is_err()
            );
        }
        assert!(
            m.for_each_cell(&Pose2::new(1e15, 0.0, 0.0), 1.0, RES, |_, _| {})
                .is_err()
        );
        for bad in [
            RayModelParams {
                hit_probability: 0.3,
                ..RayModelParams::default()
            },
            RayModelParams {
                miss_probability: 0.6,
                ..RayModelParams::default()
            },
            RayModelParams {
                max_mapped_range: 60.0,
                ..RayModelParams::default()
            },
            RayModelParams {
                no_echo_free_range: f64::NAN,
                ..RayModelParams::default()
            },
            RayModelParams {
                min_range: 51.0,
                ..RayModelParams::default()
            },
        ] {
            let err = RayModel::new(bad).unwrap_err();
            assert!(matches!(
                err,
                GridError::OutOfRange { .. } | GridError::NotFinite { .. }
            ));
        }
    }
}
