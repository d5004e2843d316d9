//! Rasterising a sonar cone: every cell whose centre lies in a circular
//! sector, each visited once, row by row.
//!
//! Rows are clipped to the sector analytically (a disk and two half-planes
//! give an interval of columns per row), so the cost is the sector's cells,
//! not its bounding box's. A final per-cell test, shared with the reference
//! implementation, decides membership so both agree exactly on boundaries.

use crate::cell::{CellBox, CellIndex, Resolution};
use crate::error::GridError;
use crate::pose::Pose2;

/// A circular sector: the cone of a sonar out to some radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sector {
    /// Apex (the sensor), metres, world frame.
    pub apex_x: f64,
    /// Apex, metres, world frame.
    pub apex_y: f64,
    /// Axis heading, radians, counter-clockwise from +x.
    pub heading: f64,
    /// Half the opening angle, radians, in (0, π/2).
    pub half_angle: f64,
    /// Metres.
    pub radius: f64,
}

/// The offsets of a point from a sector's apex, in the sector's own frame.
#[derive(Debug, Clone, Copy)]
pub struct LocalPoint {
    /// Along the axis, metres.
    pub along: f64,
    /// Across the axis (left positive), metres.
    pub across: f64,
}

impl Sector {
    /// The cone of a sensor at `pose` out to `radius`.
    pub fn from_pose(pose: &Pose2, half_angle: f64, radius: f64) -> Self {
        Self {
            apex_x: pose.x,
            apex_y: pose.y,
            heading: pose.theta,
            half_angle,
            radius,
        }
    }

    /// Whether a point, given as offsets from the apex in the sector's frame,
    /// lies inside: in front, within the half-angle, within the radius.
    #[inline]
    pub fn contains_local(&self, p: LocalPoint, tan_half_angle: f64) -> bool {
        p.along >= 0.0
            && p.across.abs() <= p.along * tan_half_angle
            && p.along * p.along + p.across * p.across <= self.radius * self.radius
    }

    /// The smallest box of cells holding every cell whose centre lies in the
    /// sector, plus a one-cell margin.
    pub fn cell_box(&self, res: Resolution) -> Result<CellBox, GridError> {
        let (ax, ay) = (self.apex_x, self.apex_y);
        // Extreme points: the apex, both ends of the arc, and the arc's
        // points along ±x and ±y where they fall inside the cone.
        let (mut min_x, mut min_y, mut max_x, mut max_y) = (ax, ay, ax, ay);
        let mut include = |angle: f64| {
            let (x, y) = (
                ax + self.radius * angle.cos(),
                ay + self.radius * angle.sin(),
            );
            (min_x, max_x) = (min_x.min(x), max_x.max(x));
            (min_y, max_y) = (min_y.min(y), max_y.max(y));
        };
        include(self.heading - self.half_angle);
        include(self.heading + self.half_angle);
        for k in 0..4 {
            let angle = f64::from(k) * std::f64::consts::FRAC_PI_2;
            if crate::pose::normalize_angle(angle - self.heading).abs() <= self.half_angle {
                include(angle);
            }
        }
        let m = res.metres();
        let min = res.cell_of(min_x - m, min_y - m)?;
        let max = res.cell_of(max_x + m, max_y + m)?;
        Ok(CellBox { min, max })
    }

    /// Calls `visit(cell, local)` for every cell whose centre lies in the
    /// sector, once each, where `local` is the centre's offset from the apex
    /// in the sector's frame (see [`LocalPoint::distance`] and
    /// [`LocalPoint::angle`]).
    ///
    /// The caller must have checked the sector's [`Sector::cell_box`], which
    /// bounds every visited cell and fails for absurd coordinates.
    pub fn for_each_cell(
        &self,
        res: Resolution,
        bounds: &CellBox,
        mut visit: impl FnMut(CellIndex, LocalPoint),
    ) {
        let m = res.metres();
        let (sin, cos) = self.heading.sin_cos();
        let tan_half = self.half_angle.tan();
        let (left_sin, left_cos) = (self.heading + self.half_angle).sin_cos();
        let (right_sin, right_cos) = (self.heading - self.half_angle).sin_cos();
        let radius_sq = self.radius * self.radius;
        // Widening of each row's interval, so that rounding never drops a
        // cell; the exact test below removes what it lets in.
        const SLACK: f64 = 1e-9;
        for row in bounds.min.y..=bounds.max.y {
            let dy = (f64::from(row) + 0.5) * m - self.apex_y;
            let half_chord_sq = radius_sq - dy * dy;
            if half_chord_sq < 0.0 {
                continue;
            }
            let half_chord = half_chord_sq.sqrt();
            let (mut lo, mut hi) = (-half_chord, half_chord);
            // Left of the right edge and right of the left edge, each a
            // constraint `a · dx <= b` on this row.
            for (a, b) in [(right_sin, right_cos * dy), (-left_sin, -left_cos * dy)] {
                if a > 1e-12 {
                    hi = hi.min(b / a);
                } else if a < -1e-12 {
                    lo = lo.max(b / a);
                } else if b < -SLACK {
                    hi = f64::NEG_INFINITY;
                }
            }
            if lo > hi + SLACK {
                continue;
            }
            let first = ((self.apex_x + lo - SLACK) / m - 0.5)
                .ceil()
                .max(f64::from(bounds.min.x)) as i32;
            let last = ((self.apex_x + hi + SLACK) / m - 0.5)
                .floor()
                .min(f64::from(bounds.max.x)) as i32;
            if first > last {
                continue;
            }
            // Walk the row incrementally in the sector's frame.
            let dx = (f64::from(first) + 0.5) * m - self.apex_x;
            let mut local = LocalPoint {
                along: dx * cos + dy * sin,
                across: dy * cos - dx * sin,
            };
            let (step_along, step_across) = (m * cos, -m * sin);
            for col in first..=last {
                if self.contains_local(local, tan_half) {
                    visit(CellIndex::new(col, row), local);
                }
                local.along += step_along;
                local.across += step_across;
            }
        }
    }
}

