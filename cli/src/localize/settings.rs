//! `deog localize`'s flags checked and turned into the filter's settings,
//! before anything connects: a bad flag is refused at once, named.

use anyhow::{Context, Result, ensure};
use deog_grid::{OccupancyThresholds, RingFiring};
use deog_localizer::beam_model::BeamModelParams;
use deog_localizer::filter::FilterSettings;
use deog_localizer::local_map::occupied_threshold_for_sonar;
use deog_localizer::preset::Preset;
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::sensors::LikelihoodFieldParams;
use deog_rig::Rig;

use super::LocalizeArgs;
use crate::rig_args::load_rig;

/// What the flags ask of the localizer; the rig the first frame names
/// decides the rest (the sensor model, the cones' ranges).
#[derive(Debug)]
pub(super) struct LocalizeSettings {
    /// The filter's settings, checked; the beam model's range is the rig's.
    pub filter: FilterSettings,
    /// The likelihood field's, checked.
    pub field: LikelihoodFieldParams,
    /// A sonar's cone as the map holds its walls (the surface depth) and
    /// what it hears (a specular sonar's critical angle).
    pub sonar_cone: ConeGeometry,
    /// When each of the ring's sonars fired.
    pub firing: RingFiring,
    /// How the map's cells are classed.
    pub thresholds: OccupancyThresholds,
    /// The rig `--rig` names, which the frames must come from.
    pub expected_rig: Option<Rig>,
}

