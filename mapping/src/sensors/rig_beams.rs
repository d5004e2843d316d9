//! Any rig mapped beam by beam: each sonar's cone with the analytical
//! sonar model, each laser ray with the ray model (OctoMap's hit and
//! miss), all of a frame folded into one delta per cell
//! ([`deog_grid::BeamFrameIntegrator`]), so a cell one beam hits is not
//! freed by another beam of the same frame.
//!
//! Each sensor's model takes its geometry from the rig: a sonar's cone
//! takes the sonar parameters with the sensor's minimum and maximum range
//! and half-angle, its mapped and no-echo ranges (and region I's
//! tolerance) cut to that maximum range; a laser's rays take the ray
//! parameters with the sensor's ranges, the mapped and no-echo ranges cut
//! likewise. Readings are judged by the rig's beams ([`Beam::classify`]):
//! what the rig calls no echo is mapped as no echo.

use deog_grid::{
    BeamFrameIntegrator, BeamModel, BeamReading, ConeGuard, FrameBeam, GridError, Pose2, RayModel,
    RayModelParams, Resolution, SonarModel, SonarModelParams, TileDelta, TileSize,
};
use deog_rig::{Beam, Reading, Rig, SensorKind};

use crate::error::MappingError;
use crate::sensors::InverseSensorModel;

/// A rig's inverse sensor model: its cones and rays, beam by beam.
#[derive(Debug, Clone)]
pub struct RigBeams {
    rig: Rig,
    integrator: BeamFrameIntegrator,
    judged: Vec<BeamReading>,
}

