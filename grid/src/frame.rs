//! Folding a whole sonar frame into per-tile delta batches.
//!
//! Each cell gets at most one delta per frame, however many cones cover it:
//! occupied evidence wins over empty (as OctoMap does: a cell one sonar saw
//! an echo in is not erased by a neighbour's cone passing through it), and
//! between two of a kind the stronger is kept. Readings are independent
//! evidence only across frames, not across overlapping cones of one frame.

use crate::cell::{CellBox, CellIndex, Resolution};
use crate::error::GridError;
use crate::pose::Pose2;
use crate::sensor_ring::SensorRing;
use crate::sonar_model::{ConeGuard, SonarModel};
use crate::tile::TileDelta;
use crate::tile_key::{TileKey, TileSize};

/// What one frame contributed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameStats {
    /// Cells given a nonzero delta.
    pub cells: usize,
    /// Tiles holding them.
    pub tiles: usize,
}

/// Turns frames into tile deltas, reusing its scratch space between frames.
#[derive(Debug, Clone)]
pub struct FrameIntegrator {
    model: SonarModel,
    ring: SensorRing,
    resolution: Resolution,
    tile_size: TileSize,
    scratch: Vec<i16>,
}

impl FrameIntegrator {
    /// An integrator for robots with `ring` on a grid of `resolution` and
    /// `tile_size`.
    pub fn new(
        model: SonarModel,
        ring: SensorRing,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Self {
        Self {
            model,
            ring,
            resolution,
            tile_size,
            scratch: Vec::new(),
        }
    }

    /// The sonar model.
    pub fn model(&self) -> &SonarModel {
        &self.model
    }

    /// The sensor ring.
    pub fn ring(&self) -> &SensorRing {
        &self.ring
    }

    /// Maps the frames that follow with `ring` (a ring that fires in turn,
    /// as it fired: [`SensorRing::as_fired`]).
    pub fn set_ring(&mut self, ring: SensorRing) {
        self.ring = ring;
    }

    /// Integrates the frame taken with the robot at `robot` (world frame),
    /// `ranges[i]` from sensor `i` of the ring, appending one delta per
    /// touched tile to `out`. Fails, appending nothing, if any input is bad.
    pub fn integrate(
        &mut self,
        robot: &Pose2,
        ranges: &[f64],
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        self.integrate_with(robot, ranges, None, out)
    }

    /// [`Self::integrate`] with each cone guarded by the map it writes to
    /// (see `SonarModel::visit_cone_guarded`): evidence stops at the
    /// cells `walls` holds occupied.
    pub fn integrate_guarded(
        &mut self,
        robot: &Pose2,
        ranges: &[f64],
        guard: &dyn ConeGuard,
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        self.integrate_with(robot, ranges, Some(guard), out)
    }

    fn integrate_with(
        &mut self,
        robot: &Pose2,
        ranges: &[f64],
        guard: Option<&dyn ConeGuard>,
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        let robot = robot.validate("pose")?;
        if ranges.len() != self.ring.len() {
            return Err(GridError::WrongReadingCount {
                expected: self.ring.len(),
                got: ranges.len(),
            });
        }
        let mut cones = Vec::with_capacity(ranges.len());
        let mut frame_box: Option<CellBox> = None;
        for (sensor, &range) in self.ring.sensor_poses(&robot).zip(ranges) {
            let reading = self.model.reading(range)?;
            if reading.extent <= 0.0 {
                continue;
            }
            let sector = self.model.sector(&sensor, &reading);
            let bounds = sector.cell_box(self.resolution)?;
            frame_box = Some(frame_box.map_or(bounds, |b| b.union(&bounds)));
            cones.push((sector, reading, bounds));
        }
        let Some(frame_box) = frame_box else {
            return Ok(FrameStats::default());
        };

        let width = frame_box.width() as usize;
        let height = frame_box.height() as usize;
        self.scratch.clear();
        self.scratch.resize(width * height, 0);
        let scratch = &mut self.scratch;
        // Cones, readings and bounds were all checked above: nothing below fails.
        for (sector, reading, bounds) in &cones {
            let fold = |cell: CellIndex, delta| {
                let col = (cell.x - frame_box.min.x) as usize;
                let row = (cell.y - frame_box.min.y) as usize;
                // Every visited cell lies in its cone's box, inside frame_box.
                if let Some(slot) = scratch.get_mut(row * width + col) {
                    *slot = combine(*slot, delta);
                }
            };
            match guard {
                None => self
                    .model
                    .visit_cone(sector, reading, self.resolution, bounds, fold),
                Some(guard) => self.model.visit_cone_guarded(
                    sector,
                    reading,
                    self.resolution,
                    bounds,
                    guard,
                    fold,
                ),
            }
        }
        Ok(self.fold_into_tiles(&frame_box, out))
    }

    fn fold_into_tiles(&self, frame_box: &CellBox, out: &mut Vec<TileDelta>) -> FrameStats {
        let width = frame_box.width() as usize;
        let side = self.tile_size.cells() as usize;
        let (first, last) = self.tile_size.tiles_covering(frame_box);
        let mut stats = FrameStats::default();
        for ty in first.y..=last.y {
            for tx in first.x..=last.x {
                let key = TileKey::new(tx, ty);
                // Keys between two keys of valid cells are valid.
                let Ok(tile_box) = self.tile_size.cell_box(key) else {
                    continue;
                };
                let Some(overlap) = tile_box.intersection(frame_box) else {
                    continue;
                };
                let mut delta: Option<TileDelta> = None;
                let run = overlap.width() as usize;
                for y in overlap.min.y..=overlap.max.y {
                    let src_start = (y - frame_box.min.y) as usize * width
                        + (overlap.min.x - frame_box.min.x) as usize;
                    let src = &self.scratch[src_start..src_start + run];
                    if src.iter().all(|&d| d == 0) {
                        continue;
                    }
                    let dst_start = (y - tile_box.min.y) as usize * side
                        + (overlap.min.x - tile_box.min.x) as usize;
                    let delta = delta.get_or_insert_with(|| TileDelta::zero(key, self.tile_size));
                    delta.raw_mut()[dst_start..dst_start + run].copy_from_slice(src);
                }
                if let Some(delta) = delta {
                    stats.cells += delta.nonzero_count();
                    stats.tiles += 1;
                    out.push(delta);
                }
            }
        }
        stats
    }

    /// The cell a world point falls in, on this integrator's grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Result<CellIndex, GridError> {
        self.resolution.cell_of(x, y)
    }
}