impl LocalizeArgs {
    /// Checks every flag and builds the settings they give.
    pub(super) fn settings(&self) -> Result<LocalizeSettings> {
        ensure!(
            self.particle_sample <= 5_000,
            "--particle-sample is at most 5000 (the map server keeps samples small), not {}",
            self.particle_sample
        );
        ensure!(
            self.particle_sample_every_s.is_finite() && self.particle_sample_every_s >= 0.0,
            "--particle-sample-every-s must be a number of seconds, at least 0, not {}",
            self.particle_sample_every_s
        );
        let preset = Preset::from(self.preset).tuning();
        let motion_noise_scale = self.motion_noise_scale.unwrap_or(preset.motion_noise_scale);
        ensure!(
            self.idle_exit.is_finite() && self.idle_exit >= 0.0,
            "--idle-exit must be zero or positive, got {}",
            self.idle_exit
        );
        ensure!(
            self.refresh_s.is_finite() && self.refresh_s >= 0.0,
            "--refresh-s must be zero or positive, got {}",
            self.refresh_s
        );
        let firing = RingFiring::over(self.firing_period).context("--firing-period (seconds)")?;
        let occupied = self
            .occupied_threshold
            .unwrap_or(occupied_threshold_for_sonar(self.specular_angle.is_some()));
        let thresholds = OccupancyThresholds::new(occupied, OccupancyThresholds::DEFAULT_FREE)
            .context("--occupied-threshold (a probability from 0.5 up to 1)")?;
        if let Some(angle) = self.specular_angle {
            ensure!(
                angle.is_finite() && (0.0..=90.0).contains(&angle),
                "--specular-angle must be in [0, 90] degrees, got {angle}"
            );
        }
        ensure!(
            self.step_budget_ms.is_finite() && (0.0..=60_000.0).contains(&self.step_budget_ms),
            "--step-budget-ms must be 0 (no budget) to 60000 milliseconds, got {}",
            self.step_budget_ms
        );
        ensure!(
            self.max_skip_s.is_finite() && self.max_skip_s > 0.0,
            "--max-skip-s must be a positive number of seconds, got {}",
            self.max_skip_s
        );
        ensure!(
            (16..=1 << 20).contains(&self.cache_mb),
            "--cache-mb must be in [16, 1048576] MiB, got {}",
            self.cache_mb
        );
        ensure!(
            motion_noise_scale.is_finite() && (0.0..=100.0).contains(&motion_noise_scale),
            "--motion-noise-scale must be in [0, 100], got {motion_noise_scale}"
        );
        let expected_rig = self.rig.as_deref().map(load_rig).transpose()?;
        let mut settings = FilterSettings {
            seed: self.seed,
            ..FilterSettings::default()
        };
        settings.kld.max_particles = self.max_particles;
        settings.kld.min_particles = self.min_particles.unwrap_or(preset.min_particles);
        // A specular sonar's beam model: its own τ and causes' weights.
        settings.beam = BeamModelParams::for_sonar(self.specular_angle.is_some());
        if let Some(tempering) = self.tempering {
            settings.beam.tempering = tempering;
        }
        settings.alpha_slow = self.recovery_alpha_slow;
        settings.alpha_fast = self.recovery_alpha_fast;
        settings.recovery_threshold = self.recovery_threshold;
        settings.search_share = self.recovery_search_share;
        settings.motion = settings.motion.scaled(motion_noise_scale);
        if self.no_realign {
            settings.realign = None;
        }
        if self.no_ambiguity_check {
            settings.ambiguity = None;
        }
        // The filter is built once the first frame names the rig; its
        // settings are checked now, before anything waits.
        let settings = settings.validate().context("the filter's settings")?;
        let field = LikelihoodFieldParams {
            sigma_hit: self.field_sigma,
            max_beams: self.field_beams.unwrap_or(preset.field_beams),
            tempering: self.field_tempering.unwrap_or(preset.field_tempering),
            search_tempering: self
                .field_search_tempering
                .or(preset.field_search_tempering),
            refine: if self.no_refine {
                None
            } else {
                LikelihoodFieldParams::default().refine
            },
            ..LikelihoodFieldParams::default()
        }
        .validate()
        .context(
            "the likelihood field's options (--field-sigma, --field-beams, --field-tempering, \
             --field-search-tempering)",
        )?;
        let sonar = ConeGeometry::for_sonar(self.specular_angle.map(f64::to_radians));
        // The range tables' own limits (the surface depth's; the angle was
        // checked in degrees above), now rather than once the first frame
        // has named the rig.
        let sonar_cone = ConeGeometry {
            surface_depth: self.surface_depth.unwrap_or(sonar.surface_depth),
            ..sonar
        }
        .validate()
        .context("--surface-depth (metres)")?;
        Ok(LocalizeSettings {
            filter: settings,
            field,
            sonar_cone,
            firing,
            thresholds,
            expected_rig,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use deog_localizer::local_map::SPECULAR_OCCUPIED_THRESHOLD;
    use deog_localizer::range_table::SPECULAR_SURFACE_DEPTH;

    #[derive(Debug, Parser)]
    struct Command {
        #[command(flatten)]
        args: LocalizeArgs,
    }

    fn settings(flags: &[&str]) -> Result<LocalizeSettings> {
        let mut line = vec!["localize", "--robot", "r1", "--map", "m"];
        line.extend_from_slice(flags);
        Command::try_parse_from(line)
            .expect("flags clap accepts")
            .args
            .settings()
    }

    fn refused(flags: &[&str]) -> String {
        format!(
            "{:#}",
            settings(flags).expect_err(&format!("{flags:?} refused"))
        )
    }

    #[test]
    fn by_default_the_filter_expects_a_plain_sonar_fired_all_at_once() {
        let s = settings(&[]).expect("the defaults");
        let sim = Preset::Simulator.tuning();
        assert_eq!(s.filter.beam, BeamModelParams::for_sonar(false));
        assert_eq!(s.filter.kld.min_particles, sim.min_particles);
        assert_eq!(s.field.max_beams, sim.field_beams);
        assert_eq!(s.sonar_cone, ConeGeometry::for_sonar(None));
        assert_eq!(s.firing, RingFiring::Together);
        assert_eq!(s.thresholds, OccupancyThresholds::default());
        assert!(s.expected_rig.is_none());
    }

    #[test]
    fn a_specular_angle_gives_a_specular_sonars_model_and_walls_a_cell_further_out() {
        let s = settings(&["--specular-angle", "30", "--firing-period", "0.1"])
            .expect("a specular sonar");
        assert_eq!(s.filter.beam, BeamModelParams::for_sonar(true));
        assert_eq!(
            s.sonar_cone.specular_max_incidence,
            Some(30f64.to_radians())
        );
        assert_eq!(s.sonar_cone.surface_depth, SPECULAR_SURFACE_DEPTH);
        assert_eq!(s.firing, RingFiring::Sequential { period_s: 0.1 });
        assert_eq!(
            s.thresholds,
            OccupancyThresholds::new(
                SPECULAR_OCCUPIED_THRESHOLD,
                OccupancyThresholds::DEFAULT_FREE
            )
            .unwrap()
        );
    }

    #[test]
    fn a_flag_given_wins_over_the_sonars_and_the_presets_defaults() {
        let s = settings(&[
            "--specular-angle",
            "30",
            "--surface-depth",
            "0.07",
            "--tempering",
            "0.2",
            "--preset",
            "real-laser",
            "--min-particles",
            "300",
            "--occupied-threshold",
            "0.7",
        ])
        .expect("flags that override");
        assert_eq!(s.sonar_cone.surface_depth, 0.07);
        assert_eq!(s.filter.beam.tempering, 0.2);
        assert_eq!(s.filter.kld.min_particles, 300);
        assert_eq!(
            s.thresholds.occupied(),
            OccupancyThresholds::new(0.7, 0.196).unwrap().occupied()
        );
        assert_eq!(s.field.max_beams, Preset::RealLaser.tuning().field_beams);
    }

    #[test]
    fn each_bad_flag_is_refused_by_name() {
        for (flags, named) in [
            (&["--surface-depth", "2"][..], "--surface-depth"),
            (&["--surface-depth", "NaN"], "--surface-depth"),
            (&["--specular-angle", "95"], "--specular-angle"),
            (&["--specular-angle", "NaN"], "--specular-angle"),
            (&["--specular-angle=-5"], "--specular-angle"),
            (&["--particle-sample", "6000"], "--particle-sample"),
            (&["--firing-period=-1"], "--firing-period"),
            (&["--cache-mb", "8"], "--cache-mb"),
            (&["--max-skip-s", "0"], "--max-skip-s"),
            (&["--idle-exit=-1"], "--idle-exit"),
            (&["--motion-noise-scale", "1000"], "--motion-noise-scale"),
            (&["--field-sigma=-1"], "--field-sigma"),
            (&["--rig", "no-such-rig"], "no-such-rig"),
            (&["--occupied-threshold", "0.4"], "--occupied-threshold"),
            (&["--occupied-threshold", "1"], "--occupied-threshold"),
            (&["--occupied-threshold", "NaN"], "--occupied-threshold"),
        ] {
            let error = refused(flags);
            assert!(error.contains(named), "{flags:?}: {error}");
        }
    }
}
