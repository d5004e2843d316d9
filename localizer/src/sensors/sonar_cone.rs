//! A ring of sonars, each reading the nearest echo inside its cone.
//!
//! The range each sonar should read at a pose comes from the map's
//! expected-range tables ([`crate::range_table`], held per tile by
//! [`LocalMap`]): one lookup per beam, interpolated between the two
//! nearest stored headings. The measured range is judged against it by
//! the beam model ([`crate::beam_model`]), tabulated per frame over the
//! predicted range, so a particle costs one table read per beam and an
//! integer sum; the sum is tempered by τ (see the beam model's docs).

use deog_grid::{Pose2, SensorRing, TileKey};

use crate::beam_model::{BeamModel, BeamModelParams, TABLE_SCALE};
use crate::error::LocalizerError;
use crate::local_map::LocalMap;
use crate::sensors::SensorModel;

/// The sonar ring's sensor model.
#[derive(Debug, Clone)]
pub struct SonarCone {
    ring: SensorRing,
    model: BeamModel,
    /// The current frame's measured-range slot per beam.
    beam_slots: Vec<usize>,
}

impl SonarCone {
    /// A model of `ring`'s sonars with the beam model `beam`.
    pub fn new(ring: SensorRing, beam: BeamModelParams) -> Result<Self, LocalizerError> {
        if ring.is_empty() {
            return Err(LocalizerError::Invalid(
                "the sensor ring has no sonar".into(),
            ));
        }
        Ok(Self {
            model: BeamModel::new(beam)?,
            beam_slots: Vec::with_capacity(ring.len()),
            ring,
        })
    }

    /// The sonars' mounts.
    pub fn ring(&self) -> &SensorRing {
        &self.ring
    }

    /// The beam model.
    pub fn beam_model(&self) -> &BeamModel {
        &self.model
    }

    /// Each beam's slot of the measured range, and its table built.
    fn prepare_beams(&mut self, ranges: &[f64]) {
        self.beam_slots.clear();
        for &z in ranges {
            let slot = self.model.measured_slot(z);
            self.model.cached_table(slot);
            self.beam_slots.push(slot);
        }
    }
}

impl SensorModel for SonarCone {
    fn readings(&self) -> usize {
        self.ring.len()
    }

    fn reach(&self) -> f64 {
        self.ring
            .mounts()
            .iter()
            .map(|m| m.x.hypot(m.y))
            .fold(0.0, f64::max)
    }

    fn observations(&self) -> f64 {
        self.ring.len() as f64 * self.model.params().tempering
    }

    fn score_particles(
        &mut self,
        map: &mut LocalMap,
        tiles: &[TileKey],
        particles: &[Pose2],
        ranges: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<usize, LocalizerError> {
        self.prepare_beams(ranges);
        let tables_built = map.ensure_tables(tiles.iter().copied(), particles)?;
        let window = map.window(tiles);
        let no_echo = self.model.no_echo_slot();
        // Each mount's offset, the sine and cosine of its heading, and its
        // heading as a position among the table's stored headings.
        let headings = window.headings() as f64;
        let mounts: Vec<(f64, f64, f64, f64, f64)> = self
            .ring
            .mounts()
            .iter()
            .map(|m| {
                let (s, c) = m.theta.sin_cos();
                (m.x, m.y, c, s, window.heading_position(m.theta))
            })
            .collect();
        let to_nats = self.model.params().tempering / TABLE_SCALE;
        let tables = beam_tables(&self.model, &self.beam_slots)?;
        let beams = mounts.len();
        let mut sensors = vec![[0.0f64; 5]; beams];
        for p in particles {
            let (sin, cos) = p.theta.sin_cos();
            let base = window.heading_position(p.theta);
            // Where each sonar sits and points, in one pass the compiler can
            // keep in registers, before the table reads.
            for (sensor, &(mx, my, mc, ms, mp)) in sensors.iter_mut().zip(&mounts) {
                let position = base + mp;
                *sensor = [
                    p.x + cos * mx - sin * my,
                    p.y + sin * mx + cos * my,
                    cos * mc - sin * ms,
                    sin * mc + cos * ms,
                    if position >= headings {
                        position - headings
                    } else {
                        position
                    },
                ];
            }
            let mut log_likelihood = 0i32;
            for (&[sx, sy, beam_cos, beam_sin, position], table) in sensors.iter().zip(&tables) {
                let slot = window.expected_slot_at(sx, sy, position, (beam_cos, beam_sin), no_echo);
                log_likelihood += i32::from(table[slot]);
            }
            out.push(f64::from(log_likelihood) * to_nats);
        }
        Ok(tables_built)
    }

    fn score_pose(
        &mut self,
        map: &mut LocalMap,
        pose: &Pose2,
        ranges: &[f64],
    ) -> Result<f64, LocalizerError> {
        self.check_frame(ranges)?;
        let pose = &pose.validate("pose")?;
        self.prepare_beams(ranges);
        let keys = map.tables_under(&self.ring, pose)?;
        let window = map.window(&keys);
        let no_echo = self.model.no_echo_slot();
        let mut total = 0i32;
        let tables = beam_tables(&self.model, &self.beam_slots)?;
        for (sensor, table) in self.ring.sensor_poses(pose).zip(&tables) {
            let (sin, cos) = sensor.theta.sin_cos();
            let slot = window.expected_slot(sensor.x, sensor.y, sensor.theta, (cos, sin), no_echo);
            total += i32::from(table[slot]);
        }
        Ok(f64::from(total) * self.model.params().tempering / TABLE_SCALE)
    }
}

/// The tables `SonarCone::prepare_beams` made ready, one per beam.
fn beam_tables<'a>(
    model: &'a BeamModel,
    slots: &[usize],
) -> Result<Vec<&'a [i16]>, LocalizerError> {
    slots
        .iter()
        .map(|&slot| {
            model.built_table(slot).ok_or_else(|| {
                LocalizerError::Invalid(format!("no beam table for range slot {slot}"))
            })
        })
        .collect()
}
