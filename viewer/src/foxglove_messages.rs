//! The view's state as Foxglove's built-in message types: a followed map
//! as a `Grid`, poses as `PoseInFrame`, a localizer's covariance as a
//! `SceneUpdate` ellipse, a frame's laser rays as `LaserScan`s and its
//! sonar cones as `SceneUpdate` triangles, robots' bodies as
//! `FrameTransforms`, paths as `PosesInFrame`. Pure: no I/O, no clock
//! (the caller passes the timestamp).
//!
//! Everything is placed in the `map` frame, metres, z = 0.

use foxglove::bytes::Bytes;
use foxglove::messages::{
    Color, FrameTransform, Grid, KeyValuePair, LaserScan, LinePrimitive, PackedElementField,
    Point3, Pose, PoseInFrame, PosesInFrame, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive,
    TextPrimitive, Timestamp, TriangleListPrimitive, Vector2, Vector3, line_primitive,
    packed_element_field::NumericType,
};

use deog_grid::Pose2;

use crate::state::{EstimateView, Kidnap, MapLayer, ParticleSample, UNKNOWN_SHADE, WorldBeam};

/// The fixed frame every message is placed in.
pub const MAP_FRAME: &str = "map";

/// The longest side, in cells, of a published grid; a larger map is sent
/// coarser (each published cell the most occupied of the cells it covers),
/// so one message stays within 5 MiB.
pub const MAX_GRID_SIDE: u32 = 1024;

/// Bytes per grid cell: red, green, blue, alpha, occupancy.
const GRID_CELL_BYTES: u32 = 5;

/// Grey level of a cell never observed (an occupancy of -1).
const UNKNOWN_GREY: u8 = 128;

/// Segments of the arc that closes a sonar cone.
const CONE_SEGMENTS: usize = 6;

/// Standard deviations the covariance ellipse spans on each side.
const ELLIPSE_SIGMAS: f64 = 2.0;

/// The frame of a robot's body: `<robot>/base_link`.
pub fn base_link(robot: &str) -> String {
    format!("{robot}/base_link")
}

/// A heading about +z as a quaternion.
pub fn yaw_quaternion(theta: f64) -> Quaternion {
    let half = theta / 2.0;
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: half.sin(),
        w: half.cos(),
    }
}

/// A planar pose as a 3D pose at z = 0.
pub fn pose3(pose: Pose2) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: pose.x,
            y: pose.y,
            z: 0.0,
        }),
        orientation: Some(yaw_quaternion(pose.theta)),
    }
}

/// A pose in the map frame.
pub fn pose_in_map(pose: Pose2, timestamp: Timestamp) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp),
        frame_id: MAP_FRAME.to_string(),
        pose: Some(pose3(pose)),
    }
}

/// A path as poses in the map frame, each facing along the path.
pub fn path_in_map(
    points: impl IntoIterator<Item = [f64; 2]>,
    timestamp: Timestamp,
) -> PosesInFrame {
    let points: Vec<[f64; 2]> = points.into_iter().collect();
    let poses = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let next = points
                .get(i + 1)
                .or_else(|| i.checked_sub(1).map(|j| &points[j]));
            let theta = match next {
                Some(n) if i + 1 < points.len() => (n[1] - p[1]).atan2(n[0] - p[0]),
                Some(n) => (p[1] - n[1]).atan2(p[0] - n[0]),
                None => 0.0,
            };
            pose3(Pose2 {
                x: p[0],
                y: p[1],
                theta,
            })
        })
        .collect();
    PosesInFrame {
        timestamp: Some(timestamp),
        frame_id: MAP_FRAME.to_string(),
        poses,
    }
}

/// The transform from the map to a robot's body.
pub fn body_transform(robot: &str, pose: Pose2, timestamp: Timestamp) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp),
        parent_frame_id: MAP_FRAME.to_string(),
        child_frame_id: base_link(robot),
        translation: Some(Vector3 {
            x: pose.x,
            y: pose.y,
            z: 0.0,
        }),
        rotation: Some(yaw_quaternion(pose.theta)),
    }
}

