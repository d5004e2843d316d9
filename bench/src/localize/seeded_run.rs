//! One seeded run: a robot at a random pose, a filter that starts knowing
//! nothing, a kidnap part-way, and the run judged.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use deog_evaluation::localization::{EstimateSample, EvalInput, TruthSample, evaluate};
use deog_evaluation::runs::RunFigures;
use deog_grid::TileMap;
use deog_localizer::filter::{FilterSettings, Mcl};
use deog_localizer::local_map::LocalMap;
use deog_localizer::searcher::{Searcher, SearcherSettings};
use deog_localizer::sensors::{LikelihoodFieldParams, SensorChoice};
use deog_localizer::step::{Localizer, TileSource};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{WanderParams, Wanderer};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::LocalizeOptions;
use super::diagnostics::{image_of, particles_near, print_beams};
use super::map_build::GrowingMap;

/// The robot's name in the simulator, whatever its rig: the name seeds the
/// robot's draws, so the Scout's figures stay as they were.
const ROBOT: &str = "scout";

/// The filter's settings for run `seed`, with the options' overrides.
fn filter_settings(options: &LocalizeOptions, seed: u64) -> FilterSettings {
    let mut settings = FilterSettings {
        seed,
        ..FilterSettings::default()
    };
    settings.kld.max_particles = options.max_particles;
    settings.kld.min_particles = options.min_particles;
    settings.beam = options.beam_params();
    settings.alpha_fast = options.alpha_fast;
    settings.recovery_threshold = options.recovery_threshold;
    settings.search_share = options.search_share;
    settings.motion = settings.motion.scaled(options.motion_noise_scale);
    settings.alpha_slow = options.alpha_slow;
    settings.cluster_keep_weight = options.cluster_keep_weight;
    settings.cluster_min_particles = options.cluster_min_particles;
    settings
}

/// Seconds after settling from which the particle count is watched: the
/// filter has had time to shed the particles it searched with.
const SHRINK_S: f64 = 10.0;

/// What one run gives besides the judge's figures.
#[derive(Debug, Clone, Copy)]
pub(super) struct RunExtras {
    /// The most particles the filter held from [`SHRINK_S`] after it
    /// settled to the kidnap (or the end); `None` if it never settled
    /// that long before.
    pub most_particles_settled: Option<usize>,
}

