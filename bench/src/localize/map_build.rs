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

/// How long a robot wanders to build a map, and whether the map is then
/// refitted to its frames.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MapPlan {
    /// Simulated minutes of wandering.
    pub minutes: f64,
    /// Refit the map to every frame through the sonar's forward model.
    pub forward_fit: bool,
    /// Draw the map from the world instead ([`true_map`]).
    pub true_map: bool,
}

/// The map a wandering robot's frames give, as the cartographer builds it
/// from the rig and sonar of `config` (and, with `forward_fit`, refits it
/// to all those frames through the sonar's forward model), with range
/// tables (for `sensor`'s cone) for the sonar of `localize_config`.
pub(crate) fn build_map(
    world: deog_world::World,
    config: &SimConfig,
    localize_config: &SimConfig,
    sensor: SensorChoice,
    plan: MapPlan,
    surface_depth: f64,
    thresholds: OccupancyThresholds,
) -> Result<(TileMap, LocalMap)> {
    let MapPlan {
        minutes,
        forward_fit,
        true_map: drawn,
    } = plan;
    if drawn {
        let tiles = true_map(&world)?;
        let mut map = empty_local_map(localize_config, sensor, surface_depth, thresholds)?;
        for (key, tile) in tiles.tiles() {
            map.insert_tile(*key, 1, Some(tile))?;
        }
        return Ok((tiles, map));
    }
    const NAME: &str = "cartographer";
    if forward_fit && config.rig != deog_rig::scout() {
        anyhow::bail!("--forward-fit fits a Scout's sonar ring; the rig is another");
    }
    let ring = deog_grid::SensorRing::scout();
    let mut readings = Vec::new();
    let mut pace = deog_grid::FrameMotion::default();
    let mut sim = Simulation::new(world, config.clone(), 1000)?;
    let mut state = sim.spawn(NAME, None)?;
    let mut wanderer = Wanderer::for_rig(WanderParams::default(), &config.rig, 1000)?;
    let mut growing = GrowingMap::new(config, &[NAME.to_string()])?;
    let mut changed = Vec::new();
    let mut fired = Vec::new();
    let period = sim.config().sonar_period_s;
    while sim.time_s() < minutes * 60.0 {
        let (v, w) = wanderer.command(&state.ranges, state.bumper, period)?;
        sim.drive(NAME, v, w)?;
        fired.clear();
        while fired.is_empty() {
            sim.advance(period, &mut fired)?;
        }
        state = fired.pop().context("a firing")?;
        changed.clear();
        growing.integrate(&state, &mut changed)?;
        if forward_fit {
            deog_mapping::ring_readings(
                &ring,
                config.ring_firing(),
                &state.true_pose,
                pace.observe(&state.odometry, state.time_s).as_ref(),
                deog_mapping::echo_below(&state.ranges, config.sonar.max_range),
                &mut readings,
            );
        }
    }
    let mut tiles = growing.tiles;
    if forward_fit {
        let settings = crate::sonar_mapping::forward_settings(&config.sonar);
        tiles = deog_mapping::fit_forward(&tiles, &readings, &settings, ClampLimits::default())?.0;
    }
    let mut map = empty_local_map(localize_config, sensor, surface_depth, thresholds)?;
    for (key, tile) in tiles.tiles() {
        map.insert_tile(*key, 1, Some(tile))?;
    }
    Ok((tiles, map))
}

/// `world` drawn as a map: a cell occupied (at 0.95) where its centre is
/// not free space, free (at 0.05, clamped to the map's floor) where it is,
/// one cell beyond the world's bounds.
pub(crate) fn true_map(world: &deog_world::World) -> Result<TileMap> {
    let res = Resolution::DEFAULT;
    let size = TileSize::new(64)?;
    let (min, max) = world.bounds();
    let margin = res.metres();
    let first = res.cell_of(min.x - margin, min.y - margin)?;
    let last = res.cell_of(max.x + margin, max.y + margin)?;
    let occupied = (0.95f64 / 0.05).ln() * deog_grid::LOG_ODDS_SCALE;
    let mut deltas: std::collections::HashMap<deog_grid::TileKey, deog_grid::TileDelta> =
        std::collections::HashMap::new();
    for y in first.y..=last.y {
        for x in first.x..=last.x {
            let cell = deog_grid::CellIndex::new(x, y);
            let (cx, cy) = res.cell_center(cell);
            let free = world.is_free(deog_world::Point2::new(cx, cy));
            let raw = if free { -occupied } else { occupied }.round() as i16;
            let (key, offset) = size.split(cell);
            deltas
                .entry(key)
                .or_insert_with(|| deog_grid::TileDelta::zero(key, size))
                .raw_mut()[offset.index(size)] = raw;
        }
    }
    let mut map = TileMap::new(res, size, ClampLimits::default());
    for delta in deltas.values() {
        map.apply(delta)?;
    }
    Ok(map)
}

