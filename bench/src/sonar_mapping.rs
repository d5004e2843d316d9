//! `deog bench sonar-mapping`: the sonar mapping methods side by side on
//! the same readings, in one process.
//!
//! Per world, `N` Scouts (the `world:N` of `--worlds`) wander the
//! simulator together for `--minutes`, with the sonar `--sonar` names; their
//! frames are recorded in the order they fire. Each method then maps exactly
//! those frames, from the true pose, into a map of its own, and the map is
//! judged against the world (`deog-evaluation`'s map quality, with the
//! robots' starting points as the seeds of the reachable free space):
//! - `thesis`: the thesis's model alone ([`SonarMethod::Thesis`]), with the
//!   mapping defaults of `deog map` (no-echo readings free their cone to
//!   3 m);
//! - `thesis-no-echo-ignored`: the same with no-echo readings ignored
//!   (`--no-echo-free-range 0`), the usual advice for a specular sonar;
//! - `keep-walls`: cones stopping at the walls the map already holds
//!   ([`SonarMethod::KeepWalls`], `deog map --sonar-method keep-walls`);
//! - `keep-walls-no-echo-ignored`: the same with no-echo readings
//!   ignored (what `deog demo` runs with a specular sonar);
//! - `directional`: evidence kept per direction of the surface normal
//!   ([`SonarMethod::Directional`], `deog map --sonar-method directional`);
//! - `directional-no-echo-ignored`: the same with no-echo readings
//!   ignored;
//! - `directional-specular`: what `deog demo` maps a specular sonar with
//!   ([`specular_sonar_mapping`]: directional, no-echo readings ignored,
//!   empty evidence out to 2 m whatever `--max-free-range` says).
//!
//! `--methods` picks some of them.
//!
//! The JSON (`--json FILE`) holds `options` and `worlds`: per world its
//! `world`, `robots`, `frames` and `methods`, each with `method`,
//! `frames_per_s` (mapping alone), and the map quality's `cells_observed`,
//! `fraction_correct`, `occupied_precision`, `occupied_recall`,
//! `observed_occupied_recall` and
//! `coverage`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_evaluation::map_quality::{QualityInput, map_quality, verdict_png};
use deog_grid::{ClampLimits, Pose2, Resolution, TileMap, TileSize};
use deog_mapping::{
    Cartographer, FrameInput, MapViewSettings, PoseChoice, SonarMethod, mapping_sonar_model,
    specular_sonar_mapping,
};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{SonarPreset, WanderParams, Wanderer};
use deog_world::{Point2, load_world_spec};
use serde::Serialize;

use crate::option_error::{OptionError, require};

/// The methods compared, in the order the table lists them.
pub const METHODS: [&str; 7] = [
    "thesis",
    "thesis-no-echo-ignored",
    "keep-walls",
    "keep-walls-no-echo-ignored",
    "directional",
    "directional-no-echo-ignored",
    "directional-specular",
];