/// One seeded run on `map` (its tiles from `tiles`), the robot carrying
/// the rig of `config` and its frames scored with `sensor`; returns its
/// figures and the map, with the tables it built, for the next run.
///
/// With `growing` (`--growing-map`), the map is built during the run
/// instead, as in `deog demo`: the robot and `--mappers` − 1 others wander
/// from the start, each frame mapped from its true pose into `growing`;
/// the filter starts after `--map-minutes` on the map as it then is
/// (`map` empty), and takes in the tiles that changed every
/// `--refresh-s` simulated seconds. `--seconds` and `--kidnap-at` count
/// from the filter's start.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_once(
    world: deog_world::World,
    config: &SimConfig,
    sensor: SensorChoice,
    map: LocalMap,
    tiles: &mut TileMap,
    mut growing: Option<&mut GrowingMap>,
    seed: u64,
    options: &LocalizeOptions,
) -> Result<(RunFigures, RunExtras, LocalMap)> {
    let mut sim = Simulation::new(world, config.clone(), seed)?;
    let mut state = sim.spawn(ROBOT, None)?;
    let rig = &config.rig;
    let mut wanderer = Wanderer::for_rig(WanderParams::default(), rig, seed)?;
    // The other mapping robots, each with its wanderer and last state.
    let mut mappers = Vec::new();
    if growing.is_some() {
        for k in 2..=options.mappers {
            let name = mapper_name(k);
            let first = sim.spawn(&name, None)?;
            let wander = Wanderer::for_rig(WanderParams::default(), rig, seed * 1000 + k)?;
            mappers.push((name, wander, first));
        }
    }
    let start_s = if growing.is_some() {
        options.map_minutes * 60.0
    } else {
        0.0
    };
    let mut settings = filter_settings(options, seed);
    // The beam model's no-echo range is the cone's the map's tables are for.
    settings.beam.max_range = map.settings().geometry.max_range;
    let model = sensor
        .build(rig, settings.beam, LikelihoodFieldParams::default())
        .with_context(|| format!("the {sensor} model for rig {}", rig.name()))?;
    let mut mcl = Mcl::with_sensor(settings, model)?;
    mcl.set_firing(config.ring_firing());
    // A fixed map never changes; a growing one is taken in every
    // `--refresh-s` of simulated time, not stretched by how long rebuilds
    // take on this machine, so that a run repeats.
    let clock = Instant::now();
    let at = |time_s: f64| clock + Duration::from_secs_f64(time_s.max(0.0));
    let refresh = if growing.is_some() {
        Duration::from_secs_f64(options.refresh_s)
    } else {
        Duration::MAX
    };
    let mut localizer = Localizer::new(mcl, map, refresh, at(start_s)).with_steady_refresh();
    if options.start == super::StartChoice::Search {
        let beams = rig.beams().to_vec();
        let settings = SearcherSettings::for_beams(&beams);
        localizer = localizer.with_searcher(Searcher::new(beams, settings)?);
    }
    let mut started = false;
    let mut changed = Vec::new();
    let mut kidnap_rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6b69_646e_6170);
    let mut kidnapped_at = None;
    // The first frame after the kidnap.
    let mut kidnap_frame = None;
    let mut fired = Vec::new();
    let period = sim.config().sonar_period_s;
    let mut truth = Vec::new();
    let mut estimates = Vec::new();
    // Each estimate's time and the particles behind it.
    let mut counts: Vec<(f64, usize)> = Vec::new();
    let mut mirror_sums = (0.0, 0.0, 0u64, 0u64);
    // The frame's scores at the true pose and at its image, until the
    // step says whether the filter weighed the frame.
    let mut mirror_scores: Option<(f64, f64)> = None;
    // Particles injected since the last trace line.
    let mut injected_since_trace = 0usize;
    while sim.time_s() < start_s + options.seconds {
        if options.kidnap_at > 0.0
            && kidnapped_at.is_none()
            && sim.time_s() >= start_s + options.kidnap_at
        {
            let to = sim.random_free_pose(&mut kidnap_rng)?;
            sim.teleport(ROBOT, to)?;
            kidnapped_at = Some(sim.time_s());
            // The mirror sums compare the halves from the new pose on.
            mirror_sums = (0.0, 0.0, 0, 0);
        }
        let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
        sim.drive(ROBOT, v, w)?;
        for (name, wander, last) in &mut mappers {
            let (v, w) = wander.command(&last.ranges, last.bumper, period)?;
            sim.drive(name, v, w)?;
        }
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired)?;
        }
        if let Some(growing) = growing.as_deref_mut() {
            changed.clear();
            for snapshot in &fired {
                growing.integrate(snapshot, &mut changed)?;
            }
            if started {
                for key in &changed {
                    localizer.tile_changed(*key);
                }
            }
        }
        for snapshot in fired.drain(..) {
            if snapshot.name == ROBOT {
                state = snapshot;
            } else if let Some(m) = mappers.iter_mut().find(|m| m.0 == snapshot.name) {
                m.2 = snapshot;
            }
        }
        if state.time_s < start_s {
            continue;
        }
        let source: &mut TileMap = match growing.as_deref_mut() {
            Some(g) => g.tiles_mut(),
            None => &mut *tiles,
        };
        if !started {
            let whole = source
                .fetch(&source.tiles().map(|(k, _)| *k).collect::<Vec<_>>())
                .map_err(|e| anyhow::anyhow!(e))?;
            localizer.start_global(whole)?;
            started = true;
        }
        localizer.note_frame(&state.odometry, state.time_s);
        if kidnapped_at.is_some() && kidnap_frame.is_none() {
            kidnap_frame = Some(state.sequence);
        }
        if let Some(centre) = &options.mirror_about {
            let t = state.true_pose;
            let image = image_of(&t, centre);
            let (mcl, map) = localizer.parts_mut();
            mirror_scores = Some((
                mcl.score_pose(map, &t, &state.ranges)?,
                mcl.score_pose(map, &image, &state.ranges)?,
            ));
            if sim.time_s() + period >= options.seconds || state.sequence % 100 == 0 {
                deog_harness::println_above_bars!(
                    "    t {:6.1}  Σ log-likelihood true {:9.1}  image {:9.1}  frames favouring the truth {}/{}",
                    state.time_s,
                    mirror_sums.0,
                    mirror_sums.1,
                    mirror_sums.2,
                    mirror_sums.3
                );
            }
        }
        if let Some(window) = &options.beams_between
            && (window[0]..=window[1]).contains(&state.time_s)
        {
            print_beams(
                localizer.parts_mut().1,
                &rig.ring(),
                &state.true_pose,
                &state.ranges,
                state.time_s,
            )?;
        }
        let report = localizer.step(&state.odometry, &state.ranges, at(state.time_s), source)?;
        if let Some(correction) = report.correction {
            injected_since_trace += correction.injected;
            // Only the frames the filter weighs count: a robot standing
            // still would otherwise count one scene many times over.
            if let Some((here, there)) = mirror_scores.take() {
                mirror_sums.0 += here;
                mirror_sums.1 += there;
                if here > there {
                    mirror_sums.2 += 1;
                }
                mirror_sums.3 += 1;
            }
        }
        if let Some(e) = report.estimate {
            let mcl = localizer.mcl();
            let t = state.true_pose;
            if options.trace_every > 0.0
                && (state.time_s / options.trace_every).fract()
                    < period / options.trace_every * 0.999
            {
                // The particles within the convergence bounds of the truth.
                let (near, near_weight) = particles_near(mcl, &t);
                // And near the truth's image, when a centre is given.
                let image = match &options.mirror_about {
                    Some(c) => {
                        let (n, w) = particles_near(mcl, &image_of(&t, c));
                        format!(
                            "  near the image {n} weighing {w:.1e}  Σ log-likelihood true {:.1} image {:.1}",
                            mirror_sums.0, mirror_sums.1
                        )
                    }
                    None => String::new(),
                };
                deog_harness::println_above_bars!(
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
                if let Some(searcher) = localizer.searcher() {
                    let probe = searcher.probe(&t, &state.odometry);
                    let stats = searcher.stats();
                    deog_harness::println_above_bars!(
                        "      search: {} searches ({} cut short), {} vetoes, {} confirmations; {}",
                        stats.searches,
                        stats.incomplete,
                        stats.vetoes,
                        stats.confirmations,
                        match probe {
                            Some(p) => format!(
                                "truth scores {:.3} (latest frame {:.3}), best of {} ({:.2}, {:.2}, {:.1}°) {:.3}, {} points",
                                p.score,
                                p.latest_score,
                                p.hypotheses,
                                p.best.map_or(0.0, |b| b.pose.x),
                                p.best.map_or(0.0, |b| b.pose.y),
                                p.best.map_or(0.0, |b| b.pose.theta.to_degrees()),
                                p.best.map_or(0.0, |b| b.score),
                                p.points
                            ),
                            None => "no grid yet".to_owned(),
                        }
                    );
                }
                injected_since_trace = 0;
            }
            counts.push((state.time_s, e.particle_count));
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
    if estimates.is_empty() {
        // A search that never found where the robot is: nothing converged.
        let extras = RunExtras {
            most_particles_settled: None,
        };
        return Ok((RunFigures::default(), extras, localizer.into_map()));
    }
    let known: Vec<u64> = kidnap_frame.into_iter().collect();
    let report = evaluate(&EvalInput {
        known_kidnaps: &known,
        ..EvalInput::new(ROBOT, &truth, &estimates)
    })
    .with_context(|| format!("judging seed {seed}"))?;
    let figures = RunFigures::from(&report);
    let most_particles_settled = report.convergence.and_then(|settled| {
        let from = settled.time_s + SHRINK_S;
        let to = kidnapped_at.unwrap_or(f64::INFINITY);
        counts
            .iter()
            .filter(|(t, _)| (from..to).contains(t))
            .map(|(_, n)| *n)
            .max()
    });
    let extras = RunExtras {
        most_particles_settled,
    };
    Ok((figures, extras, localizer.into_map()))
}

/// The name of the `k`-th mapping robot of a growing map (the robot
/// localized is the first).
fn mapper_name(k: u64) -> String {
    format!("mapper-{k}")
}

/// The names of a growing map's `count` mapping robots, the robot
/// localized first.
pub(super) fn mapping_robots(count: u64) -> Vec<String> {
    std::iter::once(ROBOT.to_string())
        .chain((2..=count).map(mapper_name))
        .collect()
}
