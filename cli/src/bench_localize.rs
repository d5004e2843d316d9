//! `deog bench localize`: localization accuracy over many seeded runs, in
//! one process with the same parts the separate processes use (simulator,
//! wanderer, cartographer, filter), so that 20 runs per world take minutes.
//!
//! Per world: one robot wanders for `--map-minutes` while the cartographer
//! builds the map from its true poses (as `deog map` does). Then, per run,
//! a robot starts at a random pose, the filter starts with no idea where
//! (uniform over the map's free cells), the wanderer drives, and half-way
//! the robot is kidnapped to another random pose.

use std::time::{Duration, Instant};

use anyhow::{Context, Result, ensure};
use clap::Args;
use deog_evaluation::localization::{
    DEFAULT_CONVERGE_M, DEFAULT_CONVERGE_RAD, EstimateSample, EvalInput, TruthSample, evaluate,
};
use deog_evaluation::runs::{RunFigures, summarize};
use deog_grid::{
    ClampLimits, OccupancyThresholds, Pose2, Resolution, SensorRing, TileMap, TileSize,
    normalize_angle,
};
use deog_localizer::beam_model::table_len;
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::step::{Localizer, TileSource};
use deog_mapping::{Cartographer, FrameInput, PoseChoice};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{Specular, WanderParams, Wanderer};
use deog_world::load_world_spec;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Options of `deog bench localize`.
#[derive(Debug, Args)]
pub struct LocalizeBenchArgs {
    /// Worlds to run in, comma-separated.
    #[arg(long, default_value = "map1,map2", value_delimiter = ',')]
    pub worlds: Vec<String>,
    /// Seeded runs per world.
    #[arg(long, default_value_t = 20)]
    pub runs: u64,
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
    /// Most particles.
    #[arg(long, default_value_t = FilterSettings::default().kld.max_particles)]
    pub max_particles: usize,
    /// Turn specular reflection (lost echoes past 60° of incidence) and 2 %
    /// dropouts on in the simulator.
    #[arg(long)]
    pub specular: bool,
    /// With `--specular`, build the map from the default sonar all the same
    /// (as a map drawn from a laser scan would be): the runs' specular
    /// readings then meet a map without the holes such readings leave in it.
    #[arg(long)]
    pub clean_map: bool,
    /// Fewest particles.
    #[arg(long, default_value_t = FilterSettings::default().kld.min_particles)]
    pub min_particles: usize,
    /// The beam model's tempering τ (see deog_localizer::beam_model).
    #[arg(long, default_value_t = deog_localizer::beam_model::BeamModelParams::default().tempering)]
    pub tempering: f64,
    /// The beam model's hit spread at zero range, metres.
    #[arg(long, default_value_t = deog_localizer::beam_model::BeamModelParams::default().hit_sigma_m)]
    pub hit_sigma: f64,
    /// The beam model's hit spread growth per metre.
    #[arg(long, default_value_t = deog_localizer::beam_model::BeamModelParams::default().hit_sigma_per_m)]
    pub hit_sigma_per_m: f64,
    /// How far past the first occupied cell's near face echoes are
    /// expected, metres (see `deog localize --surface-depth`).
    #[arg(long, default_value_t = ConeGeometry::default().surface_depth)]
    pub surface_depth: f64,
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
    /// true pose: where the sensor model and the world disagree.
    #[arg(long, value_delimiter = ',')]
    pub beams_between: Option<Vec<f64>>,
    /// Also score each frame at the true pose and at its image turned 180°
    /// about this point ("x,y"), and print the sums: how much the map tells
    /// a symmetric world's two halves apart.
    #[arg(long, value_delimiter = ',')]
    pub mirror_about: Option<Vec<f64>>,
    /// Print each run's true and estimated pose every this many simulated
    /// seconds (0: never).
    #[arg(long, default_value_t = 0.0)]
    pub trace_every: f64,
}

/// Convergence and recovery count when they come within this many
/// seconds.
const CONVERGE_LIMIT_S: f64 = 60.0;

