//! What goes to the page over its WebSocket: JSON text messages for maps
//! and robots, and a binary message per tile (its shades, never the whole
//! map again).
//!
//! A tile message is `1u8`, the tile's x and y as little-endian i32, its
//! side as little-endian u16, then side² shades, row-major from the tile's
//! lowest cell (see [`crate::state::shade`]).

use deog_grid::{Pose2, TileKey};
use serde_json::{Value, json};

use crate::state::{EstimateView, MapLayer, RobotTrack};

/// The first byte of a tile message.
pub const TILE_MESSAGE: u8 = 1;

/// A tile's binary message.
pub fn tile_message(key: TileKey, side: u32, shades: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(11 + shades.len());
    out.push(TILE_MESSAGE);
    out.extend_from_slice(&key.x.to_le_bytes());
    out.extend_from_slice(&key.y.to_le_bytes());
    out.extend_from_slice(&u16::try_from(side).unwrap_or(u16::MAX).to_le_bytes());
    out.extend_from_slice(shades);
    out
}

/// A map the server holds, as the page's list shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct MapEntry {
    /// Its name.
    pub name: String,
    /// Cells ever observed.
    pub cells: u64,
    /// Stored tiles.
    pub tiles: u64,
    /// Its version.
    pub version: u64,
}

/// The first message: the maps there are and the one this page shows.
pub fn hello(maps: &[MapEntry], shown: Option<&str>, world: Option<&str>) -> Value {
    json!({
        "type": "hello",
        "map": shown,
        "world": world,
        "maps": maps.iter().map(|m| json!({
            "name": m.name, "cells": m.cells, "tiles": m.tiles, "version": m.version,
        })).collect::<Vec<_>>(),
    })
}

/// The list of maps, again, when it changed.
pub fn maps(maps: &[MapEntry]) -> Value {
    json!({
        "type": "maps",
        "maps": maps.iter().map(|m| json!({
            "name": m.name, "cells": m.cells, "tiles": m.tiles, "version": m.version,
        })).collect::<Vec<_>>(),
    })
}

/// The shown map's geometry; its tiles follow.
pub fn map_geometry(name: &str, layer: &MapLayer) -> Value {
    json!({
        "type": "map",
        "name": name,
        "resolution_m": layer.resolution_m,
        "tile_size": layer.tile_size.cells(),
    })
}

/// The shown map was cleared.
pub fn cleared(name: &str) -> Value {
    json!({ "type": "cleared", "name": name })
}

/// Robots' current state; with `history`, their paths and kidnaps too (the
/// page keeps extending the paths from the updates that follow).
pub fn robots<'a>(robots: impl Iterator<Item = (&'a str, &'a RobotTrack)>, history: bool) -> Value {
    json!({
        "type": "robots",
        "history": history,
        "robots": robots.map(|(name, track)| robot(name, track, history)).collect::<Vec<_>>(),
    })
}

/// A kidnap just seen.
pub fn kidnap(name: &str, track: &RobotTrack) -> Option<Value> {
    let kidnap = track.kidnaps.back()?;
    Some(json!({
        "type": "kidnap",
        "robot": name,
        "time_s": round(kidnap.time_s),
        "from": [round(kidnap.from.x), round(kidnap.from.y)],
        "to": [round(kidnap.to.x), round(kidnap.to.y)],
    }))
}

/// The newest sample of a robot's particles: (x, y, theta) each, to the
/// millimetre and the milliradian.
pub fn particles(name: &str, track: &RobotTrack) -> Option<Value> {
    let sample = track.particles.as_ref()?;
    let milli = |v: f64| {
        if v.is_finite() {
            (v * 1e3).round() / 1e3
        } else {
            0.0
        }
    };
    Some(json!({
        "type": "particles",
        "robot": name,
        "map": sample.map,
        "sequence": sample.sequence,
        "time_s": round(sample.time_s),
        "poses": sample.poses.iter().map(|p| [milli(p.x), milli(p.y), milli(p.theta)]).collect::<Vec<_>>(),
    }))
}

