//! What the page shows, kept up to date from the feeds: each followed map's
//! tiles as shades, and per robot its true pose, its latest frame's beams,
//! its localizer's estimate, its paths and its kidnaps. Pure: the feeds
//! call in with what they read, and each call says what changed.

use std::collections::{BTreeMap, HashMap, VecDeque};

use deog_grid::{LogOdds, Pose2, Tile, TileKey, TileSize};
use deog_rig::{BeamShape, Reading, Rig};

/// The shade of a cell never observed.
pub const UNKNOWN_SHADE: u8 = 255;

/// Bounds on what is kept per robot, so a long run's view stays small.
#[derive(Debug, Clone, Copy)]
pub struct TrackLimits {
    /// Points kept per path; the oldest go first.
    pub path_points: usize,
    /// Frames whose true pose is kept to judge estimates that follow them.
    pub truth_frames: usize,
    /// Kidnaps kept per robot.
    pub kidnaps: usize,
    /// A path gains a point once the robot moved this far, metres.
    pub path_step_m: f64,
}

impl Default for TrackLimits {
    fn default() -> Self {
        Self {
            path_points: 4_000,
            truth_frames: 4_096,
            kidnaps: 32,
            path_step_m: 0.02,
        }
    }
}

/// A cell's belief as a grey level: 0 surely occupied, 250 surely free,
/// [`UNKNOWN_SHADE`] never observed.
pub fn shade(raw: i16) -> u8 {
    match LogOdds::from_raw(raw) {
        None => UNKNOWN_SHADE,
        Some(belief) => ((1.0 - belief.probability()) * 250.0).round() as u8,
    }
}

/// A tile's cells as shades, row-major as the tile's own cells.
pub fn shade_tile(tile: &Tile) -> Vec<u8> {
    tile.raw_cells().iter().map(|&raw| shade(raw)).collect()
}

/// A map as the page draws it.
#[derive(Debug, Clone)]
pub struct MapLayer {
    /// Metres per cell.
    pub resolution_m: f64,
    /// Cells per tile side.
    pub tile_size: TileSize,
    /// Each stored tile: its version and its shades.
    pub tiles: HashMap<TileKey, (u64, Vec<u8>)>,
}

/// One reading drawn in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldBeam {
    /// Where the beam starts and which way it points.
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// Radians, world frame.
    pub angle: f64,
    /// The echo's range, or the beam's longest range when nothing was heard.
    pub range: f64,
    /// Half the cone's opening angle; 0 for a laser ray.
    pub half_angle: f64,
    /// Whether something answered.
    pub echo: bool,
    /// Which sensor of the rig made it (an index into the rig's sensors).
    pub sensor: usize,
}

/// A localizer's latest estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateView {
    /// The map it is on.
    pub map: String,
    /// The frame it follows.
    pub sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// The estimated pose.
    pub pose: Pose2,
    /// Covariance of (x, y, theta), row-major.
    pub covariance: [f64; 9],
    /// Whether the filter believes it has converged.
    pub converged: bool,
    /// 0 when observations fit the map, towards 1 when lost.
    pub lost_score: f64,
    /// Particles in the filter.
    pub particles: u32,
    /// A sample of those particles when the localizer sent one with this
    /// estimate; moved into [`RobotTrack::particles`] when taken.
    pub particle_sample: Vec<Pose2>,
}

/// The newest sample of a localizer's particles.
#[derive(Debug, Clone, PartialEq)]
pub struct ParticleSample {
    /// The map they are on.
    pub map: String,
    /// The frame they follow.
    pub sequence: u64,
    /// That frame's time, seconds.
    pub time_s: f64,
    /// The particles.
    pub poses: Vec<Pose2>,
}

/// How far an estimate is from the truth of the frame it follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateError {
    /// Distance, metres.
    pub distance_m: f64,
    /// Heading difference, degrees, absolute.
    pub heading_deg: f64,
}

/// A jump of the true pose no drive could make.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kidnap {
    /// When it was seen, seconds.
    pub time_s: f64,
    /// Where the robot was.
    pub from: Pose2,
    /// Where it was put.
    pub to: Pose2,
}

/// A point of an estimate's path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatePoint {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Whether the filter had converged there.
    pub converged: bool,
}