/// Runs `deog bench localize`.
pub fn run(args: LocalizeBenchArgs) -> Result<()> {
    ensure!(args.runs > 0, "--runs must be at least 1");
    ensure!(args.seconds > 0.0, "--seconds must be positive");
    if let Some(window) = &args.beams_between {
        ensure!(
            window.len() == 2 && window[0] <= window[1],
            "--beams-between takes two times in seconds, \"from,to\", from no later than to"
        );
    }
    if let Some(centre) = &args.mirror_about {
        ensure!(
            centre.len() == 2 && centre.iter().all(|v| v.is_finite()),
            "--mirror-about takes a point in metres, \"x,y\""
        );
    }
    ensure!(
        !args.clean_map || args.specular,
        "--clean-map only means something with --specular"
    );
    for world_name in &args.worlds {
        let started = Instant::now();
        let world = load_world_spec(world_name)?;
        let config = sim_config(args.specular);
        let map_config = sim_config(args.specular && !args.clean_map);
        let (mut tiles, mut map) = build_map(
            world.clone(),
            &map_config,
            &config,
            args.map_minutes,
            args.surface_depth,
        )?;
        println!(
            "{world_name}: map built in {:.1} s ({} tiles)",
            started.elapsed().as_secs_f64(),
            map.tile_count()
        );
        let mut all = Vec::new();
        for seed in args.seed..args.seed + args.runs {
            let t0 = Instant::now();
            let (figures, held) = run_once(world.clone(), &config, map, &mut tiles, seed, &args)?;
            map = held;
            if args.verbose {
                println!(
                    "  seed {seed}: converge {} s, recover {} s, mean error {:.3} m {:.2}°, {} samples, {:.1} s",
                    fmt_opt(figures.converge_s),
                    fmt_opt(figures.recover_s),
                    figures.mean_position_m.unwrap_or(0.0),
                    figures.mean_heading_deg.unwrap_or(0.0),
                    figures.samples,
                    t0.elapsed().as_secs_f64()
                );
            }
            all.push(figures);
        }
        let summary = summarize(&all, CONVERGE_LIMIT_S);
        println!(
            "{world_name}: converged within 60 s {}/{} ({:.0} %), recovered within 60 s {}/{} ({:.0} %), mean error after convergence {:.3} m, {:.2}°; {:.1} s",
            summary.converged,
            summary.runs,
            summary.converged_percent(),
            summary.recovered,
            summary.runs,
            summary.recovered_percent(),
            summary.mean_position_m.unwrap_or(0.0),
            summary.mean_heading_deg.unwrap_or(0.0),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// One line: each beam's measured range and, after a slash, the range the
/// map's tables predict at `pose` (centimetres; `-` for no echo).
fn print_beams(map: &mut LocalMap, pose: &Pose2, ranges: &[f64], time_s: f64) -> Result<()> {
    let ring = SensorRing::scout();
    let keys = map.tables_under(&ring, pose)?;
    let max_range = map.settings().geometry.max_range;
    let no_echo = table_len(max_range) - 1;
    let window = map.window(&keys);
    let mut line = format!(
        "    beams t {time_s:6.1} ({:5.2}, {:5.2}, {:6.1}°)",
        pose.x,
        pose.y,
        pose.theta.to_degrees()
    );
    for (sensor, z) in ring.sensor_poses(pose).zip(ranges) {
        let (sin, cos) = sensor.theta.sin_cos();
        let slot = window.expected_slot(sensor.x, sensor.y, sensor.theta, (cos, sin), no_echo);
        let measured = if z.is_finite() && *z < max_range {
            format!("{:.0}", z * 100.0)
        } else {
            "-".into()
        };
        let expected = if slot == no_echo {
            "-".into()
        } else {
            slot.to_string()
        };
        line.push_str(&format!(" {measured}/{expected}"));
    }
    println!("{line}");
    Ok(())
}

/// `pose` turned 180° about `centre` ("x,y", as `--mirror-about` gives it).
fn image_of(pose: &Pose2, centre: &[f64]) -> Pose2 {
    Pose2::new(
        2.0 * centre[0] - pose.x,
        2.0 * centre[1] - pose.y,
        pose.theta + std::f64::consts::PI,
    )
}

/// How many particles lie within the convergence bounds of `pose`, and
/// their weight.
fn particles_near(mcl: &Mcl, pose: &Pose2) -> (usize, f64) {
    let (mut near, mut weight) = (0usize, 0.0f64);
    for (p, w) in mcl.particles().iter().zip(mcl.weights()) {
        if (p.x - pose.x).hypot(p.y - pose.y) <= DEFAULT_CONVERGE_M
            && normalize_angle(p.theta - pose.theta).abs() <= DEFAULT_CONVERGE_RAD
        {
            near += 1;
            weight += w;
        }
    }
    (near, weight)
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.1}"))
}

fn sim_config(specular: bool) -> SimConfig {
    let mut config = SimConfig::default();
    if specular {
        config.sonar.specular = Specular::Lost {
            max_incidence: 60f64.to_radians(),
        };
        config.sonar.dropout_probability = 0.02;
    }
    config
}

/// The map a wandering robot's frames give, as the cartographer builds it
/// from the sonar of `config`, with range tables for the sonar of
/// `localize_config`.
fn build_map(
    world: deog_world::World,
    config: &SimConfig,
    localize_config: &SimConfig,
    minutes: f64,
    surface_depth: f64,
) -> Result<(TileMap, LocalMap)> {
    let res = Resolution::DEFAULT;
    let size = TileSize::new(64)?;
    let mut sim = Simulation::new(world, config.clone(), 1000)?;
    let mut state = sim.spawn("cartographer", None)?;
    let mut wanderer = Wanderer::new(WanderParams::default(), &SensorRing::scout(), 1000)?;
    // The sonar model `deog map` maps with.
    let mut params = deog_mapping::mapping_sonar_model();
    if !matches!(config.sonar.specular, Specular::Off) {
        // A specular sonar's no-echo readings are mostly lost echoes, not
        // free space: the cartographer is told to ignore them.
        params.no_echo_free_range = 0.0;
    }
    let mut cartographer = Cartographer::with_model(res, size, PoseChoice::True, params)?;
    let mut tiles = TileMap::new(res, size, ClampLimits::default());
    let mut deltas = Vec::new();
    let mut fired = Vec::new();
    let period = sim.config().sonar_period_s;
    while sim.time_s() < minutes * 60.0 {
        let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
        sim.drive("cartographer", v, w)?;
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired)?;
        }
        state = fired.pop().context("a firing")?;
        deltas.clear();
        cartographer.integrate(
            &FrameInput {
                sequence: state.sequence,
                true_pose: Some(state.true_pose),
                odometry: state.odometry,
                ranges: &state.ranges,
            },
            &mut deltas,
        )?;
        for d in &deltas {
            tiles.apply(d)?;
        }
    }
    let mut map = LocalMap::new(MapSettings {
        resolution: res,
        tile_size: size,
        thresholds: OccupancyThresholds::default(),
        // The localizer knows its sonar: specular past the same angle.
        geometry: ConeGeometry {
            specular_max_incidence: match localize_config.sonar.specular {
                Specular::Off => None,
                Specular::Lost { max_incidence } | Specular::Long { max_incidence, .. } => {
                    Some(max_incidence)
                }
            },
            surface_depth,
            ..ConeGeometry::default()
        },
        budget_bytes: 512 << 20,
    })?;
    for (key, tile) in tiles.tiles() {
        map.insert_tile(*key, 1, Some(tile))?;
    }
    Ok((tiles, map))
}

