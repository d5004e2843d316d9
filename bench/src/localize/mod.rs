//! `deog bench localize`: localization accuracy over many seeded runs, in
//! one process with the same parts the separate processes use (simulator,
//! wanderer, cartographer, filter), so that 20 runs per world take minutes.
//!
//! Per world: one robot wanders for `--map-minutes` while the cartographer
//! builds the map from its true poses (as `deog map` does). Then, per run,
//! a robot starts at a random pose, the filter starts with no idea where
//! (uniform over the map's free cells), the wanderer drives, and half-way
//! the robot is kidnapped to another random pose.
//!
//! The robot carries the rig `--rig` names (the Scout's 16 sonars by
//! default, `pioneer3dx`, `laser180` or a rig file): the simulator fires
//! it, the wanderer steers by it, the cartographer maps with it and the
//! filter scores its frames with the model `--sensor` picks (by default
//! the beam model for a rig of sonars only, the likelihood field
//! otherwise, as `deog localize` does).
//!
//! The simulated sonar is the preset `--sonar` names (`default`,
//! `realistic`, `specular60`; `--specular` is `specular60`), for the runs
//! and the map alike unless `--clean-map` builds the map from the default
//! sonar.
//!
//! Its parts: `map_build` (a world's map, as the cartographer builds it),
//! `seeded_run` (one run, judged), `report` (the figures as JSON for
//! `--json`) and `diagnostics` (the optional per-frame printouts of beams,
//! mirror images and the particles).

mod diagnostics;
pub(crate) mod map_build;
mod report;
mod seeded_run;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use deog_evaluation::runs::summarize;
use deog_grid::OccupancyThresholds;
use deog_harness::Progress;
use deog_localizer::beam_model::BeamModelParams;
use deog_localizer::filter::FilterSettings;
use deog_localizer::local_map::occupied_threshold_for_sonar;
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::sensors::{LikelihoodFieldParams, SensorChoice};
use deog_rig::{BUILT_IN_RIGS, Rig, RigError, load_rig_spec};
use deog_simulator::SonarPreset;
use deog_world::load_world_spec;

use crate::option_error::{OptionError, require, require_folder_of};

/// `deog bench localize --start`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StartChoice {
    /// From the global search's hypotheses.
    Search,
    /// Uniform over every free cell.
    Uniform,
}

