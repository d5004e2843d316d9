//! The analytical sonar model of the thesis (eqs. 3.1 to 3.4, after Murphy),
//! turning one range reading into log-odds deltas for the cells of its cone.
//!
//! For a cell at distance `r` from the sensor and angle `α` off its axis,
//! with `R` the maximum range and `β` the cone's half-angle, let
//! `u = ((R − r)/R + (β − α)/β) / 2`. Then, for a reading `d`:
//! - Region I, `|r − d| ≤ tolerance` (probably occupied):
//!   `P(occupied) = u · Max_occupied` (eq. 3.1), where the angle factor
//!   may be given other values on the axis and at the edge
//!   ([`SonarModelParams::occupied_axis_factor`]): a specular sonar's
//!   echoes come from the cone's edges more than from its axis;
//! - Region II, `r < d − tolerance` (probably empty): `P(empty) = u` (eq. 3.4);
//! - Region III, beyond: no information, no delta.
//!
//! Two guards keep the regions honest where the formula alone would not:
//! a region I cell never gets `P(occupied) < 0.5` (it would be pushed towards
//! empty), and a region II cell never gets `P(empty) < 0.5` (it would be
//! pushed towards occupied) nor above `max_empty` (eq. 3.4 reaches 1 at the
//! sensor, an infinite log-odds). Each probability becomes the log-odds
//! delta `ln(P(occ) / (1 − P(occ)))`, which the Bayes update of eq. 3.13
//! adds.
//!
//! Optionally, beliefs too weak to matter are not recorded: a region II
//! cell whose `P(empty)` falls below `min_empty`, or a region I cell whose
//! `P(occupied)` falls below `min_occupied`, is left alone, as unobserved.
//! The far, off-axis part of a cone says almost nothing, and recording it
//! would only mark cells observed that stay undecided. At 0.5 (the
//! default) every belief the equations give is recorded.
//!
//! A reading at or past `R` is no echo: nothing was hit within range. It adds
//! no region I; its cone is marked empty out to `no_echo_free_range` only,
//! since sonar loses echoes off walls struck at a grazing angle and a long
//! free ray would cut through them. Set it to 0 to ignore such readings.
//!
//! A cone can be guarded by the map it writes to
//! (`SonarModel::visit_cone_guarded`): along each direction of the cone,
//! evidence stops at the first cell the map already holds as a wall. The
//! wall cell gets no empty evidence, and cells behind it get none at all.
//! A sonar misses a wall it meets at a grazing angle and hears something
//! farther through it; the plain model would then erase, one reading at a
//! time, the wall that many head-on echoes built.
//!
//! Any cone can be cut at `max_mapped_range`: an echo farther than that
//! marks its cone empty out to it and adds no region I. Far readings say
//! least (eq. 3.4 weakens with range) and are the likeliest to be lost
//! echoes or thrown by a small heading error; nearer readings map the cells
//! they would have reached as the robot moves on.

use crate::cell::{CellBox, CellIndex, Resolution};
use crate::error::{GridError, within};
use crate::log_odds::{LOG_ODDS_SCALE, logit};
use crate::pose::Pose2;
use crate::sector::{LocalPoint, Sector};

/// What a guarded cone asks of the map it writes to.
pub trait ConeGuard {
    /// Whether `cell` hides what lies behind it: a cone's evidence stops
    /// a cell past it.
    fn shadows(&self, cell: CellIndex) -> bool;
    /// Whether `cell` is a wall no reading may free. A kept cell must
    /// also shadow.
    fn keeps(&self, cell: CellIndex) -> bool;
}

/// Directions a guarded cone is split into, evenly in `tan α` across the
/// cone: about half a degree each for the Scout's 30° cone, finer than a
/// 5 cm cell seen from 5 m.
const GUARD_BINS: usize = 64;