impl LocalPoint {
    /// Distance from the apex, metres.
    #[inline]
    pub fn distance(self) -> f64 {
        (self.along * self.along + self.across * self.across).sqrt()
    }

    /// Angle off the axis, radians, in [0, π/2] for points in front.
    #[inline]
    pub fn angle(self) -> f64 {
        if self.along > 0.0 {
            atan_fast(self.across.abs() / self.along)
        } else if self.across == 0.0 {
            // The apex itself lies on the axis.
            0.0
        } else {
            std::f64::consts::FRAC_PI_2
        }
    }
}

/// `atan(t)` for `t >= 0`, within 1e-7 rad: the odd polynomial of
/// Abramowitz and Stegun 4.4.49 on [0, 1], and atan(t) = π/2 − atan(1/t) beyond.
#[inline]
pub fn atan_fast(t: f64) -> f64 {
    const C: [f64; 8] = [
        -0.333_331_452_8,
        0.199_935_508_5,
        -0.142_088_994_4,
        0.106_562_639_3,
        -0.075_289_640_0,
        0.042_909_613_8,
        -0.016_165_736_7,
        0.002_866_225_7,
    ];
    let (x, flip) = if t > 1.0 { (1.0 / t, true) } else { (t, false) };
    let x2 = x * x;
    let series = C.iter().rev().fold(0.0, |acc, c| acc * x2 + c);
    let poly = x + x * x2 * series;
    if flip {
        std::f64::consts::FRAC_PI_2 - poly
    } else {
        poly
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::HashSet;

    #[test]
    fn atan_fast_is_accurate() {
        for i in 0..=10_000 {
            let t = f64::from(i) / 1000.0;
            assert!((atan_fast(t) - t.atan()).abs() < 1e-7, "{t}");
        }
    }

    fn brute_force(sector: &Sector, res: Resolution, bounds: &CellBox) -> HashSet<CellIndex> {
        let (sin, cos) = sector.heading.sin_cos();
        let tan_half = sector.half_angle.tan();
        let mut cells = HashSet::new();
        for y in bounds.min.y - 3..=bounds.max.y + 3 {
            for x in bounds.min.x - 3..=bounds.max.x + 3 {
                let (cx, cy) = res.cell_center(CellIndex::new(x, y));
                let (dx, dy) = (cx - sector.apex_x, cy - sector.apex_y);
                let p = LocalPoint {
                    along: dx * cos + dy * sin,
                    across: dy * cos - dx * sin,
                };
                if sector.contains_local(p, tan_half) {
                    cells.insert(CellIndex::new(x, y));
                }
            }
        }
        cells
    }

    proptest! {
        /// The row-clipped walk visits exactly the cells a brute-force scan
        /// of a wider box finds, each once, with r and α right.
        #[test]
        fn visits_exactly_the_cells_in_the_sector(
            x in -50.0f64..50.0, y in -50.0f64..50.0, heading in -7.0f64..7.0,
            half_angle in 0.05f64..1.4, radius in 0.0f64..6.0,
        ) {
            let res = Resolution::DEFAULT;
            let sector = Sector { apex_x: x, apex_y: y, heading, half_angle, radius };
            let bounds = sector.cell_box(res).unwrap();
            let mut seen = Vec::new();
            sector.for_each_cell(res, &bounds, |cell, local| {
                let (cx, cy) = res.cell_center(cell);
                let (r, alpha) = (local.distance(), local.angle());
                assert!((r - (cx - x).hypot(cy - y)).abs() < 1e-9);
                assert!(alpha >= 0.0 && alpha <= half_angle + 1e-7, "alpha {alpha} beta {half_angle}");
                seen.push(cell);
            });
            let unique: HashSet<_> = seen.iter().copied().collect();
            prop_assert_eq!(unique.len(), seen.len(), "a cell was visited twice");
            prop_assert_eq!(unique, brute_force(&sector, res, &bounds));
        }
    }
}