/// A map's tiles as one grid over the tiles' bounding box, rows along +y.
/// Each cell holds `red`, `green`, `blue`, `alpha` (a grey level: black
/// occupied, white free, mid grey unknown) and `occupancy` (int8: -1
/// unknown, else 0 free to 100 occupied, as ROS's occupancy grids).
/// A map with no tile (a new map, or one just cleared) is one tile of
/// unknown cells at the origin, so a cleared map replaces what was shown.
pub fn occupancy_grid(layer: &MapLayer, timestamp: Timestamp) -> Grid {
    let side = i64::from(layer.tile_size.cells());
    let (min_x, max_x, min_y, max_y) = layer
        .tiles
        .keys()
        .fold(None, |bounds, key| {
            let (x, y) = (i64::from(key.x), i64::from(key.y));
            Some(match bounds {
                None => (x, x, y, y),
                Some((a, b, c, d)) => (x.min(a), x.max(b), y.min(c), y.max(d)),
            })
        })
        .unwrap_or((0, 0, 0, 0));
    let width = (max_x - min_x + 1) * side;
    let height = (max_y - min_y + 1) * side;
    let max_side = i64::from(MAX_GRID_SIDE);
    let step = ((width.max(height) + max_side - 1) / max_side).max(1);
    let columns = (width + step - 1) / step;
    let rows = (height + step - 1) / step;
    // Both are at most MAX_GRID_SIDE, so the casts and products fit.
    let (columns, rows) = (columns as usize, rows as usize);
    let mut shades = vec![UNKNOWN_SHADE; columns * rows];
    let side_cells = side as usize;
    for (key, (_, tile)) in &layer.tiles {
        let left = (i64::from(key.x) - min_x) * side;
        let bottom = (i64::from(key.y) - min_y) * side;
        for (index, &shade) in tile.iter().enumerate() {
            let x = (left + (index % side_cells) as i64) / step;
            let y = (bottom + (index / side_cells) as i64) / step;
            let slot = &mut shades[y as usize * columns + x as usize];
            // The darkest wins: a wall stays visible when cells are merged,
            // and any observation beats unknown (the lightest shade).
            *slot = (*slot).min(shade);
        }
    }
    let mut data = Vec::with_capacity(shades.len() * GRID_CELL_BYTES as usize);
    for shade in shades {
        let (grey, occupancy) = if shade == UNKNOWN_SHADE {
            (UNKNOWN_GREY, -1i8)
        } else {
            let occupied = (f64::from(250u8.saturating_sub(shade)) * 100.0 / 250.0).round();
            (shade, occupied as i8)
        };
        data.extend_from_slice(&[grey, grey, grey, 255, occupancy.to_le_bytes()[0]]);
    }
    let resolution = layer.resolution_m * step as f64;
    let field = |name: &str, offset: u32, kind: NumericType| PackedElementField {
        name: name.to_string(),
        offset,
        r#type: kind as i32,
    };
    Grid {
        timestamp: Some(timestamp),
        frame_id: MAP_FRAME.to_string(),
        pose: Some(Pose {
            position: Some(Vector3 {
                x: (min_x * side) as f64 * layer.resolution_m,
                y: (min_y * side) as f64 * layer.resolution_m,
                z: 0.0,
            }),
            orientation: Some(yaw_quaternion(0.0)),
        }),
        column_count: columns as u32,
        cell_size: Some(Vector2 {
            x: resolution,
            y: resolution,
        }),
        row_stride: columns as u32 * GRID_CELL_BYTES,
        cell_stride: GRID_CELL_BYTES,
        fields: vec![
            field("red", 0, NumericType::Uint8),
            field("green", 1, NumericType::Uint8),
            field("blue", 2, NumericType::Uint8),
            field("alpha", 3, NumericType::Uint8),
            field("occupancy", 4, NumericType::Int8),
        ],
        data: Bytes::from(data),
    }
}

/// One scan per laser of a frame's beams, in the rig's order of sensors.
/// Each scan starts at its laser's origin in the map frame; readings that
/// were not ranges are NaN, readings that heard nothing are +infinity
/// (as ROS's REP 117 has it).
pub fn laser_scans(beams: &[WorldBeam], timestamp: Timestamp) -> Vec<LaserScan> {
    let mut scans = Vec::new();
    let mut rest = beams;
    while let Some(first) = rest.first() {
        let count = rest
            .iter()
            .take_while(|b| b.sensor == first.sensor && b.half_angle == 0.0)
            .count();
        if count == 0 {
            rest = &rest[1..];
            continue;
        }
        let (laser, after) = rest.split_at(count);
        rest = after;
        scans.push(laser_scan(laser, timestamp));
    }
    scans
}

