//! The cartographer's step: one frame of ranges to per-tile log-odds
//! deltas, from the pose the user chose (the thesis maps from the
//! simulator's true pose; a real robot has only its odometry).

use std::cell::Cell;

use deog_grid::{
    CellIndex, ConeGuard, GridError, Pose2, RayModelParams, Resolution, RingFiring, SensorRing,
    SonarModelParams, Tile, TileDelta, TileKey, TileMap, TileSize,
};
use deog_rig::Rig;

use crate::directional::{DirectionalSettings, DirectionalTile, DirectionalView};
use crate::error::MappingError;
use crate::map_view::{MapView, MapViewSettings};
use crate::sensors::{InverseSensorModel, RigBeams, SonarCone};

/// The sonar model `deog map` builds maps with unless told otherwise: the
/// thesis's equations with the figures that measured the best maps
/// (BENCHMARKS.md, map quality):
/// - Max_occupied 0.6, not the thesis's 0.98, with which one echo's whole
///   30° arc reads as wall; with 0.6 many readings decide;
/// - empty beliefs under 0.6 left unrecorded: eq. 3.4 gives a cone's far,
///   off-axis cells beliefs barely past 0.5, and a few such readings leave
///   a cell observed yet undecided, a fringe round every explored area;
/// - occupied beliefs under 0.52 left unrecorded too: with Max_occupied
///   0.6, the edge of region I says next to nothing;
/// - cones cut at 5 m: farther, eq. 3.4 is weak, a small heading error
///   throws the cone wide, and a lost echo reads long; cells out there are
///   mapped when the robot comes nearer.
pub fn mapping_sonar_model() -> SonarModelParams {
    SonarModelParams {
        max_occupied: 0.6,
        min_occupied: 0.52,
        min_empty: 0.6,
        max_mapped_range: 5.0,
        ..SonarModelParams::default()
    }
}

/// How a specular sonar's readings are best mapped, as measured on the
/// simulator's realistic sonar (BENCHMARKS.md, sonar mapping): evidence
/// kept by direction ([`SonarMethod::Directional`]), no-echo readings
/// ignored (most are echoes lost off a grazed wall, not free space),
/// and empty evidence only out to 2 m (the farther a cell, the likelier a
/// grazed wall stands before it); echoes are still mapped out to 5 m.
pub fn specular_sonar_mapping() -> (SonarMethod, SonarModelParams) {
    (
        SonarMethod::Directional,
        SonarModelParams {
            no_echo_free_range: 0.0,
            max_free_range: SPECULAR_MAX_FREE_RANGE,
            ..mapping_sonar_model()
        },
    )
}

/// Region I's angle factor on the cone's axis that makes the most cells
/// of a specular sonar's ten-minute maps right, rising to 1 at the edge
/// (`deog map --occupied-axis-factor 0.4 --occupied-edge-factor 1`). A
/// flat wall turned from square by more than the cone's half-angle, yet
/// within the critical angle, echoes from the cone's edge; the thesis's
/// factor (1 on the axis, 0 at the edge) marks such an echo on the axis,
/// in front of the wall. Not [`specular_sonar_mapping`]'s: a wall marked
/// only from the cones' edges takes more readings to build, and on the
/// young maps `deog demo` localizes on, robots found themselves less
/// often (BENCHMARKS.md, sonar mapping: 0 to 1 tried).
pub const SPECULAR_OCCUPIED_AXIS_FACTOR: f64 = 0.4;

/// How far a specular sonar's empty evidence reaches in
/// [`specular_sonar_mapping`], metres.
pub const SPECULAR_MAX_FREE_RANGE: f64 = 2.0;

/// How far from the robot's centre a cone of `rig` mapped with `sonar`
/// reaches, metres: its mapped range from a sensor up to the rig's reach
/// off the centre, and one more cell for the cells its edge touches.
fn cone_reach(rig: &Rig, sonar: &SonarModelParams, resolution: Resolution) -> f64 {
    sonar
        .max_mapped_range
        .min(sonar.max_range)
        .min(rig.max_range())
        + rig.reach()
        + resolution.metres()
}

/// Which pose of a frame the map is built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PoseChoice {
    /// The simulator's true pose, as the thesis's mapper used.
    #[default]
    True,
    /// The robot's odometry.
    Odometry,
    /// A recording's reference pose (a corrected log's).
    Reference,
    /// A localizer's converged estimate for the frame (see
    /// [`crate::EstimateBook`]): mapping with no ground truth anywhere.
    Estimate,
}

impl PoseChoice {
    /// The field of a frame this choice reads, for messages.
    pub fn field(self) -> &'static str {
        match self {
            PoseChoice::True => "true_pose",
            PoseChoice::Odometry => "odometry",
            PoseChoice::Reference => "reference_pose",
            PoseChoice::Estimate => "estimate",
        }
    }
}