/// One delta per cell per frame: occupied beats empty, then the stronger wins.
#[inline]
pub fn combine(current: i16, new: i16) -> i16 {
    if current > 0 || new > 0 {
        current.max(new)
    } else {
        current.min(new)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sonar_model::SonarModelParams;
    use std::collections::HashMap;

    fn integrator() -> FrameIntegrator {
        FrameIntegrator::new(
            SonarModel::new(SonarModelParams::default()).unwrap(),
            SensorRing::scout(),
            Resolution::DEFAULT,
            TileSize::DEFAULT,
        )
    }

    fn flatten(deltas: &[TileDelta], size: TileSize) -> HashMap<CellIndex, i16> {
        let mut cells = HashMap::new();
        for delta in deltas {
            for (i, &d) in delta.raw().iter().enumerate().filter(|(_, d)| **d != 0) {
                let cell = size
                    .join(delta.key, crate::tile_key::CellOffset::from_index(i, size))
                    .unwrap();
                assert!(cells.insert(cell, d).is_none(), "cell in two tiles");
            }
        }
        cells
    }

    #[test]
    fn frame_equals_the_per_cell_combination_of_its_readings() {
        let mut integrator = integrator();
        let robot = Pose2::new(-0.3, 0.7, 0.4);
        let ranges: Vec<f64> = (0..16).map(|i| 0.5 + 0.37 * f64::from(i)).collect();
        let mut out = Vec::new();
        let stats = integrator.integrate(&robot, &ranges, &mut out).unwrap();
        let got = flatten(&out, TileSize::DEFAULT);
        assert_eq!(stats.cells, got.len());
        assert_eq!(stats.tiles, out.len());
        assert!(
            stats.tiles > 1,
            "the frame should straddle tiles around the origin"
        );

        let mut expected: HashMap<CellIndex, i16> = HashMap::new();
        for (sensor, &range) in integrator.ring().sensor_poses(&robot).zip(&ranges) {
            integrator
                .model()
                .for_each_cell(&sensor, range, Resolution::DEFAULT, |cell, d| {
                    let slot = expected.entry(cell).or_insert(0);
                    *slot = combine(*slot, d);
                })
                .unwrap();
        }
        expected.retain(|_, d| *d != 0);
        assert_eq!(got, expected);
    }

    #[test]
    fn occupied_wins_over_empty_within_a_frame() {
        assert_eq!(combine(-900, 40), 40);
        assert_eq!(combine(40, -900), 40);
        assert_eq!(combine(-100, -900), -900);
        assert_eq!(combine(300, 40), 300);
        // Two facing sensors: one sees a wall at 1 m, the other's cone passes
        // through that wall towards a far echo. The wall must stay occupied.
        let model = SonarModel::new(SonarModelParams::default()).unwrap();
        let ring = SensorRing::from_mounts(vec![
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(2.0, 0.0, std::f64::consts::PI),
        ])
        .unwrap();
        let mut integrator =
            FrameIntegrator::new(model, ring, Resolution::DEFAULT, TileSize::DEFAULT);
        let mut out = Vec::new();
        integrator
            .integrate(&Pose2::default(), &[1.0, 1.9], &mut out)
            .unwrap();
        let cells = flatten(&out, TileSize::DEFAULT);
        let wall = Resolution::DEFAULT.cell_of(0.99, 0.01).unwrap();
        assert!(cells[&wall] > 0, "wall cell {} erased", cells[&wall]);
    }

    #[test]
    fn bad_frames_append_nothing() {
        let mut integrator = integrator();
        let mut out = Vec::new();
        assert!(matches!(
            integrator.integrate(&Pose2::default(), &[1.0; 15], &mut out),
            Err(GridError::WrongReadingCount {
                expected: 16,
                got: 15
            })
        ));
        let mut ranges = [1.0; 16];
        ranges[7] = f64::NAN;
        assert!(
            integrator
                .integrate(&Pose2::default(), &ranges, &mut out)
                .is_err()
        );
        assert!(
            integrator
                .integrate(&Pose2::new(0.0, f64::INFINITY, 0.0), &[1.0; 16], &mut out)
                .is_err()
        );
        assert!(out.is_empty());
    }

    #[test]
    fn scratch_is_clean_between_frames() {
        let mut integrator = integrator();
        let mut first = Vec::new();
        integrator
            .integrate(&Pose2::new(5.0, 5.0, 0.0), &[2.0; 16], &mut first)
            .unwrap();
        let mut other = Vec::new();
        integrator
            .integrate(&Pose2::new(-3.0, 1.0, 1.0), &[4.0; 16], &mut other)
            .unwrap();
        let mut again = Vec::new();
        integrator
            .integrate(&Pose2::new(5.0, 5.0, 0.0), &[2.0; 16], &mut again)
            .unwrap();
        assert_eq!(first, again);
    }

    /// Cells a test calls walls.
    struct Walls(std::collections::HashSet<CellIndex>);

    impl ConeGuard for Walls {
        fn shadows(&self, cell: CellIndex) -> bool {
            self.0.contains(&cell)
        }

        fn keeps(&self, cell: CellIndex) -> bool {
            self.0.contains(&cell)
        }
    }

    /// A wall across x = `x` metres, from y = -3 to 3.
    fn wall_at(x: f64) -> Walls {
        let res = Resolution::DEFAULT;
        let column = res.cell_of(x, 0.0).unwrap().x;
        Walls((-60..=60).map(|y| CellIndex::new(column, y)).collect())
    }

    #[test]
    fn a_guard_without_walls_changes_nothing() {
        let mut plain = integrator();
        let mut guarded = integrator();
        let none = Walls(Default::default());
        for k in 0..8 {
            let k = f64::from(k);
            let robot = Pose2::new(0.3 * k - 1.0, 0.7 - 0.2 * k, 0.9 * k);
            let ranges: Vec<f64> = (0..16)
                .map(|i| 0.3 + 0.41 * f64::from(i) + 0.1 * k)
                .collect();
            let (mut a, mut b) = (Vec::new(), Vec::new());
            let sa = plain.integrate(&robot, &ranges, &mut a).unwrap();
            let sb = guarded
                .integrate_guarded(&robot, &ranges, &none, &mut b)
                .unwrap();
            assert_eq!(sa, sb);
            assert!(a == b, "frame {k}: the deltas differ");
        }
    }

    #[test]
    fn a_reading_past_a_known_wall_erases_neither_it_nor_what_lies_behind() {
        let res = Resolution::DEFAULT;
        let walls = wall_at(2.0);
        let wall_x = res.cell_of(2.0, 0.0).unwrap().x;
        let robot = Pose2::new(0.0, 0.0, 0.0);
        // Sonar 0 looks along +x from 0.2 m ahead of the centre and reads
        // 4 m: it missed the wall 1.8 m ahead (a specular miss).
        let mut ranges = vec![10.668; 16];
        ranges[0] = 4.0;
        let (mut plain, mut guarded) = (integrator(), integrator());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        plain.integrate(&robot, &ranges, &mut a).unwrap();
        guarded
            .integrate_guarded(&robot, &ranges, &walls, &mut b)
            .unwrap();
        let (a, b) = (
            flatten(&a, TileSize::DEFAULT),
            flatten(&b, TileSize::DEFAULT),
        );
        // The plain model frees the wall on the axis and marks 4 m occupied.
        assert!(a.get(&CellIndex::new(wall_x, 0)).is_some_and(|&d| d < 0));
        assert!(a.keys().any(|c| c.x > wall_x + 1));
        // Guarded: nothing on or behind the wall, the same in front of it.
        assert!(b.keys().all(|c| c.x <= wall_x), "evidence behind the wall");
        assert!(
            b.iter().all(|(c, &d)| !(walls.0.contains(c) && d < 0)),
            "a wall cell freed"
        );
        for (cell, d) in &b {
            if cell.x < wall_x - 1 {
                assert_eq!(a.get(cell), Some(d), "{cell:?} in front of the wall");
            }
        }
        assert!(b.values().filter(|&&d| d < 0).count() > 100);
    }

    #[test]
    fn an_echo_off_a_known_wall_still_marks_it() {
        let res = Resolution::DEFAULT;
        let walls = wall_at(2.0);
        let wall_x = res.cell_of(2.0, 0.0).unwrap().x;
        let robot = Pose2::new(0.0, 0.0, 0.0);
        let mut ranges = vec![10.668; 16];
        ranges[0] = 1.8;
        let mut guarded = integrator();
        let mut out = Vec::new();
        guarded
            .integrate_guarded(&robot, &ranges, &walls, &mut out)
            .unwrap();
        let cells = flatten(&out, TileSize::DEFAULT);
        assert!(
            cells
                .get(&CellIndex::new(wall_x, 0))
                .is_some_and(|&d| d > 0)
        );
        assert!(
            cells
                .get(&CellIndex::new(wall_x - 10, 0))
                .is_some_and(|&d| d < 0)
        );
    }
}
