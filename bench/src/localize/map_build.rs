//! A world's map as the cartographer builds it from a wandering robot's
//! frames, and the simulator's rig with its sonars of a preset.

use anyhow::{Context, Result};
use deog_grid::{ClampLimits, OccupancyThresholds, RayModelParams, Resolution, TileMap, TileSize};
use deog_localizer::local_map::{LocalMap, MapSettings};
use deog_localizer::range_table::ConeGeometry;
use deog_localizer::sensors::SensorChoice;
use deog_mapping::{Cartographer, FrameInput, MapViewSettings, PoseChoice, SonarMethod};
use deog_rig::Rig;
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::{SonarPreset, Specular, WanderParams, Wanderer};

/// The simulator's settings for a robot carrying `rig`, with the sonar of
/// `preset`.
pub(crate) fn sim_config(rig: &Rig, preset: SonarPreset) -> SimConfig {
    SimConfig {
        rig: rig.clone(),
        sonar: preset.params(),
        ..SimConfig::default()
    }
}

/// The map a wandering robot's frames give, as the cartographer builds it
/// from the rig and sonar of `config`, with range tables (for `sensor`'s
/// cone) for the sonar of `localize_config`.
pub(crate) fn build_map(
    world: deog_world::World,
    config: &SimConfig,
    localize_config: &SimConfig,
    sensor: SensorChoice,
    minutes: f64,
    surface_depth: f64,
) -> Result<(TileMap, LocalMap)> {
    let res = Resolution::DEFAULT;
    let size = TileSize::new(64)?;
    let mut sim = Simulation::new(world, config.clone(), 1000)?;
    let mut state = sim.spawn("cartographer", None)?;
    let mut wanderer = Wanderer::for_rig(WanderParams::default(), &config.rig, 1000)?;
    // The sonar model `deog map` maps with.
    let specular = !matches!(config.sonar.specular, Specular::Off);
    // A specular sonar's readings are mapped as `deog demo` maps them.
    let (method, params) = if specular {
        deog_mapping::specular_sonar_mapping()
    } else {
        (SonarMethod::Thesis, deog_mapping::mapping_sonar_model())
    };
    // The Scout's own path for the Scout (as `deog map` takes it): the
    // same deltas, a little faster.
    let cartographer = if config.rig == deog_rig::scout() {
        Cartographer::with_model(res, size, PoseChoice::True, params)?
    } else {
        Cartographer::for_rig(
            &config.rig,
            PoseChoice::True,
            params,
            RayModelParams::default(),
            res,
            size,
        )?
    }
    .with_sonar_method(
        method,
        &config.rig,
        &params,
        MapViewSettings::default(),
        res,
        size,
    )?;
    let mut cartographer = cartographer.with_firing(config.ring_firing());
    let mut frame_motion = deog_grid::FrameMotion::default();
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
                pace: frame_motion.observe(&state.odometry, state.time_s),
                true_pose: Some(state.true_pose),
                odometry: state.odometry,
                reference_pose: None,
                estimate: None,
                ranges: &state.ranges,
            },
            &mut deltas,
        )?;
        for d in &deltas {
            tiles.apply(d)?;
        }
    }
    // The localizer knows its sonar: specular past the same angle.
    let base = ConeGeometry {
        specular_max_incidence: match localize_config.sonar.specular {
            Specular::Off => None,
            Specular::Lost { max_incidence } | Specular::Long { max_incidence, .. } => {
                Some(max_incidence)
            }
        },
        surface_depth,
        ..ConeGeometry::default()
    };
    let mut map = LocalMap::new(MapSettings {
        resolution: res,
        tile_size: size,
        thresholds: OccupancyThresholds::default(),
        geometry: sensor.cone_geometry(&localize_config.rig, base)?,
        budget_bytes: 512 << 20,
    })?;
    for (key, tile) in tiles.tiles() {
        map.insert_tile(*key, 1, Some(tile))?;
    }
    Ok((tiles, map))
}