/// One seeded run on `map` (its tiles from `tiles`); returns its figures
/// and the map, with the tables it built, for the next run.
fn run_once(
    world: deog_world::World,
    config: &SimConfig,
    map: LocalMap,
    tiles: &mut TileMap,
    seed: u64,
    args: &LocalizeBenchArgs,
) -> Result<(RunFigures, LocalMap)> {
    let mut sim = Simulation::new(world, config.clone(), seed)?;
    let mut state = sim.spawn("scout", None)?;
    let mut wanderer = Wanderer::new(WanderParams::default(), &SensorRing::scout(), seed)?;
    let mut settings = FilterSettings {
        seed,
        ..FilterSettings::default()
    };
    settings.kld.max_particles = args.max_particles;
    settings.kld.min_particles = args.min_particles;
    settings.beam.tempering = args.tempering;
    settings.beam.hit_sigma_m = args.hit_sigma;
    settings.beam.hit_sigma_per_m = args.hit_sigma_per_m;
    settings.alpha_fast = args.alpha_fast;
    let k = args.motion_noise_scale;
    settings.motion.rot_per_rot *= k;
    settings.motion.rot_per_trans *= k;
    settings.motion.trans_per_trans *= k;
    settings.motion.trans_per_rot *= k;
    settings.alpha_slow = args.alpha_slow;
    settings.cluster_keep_weight = args.cluster_keep_weight;
    settings.cluster_min_particles = args.cluster_min_particles;
    let mcl = Mcl::new(settings)?;
    // No change is ever reported: the map in memory is the whole map.
    let mut localizer = Localizer::new(mcl, map, Duration::MAX, Instant::now());
    let whole = tiles
        .fetch(&tiles.tiles().map(|(k, _)| *k).collect::<Vec<_>>())
        .map_err(|e| anyhow::anyhow!(e))?;
    localizer.start_global(whole)?;
    let mut kidnap_rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6b69_646e_6170);
    let mut kidnapped_at = None;
    // The first frame after the kidnap.
    let mut kidnap_frame = None;
    let mut fired = Vec::new();
    let period = sim.config().sonar_period_s;
    let mut truth = Vec::new();
    let mut estimates = Vec::new();
    let mut mirror_sums = (0.0, 0.0, 0u64, 0u64);
    // Particles injected since the last trace line.
    let mut injected_since_trace = 0usize;
    while sim.time_s() < args.seconds {
        if args.kidnap_at > 0.0 && kidnapped_at.is_none() && sim.time_s() >= args.kidnap_at {
            let to = sim.random_free_pose(&mut kidnap_rng)?;
            sim.teleport("scout", to)?;
            kidnapped_at = Some(sim.time_s());
            // The mirror sums compare the halves from the new pose on.
            mirror_sums = (0.0, 0.0, 0, 0);
        }
        let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
        sim.drive("scout", v, w)?;
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired)?;
        }
        state = fired.pop().context("a firing")?;
        if kidnapped_at.is_some() && kidnap_frame.is_none() {
            kidnap_frame = Some(state.sequence);
        }
        if let Some(centre) = &args.mirror_about {
            let t = state.true_pose;
            let image = image_of(&t, centre);
            let (mcl, map) = localizer.parts_mut();
            let here = mcl.score_pose(map, &t, &state.ranges)?;
            let there = mcl.score_pose(map, &image, &state.ranges)?;
            mirror_sums.0 += here;
            mirror_sums.1 += there;
            if here > there {
                mirror_sums.2 += 1;
            }
            mirror_sums.3 += 1;
            if sim.time_s() + period >= args.seconds || state.sequence % 100 == 0 {
                println!(
                    "    t {:6.1}  Σ log-likelihood true {:9.1}  image {:9.1}  frames favouring the truth {}/{}",
                    state.time_s, mirror_sums.0, mirror_sums.1, mirror_sums.2, mirror_sums.3
                );
            }
        }
        if let Some(window) = &args.beams_between
            && (window[0]..=window[1]).contains(&state.time_s)
        {
            print_beams(
                localizer.parts_mut().1,
                &state.true_pose,
                &state.ranges,
                state.time_s,
            )?;
        }
        let report = localizer.step(&state.odometry, &state.ranges, Instant::now(), tiles)?;
        if let Some(correction) = report.correction {
            injected_since_trace += correction.injected;
        }
        if let Some(e) = report.estimate {
            let mcl = localizer.mcl();
            let t = state.true_pose;
            if args.trace_every > 0.0
                && (state.time_s / args.trace_every).fract() < period / args.trace_every * 0.999
            {
                // The particles within the convergence bounds of the truth.
                let (near, near_weight) = particles_near(mcl, &t);
                // And near the truth's image, when a centre is given.
                let image = match &args.mirror_about {
                    Some(c) => {
                        let (n, w) = particles_near(mcl, &image_of(&t, c));
                        format!(
                            "  near the image {n} weighing {w:.1e}  Σ log-likelihood true {:.1} image {:.1}",
                            mirror_sums.0, mirror_sums.1
                        )
                    }
                    None => String::new(),
                };
                println!(
                    "    t {:6.1}  true ({:5.2}, {:5.2}, {:6.1}°)  estimate ({:5.2}, {:5.2}, {:6.1}°)  particles {:5}  weight {:.2}  converged {}  lost {:.2}  near the truth {near} weighing {near_weight:.1e}{image}  injected {injected_since_trace}",
                    state.time_s,
                    t.x,
                    t.y,
                    t.theta.to_degrees(),
                    e.pose.x,
                    e.pose.y,
                    e.pose.theta.to_degrees(),
                    e.particle_count,
                    e.cluster_weight,
                    e.converged,
                    e.lost_score
                );
                injected_since_trace = 0;
            }
            estimates.push(EstimateSample {
                sequence: state.sequence,
                pose: e.pose,
                filter_converged: e.converged,
            });
        }
        truth.push(TruthSample::new(
            state.sequence,
            state.time_s,
            state.true_pose,
        ));
    }
    let known: Vec<u64> = kidnap_frame.into_iter().collect();
    let report = evaluate(&EvalInput {
        known_kidnaps: &known,
        ..EvalInput::new("scout", &truth, &estimates)
    })
    .with_context(|| format!("judging seed {seed}"))?;
    let figures = RunFigures::from(&report);
    Ok((figures, localizer.into_map()))
}