fn robot(name: &str, track: &RobotTrack, history: bool) -> Value {
    let mut value = json!({
        "name": name,
        "sequence": track.sequence,
        "time_s": round(track.time_s),
        "true_pose": track.true_pose.map(pose),
        "odometry": track.odometry.map(pose),
        "radius": track.body_radius_m,
        "beams": track.beams.iter().map(|b| json!([
            round(b.x), round(b.y), round(b.angle), round(b.range), round(b.half_angle), u8::from(b.echo),
        ])).collect::<Vec<_>>(),
        "estimate": track.estimate.as_ref().map(estimate),
        "goal": track.goal.as_ref().map(|(map, x, y)| json!({
            "map": map, "x": round(*x), "y": round(*y),
        })),
        "error": track.error.map(|e| json!({
            "m": round(e.distance_m), "deg": round(e.heading_deg),
        })),
    });
    if history && let Value::Object(fields) = &mut value {
        fields.insert(
            "true_path".into(),
            track
                .true_path
                .iter()
                .map(|p| json!([round(p[0]), round(p[1])]))
                .collect(),
        );
        fields.insert(
            "estimate_path".into(),
            track
                .estimate_path
                .iter()
                .map(|p| json!([round(p.x), round(p.y), u8::from(p.converged)]))
                .collect(),
        );
        fields.insert(
            "kidnaps".into(),
            track
                .kidnaps
                .iter()
                .map(|k| {
                    json!({
                        "time_s": round(k.time_s),
                        "from": [round(k.from.x), round(k.from.y)],
                        "to": [round(k.to.x), round(k.to.y)],
                    })
                })
                .collect(),
        );
    }
    value
}

fn estimate(estimate: &EstimateView) -> Value {
    json!({
        "map": estimate.map,
        "sequence": estimate.sequence,
        "time_s": round(estimate.time_s),
        "pose": pose(estimate.pose),
        "covariance": estimate.covariance.iter().map(|&c| (c * 1e8).round() / 1e8).collect::<Vec<_>>(),
        "converged": estimate.converged,
        "lost_score": round(estimate.lost_score),
        "particles": estimate.particles,
    })
}

fn pose(pose: Pose2) -> Value {
    json!([round(pose.x), round(pose.y), round(pose.theta)])
}

/// Four decimals: a tenth of a millimetre, and shorter messages.
fn round(value: f64) -> f64 {
    if value.is_finite() {
        (value * 1e4).round() / 1e4
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{FrameView, TrackLimits, ViewState};

    #[test]
    fn a_tile_message_carries_its_key_side_and_shades() {
        let shades: Vec<u8> = (0..64).collect();
        let message = tile_message(TileKey::new(-3, 7), 8, &shades);
        assert_eq!(message[0], TILE_MESSAGE);
        assert_eq!(i32::from_le_bytes(message[1..5].try_into().unwrap()), -3);
        assert_eq!(i32::from_le_bytes(message[5..9].try_into().unwrap()), 7);
        assert_eq!(u16::from_le_bytes(message[9..11].try_into().unwrap()), 8);
        assert_eq!(&message[11..], &shades[..]);
    }

    #[test]
    fn robots_carry_their_history_only_when_asked() {
        let mut state = ViewState::new(TrackLimits::default());
        let rig = deog_rig::scout();
        let ranges = vec![2.0; 16];
        let truth = Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.5,
        };
        state.on_frame(
            "r",
            &FrameView {
                sequence: 1,
                time_s: 0.1,
                odometry: truth,
                true_pose: Some(truth),
                ranges: &ranges,
                rig: Some(&rig),
            },
        );
        let live = robots(state.robots().iter().map(|(n, t)| (n.as_str(), t)), false);
        let entry = &live["robots"][0];
        assert_eq!(entry["name"], "r");
        assert_eq!(entry["true_pose"], json!([1.0, 2.0, 0.5]));
        assert_eq!(entry["beams"].as_array().unwrap().len(), 16);
        assert!(entry.get("true_path").is_none());
        let full = robots(state.robots().iter().map(|(n, t)| (n.as_str(), t)), true);
        assert_eq!(full["robots"][0]["true_path"], json!([[1.0, 2.0]]));
    }
}
