//! A ring of sonars, each reading the nearest echo inside its cone.
//!
//! The range each sonar should read at a pose comes from the map's
//! expected-range tables ([`crate::range_table`], held per tile by
//! [`LocalMap`]): one lookup per beam, interpolated between the two
//! nearest stored headings. The measured range is judged against it by
//! the beam model ([`crate::beam_model`]), tabulated per frame over the
//! predicted range, so a particle costs one table read per beam and an
//! integer sum; the sum is tempered by τ (see the beam model's docs).
//!
//! **Echoes from space the map has not seen.** While the filter tracks one
//! pose ([`SensorModel::set_reference`]), a beam that reads shorter than
//! the map predicts there, with no known wall as near as its echo along
//! its cone and unknown cells where the echo is, heard a wall the map does
//! not have yet: a robot at the edge of a map still being built hears them
//! all the time. Such a beam scores every particle alike, as if the map
//! had predicted it, so it neither drags the filter towards poses whose
//! known walls happen to lie at that range nor reads as a robot that is
//! lost. A beam whose echo comes from past a known wall still counts:
//! that is how a kidnapped robot finds out.

use deog_grid::{Occupancy, OccupancyView, Pose2, Resolution, SensorRing, TileKey};

use crate::beam_model::{BeamModel, BeamModelParams, TABLE_SCALE};
use crate::error::LocalizerError;
use crate::local_map::LocalMap;
use crate::sensors::SensorModel;

/// The sonar ring's sensor model.
#[derive(Debug, Clone)]
pub struct SonarCone {
    /// The sonars' mounts.
    ring: SensorRing,
    /// The mounts where the current frame's readings were taken
    /// ([`SensorModel::set_reading_poses`]).
    fired: SensorRing,
    model: BeamModel,
    /// The current frame's measured-range slot per beam.
    beam_slots: Vec<usize>,
    /// The pose the filter tracks, when it tracks one.
    reference: Option<Pose2>,
    /// Per beam of the current frame: the log-likelihood every particle
    /// gets when its echo came from space the map has not seen.
    unexplained: Vec<Option<i16>>,
    /// The readings `unexplained` was marked for.
    unexplained_for: Vec<f64>,
    /// Flat tables for those beams, reused from frame to frame.
    flat_tables: Vec<Vec<i16>>,
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
            reference: None,
            unexplained: Vec::with_capacity(ring.len()),
            unexplained_for: Vec::with_capacity(ring.len()),
            flat_tables: vec![Vec::new(); ring.len()],
            fired: ring.clone(),
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

    /// Marks the beams of `ranges` whose echoes, seen from the reference
    /// pose, came from space the map has not seen (see the module's docs);
    /// none without a reference. `tiles` have their tables built.
    fn mark_unexplained(&mut self, map: &mut LocalMap, tiles: &[TileKey], ranges: &[f64]) {
        self.unexplained.clear();
        self.unexplained.resize(ranges.len(), None);
        self.unexplained_for.clear();
        self.unexplained_for.extend_from_slice(ranges);
        let Some(reference) = self.reference else {
            return;
        };
        let no_echo = self.model.no_echo_slot();
        let params = *self.model.params();
        // Beams shorter than the map predicts at the reference: only those
        // can have heard an unmapped wall.
        let mut short = Vec::new();
        {
            let window = map.window(tiles);
            for (k, sensor) in self.fired.sensor_poses(&reference).enumerate() {
                let measured = self.beam_slots[k];
                if measured >= no_echo {
                    continue;
                }
                let (sin, cos) = sensor.theta.sin_cos();
                let expected =
                    window.expected_slot(sensor.x, sensor.y, sensor.theta, (cos, sin), no_echo);
                let z = ranges[k];
                let margin_cm = 200.0 * (params.hit_sigma_m + params.hit_sigma_per_m * z);
                if expected > 0 && (measured as f64 + margin_cm) < expected as f64 {
                    short.push((k, sensor, z));
                }
            }
        }
        let settings = map.settings();
        let (resolution, half_angle) = (settings.resolution, settings.geometry.half_angle);
        for (k, sensor, z) in short {
            if echo_from_unseen_space(&*map, resolution, &sensor, half_angle, z) {
                let table = self.model.cached_table(self.beam_slots[k]);
                let value = table[self.beam_slots[k]];
                self.unexplained[k] = Some(value);
                let flat = &mut self.flat_tables[k];
                flat.clear();
                flat.resize(no_echo + 1, value);
            }
        }
    }

    /// The frame's table per beam: the beam model's for its measured range,
    /// or a flat one where its echo is unexplained.
    fn frame_tables(&self) -> Result<Vec<&[i16]>, LocalizerError> {
        beam_tables(&self.model, &self.beam_slots)?
            .into_iter()
            .zip(self.unexplained.iter().zip(&self.flat_tables))
            .map(|(table, (value, flat))| Ok(if value.is_some() { flat } else { table }))
            .collect()
    }
}

/// Fractions of the half-angle at which [`echo_from_unseen_space`] casts
/// rays across a cone.
const CONE_RAYS: [f64; 3] = [-0.8, 0.0, 0.8];