/// Everything known of one robot.
#[derive(Debug, Clone, Default)]
pub struct RobotTrack {
    /// The newest frame's sequence.
    pub sequence: u64,
    /// The newest time seen, seconds.
    pub time_s: f64,
    /// Where the robot really is, when a simulator says.
    pub true_pose: Option<Pose2>,
    /// Where its odometry says it is.
    pub odometry: Option<Pose2>,
    /// The rig's body radius, metres.
    pub body_radius_m: Option<f64>,
    /// The newest frame's readings.
    pub beams: Vec<WorldBeam>,
    /// The localizer's newest estimate.
    pub estimate: Option<EstimateView>,
    /// The newest sample of its particles.
    pub particles: Option<ParticleSample>,
    /// That estimate against the truth of its frame.
    pub error: Option<EstimateError>,
    /// The true path, oldest first.
    pub true_path: VecDeque<[f64; 2]>,
    /// The estimates' path, oldest first.
    pub estimate_path: VecDeque<EstimatePoint>,
    /// Kidnaps seen, oldest first.
    pub kidnaps: VecDeque<Kidnap>,
    /// Where its explorer is heading (map, x, y), while it has a goal.
    pub goal: Option<(String, f64, f64)>,
    true_by_sequence: VecDeque<(u64, Pose2)>,
    last_truth_time_s: Option<f64>,
}

/// A frame as the state takes it.
#[derive(Debug, Clone)]
pub struct FrameView<'a> {
    /// Its sequence.
    pub sequence: u64,
    /// Its time, seconds.
    pub time_s: f64,
    /// The odometry pose.
    pub odometry: Pose2,
    /// The true pose, when known.
    pub true_pose: Option<Pose2>,
    /// The readings, in the rig's order.
    pub ranges: &'a [f64],
    /// The rig that made them, when it could be read.
    pub rig: Option<&'a Rig>,
}

/// What a call changed, for the pages that show it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Change {
    /// A tile of a map.
    Tile {
        /// The map.
        map: String,
        /// The tile.
        key: TileKey,
    },
    /// A map lost all its tiles.
    Cleared {
        /// The map.
        map: String,
    },
    /// A robot's pose, frame or estimate.
    Robot(String),
    /// A robot was kidnapped.
    Kidnap(String),
    /// A localizer sent a new sample of its particles.
    Particles(String),
}

/// The view's state: followed maps and every robot seen.
#[derive(Debug, Default)]
pub struct ViewState {
    maps: BTreeMap<String, MapLayer>,
    robots: BTreeMap<String, RobotTrack>,
    limits: TrackLimits,
}

impl ViewState {
    /// An empty state that keeps at most what `limits` allow per robot.
    pub fn new(limits: TrackLimits) -> Self {
        Self {
            limits,
            ..Self::default()
        }
    }

    /// The followed maps.
    pub fn maps(&self) -> &BTreeMap<String, MapLayer> {
        &self.maps
    }

    /// One followed map.
    pub fn map(&self, name: &str) -> Option<&MapLayer> {
        self.maps.get(name)
    }

    /// Every robot seen.
    pub fn robots(&self) -> &BTreeMap<String, RobotTrack> {
        &self.robots
    }

    /// Starts (or restarts, dropping its tiles) following `map`.
    pub fn follow_map(&mut self, map: &str, resolution_m: f64, tile_size: TileSize) {
        self.maps.insert(
            map.to_string(),
            MapLayer {
                resolution_m,
                tile_size,
                tiles: HashMap::new(),
            },
        );
    }

    /// A tile read or heard of; an older version than the one held is
    /// ignored (a re-read may race a change).
    pub fn on_tile(
        &mut self,
        map: &str,
        key: TileKey,
        version: u64,
        tile: &Tile,
    ) -> Option<Change> {
        let layer = self.maps.get_mut(map)?;
        if tile.size() != layer.tile_size {
            return None;
        }
        if layer
            .tiles
            .get(&key)
            .is_some_and(|(held, _)| *held > version)
        {
            return None;
        }
        layer.tiles.insert(key, (version, shade_tile(tile)));
        Some(Change::Tile {
            map: map.to_string(),
            key,
        })
    }

    /// A map was cleared.
    pub fn on_cleared(&mut self, map: &str) -> Option<Change> {
        let layer = self.maps.get_mut(map)?;
        layer.tiles.clear();
        Some(Change::Cleared {
            map: map.to_string(),
        })
    }

