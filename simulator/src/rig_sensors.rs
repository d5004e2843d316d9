//! A rig's sensors in the simulator: one frame of readings, in the rig's
//! beam order, whatever mix of sonars and lasers it carries.
//!
//! Sonar beams fire through [`SonarRing`]: they are grouped by their
//! figures (range limits, half-angle, no-echo value), each group one ring
//! with one [`SonarParams`] (the rig's figures with the simulation's noise,
//! specular and dropout options), at most [`MAX_SONARS`] to a group. Laser
//! beams fire through [`Lasers`]. Groups fire in the order of their first
//! beam, then the lasers, so a given random state always gives the same
//! frame; a rig of one kind of sonar (the Scout's) is one ring fired
//! straight into the frame, exactly as before rigs existed.
//!
//! With [`SonarFiring::Sequential`] the sonars fire one at a time in the
//! rig's order of its sonars ([`RigSensors::fire_sequential`] takes the
//! robot's pose at each firing); crosstalk is between neighbours of one
//! group's ring (for a rig of one kind of sonar, the rig's own order).
//!
//! A sonar reading at its maximum range (no echo, or an echo clamped or
//! dropped there) reads the sonar's no-echo value when the rig gives one
//! other than the maximum range.

use deog_grid::{Pose2, SensorRing};
use deog_rig::{BeamShape, Rig};
use deog_world::SegmentIndex;
use rand::Rng;

use crate::error::SimError;
use crate::laser::{LaserParams, Lasers, no_echo_reading};
use crate::sonar::{MAX_SONARS, SonarParams, SonarRing};
#[cfg(doc)]
use crate::sonar_firing::SonarFiring;

/// Sonars of one set of figures, fired as one ring.
#[derive(Debug, Clone)]
struct SonarGroup {
    ring: SonarRing,
    /// The frame slot of each of its sonars, in ring order.
    slots: Vec<usize>,
    /// Each of its sonars' place among the rig's sonars, in ring order.
    ordinals: Vec<usize>,
    /// The first slot, when the slots follow one another: the ring fires
    /// straight into the frame.
    contiguous: Option<usize>,
    /// What a reading at max range becomes, when not max range itself.
    no_echo: Option<f64>,
}

/// A sonar group being gathered.
struct Draft {
    params: SonarParams,
    no_echo: Option<f64>,
    mounts: Vec<Pose2>,
    slots: Vec<usize>,
    ordinals: Vec<usize>,
}

/// Every sensor of a rig, ready to fire.
#[derive(Debug, Clone)]
pub struct RigSensors {
    rig: Rig,
    sonars: Vec<SonarGroup>,
    /// How many of the rig's beams are sonars.
    sonar_count: usize,
    lasers: Lasers,
}

