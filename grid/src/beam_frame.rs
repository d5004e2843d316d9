//! Folding a frame of mixed beams (sonar cones and laser rays, each from
//! its own mount, each with its own model) into per-tile delta batches.
//!
//! Every beam's cells are folded into one scratch with the rule of
//! [`crate::frame`]: one delta per cell per frame, occupied evidence
//! beating empty, then the stronger kept. So a cell one beam hits is not
//! freed by another beam of the same frame passing through it, whatever
//! their kinds or order.
//!
//! The scratch is kept per tile ([`crate::frame::FrameStats`] counts the
//! same way): a laser's rays fan far and touch few of the cells of their
//! bounding box, so only the tiles they touch are made. For a ring of
//! sonars alone, [`crate::FrameIntegrator`] gives the same deltas.

use crate::cell::{CellBox, Resolution};
use crate::error::{GridError, within};
use crate::frame::FrameStats;
use crate::pose::Pose2;
use crate::ray_model::{RayModel, RayReading};
use crate::sector::Sector;
use crate::segment_walk::SegmentCells;
use crate::sensor_ring::SensorRing;
use crate::sonar_model::{ConeGuard, Reading, SonarModel};
use crate::tile::TileDelta;
use crate::tile_key::TileSize;
use crate::tile_scratch::TileScratch;

/// A reading already judged against its sensor (a rig's job).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BeamReading {
    /// An echo at this range, metres.
    Echo(f64),
    /// Nothing heard within range.
    NoEcho,
}

/// Which of the integrator's models maps a beam.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeamModel {
    /// The sonar model at this index of the integrator's cone models.
    Cone(usize),
    /// The ray model at this index of the integrator's ray models.
    Ray(usize),
}

/// One beam of a frame: where it starts and how it is mapped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameBeam {
    /// Where the beam starts and which way it points, robot frame.
    pub mount: Pose2,
    /// Its model.
    pub model: BeamModel,
}

/// A beam of the frame at hand, checked and ready to fold.
#[derive(Debug, Clone)]
enum Planned {
    Cone {
        model: usize,
        sector: Sector,
        reading: Reading,
        bounds: CellBox,
    },
    Ray {
        model: usize,
        cells: SegmentCells,
        reading: RayReading,
    },
}

/// Turns frames of mixed beams into tile deltas, reusing its scratch space
/// between frames.
#[derive(Debug, Clone)]
pub struct BeamFrameIntegrator {
    cones: Vec<SonarModel>,
    rays: Vec<RayModel>,
    beams: Vec<FrameBeam>,
    resolution: Resolution,
    tile_size: TileSize,
    planned: Vec<Planned>,
    scratch: TileScratch,
}