/// One laser's rays as a scan. Rays a frame left out (readings that were
/// not ranges) show as gaps in the angles: the step is the smallest gap.
fn laser_scan(rays: &[WorldBeam], timestamp: Timestamp) -> LaserScan {
    let first = rays[0];
    // Angles from the first ray, counter-clockwise and unwrapped.
    let mut offsets = Vec::with_capacity(rays.len());
    let mut total = 0.0;
    offsets.push(0.0);
    for pair in rays.windows(2) {
        let gap = deog_grid::normalize_angle(pair[1].angle - pair[0].angle);
        total += if gap > 0.0 {
            gap
        } else {
            gap + std::f64::consts::TAU
        };
        offsets.push(total);
    }
    let step = offsets
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let slots: Vec<usize> = if step.is_finite() && step > 1e-9 {
        offsets
            .iter()
            .map(|o| (o / step).round() as usize)
            .collect()
    } else {
        (0..rays.len()).collect()
    };
    let len = slots.last().map_or(1, |&last| last + 1);
    let mut ranges = vec![f64::NAN; len];
    for (ray, &slot) in rays.iter().zip(&slots) {
        ranges[slot] = if ray.echo { ray.range } else { f64::INFINITY };
    }
    let span = if step.is_finite() {
        step * (len - 1) as f64
    } else {
        0.0
    };
    LaserScan {
        timestamp: Some(timestamp),
        frame_id: MAP_FRAME.to_string(),
        pose: Some(pose3(Pose2 {
            x: first.x,
            y: first.y,
            theta: 0.0,
        })),
        start_angle: first.angle,
        end_angle: first.angle + span,
        ranges,
        intensities: Vec::new(),
    }
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// A frame's sonar cones as triangles in the map frame, one entity per
/// robot: cones that heard an echo in one colour, cones that heard
/// nothing (drawn to their longest range) fainter. An empty entity when
/// the frame has no cones, so the last frame's cones go away.
pub fn sonar_cones(robot: &str, beams: &[WorldBeam], timestamp: Timestamp) -> SceneUpdate {
    let mut echoes = Vec::new();
    let mut silent = Vec::new();
    for beam in beams.iter().filter(|b| b.half_angle > 0.0) {
        let points = if beam.echo { &mut echoes } else { &mut silent };
        let apex = Point3 {
            x: beam.x,
            y: beam.y,
            z: 0.0,
        };
        let arc: Vec<Point3> = (0..=CONE_SEGMENTS)
            .map(|i| {
                let angle = beam.angle - beam.half_angle
                    + 2.0 * beam.half_angle * i as f64 / CONE_SEGMENTS as f64;
                Point3 {
                    x: beam.x + beam.range * angle.cos(),
                    y: beam.y + beam.range * angle.sin(),
                    z: 0.0,
                }
            })
            .collect();
        for pair in arc.windows(2) {
            points.extend([apex, pair[0], pair[1]]);
        }
    }
    let primitive = |points: Vec<Point3>, colour: Color| TriangleListPrimitive {
        pose: Some(pose3(Pose2::default())),
        points,
        color: Some(colour),
        ..Default::default()
    };
    let mut triangles = Vec::new();
    if !echoes.is_empty() {
        triangles.push(primitive(echoes, color(1.0, 0.6, 0.1, 0.35)));
    }
    if !silent.is_empty() {
        triangles.push(primitive(silent, color(0.5, 0.5, 0.6, 0.12)));
    }
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp),
            frame_id: MAP_FRAME.to_string(),
            id: format!("{robot}/sonar"),
            triangles,
            ..Default::default()
        }],
    }
}