/// A frame as the cartographer needs it.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// Sequence number, for messages.
    pub sequence: u64,
    /// The robot's pace at the frame: its pose a second earlier seen from
    /// this frame's ([`deog_grid::FrameMotion::observe`] over a robot's
    /// odometry and frame times). With a ring that fires in turn
    /// ([`Cartographer::with_firing`]) it places each reading; `None`:
    /// every reading at the frame's pose.
    pub pace: Option<Pose2>,
    /// The true pose, if the frame has one.
    pub true_pose: Option<Pose2>,
    /// The odometry pose.
    pub odometry: Pose2,
    /// The reference pose, if the frame has one.
    pub reference_pose: Option<Pose2>,
    /// The localizer's converged estimate for the frame, if there is one.
    pub estimate: Option<Pose2>,
    /// One range per reading of the sensor (per sonar, per laser ray),
    /// metres.
    pub ranges: &'a [f64],
}

/// How sonar readings become evidence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SonarMethod {
    /// The thesis's model as it is: every reading's cone, whatever the map
    /// already holds.
    #[default]
    Thesis,
    /// The thesis's model guarded by the map being written (a bounded
    /// [`MapView`]): along each direction of a cone, evidence stops at the
    /// first cell the map holds as a wall, which gets no empty evidence.
    /// One specular reading cannot erase what many echoes built. It costs
    /// clean sonar maps some precision: a cell that reached the wall
    /// belief by mistake is never freed (BENCHMARKS.md, sonar mapping).
    KeepWalls,
    /// Evidence kept per direction of the surface normal (a bounded
    /// [`DirectionalView`] of the cartographer's own): a reading that
    /// sweeps a wall at a grazing angle frees only the directions it
    /// faces, never the one the wall echoed from; cones stop behind the
    /// walls the view holds. For a specular sonar.
    Directional,
}

/// Turns frames into tile deltas for one map.
#[derive(Debug)]
pub struct Cartographer {
    sensor: Box<dyn InverseSensorModel>,
    pose: PoseChoice,
    /// With [`SonarMethod::KeepWalls`]: the map being written, and how far
    /// from the robot a frame's cones reach, metres.
    guard: Option<(MapView, f64)>,
    /// With [`SonarMethod::Directional`]: the beliefs by direction, and
    /// the plain deltas of the frame being mapped.
    directional: Option<Directional>,
    /// When the sensors fire within a frame ([`Self::with_firing`]).
    firing: RingFiring,
    /// With a map held in the same process: every how many frames the
    /// view of it is read anew ([`Self::reading_map_every`]), and the
    /// frames since it last was.
    map_reread: Option<(u32, u32)>,
}

/// A directional cartographer's guard with a view of the map it writes
/// to: a cell hides what lies behind it if the cartographer's own beliefs
/// or the map (every writer's) hold it a wall. Another robot's
/// cartographer may have heard a wall this one only grazed.
struct OwnAndMapWalls<'a> {
    own: &'a DirectionalView,
    map: &'a MapView,
    /// The last tile asked about, as both views hold it: a cone's cells
    /// come row by row, mostly from one tile, and looking the tile up in
    /// both views at every cell was a fifth of the mapping's time.
    last: Cell<Option<TilesAt<'a>>>,
}

/// One tile as [`OwnAndMapWalls`]'s two views hold it.
type TilesAt<'a> = (TileKey, Option<&'a DirectionalTile>, Option<&'a Tile>);

impl<'a> OwnAndMapWalls<'a> {
    fn new(own: &'a DirectionalView, map: &'a MapView) -> Self {
        Self {
            own,
            map,
            last: Cell::new(None),
        }
    }
}

impl ConeGuard for OwnAndMapWalls<'_> {
    fn shadows(&self, cell: CellIndex) -> bool {
        let size = self.own.tile_size();
        let (key, offset) = size.split(cell);
        let (own, map) = match self.last.get() {
            Some((last, own, map)) if last == key => (own, map),
            _ => {
                let (own, map) = (self.own.tile(key), self.map.tile(key));
                self.last.set(Some((key, own, map)));
                (own, map)
            }
        };
        own.is_some_and(|t| self.own.tile_shadows(t, offset.index(size)))
            || map.is_some_and(|t| self.map.tile_shadows(t, offset))
    }

    /// As the cartographer's own beliefs say: a cell the map holds a wall
    /// still takes the evidence of the readings that reach it, in the
    /// directions they face. Kept from any reading's empty evidence, the
    /// arcs a sonar marks in front of a wall stayed walls for good (every
    /// world's maps 1.8 to 3.7 points less right; BENCHMARKS.md, sonar
    /// mapping).
    fn keeps(&self, cell: CellIndex) -> bool {
        self.own.keeps(cell)
    }
}

/// What [`SonarMethod::Directional`] keeps between frames.
#[derive(Debug)]
struct Directional {
    view: DirectionalView,
    /// The plain deltas of the cones being mapped.
    plain: Vec<TileDelta>,
}

impl Cartographer {
    /// A cartographer for a map of `resolution` and `tile_size`, with the
    /// Scout's sonar model and ring.
    pub fn new(
        resolution: Resolution,
        tile_size: TileSize,
        pose: PoseChoice,
    ) -> Result<Self, MappingError> {
        Self::with_model(resolution, tile_size, pose, SonarModelParams::default())
    }