/// Whether an echo at `range` of the sonar at `sensor` (a cone of
/// `half_angle`) came from space `map` has not seen: no ray across the
/// cone meets a known occupied cell before the echo (within two cells
/// past it), and some ray finds unknown cells within two cells of it.
fn echo_from_unseen_space(
    map: &impl OccupancyView,
    resolution: Resolution,
    sensor: &Pose2,
    half_angle: f64,
    range: f64,
) -> bool {
    let step = resolution.metres();
    let tolerance = 2.0 * step;
    let mut unknown_at_echo = false;
    for share in CONE_RAYS {
        let (sin, cos) = (sensor.theta + share * half_angle).sin_cos();
        let mut d = 0.0;
        while d <= range + tolerance {
            let Ok(cell) = resolution.cell_of(sensor.x + cos * d, sensor.y + sin * d) else {
                return false;
            };
            match map.occupancy(cell) {
                Occupancy::Occupied => return false,
                Occupancy::Unknown if d >= range - tolerance => unknown_at_echo = true,
                _ => {}
            }
            d += step;
        }
    }
    unknown_at_echo
}

impl SensorModel for SonarCone {
    fn readings(&self) -> usize {
        self.fired.len()
    }

    fn reach(&self) -> f64 {
        self.ring
            .mounts()
            .iter()
            .map(|m| m.x.hypot(m.y))
            .fold(0.0, f64::max)
    }

    fn observations(&self) -> f64 {
        self.fired.len() as f64 * self.model.params().tempering
    }

    fn set_reference(&mut self, reference: Option<Pose2>) {
        self.reference = reference;
    }

    fn set_reading_poses(&mut self, robot_at: Option<&[Pose2]>) {
        self.fired = match robot_at {
            Some(at) => self.ring.as_fired(at),
            None => self.ring.clone(),
        };
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
        self.mark_unexplained(map, tiles, ranges);
        let window = map.window(tiles);
        let no_echo = self.model.no_echo_slot();
        // Each mount's offset, the sine and cosine of its heading, and its
        // heading as a position among the table's stored headings.
        let headings = window.headings() as f64;
        let mounts: Vec<(f64, f64, f64, f64, f64)> = self
            .fired
            .mounts()
            .iter()
            .map(|m| {
                let (s, c) = m.theta.sin_cos();
                (m.x, m.y, c, s, window.heading_position(m.theta))
            })
            .collect();
        let to_nats = self.model.params().tempering / TABLE_SCALE;
        let tables = self.frame_tables()?;
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
        // The frame the particles were last scored with keeps its
        // unexplained beams; any other is judged by the map alone.
        if self.unexplained_for != ranges {
            self.unexplained.clear();
            self.unexplained.resize(ranges.len(), None);
        }
        let keys = map.tables_under(&self.fired, pose)?;
        let no_echo = self.model.no_echo_slot();
        let mut total = 0i32;
        let tables = self.frame_tables()?;
        let window = map.window(&keys);
        for (sensor, table) in self.fired.sensor_poses(pose).zip(&tables) {
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

#[cfg(test)]
mod tests {
    use deog_grid::CellIndex;

    use super::*;

    /// Cells west of column `seen_to` known: free, but for a wall at
    /// column `wall` (if any); the rest unknown. 5 cm cells.
    struct Corridor {
        seen_to: i32,
        wall: Option<i32>,
    }

    impl OccupancyView for Corridor {
        fn occupancy(&self, cell: CellIndex) -> Occupancy {
            if Some(cell.x) == self.wall {
                Occupancy::Occupied
            } else if cell.x <= self.seen_to {
                Occupancy::Free
            } else {
                Occupancy::Unknown
            }
        }
    }

    fn unseen(map: &Corridor, range: f64) -> bool {
        // A sonar at the origin looking east, a 15° half-angle.
        let sensor = Pose2::new(0.0, 0.0, 0.0);
        echo_from_unseen_space(map, Resolution::DEFAULT, &sensor, 15f64.to_radians(), range)
    }

    #[test]
    fn an_echo_is_unseen_only_where_the_map_knows_nothing_and_no_wall_stands_before_it() {
        // Known free to 1 m (column 19), unknown past it.
        let edge = Corridor {
            seen_to: 19,
            wall: None,
        };
        assert!(unseen(&edge, 2.0), "an echo in the unknown");
        assert!(!unseen(&edge, 0.6), "an echo in known free space");
        // A known wall at 1.5 m explains an echo there, and one past it
        // (heard through the wall) is not the map's ignorance either.
        let walled = Corridor {
            seen_to: 40,
            wall: Some(30),
        };
        assert!(!unseen(&walled, 1.5));
        assert!(!unseen(&walled, 2.5));
        // The wall stands in the known part; the echo comes from before it.
        let walled_edge = Corridor {
            seen_to: 19,
            wall: Some(30),
        };
        assert!(
            !unseen(&walled_edge, 2.0),
            "the wall is nearer than the echo"
        );
        assert!(unseen(&walled_edge, 1.2), "the echo comes before the wall");
    }
}