/// Options of `deog bench sonar-mapping`.
#[derive(Debug, Clone, Args)]
pub struct SonarMappingOptions {
    /// Worlds and how many robots wander each, `world:robots`,
    /// comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "office:3,map2:1")]
    pub worlds: Vec<String>,
    /// Simulated minutes of wandering per world.
    #[arg(long, default_value_t = 10.0)]
    pub minutes: f64,
    /// The simulated sonar: default (every wall echoes), realistic
    /// (echoes lost past 30° of incidence, 2 % dropouts, 1 % crosstalk,
    /// sequential firing) or specular60 (lost past 60°, 2 % dropouts).
    #[arg(long, default_value = "realistic")]
    pub sonar: SonarPreset,
    /// keep-walls: the probability from which a cell is a wall.
    #[arg(long, default_value_t = MapViewSettings::default().wall_probability)]
    pub wall_probability: f64,
    /// How far a reading's empty evidence reaches, metres, for every
    /// method (`deog map --max-free-range`).
    #[arg(long, default_value_t = mapping_sonar_model().max_free_range)]
    pub max_free_range: f64,
    /// Seed of the simulator and the wanderers.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The methods to compare, comma-separated (all of them by default).
    #[arg(long, value_delimiter = ',', default_values_t = METHODS.map(String::from))]
    pub methods: Vec<String>,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw each map's verdict (where it is right and wrong) into
    /// this folder, `WORLD-METHOD.png`, made if missing.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl SonarMappingOptions {
    /// Checks the options; the error names the flag.
    pub fn validate(&self) -> Result<Vec<(String, usize)>, OptionError> {
        require(
            self.minutes.is_finite() && self.minutes > 0.0 && self.minutes <= 600.0,
            "--minutes",
            || format!("--minutes takes (0, 600], got {}", self.minutes),
        )?;
        require(
            self.wall_probability > 0.5 && self.wall_probability < 1.0,
            "--wall-probability",
            || {
                format!(
                    "--wall-probability takes (0.5, 1), got {}",
                    self.wall_probability
                )
            },
        )?;
        require(
            self.max_free_range.is_finite() && (0.0..=10.668).contains(&self.max_free_range),
            "--max-free-range",
            || {
                format!(
                    "--max-free-range takes [0, 10.668] m, got {}",
                    self.max_free_range
                )
            },
        )?;
        for method in &self.methods {
            require(METHODS.contains(&method.as_str()), "--methods", || {
                format!(
                    "--methods: no method {method:?}; the methods are {}",
                    METHODS.join(", ")
                )
            })?;
        }
        if let Some(json) = &self.json {
            let folder = json.parent().filter(|p| !p.as_os_str().is_empty());
            require(folder.is_none_or(|f| f.is_dir()), "--json", || {
                format!("--json {}: its folder does not exist", json.display())
            })?;
        }
        self.worlds
            .iter()
            .map(|spec| {
                let (world, robots) = spec.split_once(':').unwrap_or((spec, "1"));
                let robots = robots
                    .parse::<usize>()
                    .ok()
                    .filter(|n| (1..=16).contains(n));
                match robots {
                    Some(robots) if !world.is_empty() => Ok((world.to_owned(), robots)),
                    _ => Err(OptionError {
                        flag: "--worlds",
                        message: format!(
                            "--worlds takes world:robots with 1 to 16 robots, got {spec:?}"
                        ),
                    }),
                }
            })
            .collect()
    }
}

/// One method's map of one world.
#[derive(Debug, Clone, Serialize)]
pub struct MethodFigures {
    /// One of [`METHODS`].
    pub method: &'static str,
    /// Frames mapped per second, mapping alone.
    pub frames_per_s: f64,
    /// Cells the map observed.
    pub cells_observed: u64,
    /// Observed cells classified as the world has them.
    pub fraction_correct: f64,
    /// Occupied cells within a cell of a wall.
    pub occupied_precision: Option<f64>,
    /// Wall surface cells the map holds occupied (within a cell).
    pub occupied_recall: Option<f64>,
    /// The same over the wall surface cells the map observed.
    pub observed_occupied_recall: Option<f64>,
    /// Reachable free space the map holds free.
    pub coverage: Option<f64>,
}

/// One world's run.
#[derive(Debug, Clone, Serialize)]
pub struct WorldFigures {
    /// The world's name.
    pub world: String,
    /// Robots that wandered it.
    pub robots: usize,
    /// Frames recorded, all robots.
    pub frames: usize,
    /// Each method's map.
    pub methods: Vec<MethodFigures>,
}

#[derive(Debug, Serialize)]
struct Report<'a> {
    options: OptionsRecord,
    worlds: &'a [WorldFigures],
}

#[derive(Debug, Serialize)]
struct OptionsRecord {
    minutes: f64,
    sonar: String,
    wall_probability: f64,
    max_free_range: f64,
    seed: u64,
}

/// A frame as recorded: where the robot really was, what it read.
struct RecordedFrame {
    sequence: u64,
    true_pose: Pose2,
    ranges: Vec<f64>,
}

