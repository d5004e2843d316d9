//! The cartographer's sensor side: an inverse sensor model turns one frame
//! of readings, taken at a known pose, into log-odds evidence per cell.
//! The cartographer ([`crate::Cartographer`]) only picks the pose and
//! names the frame in errors; a new kind of sensor is a new file here
//! implementing [`InverseSensorModel`], handed to
//! [`crate::Cartographer::with_sensor`].
//!
//! # Layout
//! - [`sonar_cone`]: [`SonarCone`], the thesis's analytical sonar model
//!   (eqs. 3.1 to 3.4) over each sonar's cone of a ring.
//! - [`rig_beams`]: [`RigBeams`], any `deog_rig::Rig` beam by beam: its
//!   sonars' cones with the sonar model, its lasers' rays with the ray
//!   model, one frame folded together.

pub mod rig_beams;
pub mod sonar_cone;

pub use rig_beams::RigBeams;
pub use sonar_cone::SonarCone;

use deog_grid::{ConeGuard, GridError, Pose2, TileDelta};

/// One frame of readings at a pose to per-tile log-odds deltas.
pub trait InverseSensorModel: std::fmt::Debug + Send {
    /// Readings in one frame, in the order the sensor reports them.
    fn readings(&self) -> usize;

    /// Appends the frame's deltas to `out`, one per touched tile, for the
    /// robot at `robot` (world frame); returns how many cells they touch.
    /// Fails, appending nothing, on bad input (a wrong count of readings,
    /// numbers that are not ranges).
    fn integrate(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError>;

    /// Where the robot stood when each reading of the frames that follow
    /// was taken, in the frame pose's own frame (a ring that fires in
    /// turn while the robot moves, [`deog_grid::RingFiring`]), or `None`
    /// for readings taken with the frame. By default, ignored.
    fn set_reading_poses(&mut self, robot_at: Option<&[Pose2]>) {
        let _ = robot_at;
    }

    /// [`Self::integrate`] guarded by the map being written: a sensor
    /// whose evidence should stop at known walls (a sonar cone) stops
    /// there; by default the guard is ignored.
    fn integrate_guarded(
        &mut self,
        robot: &Pose2,
        readings: &[f64],
        guard: &dyn ConeGuard,
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, GridError> {
        let _ = guard;
        self.integrate(robot, readings, out)
    }
}
