//! The filter's sensor side: how likely a frame of readings is at a
//! particle's pose, given the map. The filter ([`crate::filter::Mcl`])
//! knows nothing of cones or beams; it asks a [`SensorModel`] to score its
//! particles, as amcl keeps `sensors/` apart from `pf/` and
//! `motion_model/`. A new kind of sensor (a laser's beams, a likelihood
//! field) is a new file here implementing the trait, handed to
//! [`crate::filter::Mcl::with_sensor`].
//!
//! # Layout
//! - [`sonar_cone`]: [`SonarCone`], a ring of sonars, each reading the
//!   nearest echo in its cone: expected ranges from the map's range tables,
//!   scored by the beam model ([`crate::beam_model`]).

pub mod sonar_cone;

pub use sonar_cone::SonarCone;

use deog_grid::{Pose2, TileKey};

use crate::error::LocalizerError;
use crate::local_map::LocalMap;

/// A sensor's likelihood of one frame of readings at a pose on the map.
pub trait SensorModel: std::fmt::Debug + Send {
    /// Readings in one frame, in the order the sensor reports them.
    fn readings(&self) -> usize;

    /// How far from the robot's centre the sensors sit, metres: a particle
    /// reads the tiles within this distance of it.
    fn reach(&self) -> f64;

    /// The frame's weight in independent observations (readings times any
    /// tempering): the filter takes the mean likelihood per observation,
    /// so that its scale does not depend on the sensor.
    fn observations(&self) -> f64;

    /// Refuses a frame that cannot be scored: the wrong number of
    /// readings, or a reading that is not a range (NaN or negative;
    /// infinite means no echo).
    fn check_frame(&self, readings: &[f64]) -> Result<(), LocalizerError> {
        if readings.len() != self.readings() {
            return Err(LocalizerError::Invalid(format!(
                "the frame has {} ranges, the sensor reads {}",
                readings.len(),
                self.readings()
            )));
        }
        match readings.iter().position(|r| r.is_nan() || *r < 0.0) {
            Some(i) => Err(LocalizerError::Invalid(format!(
                "ranges[{i}] is {}, not a range",
                readings[i]
            ))),
            None => Ok(()),
        }
    }

    /// Each particle's log-likelihood of `readings` (tempered as the model
    /// says), pushed onto `out` in the particles' order. `tiles` are the
    /// tiles the particles' sensors fall in ([`crate::filter::Mcl::tiles_needed`]);
    /// whatever the model derives from them it builds in `map`. Returns how
    /// many such tables it built. The frame has passed
    /// [`Self::check_frame`].
    fn score_particles(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        particles: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError>;

    /// The log-likelihood of `readings` at one `pose`, as a particle there
    /// would get it: for diagnostics and tests.
    fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<f64, LocalizerError>;
}