/// Runs `deog bench sonar-mapping`.
pub fn run(options: SonarMappingOptions) -> Result<()> {
    let worlds = options.validate()?;
    let mut figures = Vec::new();
    for (name, robots) in worlds {
        let world = load_world_spec(&name).with_context(|| format!("world {name}"))?;
        let began = Instant::now();
        let (frames, seeds) = record(&world, robots, &options)?;
        eprintln!(
            "{name}: {robots} robot(s), {} frames recorded in {:.1} s",
            frames.len(),
            began.elapsed().as_secs_f64()
        );
        let mut methods = Vec::new();
        for method in METHODS
            .into_iter()
            .filter(|m| options.methods.iter().any(|chosen| chosen == m))
        {
            let (map, seconds) = build(method, &frames, &options)?;
            let input = QualityInput {
                map: &map,
                world: &world,
                seeds: &seeds,
                robot_radius_m: deog_rig::scout().body_radius(),
            };
            let quality = map_quality(&input)
                .with_context(|| format!("judging the {method} map of {name}"))?;
            if let Some(out) = &options.out {
                std::fs::create_dir_all(out)
                    .with_context(|| format!("creating {}", out.display()))?;
                let path = out.join(format!("{name}-{method}.png"));
                let png = verdict_png(&input).context("drawing the verdict")?;
                std::fs::write(&path, png)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
            methods.push(MethodFigures {
                method,
                frames_per_s: frames.len() as f64 / seconds.max(1e-9),
                cells_observed: quality.cells_observed(),
                fraction_correct: quality.fraction_correct(),
                occupied_precision: quality.occupied_precision(),
                occupied_recall: quality.occupied_recall(),
                observed_occupied_recall: quality.observed_occupied_recall(),
                coverage: quality.coverage(),
            });
        }
        figures.push(WorldFigures {
            world: name,
            robots,
            frames: frames.len(),
            methods,
        });
    }
    print!("{}", table(&figures));
    if let Some(path) = &options.json {
        let report = Report {
            options: OptionsRecord {
                minutes: options.minutes,
                sonar: options.sonar.name().to_owned(),
                wall_probability: options.wall_probability,
                max_free_range: options.max_free_range,
                seed: options.seed,
            },
            worlds: &figures,
        };
        let text = serde_json::to_string_pretty(&report).context("encoding the figures")?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        eprintln!("figures written to {}", path.display());
    }
    Ok(())
}

/// The robots' frames, in firing order, and where each robot started.
fn record(
    world: &deog_world::World,
    robots: usize,
    options: &SonarMappingOptions,
) -> Result<(Vec<RecordedFrame>, Vec<Point2>)> {
    let config = SimConfig {
        sonar: options.sonar.params(),
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(world.clone(), config, options.seed)?;
    let period = sim.config().sonar_period_s;
    let mut latest = Vec::with_capacity(robots);
    let mut wanderers = Vec::with_capacity(robots);
    let mut seeds = Vec::with_capacity(robots);
    for i in 0..robots {
        let state = sim.spawn(&format!("scout-{}", i + 1), None)?;
        seeds.push(Point2::new(state.true_pose.x, state.true_pose.y));
        latest.push(state);
        wanderers.push(Wanderer::for_rig(
            WanderParams::default(),
            sim.rig(),
            options.seed.wrapping_mul(1000).wrapping_add(i as u64),
        )?);
    }
    let mut frames = Vec::new();
    let mut fired = Vec::new();
    while sim.time_s() < options.minutes * 60.0 {
        for (state, wanderer) in latest.iter().zip(&mut wanderers) {
            let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
            sim.drive(&state.name, v, w)?;
        }
        fired.clear();
        sim.advance(period, &mut fired)?;
        for state in fired.drain(..) {
            frames.push(RecordedFrame {
                sequence: frames.len() as u64 + 1,
                true_pose: state.true_pose,
                ranges: state.ranges.clone(),
            });
            if let Some(slot) = latest.iter_mut().find(|s| s.name == state.name) {
                *slot = state;
            }
        }
    }
    if frames.is_empty() {
        bail!("no frame fired in {} minutes", options.minutes);
    }
    Ok((frames, seeds))
}

/// `frames` mapped by `method` into a map of their own; the seconds the
/// mapping took.
fn build(
    method: &str,
    frames: &[RecordedFrame],
    options: &SonarMappingOptions,
) -> Result<(TileMap, f64)> {
    let (res, size) = (Resolution::DEFAULT, TileSize::new(64)?);
    let rig = deog_rig::scout();
    let (sonar_method, params) = if method == "directional-specular" {
        specular_sonar_mapping()
    } else {
        let mut params = mapping_sonar_model();
        params.max_free_range = options.max_free_range;
        if method.ends_with("no-echo-ignored") {
            params.no_echo_free_range = 0.0;
        }
        let sonar_method = if method.starts_with("thesis") {
            SonarMethod::Thesis
        } else if method.starts_with("directional") {
            SonarMethod::Directional
        } else {
            SonarMethod::KeepWalls
        };
        (sonar_method, params)
    };
    let view = MapViewSettings {
        wall_probability: options.wall_probability,
        shadow_probability: options.wall_probability,
        ..MapViewSettings::default()
    };
    // The Scout's own ring path (as `deog map` takes it for the Scout).
    let mut cartographer = Cartographer::with_model(res, size, PoseChoice::True, params)?
        .with_sonar_method(sonar_method, &rig, &params, view, res, size)?;
    let mut map = TileMap::new(res, size, ClampLimits::default());
    let mut deltas = Vec::new();
    let began = Instant::now();
    for frame in frames {
        deltas.clear();
        cartographer.integrate(
            &FrameInput {
                sequence: frame.sequence,
                true_pose: Some(frame.true_pose),
                odometry: frame.true_pose,
                reference_pose: None,
                estimate: None,
                ranges: &frame.ranges,
            },
            &mut deltas,
        )?;
        for delta in &deltas {
            map.apply(delta)?;
        }
    }
    Ok((map, began.elapsed().as_secs_f64()))
}

/// The figures as a Markdown table.
fn table(worlds: &[WorldFigures]) -> String {
    let percent = |v: Option<f64>| v.map_or("—".to_owned(), |v| format!("{:.1} %", 100.0 * v));
    let mut out = String::from(
        "| world | robots | frames | method | right | occupied precision | occupied recall | recall of observed walls | coverage | cells observed | frames/s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for w in worlds {
        for m in &w.methods {
            out += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} |\n",
                w.world,
                w.robots,
                w.frames,
                m.method,
                percent(Some(m.fraction_correct)),
                percent(m.occupied_precision),
                percent(m.occupied_recall),
                percent(m.observed_occupied_recall),
                percent(m.coverage),
                m.cells_observed,
                m.frames_per_s
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: SonarMappingOptions,
    }

    fn parse(args: &[&str]) -> SonarMappingOptions {
        Cli::try_parse_from(std::iter::once("bench").chain(args.iter().copied()))
            .expect("parse")
            .options
    }

    #[test]
    fn the_defaults_are_the_issues_worlds() {
        let options = parse(&[]);
        assert_eq!(
            options.validate().expect("valid"),
            [("office".to_owned(), 3), ("map2".to_owned(), 1)]
        );
        assert_eq!(options.sonar, SonarPreset::Realistic);
    }

    #[test]
    fn bad_options_name_their_flag() {
        let flag = |args: &[&str]| parse(args).validate().expect_err("refused").flag;
        assert_eq!(flag(&["--worlds", "office:0"]), "--worlds");
        assert_eq!(flag(&["--worlds", "office:x"]), "--worlds");
        assert_eq!(flag(&["--minutes", "0"]), "--minutes");
        assert_eq!(flag(&["--wall-probability", "1"]), "--wall-probability");
        assert_eq!(flag(&["--json", "/no/such/folder/x.json"]), "--json");
        assert_eq!(flag(&["--methods", "thesis,nosuch"]), "--methods");
    }

    #[test]
    fn a_short_run_maps_with_every_method() {
        let options = parse(&[
            "--worlds",
            "map2:1",
            "--minutes",
            "0.5",
            "--sonar",
            "default",
        ]);
        let world = load_world_spec("map2").expect("map2");
        let (frames, seeds) = record(&world, 1, &options).expect("record");
        assert!(frames.len() > 250, "{}", frames.len());
        assert_eq!(seeds.len(), 1);
        for method in METHODS {
            let (map, _) = build(method, &frames, &options).expect("build");
            let quality = map_quality(&QualityInput {
                map: &map,
                world: &world,
                seeds: &seeds,
                robot_radius_m: 0.2,
            })
            .expect("quality");
            assert!(quality.fraction_correct() > 0.8, "{method}");
        }
    }
}
