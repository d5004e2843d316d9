//! Ray and cone casting on an occupancy grid: the range a sensor would read
//! from a pose, for the localizer's beam model and for tests.

use crate::cell::{CellIndex, Resolution};
use crate::error::{GridError, within};
use crate::log_odds::LogOdds;
use crate::pose::Pose2;
use crate::sector::Sector;

/// What a map says of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Occupancy {
    /// Never observed, or observed without a conclusion.
    Unknown,
    /// Probably empty.
    Free,
    /// Probably occupied.
    Occupied,
}

/// Anything that can say whether a cell is occupied.
pub trait OccupancyView {
    /// The state of `cell`.
    fn occupancy(&self, cell: CellIndex) -> Occupancy;
}

/// The probabilities separating occupied, unknown and free cells; the
/// defaults are ROS map_server's (0.65 and 0.196).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OccupancyThresholds {
    occupied: LogOdds,
    free: LogOdds,
}

impl OccupancyThresholds {
    /// ROS map_server's `occupied_thresh`, the default occupied threshold.
    pub const DEFAULT_OCCUPIED: f64 = 0.65;

    /// ROS map_server's `free_thresh`, the default free threshold.
    pub const DEFAULT_FREE: f64 = 0.196;

    /// Cells above `occupied` are occupied, below `free` free.
    pub fn new(occupied: f64, free: f64) -> Result<Self, GridError> {
        within("occupied_thresh", occupied, 0.5, 1.0)?;
        within("free_thresh", free, 0.0, 0.5)?;
        Ok(Self {
            occupied: LogOdds::from_probability(occupied)?,
            free: LogOdds::from_probability(free)?,
        })
    }

    /// The belief above which a cell is occupied.
    pub fn occupied(&self) -> LogOdds {
        self.occupied
    }

    /// The belief below which a cell is free.
    pub fn free(&self) -> LogOdds {
        self.free
    }

    /// The state of a cell holding `belief`.
    pub fn classify(&self, belief: Option<LogOdds>) -> Occupancy {
        match belief {
            Some(b) if b > self.occupied => Occupancy::Occupied,
            Some(b) if b < self.free => Occupancy::Free,
            _ => Occupancy::Unknown,
        }
    }
}

impl Default for OccupancyThresholds {
    fn default() -> Self {
        Self::new(Self::DEFAULT_OCCUPIED, Self::DEFAULT_FREE)
            .expect("map_server's thresholds are valid")
    }
}

/// The distance along a ray from `(x, y)` heading `angle` to the first
/// occupied cell it enters, walking cells in order (Amanatides and Woo);
/// `None` if none lies within `max_range` metres. A ray starting inside an
/// occupied cell reads 0.
pub fn cast_ray(
    view: &impl OccupancyView,
    res: Resolution,
    origin: &Pose2,
    max_range: f64,
) -> Result<Option<f64>, GridError> {
    let origin = origin.validate("origin")?;
    within("max_range", max_range, 0.0, 1e6)?;
    // Both ends must have cell indices.
    let end = res.cell_of(
        origin.x + max_range * origin.theta.cos(),
        origin.y + max_range * origin.theta.sin(),
    )?;
    let mut cell = res.cell_of(origin.x, origin.y)?;
    let m = res.metres();
    let (dir_x, dir_y) = (origin.theta.cos(), origin.theta.sin());
    let axis = |pos: f64, index: i32, dir: f64| -> (i32, f64, f64) {
        if dir > 0.0 {
            (1, ((f64::from(index) + 1.0) * m - pos) / dir, m / dir)
        } else if dir < 0.0 {
            (-1, (f64::from(index) * m - pos) / dir, -m / dir)
        } else {
            (0, f64::INFINITY, f64::INFINITY)
        }
    };
    let (step_x, mut next_x, delta_x) = axis(origin.x, cell.x, dir_x);
    let (step_y, mut next_y, delta_y) = axis(origin.y, cell.y, dir_y);
    let mut travelled = 0.0;
    let max_steps = u64::from(end.x.abs_diff(cell.x)) + u64::from(end.y.abs_diff(cell.y)) + 2;
    for _ in 0..=max_steps {
        if view.occupancy(cell) == Occupancy::Occupied {
            return Ok(Some(travelled));
        }
        // Stepping off the i32 grid ends the walk: nothing lies beyond it.
        let stepped = if next_x < next_y {
            travelled = next_x;
            next_x += delta_x;
            cell.x.checked_add(step_x).map(|x| cell.x = x)
        } else {
            travelled = next_y;
            next_y += delta_y;
            cell.y.checked_add(step_y).map(|y| cell.y = y)
        };
        if stepped.is_none() {
            break;
        }
        if travelled > max_range {
            break;
        }
    }
    Ok(None)
}