    /// As [`Cartographer::new`] with the sonar model's figures given.
    pub fn with_model(
        resolution: Resolution,
        tile_size: TileSize,
        pose: PoseChoice,
        params: SonarModelParams,
    ) -> Result<Self, MappingError> {
        let sonar = SonarCone::new(SensorRing::scout(), params, resolution, tile_size)?;
        Ok(Self::with_sensor(pose, Box::new(sonar)))
    }

    /// A cartographer for `rig`'s frames: its sonars' cones mapped with
    /// `sonar_params`, its lasers' rays with `ray_params`, each taking the
    /// sensor's ranges (and a sonar its half-angle) from the rig
    /// ([`RigBeams`]). For the Scout's rig the deltas are
    /// [`Cartographer::with_model`]'s.
    pub fn for_rig(
        rig: &Rig,
        pose: PoseChoice,
        sonar_params: SonarModelParams,
        ray_params: RayModelParams,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Result<Self, MappingError> {
        let beams = RigBeams::new(rig, sonar_params, ray_params, resolution, tile_size)?;
        Ok(Self::with_sensor(pose, Box::new(beams)))
    }

    /// A cartographer that maps with `sensor` rather than the Scout's sonars.
    pub fn with_sensor(pose: PoseChoice, sensor: Box<dyn InverseSensorModel>) -> Self {
        Self {
            sensor,
            pose,
            guard: None,
            directional: None,
            firing: RingFiring::Together,
            map_reread: None,
        }
    }

    /// Maps a ring that fires in turn while the robot moves: each reading
    /// from where the robot stood when its sensor fired, at the frame's
    /// [`FrameInput::pace`]. By default, every reading at the frame's
    /// pose.
    pub fn with_firing(mut self, firing: RingFiring) -> Self {
        self.firing = firing;
        self
    }

    /// Guards every sonar cone with `view`, the map being written
    /// ([`SonarMethod::KeepWalls`]); `reach` is how far from the robot a
    /// frame's cones may reach, metres (the tiles [`Self::missing_tiles`]
    /// names). The cartographer adds its own deltas to the view.
    pub fn keeping_walls(mut self, view: MapView, reach: f64) -> Self {
        self.guard = Some((view, reach));
        self
    }

    /// Keeps sonar evidence by direction in `view`
    /// ([`SonarMethod::Directional`]); the deltas the cartographer gives
    /// are the changes of the view's beliefs.
    pub fn by_direction(mut self, view: DirectionalView) -> Self {
        self.directional = Some(Directional {
            view,
            plain: Vec::new(),
        });
        self
    }

    /// Maps sonar readings by `method`: with [`SonarMethod::KeepWalls`]
    /// and a rig with sonars, guards its cones with a new view of
    /// `settings` reaching as far as `sonar`'s cones can from the rig's
    /// sensors; with [`SonarMethod::Directional`], keeps evidence by
    /// direction in a view of `settings`' size and wall probability (a
    /// rig with lasers too has their rays kept so as well), its cones
    /// guarded also by a view of the map written to, as keep-walls has,
    /// for the walls other robots' cartographers heard. A rig of lasers
    /// alone, or [`SonarMethod::Thesis`], leaves the cartographer as it
    /// is.
    pub fn with_sonar_method(
        self,
        method: SonarMethod,
        rig: &Rig,
        sonar: &SonarModelParams,
        settings: MapViewSettings,
        resolution: Resolution,
        tile_size: TileSize,
    ) -> Result<Self, MappingError> {
        if method == SonarMethod::Thesis || rig.all_laser() {
            return Ok(self);
        }
        if method == SonarMethod::Directional {
            let view = DirectionalView::new(
                resolution,
                tile_size,
                DirectionalSettings {
                    wall_probability: settings.wall_probability,
                    max_tiles: settings.max_tiles,
                    limits: settings.limits,
                    enclosure_period: settings.enclosure_period,
                    shadow_depth: settings.shadow_depth,
                },
            )?;
            // And a view of the map written to, for the walls other
            // robots' cartographers heard.
            return Ok(self.by_direction(view).keeping_walls(
                MapView::new(resolution, tile_size, settings)?,
                cone_reach(rig, sonar, resolution),
            ));
        }
        let view = MapView::new(resolution, tile_size, settings)?;
        Ok(self.keeping_walls(view, cone_reach(rig, sonar, resolution)))
    }

    /// The view of the map being written, when walls are kept or
    /// evidence is kept by direction.
    pub fn view_mut(&mut self) -> Option<&mut MapView> {
        self.guard.as_mut().map(|(view, _)| view)
    }

    /// The tiles a frame may reach that the view lacks: the process
    /// fetches them from the map server (or marks them unknown) before
    /// [`Self::integrate`]. Empty without a view of the map
    /// ([`Self::view_mut`]).
    pub fn missing_tiles(&mut self, frame: &FrameInput<'_>) -> Result<Vec<TileKey>, MappingError> {
        if self.guard.is_none() {
            return Ok(Vec::new());
        }
        let pose = self.pose_of(frame)?;
        match self.guard.as_mut() {
            Some((view, reach)) => view.missing_around(&pose, *reach).map_err(|e| match e {
                MappingError::Grid(e) => MappingError::UnusableFrame {
                    sequence: frame.sequence,
                    reason: e.to_string(),
                },
                other => other,
            }),
            None => Ok(Vec::new()),
        }
    }

    /// With [`Self::read_missing_tiles`]: forgets the view of the map
    /// every `frames` frames (at least 1), so that it is read anew with
    /// what other writers (other robots' cartographers) wrote since, as
    /// `deog map` reads it from the server every `--view-refresh-s`. By
    /// default the view is only filled, never read anew.
    pub fn reading_map_every(mut self, frames: u32) -> Self {
        self.map_reread = Some((frames.max(1), 0));
        self
    }

    /// For a map held in this process (benchmarks, tests): puts into the
    /// view of the map ([`Self::view_mut`]) the tiles `frame` may reach
    /// that it lacks, from `map`, the map being written, as `deog map`
    /// fetches them from the map server; the whole view anew every so
    /// many frames ([`Self::reading_map_every`]).
    pub fn read_missing_tiles(
        &mut self,
        frame: &FrameInput<'_>,
        map: &TileMap,
    ) -> Result<(), MappingError> {
        if let Some((every, since)) = &mut self.map_reread {
            *since += 1;
            if *since >= *every {
                *since = 0;
                if let Some((view, _)) = self.guard.as_mut() {
                    view.clear();
                }
            }
        }
        let missing = self.missing_tiles(frame)?;
        if let Some((view, _)) = self.guard.as_mut() {
            for key in missing {
                match map.tile(key) {
                    Some(tile) => view.insert(key, tile.clone())?,
                    None => view.insert_unknown(key)?,
                }
            }
        }
        Ok(())
    }

    /// The pose the map is built from.
    pub fn pose_choice(&self) -> PoseChoice {
        self.pose
    }

    /// Appends the frame's deltas to `out`, one per touched tile; returns
    /// how many cells they touch. Fails, appending nothing, on a frame that
    /// lacks the chosen pose or holds bad numbers.
    pub fn integrate(
        &mut self,
        frame: &FrameInput<'_>,
        out: &mut Vec<TileDelta>,
    ) -> Result<usize, MappingError> {
        let pose = self.pose_of(frame)?;
        if self.firing != RingFiring::Together {
            let at = self
                .firing
                .robot_at_readings(self.sensor.readings(), frame.pace.as_ref());
            self.sensor.set_reading_poses(at.as_deref());
        }
        let start = out.len();
        let invalid = |e: GridError| MappingError::UnusableFrame {
            sequence: frame.sequence,
            reason: e.to_string(),
        };
        if let Some(d) = &mut self.directional {
            d.plain.clear();
            let cells = match &self.guard {
                Some((map, _)) => {
                    let guard = OwnAndMapWalls::new(&d.view, map);
                    self.sensor
                        .integrate_guarded(&pose, frame.ranges, &guard, &mut d.plain)
                }
                None => self
                    .sensor
                    .integrate_guarded(&pose, frame.ranges, &d.view, &mut d.plain),
            }
            .map_err(invalid)?;
            d.view.absorb(&pose, &d.plain, out)?;
            if let Some((map, _)) = &mut self.guard {
                map.apply(&out[start..])?;
            }
            return Ok(cells);
        }
        let cells = match &self.guard {
            Some((view, _)) => self
                .sensor
                .integrate_guarded(&pose, frame.ranges, view, out),
            None => self.sensor.integrate(&pose, frame.ranges, out),
        }
        .map_err(invalid)?;
        if let Some((view, _)) = &mut self.guard {
            view.apply(&out[start..])?;
        }
        Ok(cells)
    }

    /// The frame's pose of the chosen kind.
    fn pose_of(&self, frame: &FrameInput<'_>) -> Result<Pose2, MappingError> {
        let missing = |hint: &str| {
            MappingError::invalid(
                format!("frame {}.{}", frame.sequence, self.pose.field()),
                format!("is missing; {hint}"),
            )
        };
        let pose = match self.pose {
            PoseChoice::True => frame.true_pose.ok_or_else(|| {
                missing("map from odometry (--pose odometry) or a recording's reference pose (--pose reference) for frames without one")
            })?,
            PoseChoice::Odometry => frame.odometry,
            PoseChoice::Reference => frame.reference_pose.ok_or_else(|| {
                missing("only recordings with reference poses (a corrected CARMEN log) have one")
            })?,
            PoseChoice::Estimate => frame
                .estimate
                .ok_or_else(|| missing("no converged estimate for this frame"))?,
        };
        Ok(pose)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ring_fired_in_turn_is_mapped_where_each_sonar_fired() {
        let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
        let params = mapping_sonar_model();
        let firing = RingFiring::over(0.1).expect("firing");
        // Driving at 0.4 m/s and turning at 1.2 rad/s.
        let pace = Pose2::new(-0.4, 0.0, -1.2);
        let at = firing.robot_at_readings(16, Some(&pace)).expect("moving");
        let ranges: Vec<f64> = (0..16).map(|k| 1.0 + 0.1 * k as f64).collect();
        let frame = |pace: Option<Pose2>| FrameInput {
            sequence: 1,
            pace,
            true_pose: Some(Pose2::new(1.0, 2.0, 0.5)),
            odometry: Pose2::new(0.0, 0.0, 0.0),
            reference_pose: None,
            estimate: None,
            ranges: &ranges,
        };
        let deltas = |c: &mut Cartographer, pace: Option<Pose2>| {
            let mut out = Vec::new();
            c.integrate(&frame(pace), &mut out).expect("integrate");
            out
        };
        let as_fired =
            SonarCone::new(SensorRing::scout().as_fired(&at), params, res, size).expect("cones");
        let expected = deltas(
            &mut Cartographer::with_sensor(PoseChoice::True, Box::new(as_fired)),
            None,
        );
        let plain = deltas(
            &mut Cartographer::with_model(res, size, PoseChoice::True, params).expect("c"),
            None,
        );
        assert_ne!(expected, plain, "the motion moves the cones");
        // The Scout's own path and any rig's path alike.
        let mut scout = Cartographer::with_model(res, size, PoseChoice::True, params)
            .expect("c")
            .with_firing(firing);
        assert_eq!(deltas(&mut scout, Some(pace)), expected);
        let mut by_rig = Cartographer::for_rig(
            &deog_rig::scout(),
            PoseChoice::True,
            params,
            RayModelParams::default(),
            res,
            size,
        )
        .expect("c")
        .with_firing(firing);
        assert_eq!(deltas(&mut by_rig, Some(pace)), expected);
        // No pace (a first frame, a gap): every cone at the frame's pose.
        assert_eq!(deltas(&mut scout, None), plain);
        assert_eq!(deltas(&mut by_rig, None), plain);
    }

    #[test]
    fn the_chosen_pose_places_the_cells() {
        let mut by_true =
            Cartographer::new(Resolution::DEFAULT, TileSize::DEFAULT, PoseChoice::True)
                .expect("cartographer");
        let mut by_odometry =
            Cartographer::new(Resolution::DEFAULT, TileSize::DEFAULT, PoseChoice::Odometry)
                .expect("cartographer");
        let ranges = [2.0; 16];
        let frame = FrameInput {
            sequence: 1,
            pace: None,
            true_pose: Some(Pose2::new(0.0, 0.0, 0.0)),
            odometry: Pose2::new(10.0, 0.0, 0.0),
            reference_pose: None,
            estimate: None,
            ranges: &ranges,
        };
        let (mut a, mut b) = (Vec::new(), Vec::new());
        assert!(by_true.integrate(&frame, &mut a).expect("true") > 0);
        assert!(by_odometry.integrate(&frame, &mut b).expect("odometry") > 0);
        let keys = |d: &[TileDelta]| d.iter().map(|t| t.key).collect::<Vec<_>>();
        assert_ne!(keys(&a), keys(&b), "10 m apart, different tiles");
    }

    #[test]
    fn a_frame_without_the_chosen_pose_or_with_bad_ranges_is_refused() {
        let mut c = Cartographer::new(Resolution::DEFAULT, TileSize::DEFAULT, PoseChoice::True)
            .expect("cartographer");
        let ranges = [2.0; 16];
        let mut out = Vec::new();
        let no_true = FrameInput {
            sequence: 7,
            pace: None,
            true_pose: None,
            odometry: Pose2::new(0.0, 0.0, 0.0),
            reference_pose: None,
            estimate: None,
            ranges: &ranges,
        };
        let error = c.integrate(&no_true, &mut out).expect_err("no true pose");
        assert!(error.to_string().contains("frame 7.true_pose"), "{error}");
        let short = [2.0; 15];
        let bad = FrameInput {
            sequence: 8,
            pace: None,
            true_pose: Some(Pose2::new(0.0, 0.0, 0.0)),
            odometry: Pose2::new(0.0, 0.0, 0.0),
            reference_pose: None,
            estimate: None,
            ranges: &short,
        };
        assert!(c.integrate(&bad, &mut out).is_err());
        assert!(out.is_empty());
        // A pose beyond the grid's reach is the frame's fault, not the
        // mapping's: an error that says to skip that frame.
        let far = FrameInput {
            sequence: 6,
            true_pose: Some(Pose2::new(1e300, 0.0, 0.0)),
            ranges: &ranges,
            ..bad
        };
        match c.integrate(&far, &mut out) {
            Err(MappingError::UnusableFrame {
                sequence: 6,
                reason,
            }) => {
                assert!(reason.contains("must be within"), "{reason}");
            }
            other => panic!("expected an unusable frame, got {other:?}"),
        }
        assert!(out.is_empty());
        // The same cartographer maps the next frame as if it had not been.
        let next = FrameInput {
            sequence: 7,
            true_pose: Some(Pose2::new(0.0, 0.0, 0.0)),
            ..far
        };
        assert!(c.integrate(&next, &mut out).expect("maps") > 0);
    }

    /// Frames with echoes near and far, short, at the maximum range and
    /// past it, from poses around the origin.
    fn scout_frames() -> Vec<(Pose2, Vec<f64>)> {
        (0..6)
            .map(|k| {
                let k = f64::from(k);
                let pose = Pose2::new(0.7 * k - 1.9, 0.3 - 0.45 * k, 1.1 * k - 2.0);
                let ranges = (0..16u32)
                    .map(|i| match (i + k as u32) % 5 {
                        0 => 10.668,
                        1 => 0.05,
                        2 => 25.0,
                        _ => 0.4 + 0.61 * f64::from(i) + 0.13 * k,
                    })
                    .collect();
                (pose, ranges)
            })
            .collect()
    }

    #[test]
    fn the_scout_rig_maps_as_the_scout_ring() {
        for params in [SonarModelParams::default(), crate::mapping_sonar_model()] {
            let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
            let mut ring =
                Cartographer::with_model(res, size, PoseChoice::Odometry, params).expect("ring");
            let rig = deog_rig::scout();
            let mut by_rig = Cartographer::for_rig(
                &rig,
                PoseChoice::Odometry,
                params,
                RayModelParams::default(),
                res,
                size,
            )
            .expect("rig");
            for (sequence, (pose, ranges)) in scout_frames().iter().enumerate() {
                let frame = FrameInput {
                    sequence: sequence as u64,
                    pace: None,
                    true_pose: None,
                    odometry: *pose,
                    reference_pose: None,
                    estimate: None,
                    ranges,
                };
                let (mut a, mut b) = (Vec::new(), Vec::new());
                let na = ring.integrate(&frame, &mut a).expect("ring frame");
                let nb = by_rig.integrate(&frame, &mut b).expect("rig frame");
                assert!(na > 0);
                assert_eq!(na, nb, "frame {sequence}");
                assert!(a == b, "frame {sequence}: the deltas differ");
            }
        }
    }

    #[test]
    fn a_rig_frame_of_the_wrong_count_names_both_counts() {
        let rig = deog_rig::built_in_rig("laser180").expect("laser180");
        let mut c = Cartographer::for_rig(
            &rig,
            PoseChoice::Odometry,
            SonarModelParams::default(),
            RayModelParams::default(),
            Resolution::DEFAULT,
            TileSize::DEFAULT,
        )
        .expect("cartographer");
        let ranges = [2.0; 179];
        let frame = FrameInput {
            sequence: 4,
            pace: None,
            true_pose: None,
            odometry: Pose2::default(),
            reference_pose: None,
            estimate: None,
            ranges: &ranges,
        };
        let mut out = Vec::new();
        let error = c.integrate(&frame, &mut out).expect_err("179 of 180");
        assert_eq!(
            error.to_string(),
            "frame 4: ranges: expected 180 readings, got 179"
        );
        assert!(out.is_empty());
        let full = FrameInput {
            ranges: &[2.0; 180],
            ..frame
        };
        assert!(c.integrate(&full, &mut out).expect("180") > 0);
    }

    /// A sensor the cartographer knows nothing of: one reading, the
    /// robot's own cell marked occupied when it is positive.
    #[derive(Debug)]
    struct Bumper;

    impl InverseSensorModel for Bumper {
        fn readings(&self) -> usize {
            1
        }

        fn integrate(
            &mut self,
            robot: &Pose2,
            readings: &[f64],
            out: &mut Vec<TileDelta>,
        ) -> Result<usize, deog_grid::GridError> {
            if readings.len() != 1 {
                return Err(deog_grid::GridError::WrongReadingCount {
                    expected: 1,
                    got: readings.len(),
                });
            }
            if readings[0] <= 0.0 {
                return Ok(0);
            }
            let size = TileSize::DEFAULT;
            let cell = Resolution::DEFAULT.cell_of(robot.x, robot.y)?;
            let (key, offset) = size.split(cell);
            let mut delta = TileDelta::zero(key, size);
            delta.raw_mut()[offset.index(size)] = 500;
            out.push(delta);
            Ok(1)
        }
    }

    #[test]
    fn a_new_sensor_maps_through_the_cartographer_unchanged() {
        let mut c = Cartographer::with_sensor(PoseChoice::Odometry, Box::new(Bumper));
        let mut out = Vec::new();
        let frame = FrameInput {
            sequence: 3,
            pace: None,
            true_pose: None,
            odometry: Pose2::new(1.0, -1.0, 0.0),
            reference_pose: None,
            estimate: None,
            ranges: &[1.0],
        };
        assert_eq!(c.integrate(&frame, &mut out).expect("one cell"), 1);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].key, deog_grid::TileKey::new(0, -1));
        // The count of readings is the sensor's to check, and the error
        // still names the frame.
        let sixteen = FrameInput {
            ranges: &[1.0; 16],
            ..frame
        };
        let error = c
            .integrate(&sixteen, &mut out)
            .expect_err("sixteen readings");
        assert!(error.to_string().contains("frame 3"), "{error}");
    }

