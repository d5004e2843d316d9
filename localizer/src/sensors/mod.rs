//! The filter's sensor side: how likely a frame of readings is at a
//! particle's pose, given the map. The filter ([`crate::filter::Mcl`])
//! knows nothing of cones or beams; it asks a [`SensorModel`] to score its
//! particles, as amcl keeps `sensors/` apart from `pf/` and
//! `motion_model/`. A new kind of sensor (a laser's beam model, say) is a
//! new file here implementing the trait, handed to
//! [`crate::filter::Mcl::with_sensor`] (or built by [`SensorChoice`]).
//!
//! A model also says which tiles a frame needs
//! ([`SensorModel::tiles_needed`]) and which of them, with their
//! neighbours, the map must fetch ([`SensorModel::missing_tiles`]): a
//! sonar reads the tiles under its cones, a likelihood field the tiles
//! where a laser's endpoints fall, up to 50 m away.
//!
//! # Layout
//! - [`sonar_cone`]: [`SonarCone`], a ring of sonars, each reading the
//!   nearest echo in its cone: expected ranges from the map's range tables,
//!   scored by the beam model ([`crate::beam_model`]).
//! - [`likelihood_field`]: [`LikelihoodField`], any rig's echoes judged by
//!   how far their endpoints fall from the nearest occupied cell, over the
//!   map's distance fields.
//! - [`choice`]: [`SensorChoice`], which of the two a rig is scored with.
//! - [`reach`]: [`tiles_within_reach`], the tiles under the particles'
//!   sensors (what a sonar frame needs).

pub mod choice;
pub mod likelihood_field;
pub mod reach;
pub mod sonar_cone;

pub use choice::SensorChoice;
pub use likelihood_field::{LikelihoodField, LikelihoodFieldParams};
pub use reach::tiles_within_reach;
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

    /// The tiles a frame of `readings` needs scored at `particles`: what
    /// [`Self::score_particles`] is handed and the cache keeps. By default
    /// the tiles within [`Self::reach`] of the particles
    /// ([`tiles_within_reach`]). Called before the frame is checked: a
    /// reading that is not a range is passed over, not refused.
    fn tiles_needed(&self, map: &LocalMap, particles: &[Pose2], readings: &[f64]) -> Vec<TileKey> {
        let _ = readings;
        tiles_within_reach(map, particles, self.reach(), map.table_capacity())
    }

    /// The tiles, sorted, the map must fetch before `needed` can be scored:
    /// by default those the range tables of `needed` read and the map does
    /// not hold ([`LocalMap::missing_tiles`]).
    fn missing_tiles(&self, map: &LocalMap, needed: &[TileKey]) -> Vec<TileKey> {
        map.missing_tiles(needed.iter().copied())
    }

    /// How many tiles' tables one correction may need at once within the
    /// map's budget: global localization is refused on a map with more
    /// tiles of free space, and recovery searches half as many. By default
    /// [`LocalMap::table_capacity`] (range tables).
    fn tile_capacity(&self, map: &LocalMap) -> usize {
        map.table_capacity()
    }

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
    /// tiles the frame needs ([`Self::tiles_needed`]); whatever the model
    /// derives from them (range tables, distance fields) it builds in
    /// `map`. Returns how many such tables it built. The frame has passed
    /// [`Self::check_frame`].
    fn score_particles(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        particles: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError>;

    /// As [`Self::score_particles`], but each pose scored as if it were
    /// alone, so that its score does not depend on the others scored with
    /// it (a likelihood field's beam skipping looks at the whole set): for
    /// comparing poses with one another. By default,
    /// [`Self::score_particles`].
    fn score_poses(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        poses: &[Pose2],
        readings: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError> {
        self.score_particles(map, tiles, poses, readings, out)
    }

    /// The log-likelihood of `readings` at one `pose`, as a particle there
    /// would get it: for diagnostics and tests.
    fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<f64, LocalizerError>;

    /// The filter tells the model, before each frame is scored, whether it
    /// is searching (has not settled on one pose): a model may score
    /// frames more softly then. By default, ignored.
    fn set_searching(&mut self, searching: bool) {
        let _ = searching;
    }

    /// The filter tells the model, before each frame is scored, the pose
    /// it tracks while it holds mostly one mode (`None` while it searches): a
    /// model may judge the frame's readings there once. The sonar passes
    /// over echoes from space the map has not seen ([`sonar_cone`]). By
    /// default, ignored.
    fn set_reference(&mut self, reference: Option<Pose2>) {
        let _ = reference;
    }

    /// The filter tells the model, before each frame is scored, where the
    /// robot stood when each reading was taken, in the frame pose's own
    /// frame (a ring that fires in turn while the robot moves;
    /// [`deog_grid::RingFiring`]), or `None` for readings taken with the
    /// frame. The sonar scores each where it was taken. By default,
    /// ignored.
    fn set_reading_poses(&mut self, robot_at: Option<&[Pose2]>) {
        let _ = robot_at;
    }

    /// Whether a mode of many particles is judged by the likelihood at its
    /// mean pose ([`crate::cluster::Clusters::evidence`]) rather than by
    /// its best particle. Right when the likelihood's peak is wider than a
    /// mode's spread, so that the mean lies on it: a sonar's cones. A
    /// sharp peak (a laser's hundreds of echoes) is missed by the mean of
    /// a mode spread over a few bins, and one of its many particles stands
    /// for it better. By default, at the mean.
    fn judges_modes_at_mean(&self) -> bool {
        true
    }

    /// Whether [`Self::refine_pose`] may refine a pose: when not, the
    /// localizer skips fetching its tiles.
    fn refines(&self) -> bool {
        false
    }

    /// `pose` refined by matching `readings` against the map
    /// ([`crate::refine`]), over `tiles` ([`Self::tiles_needed`] at the
    /// pose, fetched); `None` when the model does not refine or the
    /// refinement is not to be trusted. By default, `None`.
    fn refine_pose(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        pose: &Pose2,
        readings: &[f64],
    ) -> Result<Option<Pose2>, LocalizerError> {
        let _ = (map, tiles, pose, readings);
        Ok(None)
    }
}