/// Options of `deog bench localize`.
#[derive(Debug, Clone, Args)]
pub struct LocalizeOptions {
    /// Worlds to run in, comma-separated.
    #[arg(long, default_value = "map1,map2", value_delimiter = ',')]
    pub worlds: Vec<String>,
    /// Seeded runs per world.
    #[arg(long, default_value_t = 20)]
    pub runs: u64,
    /// The sensor rig the robot carries: a built-in name (scout,
    /// pioneer3dx, laser180) or a rig file (.toml).
    #[arg(long, default_value = deog_rig::DEFAULT_RIG)]
    pub rig: String,
    /// The sensor model: beam (expected ranges over each sonar's cone;
    /// sonar rigs) or likelihood-field (each echo's endpoint against the
    /// distance to the nearest wall; any rig). Default: beam for a rig of
    /// sonars only, likelihood-field otherwise. The --tempering and
    /// --hit-sigma options are the beam model's.
    #[arg(long)]
    pub sensor: Option<SensorChoice>,
    /// First seed; runs use consecutive seeds.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds per run.
    #[arg(long, default_value_t = 180.0)]
    pub seconds: f64,
    /// Simulated second of the kidnap (0: none).
    #[arg(long, default_value_t = 90.0)]
    pub kidnap_at: f64,
    /// Simulated minutes of wandering that build each world's map.
    #[arg(long, default_value_t = 10.0)]
    pub map_minutes: f64,
    /// Build the map during each run instead, as `deog demo` does: the
    /// robot and `--mappers` − 1 others wander from the start and map from
    /// their true poses; the filter starts after `--map-minutes` on the map
    /// as it then is and takes in the tiles that changed every
    /// `--refresh-s` simulated seconds. `--seconds` and `--kidnap-at`
    /// count from the filter's start.
    #[arg(long)]
    pub growing_map: bool,
    /// How a global start places its particles: `search` (the global
    /// search's hypotheses, a lost filter searching again, convergence
    /// confirmed by a search; deog_localizer::searcher) or `uniform`
    /// (the most particles allowed over every free cell).
    #[arg(long, value_enum, default_value_t = StartChoice::Search)]
    pub start: StartChoice,
    /// Robots that build a growing map, the one localized among them.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=8))]
    pub mappers: u64,
    /// Simulated seconds between two refreshes of a growing map's changed
    /// tiles, as `deog demo` has its localizers refresh (5 s of the
    /// robots' time), never stretched by slow rebuilds.
    #[arg(long, default_value_t = 5.0)]
    pub refresh_s: f64,
    /// Most particles.
    #[arg(long, default_value_t = FilterSettings::default().kld.max_particles)]
    pub max_particles: usize,
    /// The simulated sonar: default (every wall echoes), realistic (echoes
    /// lost past 30° of incidence, 2 % dropouts, 1 % crosstalk, sequential
    /// firing) or specular60 (lost past 60°, 2 % dropouts). The filter's
    /// range tables expect no echo past the preset's angle. [default:
    /// default]
    #[arg(long, conflicts_with = "specular")]
    pub sonar: Option<SonarPreset>,
    /// Turn specular reflection (lost echoes past 60° of incidence) and 2 %
    /// dropouts on in the simulator: `--sonar specular60`.
    #[arg(long)]
    pub specular: bool,
    /// With a sonar other than the default, build the map from the default
    /// sonar all the same (as a map drawn from a laser scan would be): the
    /// runs' specular readings then meet a map without the holes such
    /// readings leave in it.
    #[arg(long)]
    pub clean_map: bool,
    /// Draw the map from the world itself rather than build it from
    /// readings: a cell is occupied where its centre is not free space,
    /// free where it is. What the filter does on a perfect map.
    #[arg(long, conflicts_with_all = ["clean_map", "forward_fit", "growing_map"])]
    pub true_map: bool,
    /// Refit the map, once built, to every frame that built it through the
    /// sonar's forward model (`deog_mapping::fit_forward`, as the sonar
    /// mapping bench's `forward` method), as `deog refit` would; the Scout
    /// only, not with `--growing-map`.
    #[arg(long)]
    pub forward_fit: bool,
    /// Also write the figures as JSON to this file: per world its runs,
    /// how many converged and recovered and the mean errors, and every
    /// run's figures.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also judge each world's map against the world and draw where it is
    /// right and wrong into this folder, as `{world}-map.png` (the
    /// picture `deog eval map --png` draws): where the runs' map fails
    /// its localizer.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Fewest particles.
    #[arg(long, default_value_t = FilterSettings::default().kld.min_particles)]
    pub min_particles: usize,
    /// The beam model's tempering τ (see deog_localizer::beam_model).
    /// Default: 0.05, or 0.08 with a specular sonar (as `deog localize`).
    #[arg(long)]
    pub tempering: Option<f64>,
    /// The beam model's hit spread at zero range, metres. Default: 0.05,
    /// or 0.03 with a specular sonar (as `deog localize`).
    #[arg(long)]
    pub hit_sigma: Option<f64>,
    /// The beam model's hit spread growth per metre. Default: 0.02, or
    /// 0.005 with a specular sonar (as `deog localize`).
    #[arg(long)]
    pub hit_sigma_per_m: Option<f64>,
    /// How far past the first occupied cell's near face echoes are
    /// expected, metres (see `deog localize --surface-depth`). Default:
    /// 0.05, or 0.1 with a specular sonar.
    #[arg(long)]
    pub surface_depth: Option<f64>,
    /// The probability above which the localizer takes a map's cell for a
    /// wall (see `deog localize --occupied-threshold`). Default: 0.65 (ROS
    /// map_server's `occupied_thresh`), or 0.75 on a specular sonar's map
    /// (not a `--clean-map`): above 0.7, the walls a cartographer inferred
    /// rather than heard (space walled off from every path, what was seen
    /// only through a wall; sent at 0.7) echo nothing in the range tables.
    #[arg(long)]
    pub occupied_threshold: Option<f64>,
    /// Scale of the motion model's four noise parameters (1: the filter's
    /// defaults).
    #[arg(long, default_value_t = 1.0)]
    pub motion_noise_scale: f64,
    /// Smoothing rate of the long-term likelihood average.
    #[arg(long, default_value_t = FilterSettings::default().alpha_slow)]
    pub alpha_slow: f64,
    /// Smoothing rate of the short-term likelihood average.
    #[arg(long, default_value_t = FilterSettings::default().alpha_fast)]
    pub alpha_fast: f64,
    /// Particles are injected only when the fast average has fallen more
    /// than this share below the slow one.
    #[arg(long, default_value_t = FilterSettings::default().recovery_threshold)]
    pub recovery_threshold: f64,
    /// A settled filter injecting less than this share adds the injected
    /// particles without growing its set; more searches.
    #[arg(long, default_value_t = FilterSettings::default().search_share)]
    pub search_share: f64,
    /// A cluster holding at least this share of the weight keeps at least
    /// `--cluster-min-particles` through a resampling.
    #[arg(long, default_value_t = FilterSettings::default().cluster_keep_weight)]
    pub cluster_keep_weight: f64,
    /// The fewest particles a kept cluster gets at a resampling.
    #[arg(long, default_value_t = FilterSettings::default().cluster_min_particles)]
    pub cluster_min_particles: usize,
    /// Print every run's figures.
    #[arg(long)]
    pub verbose: bool,
    /// Print, for every frame between these simulated seconds ("from,to"),
    /// each beam's measured range beside the one the map predicts at the
    /// true pose: where the sensor model and the world disagree. The beam
    /// model's range tables make the prediction: sonar rigs only.
    #[arg(long, value_delimiter = ',')]
    pub beams_between: Option<Vec<f64>>,
    /// Also score each frame the filter weighs at the true pose and at its
    /// image turned 180° about this point ("x,y"), and print the sums: how
    /// much the map tells a symmetric world's two halves apart.
    #[arg(long, value_delimiter = ',')]
    pub mirror_about: Option<Vec<f64>>,
    /// Print each run's true and estimated pose every this many simulated
    /// seconds (0: never).
    #[arg(long, default_value_t = 0.0)]
    pub trace_every: f64,
}

