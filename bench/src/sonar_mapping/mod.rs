//! `deog bench sonar-mapping`: the sonar mapping methods side by side on
//! the same readings, in one process.
//!
//! Per world, `N` Scouts (the `world:N` of `--worlds`) wander the
//! simulator together for `--minutes`, with the sonar `--sonar` names; their
//! frames are recorded in the order they fire. Each method then maps exactly
//! those frames, from the true pose, into a map of its own, each robot's
//! through a cartographer of its own as `deog demo` maps them (one `deog
//! map` per robot; `--one-cartographer`: all through one, its views
//! shared), and the map is judged against the world (`deog-evaluation`'s
//! map quality, with the robots' starting points as the seeds of the
//! reachable free space):
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
//!   ([`SonarMethod::Directional`], `deog map --sonar-method directional`,
//!   with its default judgement of enclosed space);
//! - `directional-no-echo-ignored`: the same with no-echo readings
//!   ignored;
//! - `directional-specular`: what `deog demo` maps a specular sonar with
//!   ([`specular_sonar_mapping`]: directional, no-echo readings ignored,
//!   empty evidence out to 2 m whatever `--max-free-range` says, the
//!   space no robot could have seen sent as walls every 50 frames);
//! - `directional-specular-no-enclosure`: the same without the judgement
//!   of enclosed space (`deog map --enclosure-period 0`);
//! - `directional-specular-no-shadow`: `directional-specular` without
//!   taking back the free evidence that reached cells through a wall
//!   before it was heard (`deog map --shadow-depth 0`);
//! - `directional-specular-edges`: `directional-specular` with an echo
//!   believed to come from the cone's edges more than from its axis
//!   (region I's angle factor from [`SPECULAR_OCCUPIED_AXIS_FACTOR`] on
//!   the axis to 1 at the edge, where the thesis has 1 and 0: `deog map
//!   --occupied-axis-factor 0.4 --occupied-edge-factor 1`);
//! - `forward`: `directional-specular`'s map as the first guess of a map
//!   fitted to all the readings at once through the specular sonar's
//!   forward model ([`fit_forward`], three rounds of expectation and
//!   maximization, cells within 4 m of a sonar judged): a batch method,
//!   timed as the directional mapping plus the fit. Cells the readings
//!   decide too little, or that no ray reached, come out unknown, so it
//!   observes fewer cells;
//! - `octomap`: OctoMap, with one ray per reading with an echo, from its
//!   transducer along its axis to the range read, no-echo readings left
//!   out, OctoMap's default probabilities (hit 0.7, miss 0.4, clamping
//!   0.12 and 0.97) and rays cut at the 5 m the cones stop at; it runs in
//!   `bench/octomap_insert.py`, a child of `--python`, as in
//!   `deog bench laser-mapping` (details in `octomap_method`). Its final
//!   map's z = 0 layer, with OctoMap's log-odds, is judged as a deog map.
//!
//! `--methods` picks some of them. When the interpreter or its `octomap`
//! or numpy module is missing, the run says how to install them and
//! reports deog's methods alone, unless `--octomap` demands OctoMap:
//! then it is an error. `--no-octomap` leaves it out.
//!
//! Speed is mapping alone, on one thread: for deog's methods the
//! cartographer's integration and the deltas' application to the map,
//! for OctoMap the `insertPointCloud` calls (the script's loop included;
//! the cost of the calls themselves is also timed apart, with the same
//! calls holding no point, and reported). Cell updates are counted per
//! method: for deog's, the cells each frame's deltas touch (a frame's
//! cones folded into one delta per cell, as the cartographer returns
//! them); for OctoMap, the cells each ray's walk visits (counted in Rust
//! as OctoMap walks: one axis at a time from the transducer's cell to
//! the echo's, or to the 5 m cut), so a cell two rays of a frame cross
//! counts twice there, once on deog's side.
//!
//! The JSON (`--json FILE`) holds `options`, `octomap` (its versions and
//! settings; `null` when it did not run, and `octomap_skipped` says why if
//! it was chosen) and `worlds`: per world its `world`, `robots`, `frames`,
//! `methods` and `octomap` (`rays`, `seconds`, `empty_call_seconds`,
//! `leaf_cells`, `tree_nodes`, `memory_bytes`, or `null`); each method
//! with `method`, `frames_per_s` and `cell_updates_per_s` (mapping
//! alone), `cell_updates`, and the map quality's `cells_observed`,
//! `fraction_correct`, `occupied_precision`, `occupied_recall`,
//! `observed_occupied_recall` and `coverage`.