/// The half axes, metres, and the heading, radians, of the ellipse
/// `ELLIPSE_SIGMAS` standard deviations out of a position covariance
/// (xx, xy, yy); `None` when the covariance is not finite.
pub fn ellipse_axes(xx: f64, xy: f64, yy: f64) -> Option<(f64, f64, f64)> {
    if !(xx.is_finite() && xy.is_finite() && yy.is_finite()) {
        return None;
    }
    let mean = (xx + yy) / 2.0;
    let spread = ((xx - yy) / 2.0).hypot(xy);
    let major = (mean + spread).max(0.0).sqrt() * ELLIPSE_SIGMAS;
    let minor = (mean - spread).max(0.0).sqrt() * ELLIPSE_SIGMAS;
    let heading = 0.5 * (2.0 * xy).atan2(xx - yy);
    Some((major, minor, heading))
}

/// A localizer's estimate as its position covariance's ellipse (flat, in
/// the map frame, green once converged, amber before), with the filter's
/// state as the entity's metadata.
pub fn covariance_ellipse(
    robot: &str,
    estimate: &EstimateView,
    timestamp: Timestamp,
) -> SceneUpdate {
    let c = &estimate.covariance;
    let spheres = ellipse_axes(c[0], (c[1] + c[3]) / 2.0, c[4])
        .map(|(major, minor, heading)| SpherePrimitive {
            pose: Some(pose3(Pose2 {
                x: estimate.pose.x,
                y: estimate.pose.y,
                theta: heading,
            })),
            // Never quite flat, so a point-like estimate still shows.
            size: Some(Vector3 {
                x: (2.0 * major).max(0.01),
                y: (2.0 * minor).max(0.01),
                z: 0.01,
            }),
            color: Some(if estimate.converged {
                color(0.2, 0.8, 0.3, 0.4)
            } else {
                color(1.0, 0.7, 0.0, 0.4)
            }),
        })
        .into_iter()
        .collect();
    let pair = |key: &str, value: String| KeyValuePair {
        key: key.to_string(),
        value,
    };
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp),
            frame_id: MAP_FRAME.to_string(),
            id: format!("{robot}/estimate"),
            metadata: vec![
                pair("map", estimate.map.clone()),
                pair("frame_sequence", estimate.sequence.to_string()),
                pair("converged", estimate.converged.to_string()),
                pair("lost_score", format!("{:.3}", estimate.lost_score)),
                pair("particles", estimate.particles.to_string()),
            ],
            spheres,
            ..Default::default()
        }],
    }
}

/// A sample of a localizer's particles as poses in the map frame.
pub fn particle_poses(sample: &ParticleSample, timestamp: Timestamp) -> PosesInFrame {
    PosesInFrame {
        timestamp: Some(timestamp),
        frame_id: MAP_FRAME.to_string(),
        poses: sample.poses.iter().map(|p| pose3(*p)).collect(),
    }
}

