//! The cartographer for each frame's rig: built when a robot's first frame
//! arrives, from the rig the map server keeps under the frame's rig name,
//! and rebuilt if the robot's rig changes.

use anyhow::{Context, Result, bail};
use deog_grid::{RayModelParams, Resolution, RingFiring, SonarModelParams, TileSize};
use deog_mapping::{Cartographer, MapViewSettings, PoseChoice, SonarMethod};
use deog_proto::rig::frame_rig_name;
use deog_rig::Rig;
use deog_robot_client::MapClient;

/// Everything a cartographer is built from but the rig.
#[derive(Debug, Clone, Copy)]
pub struct ModelSettings {
    /// The pose frames are placed at.
    pub pose: PoseChoice,
    /// Sonar cones' model.
    pub sonar: SonarModelParams,
    /// Laser rays' model.
    pub ray: RayModelParams,
    /// The map's cells.
    pub resolution: Resolution,
    /// The map's tiles.
    pub tile_size: TileSize,
    /// How sonar readings become evidence.
    pub method: SonarMethod,
    /// With [`SonarMethod::KeepWalls`] or [`SonarMethod::Directional`],
    /// the view of the map cones stop in.
    pub view: MapViewSettings,
    /// When a frame's sensors fire.
    pub firing: RingFiring,
}

/// One cartographer, for the rig of the frames seen last.
#[derive(Debug)]
pub struct CartographerByRig {
    client: MapClient,
    settings: ModelSettings,
    /// The rig `--rig` says the frames come from.
    expected: Option<Rig>,
    current: Option<(String, Cartographer)>,
}

impl CartographerByRig {
    /// Cartographers with `settings`; frames must come from `expected`
    /// when it is given.
    pub fn new(client: MapClient, settings: ModelSettings, expected: Option<Rig>) -> Self {
        Self {
            client,
            settings,
            expected,
            current: None,
        }
    }

    /// The cartographer for a frame whose `rig` field is `frame_rig`.
    pub async fn for_frame(&mut self, frame_rig: &str, sequence: u64) -> Result<&mut Cartographer> {
        let name = frame_rig_name(frame_rig);
        if self.current.as_ref().is_none_or(|(n, _)| n != name) {
            if let Some(expected) = &self.expected {
                if expected.name() != name {
                    bail!(
                        "frame {sequence} comes from rig {name}, not {} (--rig)",
                        expected.name()
                    );
                }
            }
            let rig = self
                .client
                .rig(name)
                .await
                .with_context(|| format!("reading rig {name} of frame {sequence}"))?;
            tracing::info!(
                rig = name,
                readings = rig.readings(),
                "mapping with the frames' rig"
            );
            let cartographer = build(&rig, &self.settings)?;
            self.current = Some((name.to_owned(), cartographer));
        }
        Ok(&mut self.current.as_mut().expect("set above").1)
    }
}

/// A cartographer for `rig`: the Scout's own path for the Scout (same
/// deltas, a little faster), the rig's beams for any other.
fn build(rig: &Rig, s: &ModelSettings) -> Result<Cartographer> {
    let cartographer = if *rig == deog_rig::scout() {
        Cartographer::with_model(s.resolution, s.tile_size, s.pose, s.sonar)
    } else {
        Cartographer::for_rig(rig, s.pose, s.sonar, s.ray, s.resolution, s.tile_size)
    }
    .and_then(|c| c.with_sonar_method(s.method, rig, &s.sonar, s.view, s.resolution, s.tile_size))
    .map(|c| c.with_firing(s.firing));
    cartographer.with_context(|| format!("the sensor models for rig {}", rig.name()))
}