/// The cartographer `deog map` runs for a robot of `config`: the thesis's
/// sonar model, or for a specular sonar the method `deog demo` maps with;
/// from the true poses.
pub(crate) fn cartographer_for(config: &SimConfig) -> Result<Cartographer> {
    let res = Resolution::DEFAULT;
    let size = TileSize::new(64)?;
    let specular = !matches!(config.sonar.specular, Specular::Off);
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
    // The view of the map read again as `deog map` reads it from the
    // server, with what the other robots' cartographers wrote.
    Ok(cartographer
        .with_firing(config.ring_firing())
        .reading_map_every(crate::sonar_mapping::VIEW_REFRESH_FRAMES))
}

/// A localizer's map with no tile yet, its range tables for the sonar of
/// `localize_config` as `sensor`'s cone sees it, its cells classed by
/// `thresholds`.
pub(crate) fn empty_local_map(
    localize_config: &SimConfig,
    sensor: SensorChoice,
    surface_depth: f64,
    thresholds: OccupancyThresholds,
) -> Result<LocalMap> {
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
    Ok(LocalMap::new(MapSettings {
        resolution: Resolution::DEFAULT,
        tile_size: TileSize::new(64)?,
        thresholds,
        geometry: sensor.cone_geometry(&localize_config.rig, base)?,
        budget_bytes: 512 << 20,
    })?)
}

/// A map being built while a robot localizes on it, as in `deog demo`:
/// each mapping robot's cartographer turns its frames into deltas on one
/// map.
pub(crate) struct GrowingMap {
    /// Each mapping robot's cartographer and its pace.
    cartographers: Vec<(String, Cartographer, deog_grid::FrameMotion)>,
    tiles: TileMap,
    deltas: Vec<deog_grid::TileDelta>,
}

impl GrowingMap {
    /// An empty map, built from the frames of the robots `names`.
    pub(crate) fn new(config: &SimConfig, names: &[String]) -> Result<Self> {
        Ok(Self {
            cartographers: names
                .iter()
                .map(|n| Ok((n.clone(), cartographer_for(config)?, Default::default())))
                .collect::<Result<_>>()?,
            tiles: TileMap::new(
                Resolution::DEFAULT,
                TileSize::new(64)?,
                ClampLimits::default(),
            ),
            deltas: Vec::new(),
        })
    }

    /// The map as built so far.
    pub(crate) fn tiles_mut(&mut self) -> &mut TileMap {
        &mut self.tiles
    }

    /// Maps one frame of a mapping robot (others' are ignored); `changed`
    /// gets the tiles it changed.
    pub(crate) fn integrate(
        &mut self,
        state: &deog_simulator::simulation::RobotSnapshot,
        changed: &mut Vec<deog_grid::TileKey>,
    ) -> Result<()> {
        let Some((_, cartographer, motion)) = self
            .cartographers
            .iter_mut()
            .find(|(n, _, _)| *n == state.name)
        else {
            return Ok(());
        };
        self.deltas.clear();
        let input = FrameInput {
            sequence: state.sequence,
            pace: motion.observe(&state.odometry, state.time_s),
            true_pose: Some(state.true_pose),
            odometry: state.odometry,
            reference_pose: None,
            estimate: None,
            ranges: &state.ranges,
        };
        cartographer.read_missing_tiles(&input, &self.tiles)?;
        cartographer.integrate(&input, &mut self.deltas)?;
        for d in &self.deltas {
            self.tiles.apply(d)?;
            changed.push(d.key);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use deog_grid::CellIndex;

    use super::*;

    #[test]
    fn the_true_map_holds_the_world_cell_by_cell() {
        let world = deog_world::load_world_spec("map1").expect("built in");
        let map = true_map(&world).expect("drawn");
        let res = Resolution::DEFAULT;
        let at = |x: f64, y: f64| {
            let cell: CellIndex = res.cell_of(x, y).expect("cell");
            map.get(cell).expect("drawn").probability()
        };
        // The room's middle is free, the moved box and the space beyond
        // the boundary are not.
        assert!(at(5.0, 4.0) < 0.2);
        assert!(at(8.1, 5.8) > 0.9);
        assert!(at(7.05, 5.8) < 0.2, "left of the moved box");
        assert!(at(-0.02, 4.0) > 0.9);
        // Both sides of a face on a cell border land in the right cell.
        assert!(at(2.01, 2.0) > 0.9 && at(1.99, 2.0) < 0.2);
    }
}