impl LocalizeOptions {
    /// Checks the options a run cannot start with.
    pub fn validate(&self) -> Result<(), OptionError> {
        require(self.runs > 0, "--runs", || {
            "--runs must be at least 1".into()
        })?;
        require(self.seconds > 0.0, "--seconds", || {
            "--seconds must be positive".into()
        })?;
        if let Some(window) = &self.beams_between {
            require(
                window.len() == 2 && window[0] <= window[1],
                "--beams-between",
                || {
                    "--beams-between takes two times in seconds, \"from,to\", from no later than to"
                        .into()
                },
            )?;
        }
        if let Some(centre) = &self.mirror_about {
            require(
                centre.len() == 2 && centre.iter().all(|v| v.is_finite()),
                "--mirror-about",
                || "--mirror-about takes a point in metres, \"x,y\"".into(),
            )?;
        }
        require(self.thresholds().is_ok(), "--occupied-threshold", || {
            "--occupied-threshold must be a probability from 0.5 up to, not including, 1".into()
        })?;
        require(
            self.refresh_s.is_finite() && self.refresh_s > 0.0,
            "--refresh-s",
            || "--refresh-s must be a positive number of seconds".into(),
        )?;
        require(
            !self.growing_map || (self.map_minutes.is_finite() && self.map_minutes > 0.0),
            "--map-minutes",
            || {
                "--map-minutes must be positive with --growing-map: the filter starts on the map the first minutes built"
                    .into()
            },
        )?;
        require(
            !(self.growing_map && self.forward_fit),
            "--forward-fit",
            || {
                "--forward-fit refits a map built before the runs; a --growing-map changes during them"
                .into()
            },
        )?;
        require(!(self.growing_map && self.clean_map), "--clean-map", || {
            "--clean-map builds the map before the runs; a --growing-map is built from the runs' own readings"
                .into()
        })?;
        require(
            !self.clean_map || self.sonar_preset() != SonarPreset::Default,
            "--clean-map",
            || {
                "--clean-map only means something with --specular or a --sonar other than default"
                    .into()
            },
        )?;
        // The beam model's figures fail now, not after the map is built:
        // each flag's figure alone on the sonar's model, so the error
        // names the flag that holds it.
        let beam = self.beam_params();
        let sonar = BeamModelParams::for_sonar(self.specular_sonar());
        for (flag, alone) in [
            (
                "--tempering",
                BeamModelParams {
                    tempering: beam.tempering,
                    ..sonar
                },
            ),
            (
                "--hit-sigma",
                BeamModelParams {
                    hit_sigma_m: beam.hit_sigma_m,
                    ..sonar
                },
            ),
            (
                "--hit-sigma-per-m",
                BeamModelParams {
                    hit_sigma_per_m: beam.hit_sigma_per_m,
                    ..sonar
                },
            ),
        ] {
            if let Err(error) = alone.validate() {
                require(false, flag, || format!("{flag}: {error}"))?;
            }
        }
        // The range tables' depth fails now too, not once the map is built.
        let depth = self.surface_depth();
        require(
            ConeGeometry {
                surface_depth: depth,
                ..ConeGeometry::default()
            }
            .validate()
            .is_ok(),
            "--surface-depth",
            || format!("--surface-depth must be within 0 to 1 m, got {depth}"),
        )?;
        // A JSON file that cannot be written fails now, not after the runs.
        require_folder_of(self.json.as_deref(), "--json")?;
        require(
            self.out.as_ref().is_none_or(|p| !p.exists() || p.is_dir()),
            "--out",
            || "--out names a folder to write the maps' pictures into, not a file".into(),
        )?;
        Ok(())
    }

    /// The beam model's parameters: those of the runs' sonar
    /// ([`BeamModelParams::for_sonar`]) with `--tempering`, `--hit-sigma`
    /// and `--hit-sigma-per-m`.
    pub fn beam_params(&self) -> BeamModelParams {
        let mut beam = BeamModelParams::for_sonar(self.specular_sonar());
        if let Some(tempering) = self.tempering {
            beam.tempering = tempering;
        }
        if let Some(sigma) = self.hit_sigma {
            beam.hit_sigma_m = sigma;
        }
        if let Some(per_m) = self.hit_sigma_per_m {
            beam.hit_sigma_per_m = per_m;
        }
        beam
    }

