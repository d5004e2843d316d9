//! The decoders of outside input, each fed bytes as the server or command
//! that owns it would be: the same entry point, then the same pure checks.
//! An `Err` is the decoder doing its job; only a panic is a finding.

use deog_grid::{Tile, TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;
use deog_server::{Limits, convert};
use deog_simulator::data_file::{self, DataUnits};
use prost::Message;

use super::engine::Target;
use super::seeds;

/// Every target, in the order they run.
pub const TARGETS: &[Target] = &[
    Target {
        name: "tile-cells",
        decode: tile_cells,
        seeds: seeds::tile_cells,
    },
    Target {
        name: "wire-update-batch",
        decode: wire_update_batch,
        seeds: seeds::update_batch,
    },
    Target {
        name: "wire-tile-query",
        decode: wire_tile_query,
        seeds: seeds::tile_query,
    },
    Target {
        name: "wire-watch-tiles",
        decode: wire_watch_tiles,
        seeds: seeds::watch_tiles,
    },
    Target {
        name: "wire-create-map",
        decode: wire_create_map,
        seeds: seeds::create_map,
    },
    Target {
        name: "wire-publish-frames",
        decode: wire_publish_frames,
        seeds: seeds::publish_frames,
    },
    Target {
        name: "wire-read-frames",
        decode: wire_read_frames,
        seeds: seeds::read_frames,
    },
    Target {
        name: "wire-subscribe-frames",
        decode: wire_subscribe_frames,
        seeds: seeds::subscribe_frames,
    },
    Target {
        name: "wire-pose-estimate",
        decode: wire_pose_estimate,
        seeds: seeds::pose_estimate,
    },
    Target {
        name: "wire-rig",
        decode: wire_rig,
        seeds: seeds::rig,
    },
    Target {
        name: "wire-sim-spawn",
        decode: wire_sim_spawn,
        seeds: seeds::sim_spawn,
    },
    Target {
        name: "wire-sim-drive",
        decode: wire_sim_drive,
        seeds: seeds::sim_drive,
    },
    Target {
        name: "wire-sim-teleport",
        decode: wire_sim_teleport,
        seeds: seeds::sim_teleport,
    },
    Target {
        name: "rig-toml",
        decode: rig_toml,
        seeds: seeds::rig_toml,
    },
    Target {
        name: "map-yaml",
        decode: map_yaml,
        seeds: seeds::map_yaml,
    },
    Target {
        name: "map-pgm",
        decode: map_pgm,
        seeds: seeds::map_pgm,
    },
    Target {
        name: "thesis-data",
        decode: thesis_data,
        seeds: seeds::thesis_data,
    },
    Target {
        name: "world-toml",
        decode: world_toml,
        seeds: seeds::world_toml,
    },
    Target {
        name: "carmen-log",
        decode: carmen_log,
        seeds: seeds::carmen_log,
    },
    Target {
        name: "ros2-mcap",
        decode: ros2_mcap,
        seeds: seeds::ros2_mcap,
    },
];

/// The target named `name`.
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// The simulator's default request limit (`deog sim --max-message-bytes`).
const SIM_MAX_MESSAGE_BYTES: usize = 64 << 10;

/// Text decoders read files with `read_to_string`, which refuses bytes
/// that are not UTF-8; the lossy form keeps the fuzzer's bytes useful.
fn text(bytes: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(bytes)
}

/// The first byte picks the decoder and the tile size (8 to 64 cells a
/// side, so a dense tile stays small); the rest are the cells, as
/// `GetTiles` returns them (a tile) or `ApplyUpdates` takes them (deltas).
fn tile_cells(bytes: &[u8]) {
    let Some((&selector, cells)) = bytes.split_first() else {
        return;
    };
    let Ok(size) = TileSize::new(8 << (u32::from(selector >> 2) % 4)) else {
        return;
    };
    let key = TileKey::new(0, 0);
    match selector % 3 {
        0 => drop(Tile::from_dense_bytes(size, cells)),
        1 => drop(TileDelta::from_dense_bytes(key, size, cells)),
        _ => drop(TileDelta::from_sparse_bytes(key, size, cells)),
    }
}

/// `ApplyUpdates`: the map server's checks of a batch before it reaches the
/// writer, for a map of the default tile size.
fn wire_update_batch(bytes: &[u8]) {
    let Ok(batch) = pb::UpdateBatch::decode(bytes) else {
        return;
    };
    let limits = Limits::default();
    let checked = (|| {
        limits.check_size("UpdateBatch", &batch)?;
        convert::map_name("map", &batch.map)?;
        convert::client_id("client_id", &batch.client_id)?;
        if batch.tiles.len() > limits.max_tiles_per_batch {
            return Ok(());
        }
        for (i, t) in batch.tiles.iter().enumerate() {
            convert::tile_delta(&format!("tiles[{i}]"), t, TileSize::DEFAULT, &limits)?;
        }
        Ok::<_, deog_server::StoreError>(())
    })();
    drop(checked);
}

fn wire_tile_query(bytes: &[u8]) {
    let Ok(query) = pb::TileQuery::decode(bytes) else {
        return;
    };
    let limits = Limits::default();
    drop(convert::map_name("map", &query.map));
    match &query.selection {
        Some(pb::tile_query::Selection::Region(region)) => {
            drop(convert::cell_box("region", Some(region)));
        }
        Some(pb::tile_query::Selection::Keys(keys)) => {
            for (i, k) in keys.keys.iter().enumerate() {
                let field = format!("keys.keys[{i}]");
                drop(convert::tile_key(
                    &field,
                    Some(k),
                    TileSize::DEFAULT,
                    &limits,
                ));
            }
        }
        None => {}
    }
}

fn wire_watch_tiles(bytes: &[u8]) {
    let Ok(request) = pb::WatchTilesRequest::decode(bytes) else {
        return;
    };
    drop(convert::map_name("map", &request.map));
    drop(convert::cell_box("region", request.region.as_ref()));
}

fn wire_create_map(bytes: &[u8]) {
    let Ok(request) = pb::CreateMapRequest::decode(bytes) else {
        return;
    };
    drop(convert::map_name("name", &request.name));
    drop(convert::map_settings(&request));
}

/// `PublishFrames`: each frame checked, then its rig (a built-in one here;
/// the server's registry holds these and the stored ones).
fn wire_publish_frames(bytes: &[u8]) {
    let Ok(request) = pb::PublishFramesRequest::decode(bytes) else {
        return;
    };
    let limits = Limits::default();
    if limits.check_size("PublishFramesRequest", &request).is_err()
        || request.frames.len() > limits.max_frames_per_request
    {
        return;
    }
    for (i, frame) in request.frames.iter().enumerate() {
        if convert::sonar_frame(&format!("frames[{i}]"), frame, &limits).is_err() {
            return;
        }
        let name = deog_proto::rig::frame_rig_name(&frame.rig);
        if let Some(rig) = deog_rig::built_in_rig(name) {
            let _matches = rig.readings() == frame.ranges.len();
        }
    }
}

fn wire_read_frames(bytes: &[u8]) {
    let Ok(request) = pb::ReadFramesRequest::decode(bytes) else {
        return;
    };
    drop(convert::robot_name("robot", &request.robot));
    drop(convert::sequence_range(
        request.from_sequence,
        request.to_sequence,
    ));
}

fn wire_subscribe_frames(bytes: &[u8]) {
    let Ok(request) = pb::SubscribeFramesRequest::decode(bytes) else {
        return;
    };
    drop(convert::robot_name("robot", &request.robot));
}

fn wire_pose_estimate(bytes: &[u8]) {
    let Ok(estimate) = pb::PoseEstimate::decode(bytes) else {
        return;
    };
    drop(convert::pose_estimate(&estimate));
}

/// `PutRig`: the wire rig checked as a rig file's figures are.
fn wire_rig(bytes: &[u8]) {
    let Ok(wire) = pb::Rig::decode(bytes) else {
        return;
    };
    if let Ok(rig) = deog_proto::rig::rig_from_wire(&wire) {
        // What the server stores and returns must encode again.
        let _ = deog_proto::rig::rig_to_wire(&rig).encode_to_vec();
    }
}

fn wire_sim_spawn(bytes: &[u8]) {
    use deog_simulator::convert as sim;
    let Ok(request) = pb::SpawnRequest::decode(bytes) else {
        return;
    };
    drop(sim::check_size(
        "SpawnRequest",
        &request,
        SIM_MAX_MESSAGE_BYTES,
    ));
    drop(sim::robot_name("name", &request.name));
    if let Some(p) = &request.pose {
        drop(sim::pose("pose", Some(p)));
    }
}

fn wire_sim_drive(bytes: &[u8]) {
    use deog_simulator::convert as sim;
    let Ok(request) = pb::DriveRequest::decode(bytes) else {
        return;
    };
    drop(sim::check_size(
        "DriveRequest",
        &request,
        SIM_MAX_MESSAGE_BYTES,
    ));
    drop(sim::robot_name("name", &request.name));
    drop(sim::twist("command", request.command.as_ref()));
}

fn wire_sim_teleport(bytes: &[u8]) {
    use deog_simulator::convert as sim;
    let Ok(request) = pb::TeleportRequest::decode(bytes) else {
        return;
    };
    drop(sim::check_size(
        "TeleportRequest",
        &request,
        SIM_MAX_MESSAGE_BYTES,
    ));
    drop(sim::robot_name("name", &request.name));
    drop(sim::pose("pose", request.pose.as_ref()));
}

/// A rig file (`--rig FILE`).
fn rig_toml(bytes: &[u8]) {
    drop(deog_rig::parse_rig(&text(bytes), "fuzz.toml"));
}

fn map_yaml(bytes: &[u8]) {
    drop(deog_mapfile::MapYaml::parse(&text(bytes), "fuzz.yaml"));
}

/// A map's image, decoded and put beside fixed YAML metadata as
/// `MapImage::load` does.
fn map_pgm(bytes: &[u8]) {
    if let Ok(pgm) = deog_mapfile::decode_pgm(bytes, "fuzz.pgm")
        && let Ok(yaml) = deog_mapfile::MapYaml::parse(seeds::MAP_YAML, "fuzz.yaml")
    {
        let map = deog_mapfile::MapImage::from_parts(&yaml, pgm);
        let _corner = map.pixel(0, 0);
    }
}

/// The thesis data file, in both units `deog` reads it in.
fn thesis_data(bytes: &[u8]) {
    let text = text(bytes);
    drop(data_file::parse(&text, "fuzz.dat", DataUnits::Si));
    drop(data_file::parse(&text, "fuzz.dat", DataUnits::Nomad));
}

fn world_toml(bytes: &[u8]) {
    drop(deog_world::parse_world(&text(bytes), "fuzz.toml"));
}

/// A CARMEN log's text, as `CarmenLog::load` reads it after any gzip.
fn carmen_log(bytes: &[u8]) {
    drop(deog_logs::CarmenLog::parse(bytes, "fuzz.log"));
}

/// A ROS 2 recording, as `deog import --mcap` reads it.
fn ros2_mcap(bytes: &[u8]) {
    let options = deog_recording::ImportOptions {
        first_sequence: 1,
        ..deog_recording::ImportOptions::default()
    };
    drop(deog_recording::read_recording(bytes, &options));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_names_are_unique() {
        let mut names: Vec<_> = TARGETS.iter().map(|t| t.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), TARGETS.len());
    }

    #[test]
    fn every_target_has_seeds_and_runs_them() {
        for t in TARGETS {
            let seeds = (t.seeds)();
            assert!(!seeds.is_empty(), "{} has no seeds", t.name);
            for s in &seeds {
                (t.decode)(s);
            }
        }
    }
}