    /// A robot's frame: its odometry, true pose and readings.
    pub fn on_frame(&mut self, robot: &str, frame: &FrameView<'_>) -> Vec<Change> {
        let limits = self.limits;
        let track = self.robots.entry(robot.to_string()).or_default();
        if frame.sequence < track.sequence {
            // A replay from before what is held: nothing new to show.
            return Vec::new();
        }
        track.sequence = frame.sequence;
        track.odometry = Some(frame.odometry);
        let mut changes = vec![Change::Robot(robot.to_string())];
        if let Some(truth) = frame.true_pose {
            // A simulator followed alongside runs ahead of the frames: the
            // path takes only truths newer than the newest it has.
            let newer = track.last_truth_time_s.is_none_or(|t| frame.time_s >= t);
            if newer && track.note_truth(frame.time_s, truth, &limits) {
                changes.push(Change::Kidnap(robot.to_string()));
            }
            push_bounded(
                &mut track.true_by_sequence,
                (frame.sequence, truth),
                limits.truth_frames,
            );
        }
        track.time_s = track.time_s.max(frame.time_s);
        if let Some(rig) = frame.rig {
            track.body_radius_m = Some(rig.body_radius());
            let at = frame.true_pose.unwrap_or(frame.odometry);
            track.beams = world_beams(rig, at, frame.ranges);
        }
        changes
    }

    /// A simulator's word on where a robot really is.
    pub fn on_true_pose(&mut self, robot: &str, time_s: f64, truth: Pose2) -> Vec<Change> {
        let limits = self.limits;
        let track = self.robots.entry(robot.to_string()).or_default();
        let mut changes = vec![Change::Robot(robot.to_string())];
        if track.note_truth(time_s, truth, &limits) {
            changes.push(Change::Kidnap(robot.to_string()));
        }
        track.time_s = track.time_s.max(time_s);
        changes
    }

    /// A localizer's estimate.
    pub fn on_estimate(&mut self, robot: &str, mut estimate: EstimateView) -> Vec<Change> {
        let limits = self.limits;
        let track = self.robots.entry(robot.to_string()).or_default();
        if track
            .estimate
            .as_ref()
            .is_some_and(|held| held.map == estimate.map && held.sequence > estimate.sequence)
        {
            return Vec::new();
        }
        let mut changes = vec![Change::Robot(robot.to_string())];
        if !estimate.particle_sample.is_empty() {
            track.particles = Some(ParticleSample {
                map: estimate.map.clone(),
                sequence: estimate.sequence,
                time_s: estimate.time_s,
                poses: std::mem::take(&mut estimate.particle_sample),
            });
            changes.push(Change::Particles(robot.to_string()));
        }
        track.error = track
            .true_by_sequence
            .iter()
            .rev()
            .find(|(sequence, _)| *sequence == estimate.sequence)
            .map(|(_, truth)| error_of(estimate.pose, *truth));
        let point = EstimatePoint {
            x: estimate.pose.x,
            y: estimate.pose.y,
            converged: estimate.converged,
        };
        let moved = track.estimate_path.back().is_none_or(|last| {
            last.converged != point.converged
                || (last.x - point.x).hypot(last.y - point.y) >= limits.path_step_m
        });
        if moved {
            push_bounded(&mut track.estimate_path, point, limits.path_points);
        }
        track.estimate = Some(estimate);
        changes
    }
}

impl ViewState {
    /// An explorer's goal: where it heads, or `None` once given up. Says
    /// whether that changed what is shown.
    pub fn on_goal(&mut self, robot: &str, goal: Option<(String, f64, f64)>) -> Option<Change> {
        let track = self.robots.entry(robot.to_string()).or_default();
        if track.goal == goal {
            return None;
        }
        track.goal = goal;
        Some(Change::Robot(robot.to_string()))
    }
}

impl RobotTrack {
    /// Takes a true pose into the path; says whether it was a kidnap (a
    /// jump faster than any drive: 0.5 m plus 2 m/s of the time between).
    fn note_truth(&mut self, time_s: f64, truth: Pose2, limits: &TrackLimits) -> bool {
        let mut kidnapped = false;
        if let (Some(last), Some(last_time)) = (self.true_pose, self.last_truth_time_s) {
            let elapsed = (time_s - last_time).abs();
            let jump = (truth.x - last.x).hypot(truth.y - last.y);
            if jump > 0.5 + 2.0 * elapsed {
                kidnapped = true;
                push_bounded(
                    &mut self.kidnaps,
                    Kidnap {
                        time_s,
                        from: last,
                        to: truth,
                    },
                    limits.kidnaps,
                );
            }
        }
        let moved = self.true_path.back().is_none_or(|last| {
            kidnapped || (last[0] - truth.x).hypot(last[1] - truth.y) >= limits.path_step_m
        });
        if moved {
            push_bounded(&mut self.true_path, [truth.x, truth.y], limits.path_points);
        }
        self.true_pose = Some(truth);
        self.last_truth_time_s = Some(time_s);
        kidnapped
    }
}