mod octomap_method;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_evaluation::map_quality::{QualityInput, map_quality, verdict_png};
use deog_grid::{ClampLimits, Pose2, Resolution, TileMap, TileSize};
use deog_harness::Progress;
use deog_mapping::{
    Cartographer, ForwardSettings, FrameInput, MapViewSettings, PoseChoice,
    SPECULAR_OCCUPIED_AXIS_FACTOR, SonarMethod, echo_below, fit_forward, mapping_sonar_model,
    ring_readings, specular_sonar_mapping,
};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{SonarPreset, WanderParams, Wanderer};
use deog_world::{Point2, load_world_spec};
use serde::Serialize;

use crate::option_error::{OptionError, require};
use octomap_method::{OctomapDetails, OctomapRecord, OctomapSide};

/// The methods compared, in the order the table lists them.
pub const METHODS: [&str; 12] = [
    "thesis",
    "thesis-no-echo-ignored",
    "keep-walls",
    "keep-walls-no-echo-ignored",
    "directional",
    "directional-no-echo-ignored",
    "directional-specular",
    "directional-specular-no-enclosure",
    "directional-specular-no-shadow",
    "directional-specular-edges",
    "forward",
    "octomap",
];

/// A robot's frames between two readings of its cartographer's view of
/// the map from the map being written: the 5 s `deog map` waits by
/// default, at a Scout's 10 frames a second.
pub(crate) const VIEW_REFRESH_FRAMES: u32 = 50;

/// The method OctoMap runs as.
const OCTOMAP: &str = "octomap";

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
    /// method of deog's (`deog map --max-free-range`); not OctoMap's,
    /// whose rays stop at 5 m, hit and free space alike.
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
    /// The Python interpreter that runs the octomap method (it needs
    /// `pip install octomap-python numpy`).
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
    /// Leave the octomap method out.
    #[arg(long, conflicts_with = "octomap")]
    pub no_octomap: bool,
    /// Fail when the octomap method cannot run, rather than reporting
    /// deog's methods alone.
    #[arg(long)]
    pub octomap: bool,
    /// Map every robot's frames through one cartographer, whose views
    /// (walls kept, beliefs by direction) then hold what all the robots
    /// read. No process of deog's maps so: `deog demo` runs one `deog map`
    /// per robot, each with views of its own, as this bench does by
    /// default. Figures recorded before 2026-11-30 were measured so.
    #[arg(long)]
    pub one_cartographer: bool,
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
        require(
            !self.octomap || self.methods.iter().any(|m| m == OCTOMAP),
            "--octomap",
            || "--octomap demands the octomap method, which --methods leaves out".into(),
        )?;
        require(!self.chosen_methods().is_empty(), "--no-octomap", || {
            "--no-octomap leaves no method of --methods to run".into()
        })?;
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

    /// The methods to run, in [`METHODS`]' order.
    fn chosen_methods(&self) -> Vec<&'static str> {
        METHODS
            .into_iter()
            .filter(|m| self.methods.iter().any(|chosen| chosen == m))
            .filter(|m| !(self.no_octomap && *m == OCTOMAP))
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
    /// Cells updated, all frames (see the module docs for how each method
    /// counts).
    pub cell_updates: u64,
    /// Cell updates per second, mapping alone.
    pub cell_updates_per_s: f64,
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
    /// OctoMap's run beyond its map's figures, when it ran.
    octomap: Option<OctomapDetails>,
}

#[derive(Debug, Serialize)]
struct Report<'a> {
    options: OptionsRecord,
    octomap: Option<OctomapRecord>,
    octomap_skipped: Option<&'a str>,
    worlds: &'a [WorldFigures],
}

#[derive(Debug, Serialize)]
struct OptionsRecord {
    minutes: f64,
    sonar: String,
    wall_probability: f64,
    max_free_range: f64,
    seed: u64,
    one_cartographer: bool,
}