    /// A frame read at `pose`, its true pose and odometry alike.
    fn at_true_pose(sequence: u64, pose: Pose2, ranges: &[f64]) -> FrameInput<'_> {
        FrameInput {
            sequence,
            pace: None,
            true_pose: Some(pose),
            odometry: pose,
            reference_pose: None,
            estimate: None,
            ranges,
        }
    }

    /// The Scout facing a wall 2 m ahead along +x, at `y`.
    fn facing_wall(sequence: u64, y: f64, range0: f64) -> (Pose2, Vec<f64>, u64) {
        let mut ranges = vec![10.668; 16];
        ranges[0] = range0;
        (Pose2::new(0.0, y, 0.0), ranges, sequence)
    }

    #[test]
    fn keeping_walls_a_specular_miss_does_not_erase_the_wall() {
        let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
        let params = crate::mapping_sonar_model();
        let rig = deog_rig::scout();
        let build = |method| {
            Cartographer::with_model(res, size, PoseChoice::True, params)
                .expect("cartographer")
                .with_sonar_method(method, &rig, &params, MapViewSettings::default(), res, size)
                .expect("method")
        };
        let map_of = |method| {
            let mut cartographer = build(method);
            let mut map = deog_grid::TileMap::new(res, size, deog_grid::ClampLimits::default());
            // Fifteen head-on echoes off the wall 1.8 m from the front
            // sonar, then twenty readings that missed it and heard 4 m.
            let frames = (0..15)
                .map(|k| facing_wall(k, 0.0, 1.8))
                .chain((15..35).map(|k| facing_wall(k, 0.0, 4.0)));
            for (pose, ranges, sequence) in frames {
                let frame = at_true_pose(sequence, pose, &ranges);
                assert!(cartographer.missing_tiles(&frame).is_ok());
                let mut out = Vec::new();
                cartographer.integrate(&frame, &mut out).expect("frame");
                for delta in &out {
                    map.apply(delta).expect("apply");
                }
            }
            map
        };
        let wall = res.cell_of(2.0, 0.0).expect("cell");
        let behind = res.cell_of(3.0, 0.0).expect("cell");
        let thesis = map_of(SonarMethod::Thesis);
        let kept = map_of(SonarMethod::KeepWalls);
        let p = |map: &deog_grid::TileMap, cell| map.get(cell).map(|b| b.probability());
        assert!(
            p(&thesis, wall).is_some_and(|p| p < 0.5),
            "the thesis's model erases it"
        );
        assert!(
            p(&kept, wall).is_some_and(|p| p > 0.8),
            "kept: {:?}",
            p(&kept, wall)
        );
        assert_eq!(p(&kept, behind), None, "nothing behind a kept wall");
        assert!(
            p(&thesis, behind).is_some(),
            "the thesis's model maps through it"
        );
    }

    #[test]
    fn a_wall_another_robot_heard_stops_a_directional_cone() {
        let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
        let (method, params) = specular_sonar_mapping();
        let rig = deog_rig::scout();
        // The map written to: a wall across x = 1 m that another robot's
        // cartographer heard; this one has heard nothing yet.
        let mut written = deog_grid::TileMap::new(res, size, deog_grid::ClampLimits::default());
        let mut wall = Vec::new();
        for y in -20..=20 {
            let cell = res.cell_of(1.0, f64::from(y) * 0.05).expect("cell");
            let (key, offset) = size.split(cell);
            let mut delta = TileDelta::zero(key, size);
            delta.raw_mut()[offset.index(size)] = 2000;
            written.apply(&delta).expect("apply");
            wall.push(cell);
        }
        // The front sonar grazes nothing and hears 1.8 m: a reading that
        // passed the wall (a multipath echo, a neighbour's ping).
        let (pose, ranges, sequence) = facing_wall(1, 0.0, 1.8);
        let frame = at_true_pose(sequence, pose, &ranges);
        let behind = res.cell_of(1.4, 0.0).expect("cell");
        let in_front = res.cell_of(0.6, 0.0).expect("cell");
        let delta_at = |reads_the_map: bool| {
            let mut cartographer = Cartographer::with_model(res, size, PoseChoice::True, params)
                .expect("cartographer")
                .with_sonar_method(method, &rig, &params, MapViewSettings::default(), res, size)
                .expect("method");
            assert!(cartographer.view_mut().is_some(), "a view of the map");
            if reads_the_map {
                cartographer
                    .read_missing_tiles(&frame, &written)
                    .expect("read");
            }
            let mut out = Vec::new();
            cartographer.integrate(&frame, &mut out).expect("frame");
            let mut map = deog_grid::TileMap::new(res, size, deog_grid::ClampLimits::default());
            for delta in &out {
                map.apply(delta).expect("apply");
            }
            let p = |cell| map.get(cell).map(|b| b.probability());
            (
                p(in_front),
                p(behind),
                wall.iter().filter_map(|&c| p(c)).count(),
            )
        };
        let (front, past, on_wall) = delta_at(false);
        assert!(front.is_some_and(|p| p < 0.5), "freed in front: {front:?}");
        assert!(
            past.is_some_and(|p| p < 0.5),
            "alone, it frees past the wall: {past:?}"
        );
        assert!(on_wall > 0);
        let (front, past, _) = delta_at(true);
        assert!(
            front.is_some_and(|p| p < 0.5),
            "still freed in front: {front:?}"
        );
        assert_eq!(past, None, "nothing past the wall the map holds");
    }

    #[test]
    fn the_view_of_a_map_in_the_process_is_read_anew_every_so_many_frames() {
        use deog_grid::ConeGuard;
        let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
        let (method, params) = specular_sonar_mapping();
        let rig = deog_rig::scout();
        let (pose, ranges, sequence) = facing_wall(1, 0.0, 1.8);
        let frame = at_true_pose(sequence, pose, &ranges);
        let wall = res.cell_of(1.0, 0.0).expect("cell");
        // Which of seven reads see the wall another writer puts into the
        // map after the first read.
        let reads_seeing_the_wall = |every: Option<u32>| {
            let mut cartographer = Cartographer::with_model(res, size, PoseChoice::True, params)
                .expect("cartographer")
                .with_sonar_method(method, &rig, &params, MapViewSettings::default(), res, size)
                .expect("method");
            if let Some(every) = every {
                cartographer = cartographer.reading_map_every(every);
            }
            let mut written = deog_grid::TileMap::new(res, size, deog_grid::ClampLimits::default());
            let mut seen = Vec::new();
            for read in 0..7 {
                if read == 1 {
                    let (key, offset) = size.split(wall);
                    let mut delta = TileDelta::zero(key, size);
                    delta.raw_mut()[offset.index(size)] = 2000;
                    written.apply(&delta).expect("apply");
                }
                cartographer
                    .read_missing_tiles(&frame, &written)
                    .expect("read");
                let view = cartographer.view_mut().expect("a view of the map");
                seen.push(view.shadows(wall));
            }
            seen
        };
        assert_eq!(reads_seeing_the_wall(None), [false; 7], "filled once");
        assert_eq!(
            reads_seeing_the_wall(Some(3)),
            [false, false, true, true, true, true, true],
            "the third read reads the whole view anew"
        );
        assert_eq!(
            reads_seeing_the_wall(Some(0)),
            [false, true, true, true, true, true, true],
            "0 is taken as 1: every read anew"
        );
    }

    #[test]
    fn the_guard_over_both_views_says_what_each_view_says() {
        use deog_grid::ConeGuard;
        let (res, size) = (Resolution::DEFAULT, TileSize::new(8).expect("size"));
        let settings = MapViewSettings::default();
        let mut own = DirectionalView::new(
            res,
            size,
            DirectionalSettings {
                wall_probability: settings.wall_probability,
                max_tiles: settings.max_tiles,
                limits: settings.limits,
                enclosure_period: 0,
                shadow_depth: 0.0,
            },
        )
        .expect("view");
        let mut map = MapView::new(res, size, settings).expect("view");
        // Over 3 × 3 tiles: walls in one view, the other, both or
        // neither, and free cells.
        let mut own_deltas = std::collections::BTreeMap::new();
        let mut map_deltas = std::collections::BTreeMap::new();
        for y in -8..16 {
            for x in -8..16 {
                let (key, offset) = size.split(CellIndex::new(x, y));
                let (to_own, to_map) = match (x * 7 + y * 13).rem_euclid(5) {
                    0 => (3000, 0),
                    1 => (0, 3000),
                    2 => (3000, 3000),
                    3 => (-900, -900),
                    _ => (0, 0),
                };
                for (deltas, value) in [(&mut own_deltas, to_own), (&mut map_deltas, to_map)] {
                    if value != 0 {
                        let delta: &mut TileDelta = deltas
                            .entry((key.x, key.y))
                            .or_insert_with(|| TileDelta::zero(key, size));
                        delta.raw_mut()[offset.index(size)] = value;
                    }
                }
            }
        }
        let own_deltas: Vec<TileDelta> = own_deltas.into_values().collect();
        let map_deltas: Vec<TileDelta> = map_deltas.into_values().collect();
        own.absorb(&Pose2::new(-5.0, -5.0, 0.0), &own_deltas, &mut Vec::new())
            .expect("absorb");
        map.apply(&map_deltas).expect("apply");
        let guard = OwnAndMapWalls::new(&own, &map);
        // Asked in an order that jumps between tiles and comes back.
        let (mut seed, mut only_own, mut only_map) = (12345u64, 0, 0);
        for _ in 0..3000 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let x = (seed >> 33) as i32 % 28 - 10;
            let y = (seed >> 45) as i32 % 28 - 10;
            let cell = CellIndex::new(x, y);
            let (by_own, by_map) = (own.shadows(cell), map.shadows(cell));
            assert_eq!(guard.shadows(cell), by_own || by_map, "cell {cell:?}");
            only_own += usize::from(by_own && !by_map);
            only_map += usize::from(by_map && !by_own);
        }
        assert!(only_own > 0 && only_map > 0, "{only_own} {only_map}");
    }

    #[test]
    fn a_laser_rig_or_the_thesis_method_keeps_no_view() {
        let (res, size) = (Resolution::DEFAULT, TileSize::DEFAULT);
        let params = crate::mapping_sonar_model();
        let laser = deog_rig::built_in_rig("laser180").expect("laser180");
        for (rig, method) in [
            (laser, SonarMethod::KeepWalls),
            (deog_rig::scout(), SonarMethod::Thesis),
        ] {
            let mut c = Cartographer::for_rig(
                &rig,
                PoseChoice::Odometry,
                params,
                RayModelParams::default(),
                res,
                size,
            )
            .expect("cartographer")
            .with_sonar_method(method, &rig, &params, MapViewSettings::default(), res, size)
            .expect("method");
            assert!(c.view_mut().is_none(), "{} {method:?}", rig.name());
        }
    }
}
