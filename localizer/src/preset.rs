//! Named sets of the filter's tunings, each for a kind of data, so that a
//! person names the kind of data rather than five numbers.

use crate::filter::FilterSettings;
use crate::sensors::LikelihoodFieldParams;

/// A kind of data the filter's tunings are chosen for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Preset {
    /// The simulator's robots: odometry as noisy as the simulator makes
    /// it, a likelihood field scoring a sample of each frame's echoes.
    #[default]
    Simulator,
    /// A real robot's planar laser (the CARMEN logs): odometry worse than
    /// the simulator's, every beam of a 180-beam scan scored, a softer τ
    /// while searching so that look-alike corridors stay candidates, and
    /// more particles kept while tracking.
    RealLaser,
}

/// The tunings a [`Preset`] sets; each may still be overridden alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tuning {
    /// The most echoes of a frame the likelihood field scores.
    pub field_beams: usize,
    /// The likelihood field's τ once the filter has settled.
    pub field_tempering: f64,
    /// The likelihood field's τ while the filter searches (None: the
    /// settled τ).
    pub field_search_tempering: Option<f64>,
    /// The factor on the motion model's four noise figures.
    pub motion_noise_scale: f64,
    /// The fewest particles KLD-sampling keeps.
    pub min_particles: usize,
}

impl Preset {
    /// The tunings this preset stands for.
    pub fn tuning(self) -> Tuning {
        match self {
            Preset::Simulator => {
                let field = LikelihoodFieldParams::default();
                Tuning {
                    field_beams: field.max_beams,
                    field_tempering: field.tempering,
                    field_search_tempering: field.search_tempering,
                    motion_noise_scale: 1.0,
                    min_particles: FilterSettings::default().kld.min_particles,
                }
            }
            // Measured on the Intel and ACES logs (BENCHMARKS.md, "Real
            // logs"): 3.0 and 4.7 cm RMS, 20 of 20 global starts each.
            Preset::RealLaser => Tuning {
                field_beams: 180,
                field_tempering: 0.5,
                field_search_tempering: Some(0.05),
                motion_noise_scale: 2.0,
                min_particles: 2000,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulator_preset_is_the_filters_defaults() {
        let tuning = Preset::default().tuning();
        let field = LikelihoodFieldParams::default();
        assert_eq!(tuning.field_beams, field.max_beams);
        assert_eq!(tuning.field_tempering, field.tempering);
        assert_eq!(tuning.field_search_tempering, None);
        assert_eq!(tuning.motion_noise_scale, 1.0);
        assert_eq!(
            tuning.min_particles,
            FilterSettings::default().kld.min_particles
        );
    }

    #[test]
    fn every_preset_makes_valid_settings() {
        for preset in [Preset::Simulator, Preset::RealLaser] {
            let tuning = preset.tuning();
            LikelihoodFieldParams {
                max_beams: tuning.field_beams,
                tempering: tuning.field_tempering,
                search_tempering: tuning.field_search_tempering,
                ..LikelihoodFieldParams::default()
            }
            .validate()
            .unwrap_or_else(|e| panic!("{preset:?}: {e}"));
            let mut settings = FilterSettings::default();
            settings.kld.min_particles = tuning.min_particles;
            settings.motion = settings.motion.scaled(tuning.motion_noise_scale);
            settings
                .validate()
                .unwrap_or_else(|e| panic!("{preset:?}: {e}"));
        }
    }
}