impl BeamFrameIntegrator {
    /// An integrator for frames of `beams`, one reading each, in order,
    /// each mapped by one of `cones` or `rays`, on a grid of `resolution`
    /// and `tile_size`. Fails for a beam naming a model that is not there,
    /// or a mount that is not finite.
    pub fn new(
        cones: Vec<SonarModel>,
        rays: Vec<RayModel>,
        beams: Vec<FrameBeam>,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Result<Self, GridError> {
        for beam in &beams {
            beam.mount.validate("beam mount")?;
            let (index, count) = match beam.model {
                BeamModel::Cone(i) => (i, cones.len()),
                BeamModel::Ray(i) => (i, rays.len()),
            };
            let field = match beam.model {
                BeamModel::Cone(_) => "cone model index",
                BeamModel::Ray(_) => "ray model index",
            };
            within(field, index as f64, 0.0, count as f64 - 1.0)?;
        }
        Ok(Self {
            cones,
            rays,
            beams,
            resolution,
            tile_size,
            planned: Vec::new(),
            scratch: TileScratch::new(tile_size),
        })
    }

    /// An integrator for a ring of sonars, all with `model`.
    pub fn for_ring(
        model: SonarModel,
        ring: &SensorRing,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Self {
        let beams = ring
            .mounts()
            .iter()
            .map(|&mount| FrameBeam {
                mount,
                model: BeamModel::Cone(0),
            })
            .collect();
        Self {
            cones: vec![model],
            rays: Vec::new(),
            beams,
            resolution,
            tile_size,
            planned: Vec::new(),
            scratch: TileScratch::new(tile_size),
        }
    }

    /// The beams, in the order of a frame's readings.
    pub fn beams(&self) -> &[FrameBeam] {
        &self.beams
    }

    /// Moves each beam to `mounts[k]`, robot frame, for the frames that
    /// follow (a ring that fires in turn: where each sensor was when it
    /// fired, [`crate::RingFiring`]). Fails, changing nothing, for the
    /// wrong count or a mount that is not finite.
    pub fn set_mounts(&mut self, mounts: &[Pose2]) -> Result<(), GridError> {
        if mounts.len() != self.beams.len() {
            let beams = self.beams.len() as f64;
            return Err(GridError::OutOfRange {
                field: "beam mounts (one per beam)",
                value: mounts.len() as f64,
                min: beams,
                max: beams,
            });
        }
        for m in mounts {
            m.validate("beam mount")?;
        }
        for (beam, m) in self.beams.iter_mut().zip(mounts) {
            beam.mount = *m;
        }
        Ok(())
    }

    /// Readings per frame.
    pub fn readings(&self) -> usize {
        self.beams.len()
    }

    /// The grid's resolution.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// The grid's tile size.
    pub fn tile_size(&self) -> TileSize {
        self.tile_size
    }

    /// The sonar models.
    pub fn cone_models(&self) -> &[SonarModel] {
        &self.cones
    }

    /// The ray models.
    pub fn ray_models(&self) -> &[RayModel] {
        &self.rays
    }

    /// Integrates the frame taken with the robot at `robot` (world frame),
    /// `readings[i]` from beam `i`, appending one delta per touched tile
    /// to `out` (rows of tiles from the lowest, each from the left, as
    /// [`crate::FrameIntegrator`] does). Fails, appending nothing, if any
    /// input is bad.
    pub fn integrate(
        &mut self,
        robot: &Pose2,
        readings: &[BeamReading],
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        self.integrate_with(robot, readings, None, out)
    }

    /// [`Self::integrate`] with each sonar cone guarded by the map it
    /// writes to (see `SonarModel::visit_cone_guarded`); laser rays are
    /// mapped as they are.
    pub fn integrate_guarded(
        &mut self,
        robot: &Pose2,
        readings: &[BeamReading],
        guard: &dyn ConeGuard,
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        self.integrate_with(robot, readings, Some(guard), out)
    }

    fn integrate_with(
        &mut self,
        robot: &Pose2,
        readings: &[BeamReading],
        guard: Option<&dyn ConeGuard>,
        out: &mut Vec<TileDelta>,
    ) -> Result<FrameStats, GridError> {
        let robot = robot.validate("pose")?;
        if readings.len() != self.beams.len() {
            return Err(GridError::WrongReadingCount {
                expected: self.beams.len(),
                got: readings.len(),
            });
        }
        let res = self.resolution;
        self.planned.clear();
        let mut frame_box: Option<CellBox> = None;
        for (index, (beam, reading)) in self.beams.iter().zip(readings).enumerate() {
            let sensor = robot.compose(&beam.mount);
            let bad = |value: f64| move |_| GridError::BadReading { index, value };
            let (planned, bounds) = match beam.model {
                BeamModel::Cone(model) => {
                    let cone = &self.cones[model];
                    let reading = match *reading {
                        BeamReading::Echo(range) => cone.echo(range).map_err(bad(range))?,
                        BeamReading::NoEcho => cone.no_echo(),
                    };
                    if reading.extent <= 0.0 {
                        continue;
                    }
                    let sector = cone.sector(&sensor, &reading);
                    let bounds = sector.cell_box(res)?;
                    let planned = Planned::Cone {
                        model,
                        sector,
                        reading,
                        bounds,
                    };
                    (planned, bounds)
                }
                BeamModel::Ray(model) => {
                    let ray = &self.rays[model];
                    let reading = match *reading {
                        BeamReading::Echo(range) => ray.echo(range).map_err(bad(range))?,
                        BeamReading::NoEcho => ray.no_echo(),
                    };
                    if ray.is_empty(&reading) {
                        continue;
                    }
                    let (cells, bounds) = ray.walk(&sensor, &reading, res)?;
                    let planned = Planned::Ray {
                        model,
                        cells,
                        reading,
                    };
                    (planned, bounds)
                }
            };
            frame_box = Some(frame_box.map_or(bounds, |b| b.union(&bounds)));
            self.planned.push(planned);
        }
        let Some(frame_box) = frame_box else {
            return Ok(FrameStats::default());
        };

        // Every beam was checked above: nothing below fails.
        self.scratch.begin(&frame_box);
        let mut cursor = self.scratch.cursor();
        for planned in self.planned.drain(..) {
            match planned {
                Planned::Cone {
                    model,
                    sector,
                    reading,
                    bounds,
                } => match guard {
                    None => {
                        self.cones[model].visit_cone(&sector, &reading, res, &bounds, |cell, d| {
                            cursor.add(cell, d)
                        })
                    }
                    Some(guard) => self.cones[model].visit_cone_guarded(
                        &sector,
                        &reading,
                        res,
                        &bounds,
                        guard,
                        |cell, d| cursor.add(cell, d),
                    ),
                },
                Planned::Ray {
                    model,
                    cells,
                    reading,
                } => self.rays[model].visit_runs(cells, &reading, |run, d| {
                    for cell in run {
                        cursor.add(cell, d);
                    }
                }),
            }
        }
        drop(cursor);
        Ok(self.scratch.finish(out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell::CellIndex;
    use crate::frame::{FrameIntegrator, combine};
    use crate::ray_model::RayModelParams;
    use crate::sonar_model::SonarModelParams;
    use crate::tile_key::CellOffset;
    use proptest::prelude::*;
    use std::collections::HashMap;

    const RES: Resolution = Resolution::DEFAULT;
    const SIZE: TileSize = TileSize::DEFAULT;

    fn flatten(deltas: &[TileDelta]) -> HashMap<CellIndex, i16> {
        let mut cells = HashMap::new();
        for delta in deltas {
            for (i, &d) in delta.raw().iter().enumerate().filter(|(_, d)| **d != 0) {
                let cell = SIZE
                    .join(delta.key, CellOffset::from_index(i, SIZE))
                    .unwrap();
                assert!(cells.insert(cell, d).is_none(), "cell in two tiles");
            }
        }
        cells
    }

    fn sonar() -> SonarModel {
        SonarModel::new(SonarModelParams::default()).unwrap()
    }

    fn laser(count: usize) -> Vec<FrameBeam> {
        (0..count)
            .map(|i| FrameBeam {
                mount: Pose2::new(0.1, 0.0, (i as f64 - 90.0).to_radians()),
                model: BeamModel::Ray(0),
            })
            .collect()
    }

    fn ray_integrator(params: RayModelParams, count: usize) -> BeamFrameIntegrator {
        let ray = RayModel::new(params).unwrap();
        BeamFrameIntegrator::new(vec![], vec![ray], laser(count), RES, SIZE).unwrap()
    }

    proptest! {
        /// For a sonar ring the tiles, their order and every delta are the
        /// dense integrator's.
        #[test]
        fn a_sonar_ring_gives_the_dense_integrators_deltas(
            x in -20.0f64..20.0, y in -20.0f64..20.0, theta in -4.0f64..4.0,
            ranges in proptest::collection::vec(0.0f64..12.0, 16),
        ) {
            let ring = SensorRing::scout();
            let mut dense = FrameIntegrator::new(sonar(), ring.clone(), RES, SIZE);
            let mut sparse = BeamFrameIntegrator::for_ring(sonar(), &ring, RES, SIZE);
            let robot = Pose2::new(x, y, theta);
            let judged: Vec<_> = ranges
                .iter()
                .map(|&r| if r >= 10.668 { BeamReading::NoEcho } else { BeamReading::Echo(r) })
                .collect();
            let (mut a, mut b) = (Vec::new(), Vec::new());
            let sa = dense.integrate(&robot, &ranges, &mut a).unwrap();
            let sb = sparse.integrate(&robot, &judged, &mut b).unwrap();
            prop_assert_eq!(sa, sb);
            prop_assert!(a == b);
        }
    }

    #[test]
    fn a_laser_frame_is_the_per_cell_combination_of_its_rays() {
        let params = RayModelParams {
            no_echo_free_range: 4.0,
            ..RayModelParams::default()
        };
        let mut integrator = ray_integrator(params, 180);
        let robot = Pose2::new(1.3, -0.4, 0.3);
        let readings: Vec<_> = (0..180)
            .map(|i| match i % 7 {
                0 => BeamReading::NoEcho,
                k => BeamReading::Echo(0.7 * f64::from(k) + 0.01 * f64::from(i)),
            })
            .collect();
        let mut out = Vec::new();
        let stats = integrator.integrate(&robot, &readings, &mut out).unwrap();
        let got = flatten(&out);
        assert_eq!((stats.cells, stats.tiles), (got.len(), out.len()));
        assert!(stats.tiles > 1);

        let model = RayModel::new(params).unwrap();
        let mut expected: HashMap<CellIndex, i16> = HashMap::new();
        for (beam, reading) in integrator.beams().iter().zip(&readings) {
            let range = match reading {
                BeamReading::Echo(r) => *r,
                BeamReading::NoEcho => 50.0,
            };
            model
                .for_each_cell(&robot.compose(&beam.mount), range, RES, |cell, d| {
                    let slot = expected.entry(cell).or_insert(0);
                    *slot = combine(*slot, d);
                })
                .unwrap();
        }
        assert_eq!(got, expected);
    }

    #[test]
    fn a_hit_is_not_freed_by_a_ray_passing_through_it() {
        // Two rays along +x from 2 m apart, facing each other: one ends in
        // the cell at 1 m, the other's free run crosses it to a far echo.
        let ray = RayModel::new(RayModelParams::default()).unwrap();
        let beams = [
            FrameBeam {
                mount: Pose2::new(0.01, 0.01, 0.0),
                model: BeamModel::Ray(0),
            },
            FrameBeam {
                mount: Pose2::new(2.01, 0.01, std::f64::consts::PI),
                model: BeamModel::Ray(0),
            },
        ];
        for order in [[0, 1], [1, 0]] {
            let beams = order.iter().map(|&i| beams[i]).collect();
            let mut integrator =
                BeamFrameIntegrator::new(vec![], vec![ray.clone()], beams, RES, SIZE).unwrap();
            let readings = order.map(|i| BeamReading::Echo([1.0, 1.9][i]));
            let mut out = Vec::new();
            integrator
                .integrate(&Pose2::default(), &readings, &mut out)
                .unwrap();
            let cells = flatten(&out);
            assert_eq!(cells[&CellIndex::new(20, 0)], ray.hit_delta());
            assert_eq!(cells[&CellIndex::new(10, 0)], ray.miss_delta());
        }
    }

    #[test]
    fn cones_and_rays_mix_in_one_frame() {
        let ray = RayModel::new(RayModelParams::default()).unwrap();
        let beams = vec![
            FrameBeam {
                mount: Pose2::new(0.0, 0.0, 0.0),
                model: BeamModel::Cone(0),
            },
            FrameBeam {
                mount: Pose2::new(0.01, 0.01, 0.0),
                model: BeamModel::Ray(0),
            },
        ];
        let mut integrator =
            BeamFrameIntegrator::new(vec![sonar()], vec![ray.clone()], beams, RES, SIZE).unwrap();
        // The laser sees a wall at 1 m; the sonar's echo at 3 m would free
        // the cell there, and may not.
        let mut out = Vec::new();
        let readings = [BeamReading::Echo(3.0), BeamReading::Echo(1.0)];
        integrator
            .integrate(&Pose2::default(), &readings, &mut out)
            .unwrap();
        let cells = flatten(&out);
        assert_eq!(cells[&CellIndex::new(20, 0)], ray.hit_delta());
        // Beyond the laser's echo the sonar's cone still says empty, then
        // occupied at 3 m.
        assert!(cells[&CellIndex::new(40, 0)] < 0);
        assert!(cells[&CellIndex::new(59, 0)] > 0);
    }

    #[test]
    fn bad_frames_append_nothing_and_name_the_reading() {
        let mut integrator = ray_integrator(RayModelParams::default(), 3);
        let mut out = Vec::new();
        let err = integrator
            .integrate(&Pose2::default(), &[BeamReading::NoEcho; 2], &mut out)
            .unwrap_err();
        assert_eq!(
            err,
            GridError::WrongReadingCount {
                expected: 3,
                got: 2
            }
        );
        let readings = [
            BeamReading::Echo(1.0),
            BeamReading::Echo(-2.0),
            BeamReading::Echo(1.0),
        ];
        let err = integrator
            .integrate(&Pose2::default(), &readings, &mut out)
            .unwrap_err();
        assert_eq!(err.to_string(), "ranges[1] is -2, not a range");
        let far = Pose2::new(1e15, 0.0, 0.0);
        assert!(
            integrator
                .integrate(&far, &[BeamReading::Echo(1.0); 3], &mut out)
                .is_err()
        );
        assert!(out.is_empty());
        let beams = vec![FrameBeam {
            mount: Pose2::default(),
            model: BeamModel::Ray(1),
        }];
        assert!(BeamFrameIntegrator::new(vec![], vec![], beams, RES, SIZE).is_err());
    }

    #[test]
    fn a_frame_with_nothing_to_map_appends_nothing() {
        let mut integrator = ray_integrator(RayModelParams::default(), 4);
        let mut out = Vec::new();
        let stats = integrator
            .integrate(&Pose2::default(), &[BeamReading::NoEcho; 4], &mut out)
            .unwrap();
        assert_eq!(stats, FrameStats::default());
        assert!(out.is_empty());
    }
}