/// A robot's kidnaps, each one entity: a red line from where the robot was
/// to where it was put, a ball at the arrival, and the time as text.
pub fn kidnap_marks<'a>(
    robot: &str,
    kidnaps: impl IntoIterator<Item = &'a Kidnap>,
    timestamp: Timestamp,
) -> SceneUpdate {
    let red = color(0.85, 0.1, 0.15, 0.9);
    let point = |p: Pose2| Point3 {
        x: p.x,
        y: p.y,
        z: 0.05,
    };
    let entities = kidnaps
        .into_iter()
        .enumerate()
        .map(|(index, kidnap)| SceneEntity {
            timestamp: Some(timestamp),
            frame_id: MAP_FRAME.to_string(),
            id: format!("{robot}/kidnap/{index}"),
            metadata: vec![KeyValuePair {
                key: "time_s".to_string(),
                value: format!("{:.2}", kidnap.time_s),
            }],
            lines: vec![LinePrimitive {
                r#type: line_primitive::Type::LineList as i32,
                pose: Some(pose3(Pose2::default())),
                thickness: 3.0,
                scale_invariant: true,
                points: vec![point(kidnap.from), point(kidnap.to)],
                color: Some(red),
                ..Default::default()
            }],
            spheres: vec![SpherePrimitive {
                pose: Some(pose3(kidnap.to)),
                size: Some(Vector3 {
                    x: 0.2,
                    y: 0.2,
                    z: 0.2,
                }),
                color: Some(red),
            }],
            texts: vec![TextPrimitive {
                pose: Some(pose3(kidnap.to)),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: Some(red),
                text: format!("{robot} kidnapped at {:.1} s", kidnap.time_s),
            }],
            ..Default::default()
        })
        .collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use deog_grid::{TileKey, TileSize};

    use super::*;

    fn ray(sensor: usize, angle: f64, range: f64, echo: bool) -> WorldBeam {
        WorldBeam {
            x: 1.0,
            y: 2.0,
            angle,
            range,
            half_angle: 0.0,
            echo,
            sensor,
        }
    }

    #[test]
    fn a_grid_covers_the_tiles_bounding_box_rows_along_y() {
        let size = TileSize::new(8).unwrap();
        let mut tiles = HashMap::new();
        let mut wall = vec![UNKNOWN_SHADE; 64];
        wall[8 + 1] = 0; // row 1, column 1
        tiles.insert(TileKey::new(-1, 0), (1, wall));
        tiles.insert(TileKey::new(0, 1), (1, vec![250; 64]));
        let layer = MapLayer {
            resolution_m: 0.5,
            tile_size: size,
            tiles,
        };
        let grid = occupancy_grid(&layer, Timestamp::new(1, 0));
        assert_eq!(grid.column_count, 16);
        assert_eq!(grid.cell_stride, 5);
        assert_eq!(grid.row_stride, 80);
        assert_eq!(grid.data.len(), 16 * 16 * 5);
        assert_eq!(grid.cell_size.unwrap().x, 0.5);
        let origin = grid.pose.unwrap().position.unwrap();
        assert_eq!((origin.x, origin.y), (-4.0, 0.0));
        let cell = |x: usize, y: usize| &grid.data[(y * 16 + x) * 5..(y * 16 + x) * 5 + 5];
        assert_eq!(cell(1, 1), &[0, 0, 0, 255, 100]);
        assert_eq!(
            cell(0, 0),
            &[UNKNOWN_GREY, UNKNOWN_GREY, UNKNOWN_GREY, 255, 0xff]
        );
        assert_eq!(cell(8, 8), &[250, 250, 250, 255, 0]);
        assert_eq!(cell(8, 0)[4], 0xff, "no tile there: unknown");
        let empty = MapLayer {
            tiles: HashMap::new(),
            ..layer
        };
        let cleared = occupancy_grid(&empty, Timestamp::new(1, 0));
        assert_eq!(cleared.column_count, 8);
        assert!(
            cleared.data.chunks(5).all(|c| c[4] == 0xff),
            "a cleared map is all unknown"
        );
    }

    #[test]
    fn a_huge_map_is_sent_coarser_keeping_its_walls() {
        let size = TileSize::new(64).unwrap();
        let mut tiles = HashMap::new();
        let mut wall = vec![250; 64 * 64];
        wall[63 * 64 + 63] = 3;
        tiles.insert(TileKey::new(0, 0), (1, wall));
        tiles.insert(TileKey::new(99, 0), (1, vec![250; 64 * 64]));
        let layer = MapLayer {
            resolution_m: 0.1,
            tile_size: size,
            tiles,
        };
        let grid = occupancy_grid(&layer, Timestamp::new(1, 0));
        // 6400 cells wide: every 7 by 7 cells become one.
        assert_eq!(grid.column_count, 915);
        assert!(grid.column_count <= MAX_GRID_SIDE);
        assert!((grid.cell_size.unwrap().x - 0.7).abs() < 1e-12);
        let rows = grid.data.len() / grid.row_stride as usize;
        assert_eq!(rows, 10);
        let at = (9 * 915 + 9) * 5;
        assert_eq!(grid.data[at], 3, "the wall survives the merge");
    }

    #[test]
    fn a_laser_scan_keeps_its_step_over_left_out_rays_and_across_pi() {
        let step = 0.1;
        let start = std::f64::consts::PI - 0.25;
        let beams: Vec<WorldBeam> = (0..6)
            .filter(|&i| i != 3)
            .map(|i| {
                let angle = deog_grid::normalize_angle(start + step * f64::from(i));
                ray(2, angle, 1.0 + f64::from(i), i != 5)
            })
            .collect();
        let scans = laser_scans(&beams, Timestamp::new(1, 0));
        assert_eq!(scans.len(), 1);
        let scan = &scans[0];
        assert_eq!(scan.ranges.len(), 6);
        assert!(scan.ranges[3].is_nan());
        assert_eq!(scan.ranges[4], 5.0);
        assert_eq!(scan.ranges[5], f64::INFINITY);
        assert!((scan.start_angle - start).abs() < 1e-9);
        assert!((scan.end_angle - (start + 0.5)).abs() < 1e-9);
    }

    #[test]
    fn each_laser_is_its_own_scan_and_cones_are_not_scans() {
        let mut beams = vec![ray(0, 0.0, 1.0, true), ray(0, 0.1, 1.0, true)];
        beams.push(WorldBeam {
            half_angle: 0.2,
            sensor: 1,
            ..ray(1, 0.0, 2.0, true)
        });
        beams.extend([ray(2, 1.0, 1.0, true), ray(2, 1.2, 1.0, false)]);
        let scans = laser_scans(&beams, Timestamp::new(1, 0));
        assert_eq!(scans.len(), 2);
        assert_eq!(scans[1].ranges, vec![1.0, f64::INFINITY]);
        let cones = sonar_cones("r", &beams, Timestamp::new(1, 0));
        let entity = &cones.entities[0];
        assert_eq!(entity.id, "r/sonar");
        assert_eq!(entity.triangles.len(), 1);
        assert_eq!(entity.triangles[0].points.len(), 3 * CONE_SEGMENTS);
    }

    #[test]
    fn the_ellipse_follows_the_covariance() {
        let (major, minor, heading) = ellipse_axes(0.04, 0.0, 0.01).unwrap();
        assert!((major - 0.4).abs() < 1e-12 && (minor - 0.2).abs() < 1e-12);
        assert!(heading.abs() < 1e-12);
        let (major, minor, heading) = ellipse_axes(0.025, 0.015, 0.025).unwrap();
        assert!((major - 2.0 * 0.04f64.sqrt()).abs() < 1e-12);
        assert!((minor - 2.0 * 0.01f64.sqrt()).abs() < 1e-12);
        assert!((heading - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert!(ellipse_axes(f64::NAN, 0.0, 1.0).is_none());
    }

    #[test]
    fn particles_and_kidnaps_are_placed_in_the_map() {
        let sample = ParticleSample {
            map: "m".into(),
            sequence: 3,
            time_s: 0.3,
            poses: vec![Pose2::new(1.0, 2.0, 0.5), Pose2::new(-1.0, 0.0, 3.0)],
        };
        let poses = particle_poses(&sample, Timestamp::new(1, 0));
        assert_eq!(poses.frame_id, MAP_FRAME);
        assert_eq!(poses.poses.len(), 2);
        assert_eq!(poses.poses[1].position.as_ref().unwrap().x, -1.0);
        let kidnaps = [
            Kidnap {
                time_s: 10.0,
                from: Pose2::new(0.0, 0.0, 0.0),
                to: Pose2::new(3.0, 4.0, 1.0),
            },
            Kidnap {
                time_s: 20.0,
                from: Pose2::new(3.0, 4.0, 0.0),
                to: Pose2::new(-2.0, 1.0, 1.0),
            },
        ];
        let scene = kidnap_marks("r1", &kidnaps, Timestamp::new(1, 0));
        assert_eq!(scene.entities.len(), 2);
        let second = &scene.entities[1];
        assert_eq!(second.id, "r1/kidnap/1");
        let line = &second.lines[0].points;
        assert_eq!((line[0].x, line[1].x, line[1].y), (3.0, -2.0, 1.0));
        assert!(second.texts[0].text.contains("20.0 s"));
    }

    #[test]
    fn poses_turn_about_z() {
        let q = yaw_quaternion(std::f64::consts::FRAC_PI_2);
        assert!((q.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert!((q.w - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        let t = body_transform(
            "r1",
            Pose2 {
                x: 1.0,
                y: 2.0,
                theta: 0.0,
            },
            Timestamp::new(1, 0),
        );
        assert_eq!(t.child_frame_id, "r1/base_link");
        assert_eq!(t.parent_frame_id, "map");
        let path = path_in_map([[0.0, 0.0], [1.0, 1.0], [1.0, 2.0]], Timestamp::new(1, 0));
        assert_eq!(path.poses.len(), 3);
        let last = path.poses[2].orientation.unwrap();
        assert!(
            (last.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12,
            "faces +y"
        );
    }
}
