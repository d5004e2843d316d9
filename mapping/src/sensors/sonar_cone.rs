//! A ring of sonars mapped with the analytical sonar model: each reading's
//! cone, region I probably occupied, region II probably empty, folded into
//! one delta per cell per frame ([`deog_grid::FrameIntegrator`]).

use deog_grid::{
    ConeGuard, FrameIntegrator, GridError, Pose2, Resolution, SensorRing, SonarModel,
    SonarModelParams, TileDelta, TileSize,
};

use crate::sensors::InverseSensorModel;

/// The sonar ring's inverse sensor model.
#[derive(Debug, Clone)]
pub struct SonarCone {
    integrator: FrameIntegrator,
    /// The sonars' mounts, as built.
    mounts: SensorRing,
}

impl SonarCone {
    /// `ring`'s sonars with the model `params`, on a grid of `resolution`
    /// and `tile_size`.
    pub fn new(
        ring: SensorRing,
        params: SonarModelParams,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Result<Self, GridError> {
        let model = SonarModel::new(params)?;
        Ok(Self {
            mounts: ring.clone(),
            integrator: FrameIntegrator::new(model, ring, resolution, tile_size),
        })
    }
}

impl InverseSensorModel for SonarCone {
    fn readings(&self) -> usize {
        self.integrator.ring().len()
    }

    fn set_reading_poses(&mut self, robot_at: Option<&[Pose2]>) {
        let ring = match robot_at {
            Some(at) => self.mounts.as_fired(at),
            None => self.mounts.clone(),
        };
        self.integrator.set_ring(ring);
    }

    fn integrate(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError> {
        Ok(self.integrator.integrate(robot, readings, out)?.cells)
    }

    fn integrate_guarded(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        guard: &dyn ConeGuard,
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError> {
        Ok(self
            .integrator
            .integrate_guarded(robot, readings, guard, out)?
            .cells)
    }
}