/// Every figure of the sonar model; the defaults are the Scout's Polaroid
/// 6500 ranging modules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarModelParams {
    /// `R`: the largest range the sonar reports, metres (35 ft).
    pub max_range: f64,
    /// The smallest range the sonar reports, metres (6 in); shorter readings
    /// are taken as this.
    pub min_range: f64,
    /// `β`: half the cone's opening angle, radians.
    pub half_angle: f64,
    /// Half the depth of region I around the reading, metres.
    pub region_i_tolerance: f64,
    /// `Max_occupied`: the strongest belief one reading gives a region I cell.
    pub max_occupied: f64,
    /// Region I's angle factor on the cone's axis: eq. 3.1's `(β − α)/β`
    /// generalized to `a₀ + (a₁ − a₀) α/β`, with this as `a₀`. The thesis's
    /// sonar (`a₀` 1, `a₁` 0) believes an echo came from along its axis.
    pub occupied_axis_factor: f64,
    /// Region I's angle factor at the cone's edge, `a₁`. A specular sonar
    /// hears a flat wall only within its critical angle, from the nearest
    /// point of the cone: a wall turned more than the half-angle from square
    /// (two thirds of the walls it hears, with a 30° critical angle and a
    /// 15° half-angle) echoes from the cone's edge, so its echoes come
    /// from the edges more than from the axis.
    pub occupied_edge_factor: f64,
    /// The weakest belief worth recording for a region I cell: where
    /// `P(occupied)` falls below it the reading leaves the cell alone.
    /// 0.5 records every belief the equation gives.
    pub min_occupied: f64,
    /// The strongest belief one reading gives a region II cell.
    pub max_empty: f64,
    /// The weakest belief worth recording for a region II cell: where
    /// `P(empty)` falls below it (far out, near the cone's edge) the reading
    /// leaves the cell as if it had not seen it. 0.5 records every belief
    /// the equation gives.
    pub min_empty: f64,
    /// How far a no-echo reading marks its cone empty, metres; 0 ignores
    /// no-echo readings.
    pub no_echo_free_range: f64,
    /// How far any reading's cone reaches, metres: cells farther than
    /// this are left to nearer readings. The maximum range reaches all.
    pub max_mapped_range: f64,
    /// How far a reading's empty evidence reaches, metres; its region I
    /// is still marked out to `max_mapped_range`. A specular sonar's echo
    /// may come from past a wall it glanced off, and the farther a cell,
    /// the likelier such a wall stands before it. The maximum range (the
    /// default) frees the whole region II.
    pub max_free_range: f64,
}

impl Default for SonarModelParams {
    fn default() -> Self {
        Self {
            max_range: 10.668,
            min_range: 0.1524,
            half_angle: 15f64.to_radians(),
            region_i_tolerance: 0.05,
            max_occupied: 0.98,
            occupied_axis_factor: 1.0,
            occupied_edge_factor: 0.0,
            min_occupied: 0.5,
            max_empty: 0.98,
            min_empty: 0.5,
            no_echo_free_range: 3.0,
            max_mapped_range: 10.668,
            max_free_range: 10.668,
        }
    }
}

impl SonarModelParams {
    /// Checks every figure is finite and sensible.
    pub fn validate(&self) -> Result<Self, GridError> {
        within("max_range", self.max_range, 0.01, 1000.0)?;
        within("min_range", self.min_range, 0.0, self.max_range)?;
        within("half_angle", self.half_angle, 1e-3, 80f64.to_radians())?;
        within(
            "region_i_tolerance",
            self.region_i_tolerance,
            0.0,
            self.max_range,
        )?;
        within("max_occupied", self.max_occupied, 0.5, 0.9999)?;
        within("occupied_axis_factor", self.occupied_axis_factor, 0.0, 1.0)?;
        within("occupied_edge_factor", self.occupied_edge_factor, 0.0, 1.0)?;
        within("max_empty", self.max_empty, 0.5, 0.9999)?;
        within("min_empty", self.min_empty, 0.5, self.max_empty)?;
        within("min_occupied", self.min_occupied, 0.5, self.max_occupied)?;
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
        within("max_free_range", self.max_free_range, 0.0, self.max_range)?;
        Ok(*self)
    }
}

/// Which region of the model a cell falls in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Region {
    /// Around the reading: probably occupied.
    Occupied,
    /// Between the sensor and region I: probably empty.
    Empty,
}

/// A validated reading, ready to rasterise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The range in metres, raised to the minimum range.
    pub range: f64,
    /// Whether this is an echo (`false`: no echo within the maximum range).
    pub echo: bool,
    /// The cone's extent for this reading, metres.
    pub extent: f64,
}

/// Number of steps of `u` in the delta tables.
const TABLE_STEPS: usize = 2048;

/// The sonar model with its log-odds tables built.
#[derive(Debug, Clone)]
pub struct SonarModel {
    params: SonarModelParams,
    inv_max_range: f64,
    inv_half_angle: f64,
    tan_half_angle: f64,
    // Fixed-point deltas at evenly spaced `u`, interpolated linearly:
    // a logarithm per cell would cost more than the rest of the cell.
    occupied_table: Box<[f32]>,
    empty_table: Box<[f32]>,
    // `α / (2β)` at evenly spaced `tan α` in [0, tan β], for the same reason.
    angle_table: Box<[f64]>,
    angle_table_scale: f64,
    // Region I's angle factor as a loss from 1: `1 − a₀ + (a₀ − a₁) α/β`
    // (for the thesis's factors exactly `α/β`, as region II's).
    occupied_loss_at_axis: f64,
    occupied_loss_slope: f64,
}