/// Distance and heading difference of `estimate` from `truth`.
pub fn error_of(estimate: Pose2, truth: Pose2) -> EstimateError {
    EstimateError {
        distance_m: (estimate.x - truth.x).hypot(estimate.y - truth.y),
        heading_deg: deog_grid::normalize_angle(estimate.theta - truth.theta)
            .abs()
            .to_degrees(),
    }
}

/// A frame's readings in the world frame, seen from `at`; readings that
/// are not ranges are left out.
pub fn world_beams(rig: &Rig, at: Pose2, ranges: &[f64]) -> Vec<WorldBeam> {
    rig.beams()
        .iter()
        .zip(ranges)
        .filter_map(|(beam, &range)| {
            let (range, echo) = match beam.classify(range)? {
                Reading::Echo(range) => (range, true),
                Reading::NoEcho => (beam.max_range, false),
            };
            let origin = at.compose(&beam.mount);
            Some(WorldBeam {
                x: origin.x,
                y: origin.y,
                angle: origin.theta,
                range,
                half_angle: match beam.shape {
                    BeamShape::Cone { half_angle } => half_angle,
                    BeamShape::Ray => 0.0,
                },
                echo,
                sensor: beam.sensor,
            })
        })
        .collect()
}

fn push_bounded<T>(queue: &mut VecDeque<T>, item: T, limit: usize) {
    while queue.len() >= limit.max(1) {
        queue.pop_front();
    }
    queue.push_back(item);
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::LogOdds;

    fn pose(x: f64, y: f64, theta: f64) -> Pose2 {
        Pose2 { x, y, theta }
    }

    fn frame(sequence: u64, time_s: f64, truth: Pose2) -> FrameView<'static> {
        FrameView {
            sequence,
            time_s,
            odometry: truth,
            true_pose: Some(truth),
            ranges: &[],
            rig: None,
        }
    }

    #[test]
    fn shades_run_from_occupied_to_free_with_unknown_apart() {
        assert_eq!(shade(LogOdds::UNKNOWN_RAW), UNKNOWN_SHADE);
        assert_eq!(shade(0), 125);
        assert!(shade(4000) < 5, "sure walls are near black");
        assert!(shade(-4000) > 245, "sure free space is near white");
        let order: Vec<u8> = [3000, 1000, 0, -1000, -3000]
            .iter()
            .map(|&r| shade(r))
            .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{order:?}");
    }

    #[test]
    fn an_older_tile_version_does_not_replace_a_newer_one() {
        let size = TileSize::new(8).unwrap();
        let mut state = ViewState::new(TrackLimits::default());
        let key = TileKey::new(1, -2);
        assert_eq!(
            state.on_tile("m", key, 3, &Tile::unknown(size)),
            None,
            "not followed"
        );
        state.follow_map("m", 0.05, size);
        let mut wall = Tile::unknown(size);
        wall.apply(
            &deog_grid::TileDelta::from_raw(key, size, vec![2000; 64]).unwrap(),
            deog_grid::ClampLimits::NONE,
        )
        .unwrap();
        assert!(state.on_tile("m", key, 5, &wall).is_some());
        assert_eq!(state.on_tile("m", key, 4, &Tile::unknown(size)), None);
        let (version, shades) = &state.map("m").unwrap().tiles[&key];
        assert_eq!(*version, 5);
        assert!(shades.iter().all(|&s| s == shade(2000)));
        assert!(state.on_cleared("m").is_some());
        assert!(state.map("m").unwrap().tiles.is_empty());
    }

    #[test]
    fn a_jump_no_drive_could_make_is_a_kidnap_and_a_drive_is_not() {
        let mut state = ViewState::new(TrackLimits::default());
        let mut kidnaps = 0;
        for i in 0..50 {
            let t = f64::from(i) * 0.1;
            let changes = state.on_frame(
                "r",
                &frame(i as u64 + 1, t, pose(0.05 * f64::from(i), 0.0, 0.0)),
            );
            kidnaps += changes
                .iter()
                .filter(|c| matches!(c, Change::Kidnap(_)))
                .count();
        }
        assert_eq!(kidnaps, 0);
        let changes = state.on_frame("r", &frame(51, 5.0, pose(6.0, 4.0, 1.0)));
        assert!(changes.contains(&Change::Kidnap("r".into())));
        let track = &state.robots()["r"];
        assert_eq!(track.kidnaps.len(), 1);
        assert_eq!(track.kidnaps[0].to, pose(6.0, 4.0, 1.0));
        assert_eq!(track.true_path.back(), Some(&[6.0, 4.0]));
    }

    #[test]
    fn an_estimate_is_judged_against_the_truth_of_its_own_frame() {
        let mut state = ViewState::new(TrackLimits::default());
        for i in 1..=10u64 {
            state.on_frame(
                "r",
                &frame(i, i as f64 * 0.1, pose(i as f64 * 0.1, 0.0, 0.0)),
            );
        }
        let estimate = EstimateView {
            map: "m".into(),
            sequence: 4,
            time_s: 0.4,
            pose: pose(0.43, 0.04, 0.1),
            covariance: [0.0; 9],
            converged: true,
            lost_score: 0.0,
            particles: 500,
            particle_sample: Vec::new(),
        };
        assert_eq!(
            state.on_estimate("r", estimate.clone()),
            vec![Change::Robot("r".into())]
        );
        let error = state.robots()["r"].error.unwrap();
        assert!((error.distance_m - 0.05).abs() < 1e-9, "{error:?}");
        assert!((error.heading_deg - 0.1f64.to_degrees()).abs() < 1e-9);
        // An older estimate of the same map arriving late is not shown.
        let older = EstimateView {
            sequence: 2,
            ..estimate.clone()
        };
        assert_eq!(state.on_estimate("r", older), Vec::new());
        // A sample of particles is kept apart, and said.
        let sampled = EstimateView {
            sequence: 5,
            particle_sample: vec![pose(0.4, 0.0, 0.0), pose(0.5, 0.1, 0.2)],
            ..estimate
        };
        assert_eq!(
            state.on_estimate("r", sampled),
            vec![Change::Robot("r".into()), Change::Particles("r".into())]
        );
        let track = &state.robots()["r"];
        let held = track.particles.as_ref().unwrap();
        assert_eq!((held.sequence, held.poses.len()), (5, 2));
        assert!(track.estimate.as_ref().unwrap().particle_sample.is_empty());
    }

    #[test]
    fn a_goal_shows_until_it_is_given_up() {
        let mut state = ViewState::new(TrackLimits::default());
        let goal = Some(("m".to_string(), 1.0, 2.0));
        assert!(state.on_goal("r", goal.clone()).is_some());
        assert_eq!(state.on_goal("r", goal.clone()), None, "nothing new");
        assert_eq!(state.robots()["r"].goal, goal);
        assert!(state.on_goal("r", None).is_some());
        assert_eq!(state.robots()["r"].goal, None);
    }

    #[test]
    fn paths_stay_within_their_limits() {
        let limits = TrackLimits {
            path_points: 10,
            truth_frames: 5,
            kidnaps: 2,
            path_step_m: 0.01,
        };
        let mut state = ViewState::new(limits);
        for i in 0..100u64 {
            state.on_frame("r", &frame(i + 1, i as f64, pose(i as f64 * 0.1, 0.0, 0.0)));
        }
        let track = &state.robots()["r"];
        assert_eq!(track.true_path.len(), 10);
        assert_eq!(track.true_by_sequence.len(), 5);
        assert_eq!(track.true_path.back(), Some(&[9.9, 0.0]));
    }

    #[test]
    fn beams_start_at_their_mounts_in_the_world() {
        let rig = deog_rig::scout();
        let at = pose(1.0, 2.0, std::f64::consts::FRAC_PI_2);
        let ranges = vec![1.0; rig.readings()];
        let beams = world_beams(&rig, at, &ranges);
        assert_eq!(beams.len(), 16);
        // Sonar 0 faces forward: up the y axis from a mount ahead of the centre.
        assert!((beams[0].x - 1.0).abs() < 1e-9);
        assert!(beams[0].y > 2.0);
        assert!((beams[0].angle - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!(beams.iter().all(|b| b.echo && b.half_angle > 0.0));
    }
}