/// A frame as recorded: where the robot really was, what it read.
struct RecordedFrame {
    sequence: u64,
    /// Which robot read it, 0 to `robots − 1`.
    robot: usize,
    /// The robot's pace by its odometry ([`deog_mapping::FrameInput::pace`]).
    pace: Option<Pose2>,
    true_pose: Pose2,
    ranges: Vec<f64>,
}

/// One method's map of one world, and what making it took.
struct Built {
    map: TileMap,
    /// Seconds of mapping alone.
    seconds: f64,
    /// Cells updated (see the module docs).
    cell_updates: u64,
    /// OctoMap's figures beyond those, for its method.
    octomap: Option<OctomapDetails>,
}

/// Runs `deog bench sonar-mapping`.
pub fn run(options: SonarMappingOptions) -> Result<()> {
    let worlds = options.validate()?;
    let mut methods = options.chosen_methods();
    let (res, size) = (Resolution::DEFAULT, TileSize::new(64)?);
    let mut octomap_skipped = None;
    let octomap = if methods.contains(&OCTOMAP) {
        match OctomapSide::new(&options.python, res)? {
            Ok(side) => {
                let r = side.record();
                deog_harness::eprintln_above_bars!(
                    "octomap: octomap-python {} on Python {} (numpy {})",
                    r.octomap,
                    r.python,
                    r.numpy
                );
                Some(side)
            }
            Err(reason) if options.octomap => {
                bail!("--octomap: OctoMap's side cannot run: {reason}")
            }
            Err(reason) => {
                methods.retain(|m| *m != OCTOMAP);
                if methods.is_empty() {
                    bail!("the octomap method cannot run, and no other was chosen: {reason}");
                }
                deog_harness::eprintln_above_bars!(
                    "octomap: not run: {reason}; reporting deog's methods alone"
                );
                octomap_skipped = Some(reason);
                None
            }
        }
    } else {
        None
    };
    let rig = deog_rig::scout();
    let mut figures = Vec::new();
    // Per world: its recording, then one map per method.
    let progress = Progress::new(
        "sonar mapping",
        "steps",
        (worlds.len() * (1 + methods.len())) as u64,
    );
    for (name, robots) in worlds {
        let world = load_world_spec(&name).with_context(|| format!("world {name}"))?;
        let began = Instant::now();
        let (frames, seeds) = record(&world, robots, &options)?;
        progress.inc(1);
        deog_harness::eprintln_above_bars!(
            "{name}: {robots} robot(s), {} frames recorded in {:.1} s",
            frames.len(),
            began.elapsed().as_secs_f64()
        );
        let mut world_figures = WorldFigures {
            world: name.clone(),
            robots,
            frames: frames.len(),
            methods: Vec::new(),
            octomap: None,
        };
        for &method in &methods {
            let built = match (&octomap, method) {
                (Some(side), OCTOMAP) => {
                    let o = side.build(&rig, &frames, size)?;
                    Built {
                        map: o.map,
                        seconds: o.seconds,
                        cell_updates: o.cell_updates,
                        octomap: Some(o.details),
                    }
                }
                _ => build(method, &frames, &options, res, size)?,
            };
            let input = QualityInput {
                map: &built.map,
                world: &world,
                seeds: &seeds,
                robot_radius_m: rig.body_radius(),
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
            let seconds = built.seconds.max(1e-9);
            world_figures.methods.push(MethodFigures {
                method,
                frames_per_s: frames.len() as f64 / seconds,
                cell_updates: built.cell_updates,
                cell_updates_per_s: built.cell_updates as f64 / seconds,
                cells_observed: quality.cells_observed(),
                fraction_correct: quality.fraction_correct(),
                occupied_precision: quality.occupied_precision(),
                occupied_recall: quality.occupied_recall(),
                observed_occupied_recall: quality.observed_occupied_recall(),
                coverage: quality.coverage(),
            });
            if built.octomap.is_some() {
                world_figures.octomap = built.octomap;
            }
            progress.inc(1);
        }
        figures.push(world_figures);
    }
    progress.finish();
    let octomap_record = octomap.as_ref().map(OctomapSide::record);
    deog_harness::print_above_bars!("{}", table(&figures, octomap_record.as_ref()));
    if let Some(path) = &options.json {
        let report = Report {
            options: OptionsRecord {
                minutes: options.minutes,
                sonar: options.sonar.name().to_owned(),
                wall_probability: options.wall_probability,
                max_free_range: options.max_free_range,
                seed: options.seed,
                one_cartographer: options.one_cartographer,
            },
            octomap: octomap_record,
            octomap_skipped: octomap_skipped.as_deref(),
            worlds: &figures,
        };
        let text = serde_json::to_string_pretty(&report).context("encoding the figures")?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        deog_harness::eprintln_above_bars!("figures written to {}", path.display());
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
    let mut motions = vec![deog_grid::FrameMotion::default(); robots];
    while sim.time_s() < options.minutes * 60.0 {
        for (state, wanderer) in latest.iter().zip(&mut wanderers) {
            let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
            sim.drive(&state.name, v, w)?;
        }
        fired.clear();
        sim.advance(period, &mut fired)?;
        for state in fired.drain(..) {
            let robot = latest
                .iter()
                .position(|s| s.name == state.name)
                .unwrap_or(0);
            let motion = &mut motions[robot];
            frames.push(RecordedFrame {
                sequence: frames.len() as u64 + 1,
                robot,
                pace: motion.observe(&state.odometry, state.time_s),
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

/// `frames` mapped by deog's `method` into a map of their own, the
/// seconds the mapping took and the cells it updated.
fn build(
    method: &str,
    frames: &[RecordedFrame],
    options: &SonarMappingOptions,
    res: Resolution,
    size: TileSize,
) -> Result<Built> {
    if method == OCTOMAP {
        bail!("the octomap method is OctoMap's side, not deog's");
    }
    if method == "forward" {
        return build_forward(frames, options, res, size);
    }
    let rig = deog_rig::scout();
    let (sonar_method, params) = if method.starts_with("directional-specular") {
        let (sonar_method, mut params) = specular_sonar_mapping();
        if method.ends_with("-edges") {
            params.occupied_axis_factor = SPECULAR_OCCUPIED_AXIS_FACTOR;
            params.occupied_edge_factor = 1.0;
        }
        (sonar_method, params)
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
        enclosure_period: if method.ends_with("no-enclosure") {
            0
        } else {
            MapViewSettings::default().enclosure_period
        },
        shadow_depth: if method.ends_with("no-shadow") {
            0.0
        } else {
            MapViewSettings::default().shadow_depth
        },
        ..MapViewSettings::default()
    };
    // The Scout's own ring path (as `deog map` takes it for the Scout).
    // Each reading where its sonar fired, as `deog map --firing-period`.
    let firing = SimConfig {
        sonar: options.sonar.params(),
        ..SimConfig::default()
    }
    .ring_firing();
    // One cartographer per robot, as `deog demo` runs one `deog map` per
    // robot; their deltas go to one map, as the map server adds them.
    let robots = if options.one_cartographer {
        1
    } else {
        frames.iter().map(|f| f.robot + 1).max().unwrap_or(1)
    };
    let mut cartographers = (0..robots)
        .map(|_| {
            Ok(
                Cartographer::with_model(res, size, PoseChoice::True, params)?
                    .with_sonar_method(sonar_method, &rig, &params, view, res, size)?
                    .with_firing(firing)
                    .reading_map_every(VIEW_REFRESH_FRAMES),
            )
        })
        .collect::<Result<Vec<_>>>()?;
    let mut map = TileMap::new(res, size, ClampLimits::default());
    let mut deltas = Vec::new();
    let mut cell_updates = 0;
    let began = Instant::now();
    for frame in frames {
        deltas.clear();
        let robot = frame.robot.min(robots - 1);
        let cartographer = &mut cartographers[robot];
        let input = FrameInput {
            sequence: frame.sequence,
            pace: frame.pace,
            true_pose: Some(frame.true_pose),
            odometry: frame.true_pose,
            reference_pose: None,
            estimate: None,
            ranges: &frame.ranges,
        };
        cartographer.read_missing_tiles(&input, &map)?;
        cell_updates += cartographer.integrate(&input, &mut deltas)? as u64;
        for delta in &deltas {
            map.apply(delta)?;
        }
    }
    Ok(Built {
        seconds: began.elapsed().as_secs_f64(),
        map,
        cell_updates,
        octomap: None,
    })
}

/// The forward model of the simulator's sonar `params`.
pub(crate) fn forward_settings(params: &deog_simulator::SonarParams) -> ForwardSettings {
    let critical = match params.specular {
        deog_simulator::Specular::Off => None,
        deog_simulator::Specular::Lost { max_incidence }
        | deog_simulator::Specular::Long { max_incidence, .. } => Some(max_incidence),
    };
    ForwardSettings::for_sonar(params.half_angle, params.max_range, critical)
}

/// `directional-specular`'s map refitted to every reading through the
/// forward model ([`fit_forward`]).
fn build_forward(
    frames: &[RecordedFrame],
    options: &SonarMappingOptions,
    res: Resolution,
    size: TileSize,
) -> Result<Built> {
    let first = build("directional-specular", frames, options, res, size)?;
    let began = Instant::now();
    let ring = deog_grid::SensorRing::scout();
    let params = options.sonar.params();
    let firing = SimConfig {
        sonar: params,
        ..SimConfig::default()
    }
    .ring_firing();
    let mut readings = Vec::with_capacity(frames.len() * ring.len());
    for frame in frames {
        ring_readings(
            &ring,
            firing,
            &frame.true_pose,
            frame.pace.as_ref(),
            echo_below(&frame.ranges, params.max_range),
            &mut readings,
        );
    }
    let (map, stats) = fit_forward(
        &first.map,
        &readings,
        &forward_settings(&params),
        ClampLimits::default(),
    )?;
    deog_harness::eprintln_above_bars!(
        "forward: {} readings, {} cells reached, {} crossed p = 0.5 in the last round, log-likelihood {:.0}, {:.1} s",
        stats.readings,
        stats.cells_reached,
        stats.last_changes,
        stats.log_likelihood,
        began.elapsed().as_secs_f64()
    );
    Ok(Built {
        seconds: first.seconds + began.elapsed().as_secs_f64(),
        map,
        cell_updates: first.cell_updates,
        octomap: None,
    })
}

/// The figures as a Markdown table; OctoMap's settings and runs, when it
/// ran, on lines before and after.
fn table(worlds: &[WorldFigures], octomap: Option<&OctomapRecord>) -> String {
    let percent = |v: Option<f64>| v.map_or("—".to_owned(), |v| format!("{:.1} %", 100.0 * v));
    let mut out = String::new();
    if let Some(o) = octomap {
        out += &format!(
            "octomap: octomap-python {} (Python {}, numpy {}), one insertPointCloud call per echo from its transducer, {} m voxels, hit {} miss {}, clamp {}..{}, rays cut at {} m\n\n",
            o.octomap,
            o.python,
            o.numpy,
            o.resolution_m,
            o.prob_hit,
            o.prob_miss,
            o.clamp_min,
            o.clamp_max,
            o.max_range_m
        );
    }
    out += "| world | robots | frames | method | right | occupied precision | occupied recall | recall of observed walls | coverage | cells observed | frames/s | cell updates/s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for w in worlds {
        for m in &w.methods {
            out += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} | {:.2} M |\n",
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
                m.frames_per_s,
                m.cell_updates_per_s / 1e6
            );
        }
    }
    for w in worlds {
        if let Some(o) = &w.octomap {
            let calls = o.empty_call_seconds.map_or(String::new(), |s| {
                format!(
                    ", of which about {s:.3} s ({:.0} %) is the calls' own cost (the same calls with no point)",
                    100.0 * s / o.seconds.max(1e-9)
                )
            });
            out += &format!(
                "\noctomap, {}: {} rays in {:.3} s{calls}; its tree: {} leaves, {} nodes, {:.1} MB",
                w.world,
                o.rays,
                o.seconds,
                o.leaf_cells,
                o.tree_nodes,
                o.memory_bytes as f64 / 1e6
            );
        }
    }
    if worlds.iter().any(|w| w.octomap.is_some()) {
        out += "\n";
    }
    out
}

#[cfg(test)]
mod tests {
    use std::path::Path;

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
    fn octomap_is_a_method_its_flags_choose_or_refuse() {
        let options = parse(&[]);
        assert_eq!(options.chosen_methods(), METHODS);
        assert_eq!(METHODS.last(), Some(&"octomap"));
        assert_eq!(options.python, PathBuf::from("python3"));
        assert!(!options.octomap && !options.no_octomap);

        let options = parse(&["--no-octomap"]);
        assert_eq!(options.chosen_methods(), &METHODS[..METHODS.len() - 1]);
        assert!(options.validate().is_ok());
        let options = parse(&["--octomap", "--python", "/opt/py/bin/python3"]);
        assert!(options.octomap && options.validate().is_ok());
        assert_eq!(options.python, PathBuf::from("/opt/py/bin/python3"));
        // The table's order, whatever the order asked.
        let options = parse(&["--methods", "octomap,thesis"]);
        assert_eq!(options.chosen_methods(), ["thesis", "octomap"]);

        assert!(
            Cli::try_parse_from(["bench", "--octomap", "--no-octomap"]).is_err(),
            "demanded and refused at once"
        );
        let flag = |args: &[&str]| parse(args).validate().expect_err("refused").flag;
        assert_eq!(flag(&["--octomap", "--methods", "thesis"]), "--octomap");
        assert_eq!(
            flag(&["--no-octomap", "--methods", "octomap"]),
            "--no-octomap"
        );
    }

    #[test]
    fn without_octomap_the_run_reports_deogs_methods_alone_unless_octomap_is_demanded() {
        let missing = ["--python", "/nonexistent/python3", "--worlds", "map2:1"];
        let demanded = parse(&[&missing[..], &["--octomap", "--minutes", "0.2"]].concat());
        let error = run(demanded).expect_err("demanded").to_string();
        assert!(
            error.starts_with("--octomap: OctoMap's side cannot run"),
            "{error}"
        );
        let alone = parse(&[&missing[..], &["--methods", "octomap"]].concat());
        let error = run(alone).expect_err("nothing left").to_string();
        assert!(error.contains("no other was chosen"), "{error}");

        let work = tempfile::tempdir().expect("a temporary directory");
        let json = work.path().join("figures.json");
        let json_arg = json.to_str().expect("a UTF-8 path");
        let options = parse(
            &[
                &missing[..],
                &["--methods", "thesis,octomap", "--minutes", "0.2"],
                &["--json", json_arg],
            ]
            .concat(),
        );
        run(options).expect("deog's methods alone");
        let figures: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("read")).expect("JSON");
        assert!(figures["octomap"].is_null());
        let skipped = figures["octomap_skipped"].as_str().expect("a reason");
        assert!(skipped.contains("/nonexistent/python3"), "{skipped}");
        let methods = figures["worlds"][0]["methods"].as_array().expect("methods");
        assert_eq!(methods.len(), 1);
        assert_eq!(methods[0]["method"], "thesis");
        assert!(methods[0]["cell_updates_per_s"].as_f64().expect("a rate") > 0.0);
        assert!(figures["worlds"][0]["octomap"].is_null());
    }

    /// OctoMap's side when `python3` has octomap and numpy; `None`, said
    /// so, when it has not.
    fn octomap_side() -> Option<OctomapSide> {
        match OctomapSide::new(Path::new("python3"), Resolution::DEFAULT).expect("the script") {
            Ok(side) => Some(side),
            Err(reason) => {
                deog_harness::eprintln_above_bars!(
                    "skipped OctoMap's part: it cannot run here: {reason}"
                );
                None
            }
        }
    }

    #[test]
    fn octomaps_map_holds_the_cells_its_rays_update() {
        let Some(side) = octomap_side() else {
            return;
        };
        // Facing +x: sonar 0 reads 1 m ahead, sonar 4 (to the left) 2 m,
        // sonar 12 (to the right) 7 m, past the 5 m cut; the rays share
        // no cell.
        let mut ranges = vec![10.668; 16];
        ranges[0] = 1.0;
        ranges[4] = 2.0;
        ranges[12] = 7.0;
        let frames = [RecordedFrame {
            sequence: 1,
            robot: 0,
            pace: None,
            true_pose: Pose2::new(0.01, 0.01, 0.0),
            ranges,
        }];
        let rig = deog_rig::scout();
        let built = side
            .build(&rig, &frames, TileSize::new(64).expect("size"))
            .expect("OctoMap's map");
        let details = &built.details;
        assert_eq!(details.rays, 3);
        assert!(details.seconds > 0.0 && details.empty_call_seconds.is_some());
        // Every cell updated once: the map observed just the counted cells.
        assert_eq!(built.map.observed_count() as u64, built.cell_updates);
        // 0.2 + 1 m ahead, 0.2 + 2 m left, 0.2 + 5 m right (cut, no hit),
        // each ray from its transducer's cell: about 20 + 40 + 100 cells.
        assert!(
            (150..=175).contains(&built.cell_updates),
            "{}",
            built.cell_updates
        );
        let res = Resolution::DEFAULT;
        let belief = |x: f64, y: f64| {
            built
                .map
                .get(res.cell_of(x, y).expect("cell"))
                .map(|b| b.probability())
        };
        let near = |p: Option<f64>, want: f64| {
            assert!(p.is_some_and(|p| (p - want).abs() < 1e-3), "{p:?}");
        };
        near(belief(1.21, 0.01), 0.7); // sonar 0's echo
        near(belief(0.7, 0.01), 0.4); // on its way
        near(belief(0.01, 2.21), 0.7); // sonar 4's echo
        near(belief(0.01, -5.0), 0.4); // sonar 12's ray, freed to 5 m
        assert_eq!(belief(0.01, -5.25), None, "nothing past the cut");
        assert_eq!(belief(-1.0, 0.01), None, "sonar 8 heard nothing");
    }

    #[test]
    fn each_robot_has_a_cartographer_of_its_own_unless_one_is_asked_for() {
        let options = |one: bool| {
            let mut args = vec!["--worlds", "map2:2", "--minutes", "0.3"];
            if one {
                args.push("--one-cartographer");
            }
            parse(&args)
        };
        let world = load_world_spec("map2").expect("map2");
        let (frames, _) = record(&world, 2, &options(false)).expect("record");
        assert!(frames.iter().any(|f| f.robot == 0) && frames.iter().any(|f| f.robot == 1));
        let (res, size) = (Resolution::DEFAULT, TileSize::new(64).expect("size"));
        let cells = |method: &str, one: bool| {
            let built = build(method, &frames, &options(one), res, size).expect("build");
            let mut cells: Vec<_> = built
                .map
                .tiles()
                .flat_map(|(key, tile)| {
                    tile.raw_cells()
                        .iter()
                        .enumerate()
                        .map(move |(i, v)| (*key, i, *v))
                })
                .collect();
            cells.sort();
            cells
        };
        // The thesis's model keeps nothing between frames: one
        // cartographer or two, the map server's sums are the same.
        assert_eq!(cells("thesis", false), cells("thesis", true));
        // Beliefs by direction are a cartographer's own: two robots' views
        // apart make another map than one view of both.
        assert_ne!(
            cells("directional-specular", false),
            cells("directional-specular", true)
        );
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
        let (res, size) = (Resolution::DEFAULT, TileSize::new(64).expect("size"));
        let octomap = octomap_side();
        for method in METHODS {
            let built = match (method, &octomap) {
                (OCTOMAP, None) => continue,
                (OCTOMAP, Some(side)) => {
                    let o = side
                        .build(&deog_rig::scout(), &frames, size)
                        .expect("build");
                    assert!(o.details.rays > 1000, "{}", o.details.rays);
                    Built {
                        map: o.map,
                        seconds: o.seconds,
                        cell_updates: o.cell_updates,
                        octomap: Some(o.details),
                    }
                }
                _ => build(method, &frames, &options, res, size).expect("build"),
            };
            assert!(built.seconds > 0.0, "{method}");
            assert!(
                built.cell_updates >= built.map.observed_count() as u64,
                "{method}: every observed cell was updated"
            );
            let quality = map_quality(&QualityInput {
                map: &built.map,
                world: &world,
                seeds: &seeds,
                robot_radius_m: 0.2,
            })
            .expect("quality");
            assert!(quality.fraction_correct() > 0.8, "{method}");
        }
        assert!(build(OCTOMAP, &frames, &options, res, size).is_err());
    }
}