impl SonarModel {
    /// The model for validated parameters.
    pub fn new(params: SonarModelParams) -> Result<Self, GridError> {
        let params = params.validate()?;
        // The tables leave out the floors, steps that linear interpolation
        // would smear: `delta_for_strength` applies them exactly.
        let unfloored = SonarModelParams {
            min_occupied: 0.5,
            min_empty: 0.5,
            ..params
        };
        let table = |region| {
            (0..=TABLE_STEPS)
                .map(|i| exact_delta(&unfloored, region, i as f64 / TABLE_STEPS as f64) as f32)
                .collect()
        };
        Ok(Self {
            params,
            inv_max_range: 1.0 / params.max_range,
            inv_half_angle: 1.0 / params.half_angle,
            tan_half_angle: params.half_angle.tan(),
            occupied_table: table(Region::Occupied),
            empty_table: table(Region::Empty),
            angle_table: (0..=TABLE_STEPS)
                .map(|i| {
                    let tan = params.half_angle.tan() * i as f64 / TABLE_STEPS as f64;
                    0.5 * tan.atan() / params.half_angle
                })
                .collect(),
            angle_table_scale: TABLE_STEPS as f64 / params.half_angle.tan(),
            occupied_loss_at_axis: 1.0 - params.occupied_axis_factor,
            occupied_loss_slope: params.occupied_axis_factor - params.occupied_edge_factor,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &SonarModelParams {
        &self.params
    }

    /// Checks a range and decides how far its cone reaches.
    pub fn reading(&self, range: f64) -> Result<Reading, GridError> {
        let range = within("range", range, 0.0, f64::MAX)?.max(self.params.min_range);
        Ok(if range >= self.params.max_range {
            self.no_echo_at(range)
        } else {
            self.echo_at(range)
        })
    }

    /// A reading already judged an echo (by a rig, say), at `range`
    /// metres raised to the minimum range and lowered to the maximum: an
    /// echo even at the maximum range, where [`Self::reading`] would say
    /// no echo.
    pub fn echo(&self, range: f64) -> Result<Reading, GridError> {
        let p = &self.params;
        let range = within("range", range, 0.0, f64::MAX)?.clamp(p.min_range, p.max_range);
        Ok(self.echo_at(range))
    }

    /// A reading already judged no echo.
    pub fn no_echo(&self) -> Reading {
        self.no_echo_at(self.params.max_range)
    }

    #[inline]
    fn echo_at(&self, range: f64) -> Reading {
        let p = &self.params;
        Reading {
            range,
            echo: true,
            extent: (range + p.region_i_tolerance)
                .min(p.max_range)
                .min(p.max_mapped_range),
        }
    }

    #[inline]
    fn no_echo_at(&self, range: f64) -> Reading {
        let p = &self.params;
        Reading {
            range,
            echo: false,
            extent: p.no_echo_free_range.min(p.max_mapped_range),
        }
    }

    /// The region of a cell at distance `r` for `reading`; `None` past the cone.
    #[inline]
    pub fn region(&self, reading: &Reading, r: f64) -> Option<Region> {
        if r > reading.extent {
            None
        } else if reading.echo && r >= reading.range - self.params.region_i_tolerance {
            Some(Region::Occupied)
        } else if r > self.params.max_free_range {
            None
        } else {
            Some(Region::Empty)
        }
    }

    /// The thesis's `u` for a cell of `region`: the mean of the range and
    /// angle factors, in [0, 1]; region I's angle factor as its parameters
    /// say ([`SonarModelParams::occupied_axis_factor`]).
    #[inline]
    pub fn strength(&self, region: Region, r: f64, alpha: f64) -> f64 {
        let angle = alpha * self.inv_half_angle;
        (1.0 - 0.5 * (r * self.inv_max_range + self.angle_loss(region, angle))).clamp(0.0, 1.0)
    }

    /// One minus the angle factor of `region` at `angle` (`α/β`, or any
    /// fraction of it: the loss is linear).
    #[inline]
    fn angle_loss(&self, region: Region, angle: f64) -> f64 {
        match region {
            Region::Occupied => self.occupied_loss_at_axis + self.occupied_loss_slope * angle,
            Region::Empty => angle,
        }
    }

    /// The probability of occupancy one reading gives a cell in `region`
    /// at distance `r` and angle `alpha`, exactly as the equations say (with
    /// the guards described in the module docs).
    pub fn probability(&self, region: Region, r: f64, alpha: f64) -> f64 {
        occupied_probability(&self.params, region, self.strength(region, r, alpha))
    }

    /// The fixed-point log-odds delta for a cell, from the tables.
    #[inline]
    pub fn delta(&self, region: Region, r: f64, alpha: f64) -> i16 {
        self.delta_for_strength(region, self.strength(region, r, alpha))
    }

    #[inline]
    fn delta_for_strength(&self, region: Region, u: f64) -> i16 {
        let table = match region {
            Region::Occupied if u * self.params.max_occupied < self.params.min_occupied => {
                return 0;
            }
            Region::Occupied => &self.occupied_table,
            Region::Empty if u < self.params.min_empty => return 0,
            Region::Empty => &self.empty_table,
        };
        let (i, frac) = table_position(u * TABLE_STEPS as f64);
        let value = table[i] + (table[i + 1] - table[i]) * frac as f32;
        // Round half away from zero without a libm call.
        (value + 0.5f32.copysign(value)) as i16
    }

    /// `u` for a point of `region` in a cone's own frame, angle from the
    /// table.
    #[inline]
    fn local_strength(&self, region: Region, local: LocalPoint, r: f64) -> f64 {
        // Half of α/β, as the table holds it.
        let half_angle = if local.along > 0.0 {
            let (i, frac) =
                table_position(local.across.abs() / local.along * self.angle_table_scale);
            self.angle_table[i] + (self.angle_table[i + 1] - self.angle_table[i]) * frac
        } else {
            0.0
        };
        let half_loss = match region {
            Region::Occupied => {
                0.5 * self.occupied_loss_at_axis + self.occupied_loss_slope * half_angle
            }
            Region::Empty => half_angle,
        };
        (1.0 - 0.5 * r * self.inv_max_range - half_loss).clamp(0.0, 1.0)
    }

    /// The sector a reading from a sensor at `sensor` covers.
    pub fn sector(&self, sensor: &Pose2, reading: &Reading) -> Sector {
        Sector::from_pose(sensor, self.params.half_angle, reading.extent)
    }

    /// Calls `visit(cell, delta)` for every cell of the cone of a reading
    /// `range` taken by a sensor at `sensor` (world frame), once each, with
    /// its nonzero log-odds delta. Fails, visiting nothing, on a non-finite
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
        if reading.extent <= 0.0 {
            return Ok(());
        }
        let sector = self.sector(&sensor, &reading);
        let bounds = sector.cell_box(res)?;
        self.visit_cone(&sector, &reading, res, &bounds, visit);
        Ok(())
    }

    /// The cell walk of [`Self::for_each_cell`] for a sector and bounds the
    /// caller has already built and checked from a valid reading.
    pub(crate) fn visit_cone(
        &self,
        sector: &Sector,
        reading: &Reading,
        res: Resolution,
        bounds: &CellBox,
        mut visit: impl FnMut(CellIndex, i16),
    ) {
        self.walk_cone(sector, reading, res, bounds, |cell, _, _, delta| {
            visit(cell, delta)
        });
    }

    /// Calls `visit(cell, local, r, delta)` for every cell of the cone
    /// with a nonzero delta: its place in the cone's frame, its distance
    /// from the apex and its delta.
    #[inline]
    fn walk_cone(
        &self,
        sector: &Sector,
        reading: &Reading,
        res: Resolution,
        bounds: &CellBox,
        mut visit: impl FnMut(CellIndex, LocalPoint, f64, i16),
    ) {
        // The sector ends at the reading's extent, so every visited cell is
        // in region I or II: only the boundary between them is tested here.
        let max_free = self.params.max_free_range;
        let region_i_start = if reading.echo {
            reading.range - self.params.region_i_tolerance
        } else {
            f64::INFINITY
        };
        sector.for_each_cell(res, bounds, |cell, local| {
            let r = local.distance();
            let region = if r >= region_i_start {
                Region::Occupied
            } else if r > max_free {
                return;
            } else {
                Region::Empty
            };
            let delta = self.delta_for_strength(region, self.local_strength(region, local, r));
            if delta != 0 {
                visit(cell, local, r, delta);
            }
        });
    }

    /// [`Self::visit_cone`] guarded by the map it writes to: along each
    /// direction of the cone, cells more than a cell behind the nearest
    /// one `guard` says shadows get no evidence, and a cell it keeps gets
    /// no empty evidence. An echo off a wall still marks it (its region I
    /// lies within a cell of it); a reading that passed it (a specular
    /// miss, a multipath echo) changes nothing behind it.
    pub(crate) fn visit_cone_guarded(
        &self,
        sector: &Sector,
        reading: &Reading,
        res: Resolution,
        bounds: &CellBox,
        guard: &dyn ConeGuard,
        mut visit: impl FnMut(CellIndex, i16),
    ) {
        let cell = res.metres();
        let tan_half = self.tan_half_angle;
        let bins = GUARD_BINS as f64;
        let bin_of = |tan: f64| -> f64 { (tan / tan_half + 1.0) * 0.5 * bins };
        // The nearest wall along each direction.
        let mut shadow = [f64::INFINITY; GUARD_BINS];
        let mut any_wall = false;
        sector.for_each_cell(res, bounds, |index, local| {
            if local.along <= 0.0 || !guard.shadows(index) {
                return;
            }
            any_wall = true;
            let r = local.distance();
            let tan = local.across / local.along;
            // The cell's half-width seen from the apex, in tan α (d tan α =
            // (1 + tan²α) dα), a little more than half a cell's diagonal.
            let half = 0.75 * cell / r * (1.0 + tan * tan);
            let first = bin_of(tan - half).floor().max(0.0) as usize;
            let last = (bin_of(tan + half).floor().min(bins - 1.0)).max(0.0) as usize;
            for slot in &mut shadow[first.min(GUARD_BINS - 1)..=last] {
                *slot = slot.min(r);
            }
        });
        if !any_wall {
            self.visit_cone(sector, reading, res, bounds, visit);
            return;
        }
        self.walk_cone(sector, reading, res, bounds, |index, local, r, delta| {
            if local.along > 0.0 {
                let bin = (bin_of(local.across / local.along).floor().max(0.0) as usize)
                    .min(GUARD_BINS - 1);
                // Behind the nearest shadowing cell: an echo off it may
                // still mark the next cell (region I's tolerance), nothing
                // frees it.
                if r > shadow[bin] + cell || (delta < 0 && r > shadow[bin] + 0.5 * cell) {
                    return;
                }
            }
            if delta < 0 && guard.keeps(index) {
                return;
            }
            visit(index, delta);
        });
    }

    /// The plain way: every cell of the cone's bounding box, angle by
    /// `atan2` and delta by `ln`, with no tables and no row clipping. The
    /// reference the fast path is tested against, and the benchmark baseline.
    pub fn for_each_cell_reference(
        &self,
        sensor: &Pose2,
        range: f64,
        res: Resolution,
        mut visit: impl FnMut(CellIndex, i16),
    ) -> Result<(), GridError> {
        let sensor = sensor.validate("sensor pose")?;
        let reading = self.reading(range)?;
        if reading.extent <= 0.0 {
            return Ok(());
        }
        let sector = self.sector(&sensor, &reading);
        let bounds = sector.cell_box(res)?;
        for y in bounds.min.y..=bounds.max.y {
            for x in bounds.min.x..=bounds.max.x {
                let cell = CellIndex::new(x, y);
                let (cx, cy) = res.cell_center(cell);
                let (dx, dy) = (cx - sensor.x, cy - sensor.y);
                let alpha = crate::pose::normalize_angle(dy.atan2(dx) - sensor.theta).abs();
                // Membership by the same test the fast path uses, so the two
                // agree on cells whose centres lie on the cone's edge.
                let exact = LocalPoint {
                    along: dx * sensor.theta.cos() + dy * sensor.theta.sin(),
                    across: dy * sensor.theta.cos() - dx * sensor.theta.sin(),
                };
                if !sector.contains_local(exact, self.tan_half_angle) {
                    continue;
                }
                let r = dx.hypot(dy);
                if let Some(region) = self.region(&reading, r) {
                    let p = self.probability(region, r, alpha);
                    let delta = (logit(p) * LOG_ODDS_SCALE).round() as i16;
                    if delta != 0 {
                        visit(cell, delta);
                    }
                }
            }
        }
        Ok(())
    }
}

/// Eqs. 3.1 and 3.3–3.4 with their guards, as a probability of occupancy.
fn occupied_probability(p: &SonarModelParams, region: Region, u: f64) -> f64 {
    match region {
        Region::Occupied if u * p.max_occupied < p.min_occupied => 0.5,
        Region::Occupied => (u * p.max_occupied).max(0.5),
        Region::Empty if u < p.min_empty => 0.5,
        Region::Empty => 1.0 - u.clamp(0.5, p.max_empty),
    }
}

/// The table index below `pos` and the fraction past it, kept inside the table.
#[inline]
fn table_position(pos: f64) -> (usize, f64) {
    let pos = pos.clamp(0.0, TABLE_STEPS as f64);
    let i = (pos as usize).min(TABLE_STEPS - 1);
    (i, pos - i as f64)
}

fn exact_delta(p: &SonarModelParams, region: Region, u: f64) -> f64 {
    logit(occupied_probability(p, region, u)) * LOG_ODDS_SCALE
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::HashMap;

    fn model() -> SonarModel {
        SonarModel::new(SonarModelParams::default()).unwrap()
    }

    fn cells(model: &SonarModel, pose: Pose2, range: f64) -> HashMap<CellIndex, i16> {
        let mut out = HashMap::new();
        model
            .for_each_cell(&pose, range, Resolution::DEFAULT, |cell, delta| {
                assert!(
                    out.insert(cell, delta).is_none(),
                    "cell {cell:?} visited twice"
                );
            })
            .unwrap();
        out
    }

    #[test]
    fn thesis_equations_on_the_axis() {
        let m = model();
        let p = m.params();
        // Eq. 3.1 on the axis at 2 m: ((R - r)/R + 1) / 2 * Max_occupied.
        let expected = ((p.max_range - 2.0) / p.max_range + 1.0) / 2.0 * p.max_occupied;
        assert!((m.probability(Region::Occupied, 2.0, 0.0) - expected).abs() < 1e-12);
        // Eq. 3.4 at 2 m, half-way to the cone's edge.
        let beta = p.half_angle;
        let empty = ((p.max_range - 2.0) / p.max_range + 0.5) / 2.0;
        assert!((m.probability(Region::Empty, 2.0, beta / 2.0) - (1.0 - empty)).abs() < 1e-12);
    }

    #[test]
    fn guards_keep_each_region_on_its_side() {
        let m = model();
        let beta = m.params().half_angle;
        // Far and at the edge, eq. 3.1 alone would fall below 0.5.
        assert_eq!(m.probability(Region::Occupied, 10.0, beta), 0.5);
        assert_eq!(m.probability(Region::Empty, 10.0, beta), 0.5);
        // At the sensor eq. 3.4 reaches 1; the cap keeps log-odds finite.
        assert!((m.probability(Region::Empty, 0.0, 0.0) - 0.02).abs() < 1e-12);
    }

    #[test]
    fn regions_of_a_reading_at_two_metres() {
        let m = model();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let deltas = cells(&m, pose, 2.0);
        let res = Resolution::DEFAULT;
        let tol = m.params().region_i_tolerance;
        assert!(deltas.values().any(|&d| d > 0) && deltas.values().any(|&d| d < 0));
        for (cell, delta) in &deltas {
            let (cx, cy) = res.cell_center(*cell);
            let r = cx.hypot(cy);
            assert!(r <= 2.0 + tol + 1e-9, "cell beyond region I at {r}");
            if r < 2.0 - tol {
                assert!(*delta < 0, "region II cell at {r} pushed towards occupied");
            } else {
                assert!(*delta > 0, "region I cell at {r} pushed towards empty");
            }
        }
        // The strongest occupied cell lies on the axis, at the near edge of region I.
        let (best, _) = deltas.iter().max_by_key(|(_, d)| **d).unwrap();
        let (bx, by) = res.cell_center(*best);
        assert!(
            by.abs() < res.metres(),
            "strongest cell off the axis: {best:?}"
        );
        assert!(
            (bx - (2.0 - tol)).abs() <= res.metres(),
            "strongest cell at {bx}"
        );
    }

    #[test]
    fn region_i_angle_factors_move_the_strongest_belief_to_the_edges() {
        let edges = SonarModel::new(SonarModelParams {
            occupied_axis_factor: 0.4,
            occupied_edge_factor: 1.0,
            ..SonarModelParams::default()
        })
        .unwrap();
        let p = edges.params();
        let (r, beta) = (2.0, p.half_angle);
        let range_factor = (p.max_range - r) / p.max_range;
        // Eq. 3.1 with the factor 0.4 on the axis, 1 at the edge, linear.
        for (alpha, factor) in [(0.0, 0.4), (beta / 2.0, 0.7), (beta, 1.0)] {
            let expected = (range_factor + factor) / 2.0 * p.max_occupied;
            let got = edges.probability(Region::Occupied, r, alpha);
            assert!(
                (got - expected).abs() < 1e-12,
                "{alpha}: {got} vs {expected}"
            );
        }
        // Region II keeps the thesis's factor.
        assert_eq!(
            edges.probability(Region::Empty, r, beta / 2.0),
            model().probability(Region::Empty, r, beta / 2.0)
        );
        // On a cone, the strongest occupied cell lies at an edge.
        let res = Resolution::DEFAULT;
        let deltas = cells(&edges, Pose2::new(0.0, 0.0, 0.0), r);
        let (best, _) = deltas.iter().max_by_key(|(_, d)| **d).unwrap();
        let (bx, by) = res.cell_center(*best);
        let off_axis = by.atan2(bx).abs();
        assert!(
            off_axis > 0.8 * beta,
            "strongest cell {off_axis} rad off the axis"
        );
        // Factors outside [0, 1] are refused.
        for bad in [-0.1, 1.1, f64::NAN] {
            let params = SonarModelParams {
                occupied_edge_factor: bad,
                ..SonarModelParams::default()
            };
            assert!(SonarModel::new(params).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn no_echo_marks_free_space_only_out_to_its_limit() {
        let m = model();
        let deltas = cells(&m, Pose2::new(1.0, -2.0, 1.0), 50.0);
        assert!(!deltas.is_empty());
        let limit = m.params().no_echo_free_range;
        for (cell, delta) in &deltas {
            let (cx, cy) = Resolution::DEFAULT.cell_center(*cell);
            assert!(*delta < 0);
            assert!((cx - 1.0).hypot(cy + 2.0) <= limit + 1e-9);
        }
        let ignoring = SonarModel::new(SonarModelParams {
            no_echo_free_range: 0.0,
            ..SonarModelParams::default()
        })
        .unwrap();
        assert!(cells(&ignoring, Pose2::default(), m.params().max_range).is_empty());
    }

    #[test]
    fn bad_readings_and_parameters_are_errors() {
        let m = model();
        let res = Resolution::DEFAULT;
        for range in [f64::NAN, f64::INFINITY, -0.5] {
            assert!(
                m.for_each_cell(&Pose2::default(), range, res, |_, _| {})
                    .is_err()
            );
        }
        let far = Pose2::new(1e15, 0.0, 0.0);
        assert!(m.for_each_cell(&far, 1.0, res, |_, _| {}).is_err());
        let bad = SonarModelParams {
            max_occupied: 1.0,
            ..SonarModelParams::default()
        };
        assert!(SonarModel::new(bad).is_err());
        let bad = SonarModelParams {
            half_angle: f64::NAN,
            ..SonarModelParams::default()
        };
        assert!(SonarModel::new(bad).is_err());
    }

    #[test]
    fn short_readings_count_as_the_minimum_range() {
        let m = model();
        assert_eq!(m.reading(0.01).unwrap().range, m.params().min_range);
    }

    #[test]
    fn judged_readings_agree_with_raw_ones() {
        let m = model();
        for range in [0.0, 0.01, 0.5, 3.0, 10.0, 10.6] {
            assert_eq!(m.echo(range).unwrap(), m.reading(range).unwrap(), "{range}");
        }
        let none = m.reading(50.0).unwrap();
        assert_eq!(
            (m.no_echo().echo, m.no_echo().extent),
            (none.echo, none.extent)
        );
        // An echo at the maximum range stays an echo when judged so.
        let edge = m.echo(20.0).unwrap();
        assert!(edge.echo);
        assert_eq!(edge.range, m.params().max_range);
        assert!(m.echo(f64::NAN).is_err() && m.echo(-1.0).is_err());
    }

    #[test]
    fn belief_floors_leave_weak_cells_alone() {
        let floored = SonarModel::new(SonarModelParams {
            min_empty: 0.6,
            min_occupied: 0.55,
            ..SonarModelParams::default()
        })
        .unwrap();
        let beta = floored.params().half_angle;
        let plain = model();
        // Eq. 3.4 at 8 m on the axis: P(empty) = 0.625, kept; at 4 m
        // half-way to the edge, 0.5625: recorded without the floor only.
        assert!((floored.probability(Region::Empty, 8.0, 0.0) - 0.375).abs() < 0.01);
        assert!(floored.delta(Region::Empty, 8.0, 0.0) < 0);
        assert!(plain.delta(Region::Empty, 4.0, beta / 2.0) < 0);
        assert_eq!(floored.probability(Region::Empty, 4.0, beta / 2.0), 0.5);
        assert_eq!(floored.delta(Region::Empty, 4.0, beta / 2.0), 0);
        // Eq. 3.1 with Max_occupied 0.98 at 4 m half-way: 0.98 · 0.5625 =
        // 0.55125, kept; further off the axis (0.98 · 0.5125 = 0.502),
        // recorded without the floor only.
        assert!(floored.delta(Region::Occupied, 4.0, beta / 2.0) > 0);
        assert!(plain.delta(Region::Occupied, 4.0, 0.6 * beta) > 0);
        assert_eq!(floored.delta(Region::Occupied, 4.0, 0.6 * beta), 0);
    }

    #[test]
    fn cones_end_at_the_mapped_range() {
        let near = SonarModel::new(SonarModelParams {
            max_mapped_range: 5.0,
            ..SonarModelParams::default()
        })
        .unwrap();
        let pose = Pose2::new(0.5, -1.0, 0.3);
        let res = Resolution::DEFAULT;
        let reach = 5.0 + res.metres();
        let distance = |cell: &CellIndex| {
            let (x, y) = res.cell_center(*cell);
            (x - pose.x).hypot(y - pose.y)
        };
        // A far echo: region II out to 5 m only, and no region I.
        let far = cells(&near, pose, 8.0);
        assert!(!far.is_empty());
        assert!(far.keys().all(|c| distance(c) <= reach));
        assert!(far.values().all(|&d| d < 0));
        // Within 5 m the cells and deltas are the unlimited model's.
        let plain = cells(&model(), pose, 8.0);
        for (cell, d) in plain
            .iter()
            .filter(|(c, _)| distance(c) < 5.0 - res.metres())
        {
            assert_eq!(far.get(cell), Some(d), "{cell:?}");
        }
        // A near echo is untouched.
        assert_eq!(cells(&near, pose, 3.0), cells(&model(), pose, 3.0));
        // No echo: still at most no_echo_free_range (3 m) here.
        let none = cells(&near, pose, 50.0);
        assert!(none.keys().all(|c| distance(c) <= 3.0 + res.metres()));
    }

    #[test]
    fn empty_evidence_ends_at_the_free_range_and_the_echo_is_still_marked() {
        let short = SonarModel::new(SonarModelParams {
            max_free_range: 1.0,
            ..SonarModelParams::default()
        })
        .unwrap();
        let pose = Pose2::new(-0.2, 0.4, 1.1);
        let res = Resolution::DEFAULT;
        let distance = |cell: &CellIndex| {
            let (x, y) = res.cell_center(*cell);
            (x - pose.x).hypot(y - pose.y)
        };
        let cut = cells(&short, pose, 3.0);
        let plain = cells(&model(), pose, 3.0);
        assert!(cut.iter().all(|(c, &d)| d > 0 || distance(c) <= 1.0));
        // Region I and the empty cells within 1 m are the plain model's.
        for (cell, d) in &plain {
            if *d > 0 || distance(cell) <= 1.0 {
                assert_eq!(cut.get(cell), Some(d), "{cell:?}");
            }
        }
        assert!(cut.values().any(|&d| d > 0) && cut.values().any(|&d| d < 0));
        let bad = SonarModelParams {
            max_free_range: -1.0,
            ..SonarModelParams::default()
        };
        assert!(SonarModel::new(bad).is_err());
    }

    #[test]
    fn floors_out_of_range_are_refused() {
        for (min_empty, min_occupied) in [
            (0.49, 0.5),
            (0.99, 0.5),
            (0.5, 0.4),
            (0.5, 0.99),
            (f64::NAN, 0.5),
        ] {
            let params = SonarModelParams {
                min_empty,
                min_occupied,
                ..SonarModelParams::default()
            };
            assert!(
                SonarModel::new(params).is_err(),
                "{min_empty} {min_occupied}"
            );
        }
    }

    proptest! {
        /// A floored model gives exactly the unfloored model's cells whose
        /// belief reaches the floor, with the same deltas, and drops only
        /// cells whose belief falls short of it.
        #[test]
        fn floors_only_drop_weak_cells(
            x in -5.0f64..5.0, y in -5.0f64..5.0, theta in -4.0f64..4.0, range in 0.0f64..12.0,
        ) {
            let plain = model();
            let floored = SonarModel::new(SonarModelParams {
                min_empty: 0.6,
                min_occupied: 0.55,
                ..SonarModelParams::default()
            })
            .unwrap();
            let pose = Pose2::new(x, y, theta);
            let all = cells(&plain, pose, range);
            let kept = cells(&floored, pose, range);
            let strength = |p: f64| (logit(p) * LOG_ODDS_SCALE).abs().round() as i32;
            for (cell, d) in &kept {
                prop_assert_eq!(all.get(cell), Some(d));
            }
            for (cell, d) in all.iter().filter(|(c, _)| !kept.contains_key(c)) {
                let floor = if *d < 0 { strength(0.6) } else { strength(0.55) };
                prop_assert!(i32::from(*d).abs() <= floor + 1, "{:?}: {} dropped", cell, d);
            }
        }

        /// The tabled, row-clipped path gives the cells and deltas of the
        /// plain trigonometric one, each delta within one fixed-point unit.
        #[test]
        fn fast_path_matches_reference(
            x in -20.0f64..20.0, y in -20.0f64..20.0, theta in -4.0f64..4.0, range in 0.0f64..12.0,
            axis in 0.0f64..=1.0, edge in 0.0f64..=1.0, thesis in proptest::bool::ANY,
        ) {
            let m = if thesis {
                model()
            } else {
                SonarModel::new(SonarModelParams {
                    occupied_axis_factor: axis,
                    occupied_edge_factor: edge,
                    ..SonarModelParams::default()
                })
                .unwrap()
            };
            let pose = Pose2::new(x, y, theta);
            let fast = cells(&m, pose, range);
            let mut reference = HashMap::new();
            m.for_each_cell_reference(&pose, range, Resolution::DEFAULT, |c, d| { reference.insert(c, d); }).unwrap();
            for (cell, d) in &reference {
                let f = fast.get(cell).copied().unwrap_or(0);
                prop_assert!((i32::from(f) - i32::from(*d)).abs() <= 1, "{cell:?}: {f} vs {d}");
            }
            for (cell, f) in &fast {
                let d = reference.get(cell).copied().unwrap_or(0);
                prop_assert!((i32::from(*f) - i32::from(d)).abs() <= 1, "{cell:?}: {f} vs {d}");
            }
        }
    }
}
