//! `deog map`'s flags checked and turned into the cartographer's
//! settings, before anything connects: a bad flag is refused at once,
//! named.

use std::time::Duration;

use anyhow::{Context, Result, bail};
use deog_grid::{RayModelParams, RingFiring, SonarModelParams};
use deog_mapping::{DirectionalSettings, MapViewSettings, mapping_sonar_model};
use deog_proto::names::check_robot_name;
use deog_rig::Rig;

use super::{MapArgs, SonarMethodChoice};
use crate::rig_args::load_rig;

/// What the flags ask of the cartographer; the map's resolution and tile
/// size are the server's.
#[derive(Debug)]
pub(super) struct MapSettings {
    /// The sonar model, checked.
    pub sonar: SonarModelParams,
    /// The laser ray model, checked.
    pub ray: RayModelParams,
    /// The view of the map the guarded sonar methods keep, checked.
    pub view: MapViewSettings,
    /// Least time between two refreshes of that view from the server.
    pub view_refresh: Duration,
    /// When each of the ring's sonars fired.
    pub firing: RingFiring,
    /// The rig `--rig` names, which the frames must come from.
    pub expected_rig: Option<Rig>,
}

impl MapArgs {
    /// Checks every flag and builds the settings they give.
    pub(super) fn settings(&self) -> Result<MapSettings> {
        check_robot_name(&self.robot).context("--robot")?;
        if self.batch_frames == 0 {
            bail!("--batch-frames must be at least 1");
        }
        if !(self.idle_exit.is_finite() && self.idle_exit >= 0.0) {
            bail!(
                "--idle-exit must be zero or positive, got {}",
                self.idle_exit
            );
        }
        if !(self.estimate_wait.is_finite() && self.estimate_wait >= 0.0) {
            bail!(
                "--estimate-wait must be zero or positive, got {}",
                self.estimate_wait
            );
        }
        let firing = RingFiring::over(self.firing_period).context("--firing-period (seconds)")?;
        let params = SonarModelParams {
            max_occupied: self.max_occupied,
            max_empty: self.max_empty,
            min_empty: self.min_empty,
            min_occupied: self.min_occupied,
            region_i_tolerance: self.region_tolerance,
            occupied_axis_factor: self.occupied_axis_factor,
            occupied_edge_factor: self.occupied_edge_factor,
            no_echo_free_range: self.no_echo_free_range,
            max_mapped_range: self.max_mapped_range,
            max_free_range: self.max_free_range,
            ..mapping_sonar_model()
        };
        let params = params.validate().context(
            "the sonar model's options (--max-occupied, --max-empty, --min-empty, --min-occupied, \
             --region-tolerance, --occupied-axis-factor, --occupied-edge-factor, \
             --no-echo-free-range, --max-mapped-range, --max-free-range)",
        )?;
        let ray = RayModelParams {
            hit_probability: self.hit_probability,
            miss_probability: self.miss_probability,
            no_echo_free_range: self.ray_no_echo_free_range,
            max_mapped_range: self.ray_max_mapped_range,
            ..RayModelParams::default()
        };
        let ray = ray.validate().context(
            "the laser ray model's options (--hit-probability, --miss-probability, \
             --ray-no-echo-free-range, --ray-max-mapped-range)",
        )?;
        let view = MapViewSettings {
            wall_probability: self.wall_probability,
            shadow_probability: self.wall_probability,
            max_tiles: self.view_tiles.unwrap_or(match self.sonar_method {
                SonarMethodChoice::Directional => DirectionalSettings::default().max_tiles,
                _ => MapViewSettings::default().max_tiles,
            }),
            enclosure_period: self.enclosure_period,
            shadow_depth: self.shadow_depth,
            ..MapViewSettings::default()
        }
        .validate()
        .context("--wall-probability, --view-tiles, --shadow-depth")?;
        if !(self.view_refresh_s.is_finite() && self.view_refresh_s > 0.0) {
            bail!(
                "--view-refresh-s must be positive, got {}",
                self.view_refresh_s
            );
        }
        Ok(MapSettings {
            sonar: params,
            ray,
            view,
            view_refresh: Duration::from_secs_f64(self.view_refresh_s),
            firing,
            expected_rig: self.rig.as_deref().map(load_rig).transpose()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Command {
        #[command(flatten)]
        args: MapArgs,
    }

    fn settings(flags: &[&str]) -> Result<MapSettings> {
        let mut line = vec!["map", "--map", "m"];
        if !flags.contains(&"--robot") {
            line.extend_from_slice(&["--robot", "r1"]);
        }
        line.extend_from_slice(flags);
        Command::try_parse_from(line)
            .expect("flags clap accepts")
            .args
            .settings()
    }

    #[test]
    fn by_default_the_mapping_model_the_plain_view_and_a_ring_fired_at_once() {
        let s = settings(&[]).expect("the defaults");
        assert_eq!(s.sonar, mapping_sonar_model());
        assert_eq!(s.ray, RayModelParams::default());
        assert_eq!(s.view.max_tiles, MapViewSettings::default().max_tiles);
        assert_eq!(s.firing, RingFiring::Together);
        assert_eq!(s.view_refresh, Duration::from_secs(5));
        assert!(s.expected_rig.is_none());
    }

    #[test]
    fn the_directional_method_holds_its_own_number_of_tiles_unless_told() {
        let s = settings(&["--sonar-method", "directional"]).expect("directional");
        assert_eq!(s.view.max_tiles, DirectionalSettings::default().max_tiles);
        let s = settings(&["--sonar-method", "directional", "--view-tiles", "64"])
            .expect("a view size given");
        assert_eq!(s.view.max_tiles, 64);
        let s =
            settings(&["--firing-period", "0.1", "--max-free-range", "2"]).expect("flags given");
        assert_eq!(s.firing, RingFiring::Sequential { period_s: 0.1 });
        assert_eq!(s.sonar.max_free_range, 2.0);
        let s = settings(&[
            "--occupied-axis-factor",
            "0.4",
            "--occupied-edge-factor",
            "1",
        ])
        .expect("region I's angle factors");
        assert_eq!(
            (s.sonar.occupied_axis_factor, s.sonar.occupied_edge_factor),
            (0.4, 1.0)
        );
    }

    #[test]
    fn each_bad_flag_is_refused_by_name() {
        for (flags, named) in [
            (&["--robot", "no/slash"][..], "--robot"),
            (&["--batch-frames", "0"], "--batch-frames"),
            (&["--idle-exit=-1"], "--idle-exit"),
            (&["--estimate-wait", "NaN"], "--estimate-wait"),
            (&["--firing-period", "11"], "--firing-period"),
            (&["--max-occupied", "1.5"], "--max-occupied"),
            (&["--occupied-edge-factor", "1.5"], "--occupied-edge-factor"),
            (&["--hit-probability", "2"], "--hit-probability"),
            (&["--shadow-depth", "11"], "--shadow-depth"),
            (&["--wall-probability", "0.2"], "--wall-probability"),
            (&["--view-refresh-s", "0"], "--view-refresh-s"),
            (&["--rig", "no-such-rig"], "no-such-rig"),
        ] {
            let error = format!(
                "{:#}",
                settings(flags).expect_err(&format!("{flags:?} refused"))
            );
            assert!(error.contains(named), "{flags:?}: {error}");
        }
    }
}