    /// The specular angle of the sonar the map is built from, radians (a
    /// `--clean-map` is the default sonar's).
    fn map_sonar_angle(&self) -> Option<f64> {
        if self.clean_map || self.true_map {
            None
        } else {
            self.sonar_preset().specular_angle_deg()
        }
        .map(f64::to_radians)
    }

    /// How far past the first occupied cell's near face the runs expect
    /// echoes: `--surface-depth`, or that of the map's sonar
    /// ([`ConeGeometry::for_sonar`]).
    pub fn surface_depth(&self) -> f64 {
        self.surface_depth
            .unwrap_or(ConeGeometry::for_sonar(self.map_sonar_angle()).surface_depth)
    }

    /// The probability above which the runs' localizer takes a cell for a
    /// wall: `--occupied-threshold`, or that for the map's sonar
    /// ([`occupied_threshold_for_sonar`]).
    pub fn occupied_threshold(&self) -> f64 {
        self.occupied_threshold
            .unwrap_or(occupied_threshold_for_sonar(
                self.map_sonar_angle().is_some(),
            ))
    }

    /// How the runs' localizer classes the map's cells:
    /// [`Self::occupied_threshold`] and map_server's free threshold.
    pub fn thresholds(&self) -> Result<OccupancyThresholds> {
        OccupancyThresholds::new(self.occupied_threshold(), OccupancyThresholds::DEFAULT_FREE)
            .context("--occupied-threshold")
    }

    /// Whether the runs' sonar loses echoes off grazed walls.
    fn specular_sonar(&self) -> bool {
        self.sonar_preset().specular_angle_deg().is_some()
    }

    /// The sonar preset of the runs: `--sonar`, or specular60 for
    /// `--specular`.
    pub fn sonar_preset(&self) -> SonarPreset {
        if self.specular {
            SonarPreset::Specular60
        } else {
            self.sonar.unwrap_or_default()
        }
    }

    /// The rig `--rig` names and the sensor model its frames are scored
    /// with, checked against each other and against the diagnostics that
    /// need the beam model.
    pub fn rig_setup(&self) -> Result<RigSetup, OptionError> {
        let rig = load_rig_spec(&self.rig).map_err(|error| OptionError {
            flag: "--rig",
            message: format!("--rig {}: {}", self.rig, rig_error_line(error)),
        })?;
        let sensor = self.sensor.unwrap_or(SensorChoice::for_rig(&rig));
        // The errors the run would meet building the filter and its map,
        // met now and blamed on the flag.
        let checked = sensor
            .cone_geometry(&rig, ConeGeometry::default())
            .and_then(|_| {
                sensor.build(
                    &rig,
                    BeamModelParams::default(),
                    LikelihoodFieldParams::default(),
                )
            });
        if let Err(error) = checked {
            let (flag, value) = match self.sensor {
                Some(choice) => ("--sensor", choice.name()),
                None => ("--rig", self.rig.as_str()),
            };
            return Err(OptionError {
                flag,
                message: format!("{flag} {value}: {error}"),
            });
        }
        if self.beams_between.is_some() {
            require(
                sensor == SensorChoice::Beam && rig.all_sonar(),
                "--beams-between",
                || {
                    format!(
                        "--beams-between prints the beam model's predicted range per sonar: \
                         it needs a rig of sonars scored with the beam model, not rig {} with the {sensor} model",
                        rig.name()
                    )
                },
            )?;
        }
        Ok(RigSetup { rig, sensor })
    }
}

/// The robot's rig and the sensor model that scores its frames.
#[derive(Debug, Clone)]
pub struct RigSetup {
    /// The rig the simulator fires, the wanderer steers by, the
    /// cartographer maps with and the filter scores.
    pub rig: Rig,
    /// The filter's sensor model.
    pub sensor: SensorChoice,
}