impl RigBeams {
    /// `rig`'s sensors mapped with `sonar` for its cones and `ray` for its
    /// rays (each taking the sensor's ranges, see the module docs), on a
    /// grid of `resolution` and `tile_size`. Fails, naming the sensor, if
    /// a sensor's model does not hold together.
    pub fn new(
        rig: &Rig,
        sonar: SonarModelParams,
        ray: RayModelParams,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Result<Self, MappingError> {
        let mut cones: Vec<SonarModel> = Vec::new();
        let mut rays: Vec<RayModel> = Vec::new();
        let mut sensor_models = Vec::with_capacity(rig.sensors().len());
        for (i, s) in rig.sensors().iter().enumerate() {
            let refused = |e: GridError| {
                MappingError::invalid(format!("rig {} sensor[{i}]", rig.name()), e.to_string())
            };
            // Sensors alike share one model (a ring's sonars, say): one set
            // of tables, warm in the cache for every cone of a frame.
            let model = match s.kind {
                SensorKind::Sonar { half_angle } => {
                    let params = SonarModelParams {
                        min_range: s.min_range,
                        max_range: s.max_range,
                        half_angle,
                        region_i_tolerance: sonar.region_i_tolerance.min(s.max_range),
                        no_echo_free_range: sonar.no_echo_free_range.min(s.max_range),
                        max_mapped_range: sonar.max_mapped_range.min(s.max_range),
                        max_free_range: sonar.max_free_range.min(s.max_range),
                        ..sonar
                    };
                    match cones.iter().position(|m| *m.params() == params) {
                        Some(index) => BeamModel::Cone(index),
                        None => {
                            cones.push(SonarModel::new(params).map_err(refused)?);
                            BeamModel::Cone(cones.len() - 1)
                        }
                    }
                }
                SensorKind::Laser { .. } => {
                    let params = RayModelParams {
                        min_range: s.min_range,
                        max_range: s.max_range,
                        no_echo_free_range: ray.no_echo_free_range.min(s.max_range),
                        max_mapped_range: ray.max_mapped_range.min(s.max_range),
                        ..ray
                    };
                    match rays.iter().position(|m| *m.params() == params) {
                        Some(index) => BeamModel::Ray(index),
                        None => {
                            rays.push(RayModel::new(params).map_err(refused)?);
                            BeamModel::Ray(rays.len() - 1)
                        }
                    }
                }
            };
            sensor_models.push(model);
        }
        let beams = rig
            .beams()
            .iter()
            .map(|b| FrameBeam {
                mount: b.mount,
                model: sensor_models[b.sensor],
            })
            .collect();
        let integrator = BeamFrameIntegrator::new(cones, rays, beams, resolution, tile_size)?;
        Ok(Self {
            rig: rig.clone(),
            integrator,
            judged: Vec::with_capacity(rig.readings()),
        })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The integrator, with each sensor's model.
    pub fn integrator(&self) -> &BeamFrameIntegrator {
        &self.integrator
    }
}

/// A reading as its beam judges it; `None` for a value that is not a range.
fn judge(beam: &Beam, range: f64) -> Option<BeamReading> {
    Some(match beam.classify(range)? {
        Reading::Echo(r) => BeamReading::Echo(r),
        Reading::NoEcho => BeamReading::NoEcho,
    })
}

impl InverseSensorModel for RigBeams {
    fn readings(&self) -> usize {
        self.rig.readings()
    }

    fn set_reading_poses(&mut self, robot_at: Option<&[Pose2]>) {
        let beams = self.rig.beams();
        let mounts: Vec<Pose2> = match robot_at {
            Some(at) if at.len() == beams.len() => beams
                .iter()
                .zip(at)
                .map(|(b, at)| at.compose(&b.mount))
                .collect(),
            _ => beams.iter().map(|b| b.mount).collect(),
        };
        // The rig's mounts are finite, and so are poses composed from them
        // with finite motion: the count is the rig's own.
        let _ = self.integrator.set_mounts(&mounts);
    }

    fn integrate(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError> {
        self.judge_all(readings)?;
        Ok(self.integrator.integrate(robot, &self.judged, out)?.cells)
    }

    fn integrate_guarded(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        guard: &dyn ConeGuard,
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError> {
        self.judge_all(readings)?;
        Ok(self
            .integrator
            .integrate_guarded(robot, &self.judged, guard, out)?
            .cells)
    }
}

impl RigBeams {
    /// Judges a frame's readings into `self.judged`, one per beam.
    fn judge_all(&mut self, readings: &[f64]) -> Result<(), GridError> {
        if readings.len() != self.rig.readings() {
            return Err(GridError::WrongReadingCount {
                expected: self.rig.readings(),
                got: readings.len(),
            });
        }
        self.judged.clear();
        for (index, (beam, &value)) in self.rig.beams().iter().zip(readings).enumerate() {
            let judged = judge(beam, value).ok_or(GridError::BadReading { index, value })?;
            self.judged.push(judged);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use deog_grid::{CellIndex, CellOffset};
    use deog_rig::{NoEcho, RangeSensor};

    use super::*;

    const RES: Resolution = Resolution::DEFAULT;
    const SIZE: TileSize = TileSize::DEFAULT;

    fn laser(first_deg: f64, count: u32) -> RangeSensor {
        RangeSensor {
            mount: Pose2::new(0.0, 0.0, 0.0),
            kind: SensorKind::Laser {
                first_angle: first_deg.to_radians(),
                angle_step: 1f64.to_radians(),
                beam_count: count,
            },
            min_range: 0.02,
            max_range: 50.0,
            no_echo: NoEcho {
                at_or_beyond: 50.0,
                zero: true,
            },
        }
    }

    fn sonar() -> RangeSensor {
        RangeSensor {
            mount: Pose2::new(0.0, 0.0, 0.0),
            kind: SensorKind::Sonar {
                half_angle: 15f64.to_radians(),
            },
            min_range: 0.1524,
            max_range: 6.0,
            no_echo: NoEcho {
                at_or_beyond: 6.0,
                zero: false,
            },
        }
    }

    fn model(sensors: Vec<RangeSensor>, ray: RayModelParams) -> RigBeams {
        let rig = Rig::new("test", 0.2, sensors).expect("rig");
        RigBeams::new(&rig, SonarModelParams::default(), ray, RES, SIZE).expect("model")
    }

    fn flatten(deltas: &[TileDelta]) -> HashMap<CellIndex, i16> {
        let mut cells = HashMap::new();
        for delta in deltas {
            for (i, &d) in delta.raw().iter().enumerate().filter(|(_, d)| **d != 0) {
                let cell = SIZE
                    .join(delta.key, CellOffset::from_index(i, SIZE))
                    .expect("cell");
                cells.insert(cell, d);
            }
        }
        cells
    }

    #[test]
    fn a_laser_in_front_of_a_wall_marks_the_wall_and_frees_the_way() {
        let mut m = model(vec![laser(-20.0, 41)], RayModelParams::default());
        // A wall whose face is at x = 3.02 m, inside column 60; the robot
        // at (0.01, 0.01) facing it.
        let robot = Pose2::new(0.01, 0.01, 0.0);
        let ranges: Vec<f64> = m
            .rig()
            .beams()
            .iter()
            .map(|b| 3.01 / b.mount.theta.cos())
            .collect();
        let mut out = Vec::new();
        let touched = m.integrate(&robot, &ranges, &mut out).expect("frame");
        let cells = flatten(&out);
        assert_eq!(touched, cells.len());
        let hit = RayModel::new(RayModelParams::default())
            .expect("ray")
            .hit_delta();
        // Each ray's echo cell is hit (a slanted ray may cross a row inside
        // column 60 before its echo: free space in front of the face).
        for (beam, range) in m.rig().beams().iter().zip(&ranges) {
            let (x, y) = (
                robot.x + range * beam.mount.theta.cos(),
                robot.y + range * beam.mount.theta.sin(),
            );
            let end = RES.cell_of(x, y).expect("cell");
            assert_eq!((end.x, cells[&end]), (60, hit), "{end:?}");
        }
        assert!(
            cells
                .iter()
                .filter(|(_, d)| **d > 0)
                .all(|(c, _)| c.x == 60)
        );
        assert!(cells.iter().filter(|(c, _)| c.x < 60).all(|(_, d)| *d < 0));
        assert!(cells.keys().all(|c| c.x <= 60), "cells behind the wall");
        // Straight ahead, every cell from the robot to the wall is free.
        for x in 0..60 {
            assert!(cells[&CellIndex::new(x, 0)] < 0, "cell {x}");
        }
    }

    #[test]
    fn a_no_echo_ray_frees_up_to_the_no_echo_range_only() {
        let freeing = RayModelParams {
            no_echo_free_range: 2.0,
            ..RayModelParams::default()
        };
        let robot = Pose2::new(0.01, 0.01, 0.0);
        for no_echo in [50.0, 70.0, 0.0] {
            let mut m = model(vec![laser(0.0, 1)], freeing);
            let mut out = Vec::new();
            m.integrate(&robot, &[no_echo], &mut out).expect("frame");
            let cells = flatten(&out);
            // 2.01 m lies in column 40.
            let expected: HashMap<_, _> = (0..=40)
                .map(|x| (CellIndex::new(x, 0), cells[&CellIndex::new(0, 0)]))
                .collect();
            assert_eq!(cells, expected, "{no_echo}");
            assert!(cells.values().all(|d| *d < 0));
        }
        let mut ignoring = model(vec![laser(0.0, 1)], RayModelParams::default());
        let mut out = Vec::new();
        assert_eq!(
            ignoring
                .integrate(&robot, &[50.0], &mut out)
                .expect("frame"),
            0
        );
        assert!(out.is_empty());
    }

    #[test]
    fn a_rig_of_a_sonar_and_a_laser_maps_both() {
        let mut m = model(vec![sonar(), laser(-1.0, 3)], RayModelParams::default());
        assert_eq!(m.readings(), 4);
        assert_eq!(m.integrator().cone_models().len(), 1);
        assert_eq!(m.integrator().ray_models().len(), 1);
        // The sonar's cone is cut at its own maximum range.
        assert_eq!(
            m.integrator().cone_models()[0].params().max_mapped_range,
            6.0
        );
        let robot = Pose2::new(0.01, 0.01, 0.0);
        // The laser sees a post at 1.5 m that the sonar (echo at 4 m)
        // passes through: the post stays occupied.
        let mut out = Vec::new();
        m.integrate(&robot, &[4.0, 1.5, 1.5, 1.5], &mut out)
            .expect("frame");
        let cells = flatten(&out);
        assert!(cells[&CellIndex::new(30, 0)] > 0, "the post");
        assert!(cells[&CellIndex::new(50, 0)] < 0, "the cone beyond it");
        assert!(cells[&CellIndex::new(80, 0)] > 0, "the sonar's echo");
        // 10° off the axis only the cone reaches.
        let (x, y) = (
            2.0 * 10f64.to_radians().cos(),
            2.0 * 10f64.to_radians().sin(),
        );
        assert!(cells[&RES.cell_of(x, y).expect("cell")] < 0);
    }

    #[test]
    fn wrong_counts_and_bad_readings_are_refused_with_nothing_appended() {
        let mut m = model(vec![sonar(), laser(-1.0, 3)], RayModelParams::default());
        let mut out = Vec::new();
        let err = m
            .integrate(&Pose2::default(), &[1.0; 3], &mut out)
            .expect_err("three of four");
        assert_eq!(err.to_string(), "ranges: expected 4 readings, got 3");
        let err = m
            .integrate(&Pose2::default(), &[1.0, 1.0, f64::NAN, 1.0], &mut out)
            .expect_err("NaN");
        assert_eq!(err.to_string(), "ranges[2] is NaN, not a range");
        assert!(out.is_empty());
        // What the rig calls no echo (infinity, 0 for this laser, its
        // maximum range or past it) is mapped, not refused.
        m.integrate(
            &Pose2::default(),
            &[6.0, f64::INFINITY, 0.0, 70.0],
            &mut out,
        )
        .expect("no echoes");
    }

    #[test]
    fn a_sensor_the_model_cannot_fit_is_named() {
        let mut tiny = sonar();
        tiny.max_range = 0.3;
        tiny.no_echo.at_or_beyond = 0.3;
        let rig = Rig::new("tiny", 0.2, vec![laser(0.0, 1), tiny]).expect("rig");
        let bad = SonarModelParams {
            min_range: 0.2,
            half_angle: 2.0,
            ..SonarModelParams::default()
        };
        // The rig's half-angle replaces the bad one; the rig's minimum
        // range is kept too.
        assert!(RigBeams::new(&rig, bad, RayModelParams::default(), RES, SIZE).is_ok());
        let bad = SonarModelParams {
            max_occupied: 1.5,
            ..SonarModelParams::default()
        };
        let err = RigBeams::new(&rig, bad, RayModelParams::default(), RES, SIZE)
            .expect_err("max_occupied");
        assert!(err.to_string().contains("rig tiny sensor[1]"), "{err}");
        assert!(err.to_string().contains("max_occupied"), "{err}");
    }
}