/// The range a sonar at `sensor` would read: the distance from the sensor to
/// the nearest point of the nearest occupied cell whose centre lies in its
/// cone of half-angle `half_angle`, out to `max_range`; `None` if there is
/// none (no echo).
pub fn cast_cone(
    view: &impl OccupancyView,
    res: Resolution,
    sensor: &Pose2,
    half_angle: f64,
    max_range: f64,
) -> Result<Option<f64>, GridError> {
    let sensor = sensor.validate("sensor pose")?;
    within("half_angle", half_angle, 1e-6, 80f64.to_radians())?;
    within("max_range", max_range, 0.0, 1e6)?;
    let sector = Sector::from_pose(&sensor, half_angle, max_range);
    let bounds = sector.cell_box(res)?;
    let half_cell = res.metres() / 2.0;
    let mut nearest: Option<f64> = None;
    sector.for_each_cell(res, &bounds, |cell, _| {
        if view.occupancy(cell) != Occupancy::Occupied {
            return;
        }
        let (cx, cy) = res.cell_center(cell);
        let gap_x = ((cx - sensor.x).abs() - half_cell).max(0.0);
        let gap_y = ((cy - sensor.y).abs() - half_cell).max(0.0);
        let distance = gap_x.hypot(gap_y);
        if nearest.is_none_or(|n| distance < n) {
            nearest = Some(distance);
        }
    });
    Ok(nearest.filter(|d| *d <= max_range))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use std::collections::HashSet;

    /// A set of occupied cells; everything else free.
    struct Cells(HashSet<CellIndex>);

    impl OccupancyView for Cells {
        fn occupancy(&self, cell: CellIndex) -> Occupancy {
            if self.0.contains(&cell) {
                Occupancy::Occupied
            } else {
                Occupancy::Free
            }
        }
    }

    /// A vertical wall filling cells x = `column` for |y| <= 100.
    fn wall(column: i32) -> Cells {
        Cells((-100..=100).map(|y| CellIndex::new(column, y)).collect())
    }

    const RES: Resolution = Resolution::DEFAULT;

    #[test]
    fn ray_hits_a_wall_at_its_face() {
        // Wall face at x = 2.0 m (cell 40 starts there).
        let view = wall(40);
        let hit = cast_ray(&view, RES, &Pose2::new(0.01, 0.02, 0.0), 5.0)
            .unwrap()
            .unwrap();
        assert_abs_diff_eq!(hit, 1.99, epsilon = 1e-9);
        // At 60° off the normal the distance doubles.
        let slanted = cast_ray(&view, RES, &Pose2::new(0.0, 0.0, 60f64.to_radians()), 10.0)
            .unwrap()
            .unwrap();
        assert_abs_diff_eq!(slanted, 4.0, epsilon = 1e-9);
        // Facing away, or too short, no hit.
        assert_eq!(
            cast_ray(&view, RES, &Pose2::new(0.0, 0.0, 3.0), 10.0).unwrap(),
            None
        );
        assert_eq!(
            cast_ray(&view, RES, &Pose2::new(0.0, 0.0, 0.0), 1.5).unwrap(),
            None
        );
        // Starting inside the wall.
        assert_eq!(
            cast_ray(&view, RES, &Pose2::new(2.01, 0.0, 0.0), 1.0).unwrap(),
            Some(0.0)
        );
    }

    #[test]
    fn cone_reads_the_perpendicular_distance_to_a_wall() {
        let view = wall(40);
        let range = cast_cone(
            &view,
            RES,
            &Pose2::new(0.0, 0.0, 0.2),
            15f64.to_radians(),
            10.0,
        )
        .unwrap();
        assert_abs_diff_eq!(range.unwrap(), 2.0, epsilon = 1e-9);
    }

    #[test]
    fn cone_finds_an_obstacle_off_its_axis_that_a_ray_misses() {
        let beta = 15f64.to_radians();
        // A single occupied cell 3 m away, 12° off the axis: inside the cone.
        let (x, y) = (
            3.0 * 12f64.to_radians().cos(),
            3.0 * 12f64.to_radians().sin(),
        );
        let post = RES.cell_of(x, y).unwrap();
        let view = Cells(HashSet::from([post]));
        let sensor = Pose2::default();
        assert_eq!(cast_ray(&view, RES, &sensor, 10.0).unwrap(), None);
        let range = cast_cone(&view, RES, &sensor, beta, 10.0).unwrap().unwrap();
        assert!((range - 3.0).abs() < RES.metres(), "{range}");
        // At 18° it lies outside the cone.
        let outside = RES
            .cell_of(
                3.0 * 18f64.to_radians().cos(),
                3.0 * 18f64.to_radians().sin(),
            )
            .unwrap();
        let view = Cells(HashSet::from([outside]));
        assert_eq!(cast_cone(&view, RES, &sensor, beta, 10.0).unwrap(), None);
    }

    #[test]
    fn rays_at_the_edge_of_the_grid_end_without_overflow() {
        let view = Cells(HashSet::new());
        let edge = f64::from(i32::MAX) * RES.metres() - 0.5;
        assert_eq!(
            cast_ray(&view, RES, &Pose2::new(edge, 0.0, 0.0), 0.45).unwrap(),
            None
        );
        let corner = Pose2::new(-edge, -edge, -2.0);
        assert_eq!(cast_ray(&view, RES, &corner, 0.45).unwrap(), None);
    }

    #[test]
    fn bad_casts_are_errors() {
        let view = wall(40);
        assert!(cast_ray(&view, RES, &Pose2::new(f64::NAN, 0.0, 0.0), 1.0).is_err());
        assert!(cast_ray(&view, RES, &Pose2::default(), -1.0).is_err());
        assert!(cast_cone(&view, RES, &Pose2::default(), 2.0, 1.0).is_err());
        assert!(cast_cone(&view, RES, &Pose2::new(1e300, 0.0, 0.0), 0.2, 1.0).is_err());
    }
}