/// A rig that would not load, on one line, with the built-in names.
fn rig_error_line(error: RigError) -> String {
    let text = match error {
        // Already lists the built-in names.
        RigError::Unknown { .. } => error.to_string(),
        other => {
            let names: Vec<&str> = BUILT_IN_RIGS.iter().map(|(n, _)| *n).collect();
            format!("{other} (built-in rigs: {})", names.join(", "))
        }
    };
    // A TOML error spans lines (the line quoted, a caret under it).
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Convergence and recovery count when they come within this many
/// seconds.
const CONVERGE_LIMIT_S: f64 = 60.0;

/// Runs `deog bench localize`: per world, a line when its map is built,
/// with `--verbose` a line per run, and a summary line.
pub fn run(options: LocalizeOptions) -> Result<()> {
    options.validate()?;
    let setup = options.rig_setup()?;
    let preset = options.sonar_preset();
    let beam = (setup.sensor == SensorChoice::Beam).then(|| options.beam_params());
    let mut report = report::LocalizeReport {
        rig: setup.rig.name().to_string(),
        sensor: setup.sensor.name().to_string(),
        sonar: preset.name().to_string(),
        clean_map: options.clean_map,
        forward_fit: options.forward_fit,
        true_map: options.true_map,
        map_minutes: options.map_minutes,
        growing_map: options.growing_map.then_some(report::GrowingMapFigures {
            mappers: options.mappers,
            refresh_s: options.refresh_s,
        }),
        beam_tempering: beam.map(|b| b.tempering),
        beam_hit_sigma_m: beam.map(|b| b.hit_sigma_m),
        beam_hit_sigma_per_m: beam.map(|b| b.hit_sigma_per_m),
        surface_depth_m: beam.map(|_| options.surface_depth()),
        occupied_threshold: options.occupied_threshold(),
        seconds: options.seconds,
        kidnap_at_s: options.kidnap_at,
        converge_limit_s: CONVERGE_LIMIT_S,
        worlds: Vec::new(),
    };
    let progress = Progress::new(
        "localization runs",
        "runs",
        options.worlds.len() as u64 * options.runs,
    );
    for world_name in &options.worlds {
        let started = Instant::now();
        let world = load_world_spec(world_name)?;
        let config = map_build::sim_config(&setup.rig, preset);
        let map_preset = if options.clean_map {
            SonarPreset::Default
        } else {
            preset
        };
        let map_config = map_build::sim_config(&setup.rig, map_preset);
        let (mut tiles, mut map) = if options.growing_map {
            (
                deog_grid::TileMap::new(
                    deog_grid::Resolution::DEFAULT,
                    deog_grid::TileSize::new(64)?,
                    deog_grid::ClampLimits::default(),
                ),
                map_build::empty_local_map(
                    &config,
                    setup.sensor,
                    options.surface_depth(),
                    options.thresholds()?,
                )?,
            )
        } else {
            let built = map_build::build_map(
                world.clone(),
                &map_config,
                &config,
                setup.sensor,
                map_build::MapPlan {
                    minutes: options.map_minutes,
                    forward_fit: options.forward_fit,
                    true_map: options.true_map,
                },
                options.surface_depth(),
                options.thresholds()?,
            )?;
            deog_harness::println_above_bars!(
                "{world_name}: map built in {:.1} s ({} tiles)",
                started.elapsed().as_secs_f64(),
                built.1.tile_count()
            );
            if let Some(out) = &options.out {
                write_verdict(out, world_name, &world, &built.0, &setup.rig)?;
            }
            built
        };
        let mut all = Vec::new();
        let mut particles = Vec::new();
        for seed in options.seed..options.seed + options.runs {
            let t0 = Instant::now();
            // A growing map starts anew each run, from nothing.
            let mut growing = if options.growing_map {
                let names = seeded_run::mapping_robots(options.mappers);
                map = map_build::empty_local_map(
                    &config,
                    setup.sensor,
                    options.surface_depth(),
                    options.thresholds()?,
                )?;
                Some(map_build::GrowingMap::new(&map_config, &names)?)
            } else {
                None
            };
            let (figures, extras, held) = seeded_run::run_once(
                world.clone(),
                &config,
                setup.sensor,
                map,
                &mut tiles,
                growing.as_mut(),
                seed,
                &options,
            )?;
            map = held;
            if let (Some(out), Some(growing)) = (&options.out, &mut growing) {
                write_verdict(out, world_name, &world, growing.tiles_mut(), &setup.rig)?;
            }
            progress.inc(1);
            if options.verbose {
                deog_harness::println_above_bars!(
                    "  seed {seed}: converge {} s, recover {} s, mean error {:.3} m {:.2}°, {} samples, {} falsely converged, {:.1} s",
                    fmt_opt(figures.converge_s),
                    fmt_opt(figures.recover_s),
                    figures.mean_position_m.unwrap_or(0.0),
                    figures.mean_heading_deg.unwrap_or(0.0),
                    figures.samples,
                    figures.false_converged,
                    t0.elapsed().as_secs_f64()
                );
            }
            all.push(figures);
            particles.push(extras.most_particles_settled);
        }
        let summary = summarize(&all, CONVERGE_LIMIT_S);
        deog_harness::println_above_bars!(
            "{world_name}: converged within 60 s {}/{} ({:.0} %), recovered within 60 s {}/{} ({:.0} %), mean error after convergence {:.3} m, {:.2}°; false convergence {} estimates in {} runs; {:.1} s",
            summary.converged,
            summary.runs,
            summary.converged_percent(),
            summary.recovered,
            summary.runs,
            summary.recovered_percent(),
            summary.mean_position_m.unwrap_or(0.0),
            summary.mean_heading_deg.unwrap_or(0.0),
            summary.false_converged,
            summary.runs_false_converged,
            started.elapsed().as_secs_f64()
        );
        let settled_15 = all
            .iter()
            .filter(|r| r.converge_s.is_some_and(|s| s <= SETTLE_TARGET_S))
            .count();
        let most = particles.iter().flatten().max();
        deog_harness::println_above_bars!(
            "{world_name}: settled within {SETTLE_TARGET_S:.0} s {settled_15}/{} ({:.0} %); most particles from 10 s after settling to the kidnap {}",
            all.len(),
            100.0 * settled_15 as f64 / all.len().max(1) as f64,
            most.map_or("-".to_string(), |n| n.to_string())
        );
        if let Some(path) = &options.json {
            report.worlds.push(report::WorldFigures::new(
                world_name,
                options.seed,
                &all,
                &particles,
                &summary,
            ));
            // Rewritten after each world, so a long bench leaves the
            // worlds done so far.
            std::fs::write(path, report.json()?)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    progress.finish();
    if let Some(path) = &options.json {
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
    }
    Ok(())
}

/// Judges a world's map and writes its verdict picture into `out`.
fn write_verdict(
    out: &std::path::Path,
    world_name: &str,
    world: &deog_world::World,
    tiles: &deog_grid::TileMap,
    rig: &Rig,
) -> Result<()> {
    use deog_evaluation::map_quality::{QualityInput, map_quality, verdict_png};
    let input = QualityInput {
        map: tiles,
        world,
        seeds: &[],
        robot_radius_m: rig.body_radius(),
    };
    let quality =
        map_quality(&input).with_context(|| format!("judging the map of {world_name}"))?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // A world given as a file is named by its file name.
    let stem = std::path::Path::new(world_name).file_stem().map_or_else(
        || world_name.to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    let path = out.join(format!("{stem}-map.png"));
    let png = verdict_png(&input).context("drawing the verdict")?;
    std::fs::write(&path, png).with_context(|| format!("writing {}", path.display()))?;
    let percent = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1} %", 100.0 * v));
    deog_harness::println_above_bars!(
        "{world_name}: map {:.1} % of {} observed cells right, occupied precision {}, recall {}; drawn to {}",
        100.0 * quality.fraction_correct(),
        quality.cells_observed(),
        percent(quality.occupied_precision()),
        percent(quality.occupied_recall()),
        path.display()
    );
    Ok(())
}

/// Seconds within which a global localization should settle.
const SETTLE_TARGET_S: f64 = 15.0;

/// A time to a tenth of a second, or `-` for none.
fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.1}"))
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use deog_localizer::local_map::SPECULAR_OCCUPIED_THRESHOLD;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: LocalizeOptions,
    }

    fn parse(args: &[&str]) -> LocalizeOptions {
        Cli::try_parse_from(std::iter::once("localize").chain(args.iter().copied()))
            .expect("options parse")
            .options
    }

    #[test]
    fn the_defaults_are_valid() {
        let options = parse(&[]);
        assert_eq!(options.worlds, ["map1", "map2"]);
        assert_eq!(options.validate(), Ok(()));
        let diagnostics = parse(&[
            "--beams-between",
            "1,2",
            "--mirror-about",
            "3,4",
            "--specular",
            "--clean-map",
        ]);
        assert_eq!(diagnostics.validate(), Ok(()));
    }

    #[test]
    fn a_specular_sonar_gets_its_own_beam_model_with_the_options_on_top() {
        let plain = BeamModelParams::default();
        let specular = BeamModelParams::for_sonar(true);
        assert_eq!(parse(&[]).beam_params(), plain);
        assert_eq!(parse(&["--sonar", "realistic"]).beam_params(), specular);
        assert_eq!(parse(&["--specular"]).beam_params(), specular);
        let tuned = parse(&[
            "--sonar",
            "realistic",
            "--tempering",
            "0.2",
            "--hit-sigma",
            "0.07",
        ])
        .beam_params();
        assert_eq!(
            tuned,
            BeamModelParams {
                tempering: 0.2,
                hit_sigma_m: 0.07,
                ..specular
            }
        );
    }

    #[test]
    fn a_specular_sonars_map_is_expected_deeper_unless_it_is_clean() {
        let plain = ConeGeometry::default().surface_depth;
        let specular = ConeGeometry::for_sonar(Some(0.5)).surface_depth;
        assert_eq!(parse(&[]).surface_depth(), plain);
        assert_eq!(parse(&["--sonar", "realistic"]).surface_depth(), specular);
        assert_eq!(
            parse(&["--sonar", "realistic", "--clean-map"]).surface_depth(),
            plain
        );
        assert_eq!(
            parse(&["--sonar", "realistic", "--surface-depth", "0.2"]).surface_depth(),
            0.2
        );
    }

    #[test]
    fn a_specular_sonars_map_leaves_its_inferred_walls_out_unless_it_is_clean() {
        let plain = OccupancyThresholds::DEFAULT_OCCUPIED;
        assert_eq!(parse(&[]).occupied_threshold(), plain);
        assert_eq!(
            parse(&["--sonar", "realistic"]).occupied_threshold(),
            SPECULAR_OCCUPIED_THRESHOLD
        );
        assert_eq!(
            parse(&["--sonar", "realistic", "--clean-map"]).occupied_threshold(),
            plain
        );
        assert_eq!(
            parse(&["--sonar", "realistic", "--occupied-threshold", "0.65"]).occupied_threshold(),
            0.65
        );
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        for (flag, args) in [
            ("--runs", &["--runs", "0"][..]),
            ("--seconds", &["--seconds", "0"][..]),
            ("--beams-between", &["--beams-between", "2,1"][..]),
            ("--beams-between", &["--beams-between", "1"][..]),
            ("--mirror-about", &["--mirror-about", "1,2,3"][..]),
            ("--mirror-about", &["--mirror-about", "1,NaN"][..]),
            ("--clean-map", &["--clean-map"][..]),
            (
                "--clean-map",
                &["--sonar", "realistic", "--clean-map", "--growing-map"][..],
            ),
            ("--refresh-s", &["--refresh-s", "0"][..]),
            ("--occupied-threshold", &["--occupied-threshold", "0.4"][..]),
            ("--occupied-threshold", &["--occupied-threshold", "1"][..]),
            ("--occupied-threshold", &["--occupied-threshold", "NaN"][..]),
            (
                "--map-minutes",
                &["--growing-map", "--map-minutes", "0"][..],
            ),
            ("--clean-map", &["--clean-map", "--sonar", "default"][..]),
            ("--json", &["--json", "no-such-folder/figures.json"][..]),
            ("--out", &["--out", "Cargo.toml"][..]),
            ("--tempering", &["--tempering=-1"][..]),
            (
                "--tempering",
                &["--sonar", "realistic", "--tempering", "NaN"][..],
            ),
            ("--hit-sigma", &["--hit-sigma", "0"][..]),
            ("--hit-sigma-per-m", &["--hit-sigma-per-m", "2"][..]),
            ("--surface-depth", &["--surface-depth", "2"][..]),
            (
                "--surface-depth",
                &["--sonar", "realistic", "--surface-depth", "NaN"][..],
            ),
        ] {
            let err = parse(args).validate().expect_err(flag);
            assert_eq!(err.flag, flag);
            assert!(err.to_string().starts_with(flag), "{err}");
        }
    }

    #[test]
    fn the_sonar_preset_comes_from_sonar_or_specular() {
        assert_eq!(parse(&[]).sonar_preset(), SonarPreset::Default);
        assert_eq!(
            parse(&["--specular"]).sonar_preset(),
            SonarPreset::Specular60
        );
        let realistic = parse(&["--sonar", "realistic", "--clean-map"]);
        assert_eq!(realistic.sonar_preset(), SonarPreset::Realistic);
        assert_eq!(realistic.validate(), Ok(()));
        assert!(Cli::try_parse_from(["localize", "--sonar", "realistic", "--specular"]).is_err());
        assert!(Cli::try_parse_from(["localize", "--sonar", "loud"]).is_err());
        let dir = tempfile::tempdir().expect("a temporary folder");
        let json = dir.path().join("figures.json");
        let with_json = parse(&["--json", json.to_str().expect("a UTF-8 path")]);
        assert_eq!(with_json.validate(), Ok(()));
        assert_eq!(parse(&["--json", "figures.json"]).validate(), Ok(()));
    }

    #[test]
    fn a_worlds_map_is_judged_and_drawn_into_the_folder() {
        let options = parse(&["--worlds", "map2"]);
        let setup = options.rig_setup().expect("the scout");
        let world = load_world_spec("map2").expect("built in");
        let config = map_build::sim_config(&setup.rig, SonarPreset::Default);
        let (tiles, _) = map_build::build_map(
            world.clone(),
            &config,
            &config,
            setup.sensor,
            map_build::MapPlan {
                minutes: 0.2,
                forward_fit: false,
                true_map: false,
            },
            options.surface_depth(),
            options.thresholds().expect("the default"),
        )
        .expect("a map from 12 simulated seconds");
        let out = tempfile::tempdir().expect("temp dir");
        let folder = out.path().join("pictures");
        write_verdict(&folder, "map2", &world, &tiles, &setup.rig).expect("written");
        let png = std::fs::read(folder.join("map2-map.png")).expect("the picture");
        assert_eq!(&png[1..4], b"PNG");
        // A world given as a file is named by its file's stem.
        write_verdict(&folder, "worlds/map2.toml", &world, &tiles, &setup.rig).expect("written");
        assert!(folder.join("map2-map.png").is_file());
        assert_eq!(std::fs::read_dir(&folder).expect("listed").count(), 1);
    }

    #[test]
    fn a_growing_map_is_built_while_the_robot_localizes_on_it() {
        let options = parse(&[
            "--worlds",
            "map2",
            "--growing-map",
            "--map-minutes",
            "0.2",
            "--seconds",
            "4",
            "--kidnap-at",
            "0",
            "--mappers",
            "2",
            "--refresh-s",
            "1",
            "--max-particles",
            "5000",
            // The filter runs 4 s: too few for a search to see the room.
            "--start",
            "uniform",
        ]);
        assert_eq!(options.validate(), Ok(()));
        let setup = options.rig_setup().expect("the scout");
        let world = load_world_spec("map2").expect("built in");
        let config = map_build::sim_config(&setup.rig, SonarPreset::Default);
        let names = seeded_run::mapping_robots(options.mappers);
        assert_eq!(names.len(), 2);
        let mut growing = map_build::GrowingMap::new(&config, &names).expect("cartographers");
        let map = map_build::empty_local_map(
            &config,
            setup.sensor,
            options.surface_depth(),
            options.thresholds().expect("the default"),
        )
        .expect("an empty map");
        let mut unused = deog_grid::TileMap::new(
            deog_grid::Resolution::DEFAULT,
            deog_grid::TileSize::new(64).expect("a size"),
            deog_grid::ClampLimits::default(),
        );
        let (figures, _, held) = seeded_run::run_once(
            world,
            &config,
            setup.sensor,
            map,
            &mut unused,
            Some(&mut growing),
            1,
            &options,
        )
        .expect("a run");
        // The filter ran for the last 4 s of frames, on tiles the two
        // robots mapped: 12 s of mapping before it, and more during.
        assert!(figures.samples > 0, "{figures:?}");
        assert!(held.tile_count() > 0);
        assert!(growing.tiles_mut().tiles().count() > 0);
        assert_eq!(unused.tiles().count(), 0, "a growing map is its own");
    }

    fn setup(args: &[&str]) -> RigSetup {
        parse(args)
            .rig_setup()
            .expect("the rig and sensor go together")
    }

    fn refused(args: &[&str]) -> OptionError {
        parse(args).rig_setup().expect_err("refused")
    }

    #[test]
    fn the_default_rig_is_the_scout_with_the_beam_model() {
        let options = parse(&[]);
        assert_eq!((options.rig.as_str(), options.sensor), ("scout", None));
        let setup = setup(&[]);
        assert_eq!(setup.rig, deog_rig::scout());
        assert_eq!(setup.sensor, SensorChoice::Beam);
    }

    #[test]
    fn each_built_in_rig_gets_its_sensor_model() {
        for (rig, sensor) in [
            ("scout", SensorChoice::Beam),
            ("pioneer3dx", SensorChoice::Beam),
            ("laser180", SensorChoice::LikelihoodField),
        ] {
            let setup = setup(&["--rig", rig]);
            assert_eq!((setup.rig.name(), setup.sensor), (rig, sensor));
        }
        let field = setup(&["--sensor", "likelihood-field"]);
        assert_eq!(field.sensor, SensorChoice::LikelihoodField);
        // The mirror images are scored by whatever model the filter has.
        setup(&["--rig", "laser180", "--mirror-about", "1,2"]);
    }

    #[test]
    fn a_rig_file_is_read() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let path = dir.path().join("front.toml");
        std::fs::write(
            &path,
            "name = \"front\"\n[[sensor]]\nkind = \"laser\"\nfirst_angle_deg = -45\n\
             angle_step_deg = 1\nbeam_count = 91\nmin_range_m = 0.1\nmax_range_m = 8\n",
        )
        .expect("the rig file is written");
        let setup = setup(&["--rig", path.to_str().expect("a UTF-8 path")]);
        assert_eq!(
            (setup.rig.readings(), setup.sensor),
            (91, SensorChoice::LikelihoodField)
        );
        std::fs::write(&path, "name = [").expect("the rig file is written");
        let err = refused(&["--rig", path.to_str().expect("a UTF-8 path")]);
        assert_eq!(err.flag, "--rig");
        assert!(!err.message.contains('\n'), "{err}");
    }

    #[test]
    fn rigs_and_sensors_that_do_not_fit_are_refused_naming_the_flag() {
        let err = refused(&["--rig", "no-such-rig"]);
        assert_eq!(err.flag, "--rig");
        assert!(err.message.starts_with("--rig no-such-rig: "), "{err}");
        assert!(err.message.contains("scout, pioneer3dx, laser180"), "{err}");
        let err = refused(&["--rig", "laser180", "--sensor", "beam"]);
        assert_eq!(err.flag, "--sensor");
        assert!(err.message.contains("use the likelihood field"), "{err}");
        for args in [
            &["--rig", "laser180", "--beams-between", "1,2"][..],
            &["--sensor", "likelihood-field", "--beams-between", "1,2"][..],
        ] {
            let err = refused(args);
            assert_eq!(err.flag, "--beams-between");
            assert!(err.message.starts_with("--beams-between "), "{err}");
        }
        setup(&["--rig", "pioneer3dx", "--beams-between", "1,2"]);
        let unknown = Cli::try_parse_from(["localize", "--sensor", "laser"]);
        assert!(unknown.is_err(), "--sensor laser parsed");
    }
}