impl RigSensors {
    /// The sensors of `rig`: its sonars with `sonar`'s noise, specular and
    /// dropout figures (the range limits and half-angle are each sonar's
    /// own), its lasers with `laser`. Errors on figures out of range.
    pub fn new(rig: Rig, sonar: SonarParams, laser: LaserParams) -> Result<Self, SimError> {
        // Groups in the order of their first beams.
        let mut groups: Vec<Draft> = Vec::new();
        let mut sonar_count = 0;
        for (slot, beam) in rig.beams().iter().enumerate() {
            let BeamShape::Cone { half_angle } = beam.shape else {
                continue;
            };
            let ordinal = sonar_count;
            sonar_count += 1;
            let params = SonarParams {
                min_range: beam.min_range,
                max_range: beam.max_range,
                half_angle,
                ..sonar
            };
            let reading = no_echo_reading(&beam.no_echo);
            let no_echo = (reading != beam.max_range).then_some(reading);
            let same = |g: &Draft| {
                g.params == params
                    && g.no_echo.map(f64::to_bits) == no_echo.map(f64::to_bits)
                    && g.slots.len() < MAX_SONARS
            };
            match groups.iter_mut().find(|g| same(g)) {
                Some(group) => {
                    group.mounts.push(beam.mount);
                    group.slots.push(slot);
                    group.ordinals.push(ordinal);
                }
                None => groups.push(Draft {
                    params,
                    no_echo,
                    mounts: vec![beam.mount],
                    slots: vec![slot],
                    ordinals: vec![ordinal],
                }),
            }
        }
        let sonars = groups
            .into_iter()
            .map(|g| {
                let ring = SensorRing::from_mounts(g.mounts)
                    .map_err(|e| SimError::invalid("rig", e.to_string()))?;
                let contiguous = g
                    .slots
                    .windows(2)
                    .all(|w| w[1] == w[0] + 1)
                    .then_some(g.slots[0]);
                Ok(SonarGroup {
                    ring: SonarRing::new(ring, g.params)?,
                    slots: g.slots,
                    ordinals: g.ordinals,
                    contiguous,
                    no_echo: g.no_echo,
                })
            })
            .collect::<Result<Vec<_>, SimError>>()?;
        let lasers = Lasers::new(&rig, laser)?;
        Ok(Self {
            rig,
            sonars,
            sonar_count,
            lasers,
        })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Readings per frame (the length `fire` expects of its output).
    pub fn readings(&self) -> usize {
        self.rig.readings()
    }

    /// How many of the rig's beams are sonars (the length
    /// [`fire_sequential`](Self::fire_sequential) expects of its poses).
    pub fn sonar_count(&self) -> usize {
        self.sonar_count
    }

    /// The sonar rings the rig's sonars fire as, one per set of figures.
    pub fn sonar_rings(&self) -> impl Iterator<Item = &SonarRing> {
        self.sonars.iter().map(|g| &g.ring)
    }

    /// The lasers.
    pub fn lasers(&self) -> &Lasers {
        &self.lasers
    }

    /// One frame for a robot at `pose` (world frame) among the walls of
    /// `index`: every reading, in the rig's beam order, with noise drawn
    /// from `rng`. Errors on a non-finite pose or an `out` whose length is
    /// not [`readings`](Self::readings).
    pub fn fire<R: Rng + ?Sized>(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        rng: &mut R,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.frame(out, |group, slots| group.ring.fire(index, pose, rng, slots))?;
        if !self.lasers.is_empty() {
            self.lasers.fire(index, pose, rng, out)?;
        }
        Ok(())
    }

    /// One frame of sonars fired one after another: as
    /// [`fire`](Self::fire), but the rig's `k`th sonar (in beam order,
    /// counting sonars only) reads for a robot at `sonar_poses[k]`, its pose
    /// when that sonar fired; the lasers read at `pose`. Errors on a
    /// non-finite pose or a `sonar_poses` whose length is not
    /// [`sonar_count`](Self::sonar_count) or an `out` whose length is not
    /// [`readings`](Self::readings).
    pub fn fire_sequential<R: Rng + ?Sized>(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        sonar_poses: &[Pose2],
        rng: &mut R,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        if sonar_poses.len() != self.sonar_count {
            return Err(SimError::invalid(
                "sonar poses",
                format!(
                    "expected one per sonar ({}), got {}",
                    self.sonar_count,
                    sonar_poses.len()
                ),
            ));
        }
        self.frame(out, |group, slots| {
            let mut poses = [Pose2::default(); MAX_SONARS];
            for (pose, &k) in poses.iter_mut().zip(&group.ordinals) {
                *pose = sonar_poses[k];
            }
            group
                .ring
                .fire_posed(index, &poses[..group.ordinals.len()], rng, slots)
        })?;
        if !self.lasers.is_empty() {
            self.lasers.fire(index, pose, rng, out)?;
        }
        Ok(())
    }

    /// The readings without noise or dropouts, in beam order.
    pub fn true_ranges(
        &self,
        index: &SegmentIndex,
        pose: &Pose2,
        out: &mut [f64],
    ) -> Result<(), SimError> {
        self.frame(out, |group, slots| {
            group.ring.true_ranges(index, pose, slots)
        })?;
        if !self.lasers.is_empty() {
            self.lasers.true_ranges(index, pose, out)?;
        }
        Ok(())
    }

    /// Checks `out` and has each sonar group write its readings into their
    /// slots through `fire`.
    fn frame(
        &self,
        out: &mut [f64],
        mut fire: impl FnMut(&SonarGroup, &mut [f64]) -> Result<(), SimError>,
    ) -> Result<(), SimError> {
        let n = self.readings();
        if out.len() != n {
            return Err(SimError::invalid(
                "ranges",
                format!("expected {n} slots, got {}", out.len()),
            ));
        }
        for group in &self.sonars {
            let len = group.slots.len();
            match group.contiguous {
                Some(first) => fire(group, &mut out[first..first + len])?,
                None => {
                    let mut scratch = [0.0; MAX_SONARS];
                    fire(group, &mut scratch[..len])?;
                    for (&slot, &range) in group.slots.iter().zip(&scratch) {
                        out[slot] = range;
                    }
                }
            }
            if let Some(no_echo) = group.no_echo {
                let max_range = group.ring.params().max_range;
                for &slot in &group.slots {
                    if out[slot] >= max_range {
                        out[slot] = no_echo;
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_rig::{NoEcho, RangeSensor, SensorKind, load_rig_spec, parse_rig};
    use deog_world::{Point2, Segment};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn room() -> SegmentIndex {
        let corners = [(-3.0, -2.0), (4.0, -2.0), (4.0, 2.5), (-3.0, 2.5)];
        SegmentIndex::new(
            (0..4)
                .map(|i| {
                    let (a, b) = (corners[i], corners[(i + 1) % 4]);
                    Segment::new(Point2::new(a.0, a.1), Point2::new(b.0, b.1))
                })
                .collect(),
        )
    }

    #[test]
    fn the_scout_fires_as_the_ring_it_always_was() {
        let sensors = RigSensors::new(
            deog_rig::scout(),
            SonarParams::default(),
            LaserParams::default(),
        )
        .expect("valid");
        assert_eq!(sensors.sonar_rings().count(), 1);
        let ring = SonarRing::scout();
        let index = room();
        let pose = Pose2::new(0.5, -0.3, 2.0);
        let (mut a, mut b) = ([0.0; 16], [0.0; 16]);
        let (mut rng_a, mut rng_b) = (ChaCha8Rng::seed_from_u64(4), ChaCha8Rng::seed_from_u64(4));
        for _ in 0..20 {
            sensors
                .fire(&index, &pose, &mut rng_a, &mut a)
                .expect("fires");
            ring.fire(&index, &pose, &mut rng_b, &mut b).expect("fires");
            assert_eq!(a, b);
        }
    }

    #[test]
    fn a_mixed_rig_reads_in_beam_order() {
        // A sonar, a 5-ray laser, two sonars of other figures, a sonar
        // like the first: three groups and a laser, interleaved.
        let rig = parse_rig(
            r#"
            name = "mixed"
            [[sensor]]
            kind = "sonar"
            half_angle_deg = 15
            min_range_m = 0.1
            max_range_m = 8
            [[sensor]]
            kind = "laser"
            first_angle_deg = -20
            angle_step_deg = 10
            beam_count = 5
            min_range_m = 0.05
            max_range_m = 30
            [[sensor]]
            kind = "sonar"
            heading_deg = 90
            half_angle_deg = 10
            min_range_m = 0.1
            max_range_m = 2.8
            no_echo_m = 6
            [[sensor]]
            kind = "sonar"
            heading_deg = 180
            half_angle_deg = 10
            min_range_m = 0.1
            max_range_m = 2.8
            no_echo_m = 6
            [[sensor]]
            kind = "sonar"
            heading_deg = -90
            half_angle_deg = 15
            min_range_m = 0.1
            max_range_m = 8
            "#,
            "test",
        )
        .expect("valid rig");
        let sensors = RigSensors::new(rig.clone(), SonarParams::exact(), LaserParams::exact())
            .expect("valid");
        assert_eq!(sensors.sonar_rings().count(), 2);
        assert_eq!(sensors.readings(), 9);
        // The room: walls at x = 4 and -3, y = -2 and 2.5.
        let index = room();
        let mut out = [0.0; 9];
        sensors
            .true_ranges(&index, &Pose2::default(), &mut out)
            .expect("fires");
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        assert!(close(out[0], 4.0), "sonar ahead: {out:?}");
        for (k, deg) in [-20.0f64, -10.0, 0.0, 10.0, 20.0].iter().enumerate() {
            assert!(close(out[1 + k], 4.0 / deg.to_radians().cos()), "{out:?}");
        }
        assert!(close(out[6], 2.5), "sonar left: {out:?}");
        // 3 m behind is beyond its 2.8 m: no echo, which this sonar reads 6.
        assert_eq!(out[7], 6.0, "{out:?}");
        assert!(close(out[8], 2.0), "sonar right: {out:?}");
        // And fired with noise, the same slots hold the same sensors.
        let noisy =
            RigSensors::new(rig, SonarParams::default(), LaserParams::default()).expect("valid");
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut fired = [0.0; 9];
        noisy
            .fire(&index, &Pose2::default(), &mut rng, &mut fired)
            .expect("fires");
        for (a, b) in fired.iter().zip(&out) {
            assert!((a - b).abs() < 0.1, "{fired:?} vs {out:?}");
        }
    }

    #[test]
    fn many_like_sonars_fire_as_several_rings() {
        let sonar = |i: u32| RangeSensor {
            mount: Pose2::new(0.0, 0.0, f64::from(i) * 0.05),
            kind: SensorKind::Sonar { half_angle: 0.1 },
            min_range: 0.1,
            max_range: 5.0,
            no_echo: NoEcho {
                at_or_beyond: 5.0,
                zero: false,
            },
        };
        let rig = Rig::new("many", 0.2, (0..100).map(sonar).collect()).expect("valid");
        let sensors =
            RigSensors::new(rig, SonarParams::exact(), LaserParams::exact()).expect("valid");
        assert_eq!(sensors.sonar_rings().count(), 2);
        let mut out = vec![0.0; 100];
        sensors
            .true_ranges(&room(), &Pose2::default(), &mut out)
            .expect("fires");
        assert!((out[0] - 4.0).abs() < 1e-9);
        assert!(out.iter().all(|r| (0.1..=5.0).contains(r)));
        assert!(
            sensors
                .fire(
                    &room(),
                    &Pose2::default(),
                    &mut ChaCha8Rng::seed_from_u64(0),
                    &mut out[..99]
                )
                .is_err()
        );
        let laser = load_rig_spec("laser180").expect("built in");
        let sensors =
            RigSensors::new(laser, SonarParams::exact(), LaserParams::exact()).expect("valid");
        assert_eq!(sensors.sonar_rings().count(), 0);
        assert_eq!(sensors.lasers().len(), 1);
    }
}
