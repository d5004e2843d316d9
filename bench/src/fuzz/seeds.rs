//! The seed inputs of each target: valid inputs, small so execs stay fast.
//! Wire messages are encoded with prost from valid values, files are the
//! repo's own (a world, a ROS map, the head of a real CARMEN log) or made
//! by the matching writer.

use deog_grid::{Pose2, Tile, TileSize};
use deog_proto::v1 as pb;
use deog_simulator::data_file::{self, DataUnits};
use prost::Message;

/// A real map_server YAML file (the LSE arena of `mapfile/tests/data`).
pub const MAP_YAML: &str = include_str!("../../../mapfile/tests/data/lse_arena.yaml");
/// Its image: 80 x 60 binary PGM.
const MAP_PGM: &[u8] = include_bytes!("../../../mapfile/tests/data/lse_arena.pgm");
/// The thesis's two rooms.
const WORLDS: [&str; 2] = [
    include_str!("../../../worlds/map1.toml"),
    include_str!("../../../worlds/map2.toml"),
];
/// The first lines of the Intel lab log (`../shared/data/carmen`), with
/// two laser scans.
const CARMEN_HEAD: &[u8] = include_bytes!("seeds/intel_head.log");

fn pose(x: f64, y: f64, theta: f64) -> pb::Pose2 {
    pb::Pose2 { x, y, theta }
}

/// Tile size 8 dense cells, a 16-cell delta, a sparse delta: the selector
/// byte first, as `tile-cells` reads it.
pub fn tile_cells() -> Vec<Vec<u8>> {
    let size = TileSize::new(8).expect("8 is a tile size");
    let mut tile = vec![0];
    tile.extend(Tile::unknown(size).to_dense_bytes());
    let mut dense = vec![4];
    dense.extend((0..256i16).flat_map(|i| (i * 7 - 900).to_le_bytes()));
    let mut sparse = vec![2];
    for (index, delta) in [(0u16, 30i16), (9, -12), (63, 400)] {
        sparse.extend(index.to_le_bytes());
        sparse.extend(delta.to_le_bytes());
    }
    vec![tile, dense, sparse]
}

fn sparse_cells(pairs: &[(u16, i16)]) -> Vec<u8> {
    pairs
        .iter()
        .flat_map(|(i, d)| i.to_le_bytes().into_iter().chain(d.to_le_bytes()))
        .collect()
}

pub fn update_batch() -> Vec<Vec<u8>> {
    let sparse = pb::TileDelta {
        key: Some(pb::TileKey { x: -1, y: 2 }),
        encoding: pb::CellEncoding::SparseI16Le as i32,
        cells: sparse_cells(&[(0, 40), (65, -40), (4095, 7)]),
    };
    let dense = pb::TileDelta {
        key: Some(pb::TileKey { x: 0, y: 0 }),
        encoding: pb::CellEncoding::DenseI16Le as i32,
        cells: vec![0; TileSize::DEFAULT.area() * 2],
    };
    let batch = |tiles| pb::UpdateBatch {
        map: "lab".into(),
        client_id: "mapper-1".into(),
        sequence: 1,
        tiles,
    };
    vec![
        batch(vec![sparse.clone()]).encode_to_vec(),
        batch(vec![dense, sparse]).encode_to_vec(),
    ]
}

pub fn tile_query() -> Vec<Vec<u8>> {
    let region = pb::TileQuery {
        map: "lab".into(),
        selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
            min_x: -10,
            min_y: -10,
            max_x: 100,
            max_y: 50,
        })),
        newer_than_version: 3,
    };
    let keys = pb::TileQuery {
        map: "lab".into(),
        selection: Some(pb::tile_query::Selection::Keys(pb::TileKeys {
            keys: vec![pb::TileKey { x: 0, y: 0 }, pb::TileKey { x: -3, y: 7 }],
        })),
        newer_than_version: 0,
    };
    vec![region.encode_to_vec(), keys.encode_to_vec()]
}

pub fn watch_tiles() -> Vec<Vec<u8>> {
    let request = pb::WatchTilesRequest {
        map: "lab".into(),
        region: Some(pb::CellBox {
            min_x: 0,
            min_y: 0,
            max_x: 63,
            max_y: 63,
        }),
        include_cells: true,
    };
    vec![request.encode_to_vec()]
}

pub fn create_map() -> Vec<Vec<u8>> {
    let request = pb::CreateMapRequest {
        name: "lab".into(),
        resolution_m: 0.05,
        tile_size: 64,
        clamp_min_probability: 0.12,
        clamp_max_probability: 0.97,
    };
    vec![
        request.encode_to_vec(),
        pb::CreateMapRequest::default().encode_to_vec(),
    ]
}

fn sonar_frame(sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: "scout-1".into(),
        sequence,
        time_s: 0.5 * sequence as f64,
        odometry: Some(pose(1.0, 2.0, 0.3)),
        true_pose: Some(pose(1.1, 2.0, 0.31)),
        ranges: (0..deog_rig::scout().readings())
            .map(|i| 0.3 + 0.1 * i as f64)
            .collect(),
        rig: String::new(),
        reference_pose: None,
    }
}

pub fn publish_frames() -> Vec<Vec<u8>> {
    let one = pb::PublishFramesRequest {
        frames: vec![sonar_frame(1)],
    };
    let two = pb::PublishFramesRequest {
        frames: vec![sonar_frame(2), sonar_frame(3)],
    };
    vec![one.encode_to_vec(), two.encode_to_vec()]
}

pub fn read_frames() -> Vec<Vec<u8>> {
    let request = pb::ReadFramesRequest {
        robot: "scout-1".into(),
        from_sequence: 5,
        to_sequence: 90,
        limit: 10,
    };
    vec![request.encode_to_vec()]
}

pub fn subscribe_frames() -> Vec<Vec<u8>> {
    let request = pb::SubscribeFramesRequest {
        robot: "scout-1".into(),
        from_sequence: 1,
    };
    vec![request.encode_to_vec()]
}

pub fn pose_estimate() -> Vec<Vec<u8>> {
    let estimate = pb::PoseEstimate {
        robot: "scout-1".into(),
        map: "lab".into(),
        frame_sequence: 12,
        time_s: 6.0,
        pose: Some(pose(3.0, -1.0, 1.5)),
        covariance: vec![0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.002],
        particle_count: 500,
        ..Default::default()
    };
    vec![estimate.encode_to_vec()]
}

fn built_in_rigs() -> impl Iterator<Item = deog_rig::Rig> {
    deog_rig::BUILT_IN_RIGS
        .iter()
        .filter_map(|(name, _)| deog_rig::built_in_rig(name))
}

pub fn rig() -> Vec<Vec<u8>> {
    built_in_rigs()
        .map(|r| deog_proto::rig::rig_to_wire(&r).encode_to_vec())
        .collect()
}

pub fn rig_toml() -> Vec<Vec<u8>> {
    built_in_rigs()
        .map(|r| deog_rig::rig_to_toml(&r).into_bytes())
        .collect()
}

pub fn sim_spawn() -> Vec<Vec<u8>> {
    let placed = pb::SpawnRequest {
        name: "scout-1".into(),
        pose: Some(pose(2.0, 2.0, 0.0)),
    };
    let anywhere = pb::SpawnRequest {
        name: "scout-2".into(),
        pose: None,
    };
    vec![placed.encode_to_vec(), anywhere.encode_to_vec()]
}

pub fn sim_drive() -> Vec<Vec<u8>> {
    let request = pb::DriveRequest {
        name: "scout-1".into(),
        command: Some(pb::Twist2 {
            linear: 0.5,
            angular: -0.2,
        }),
    };
    vec![request.encode_to_vec()]
}

pub fn sim_teleport() -> Vec<Vec<u8>> {
    let request = pb::TeleportRequest {
        name: "scout-1".into(),
        pose: Some(pose(4.0, 1.0, 3.1)),
    };
    vec![request.encode_to_vec()]
}

pub fn map_yaml() -> Vec<Vec<u8>> {
    let negated = "image: a.png\nresolution: 0.1\norigin: [-1.5, 2.0, 0.0]\n\
                   negate: 1\noccupied_thresh: 0.7\nfree_thresh: 0.2\nmode: trinary\n";
    vec![MAP_YAML.as_bytes().to_vec(), negated.as_bytes().to_vec()]
}

pub fn map_pgm() -> Vec<Vec<u8>> {
    let small = deog_mapfile::encode_pgm(3, 2, &[0, 128, 255, 255, 128, 0], "fuzz seed");
    let ascii = b"P2\n# ascii\n3 2\n255\n0 128 255\n255 128 0\n".to_vec();
    vec![MAP_PGM.to_vec(), small, ascii]
}

pub fn thesis_data() -> Vec<Vec<u8>> {
    let ranges = [0.5, 1.25, 2.0, 3.5, 0.75, 1.0, 1.5, 2.5];
    let poses = [Pose2::new(1.0, 2.0, 0.0), Pose2::new(1.2, 2.1, 0.4)];
    [DataUnits::Si, DataUnits::Nomad]
        .into_iter()
        .map(|units| {
            let mut text = String::from("# x y theta ranges\n");
            for p in &poses {
                text.push_str(&data_file::format_line(p, &ranges, units));
            }
            text.into_bytes()
        })
        .collect()
}

pub fn world_toml() -> Vec<Vec<u8>> {
    WORLDS.iter().map(|w| w.as_bytes().to_vec()).collect()
}

pub fn carmen_log() -> Vec<Vec<u8>> {
    vec![CARMEN_HEAD.to_vec()]
}

/// Recordings as `deog record` writes them: a laser's and the Scout's
/// sonars', three frames each.
pub fn ros2_mcap() -> Vec<Vec<u8>> {
    ["laser180", "scout"]
        .iter()
        .map(|name| {
            let rig = deog_rig::built_in_rig(name).expect("a built-in rig");
            let frames: Vec<deog_recording::Frame> = (0..3u32)
                .map(|i| deog_recording::Frame {
                    sequence: u64::from(i) + 1,
                    time_s: 1.0 + f64::from(i) * 0.1,
                    odometry: Pose2::new(0.1 * f64::from(i), 0.0, 0.0),
                    true_pose: Some(Pose2::new(0.1 * f64::from(i), 0.0, 0.0)),
                    reference_pose: None,
                    ranges: vec![1.5; rig.readings()],
                })
                .collect();
            let mut out = std::io::Cursor::new(Vec::new());
            let recording = deog_recording::Recording {
                rig: &rig,
                frames: &frames,
                estimates: &[],
                map: None,
            };
            deog_recording::write_recording(&mut out, &recording).expect("a recording");
            out.into_inner()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seeds that the decoder refuses start the fuzzer in the wrong place.
    #[test]
    fn file_seeds_are_valid_inputs() {
        for s in map_yaml() {
            deog_mapfile::MapYaml::parse(std::str::from_utf8(&s).unwrap(), "seed").unwrap();
        }
        for s in map_pgm() {
            deog_mapfile::decode_pgm(&s, "seed").unwrap();
        }
        for (s, units) in thesis_data().iter().zip([DataUnits::Si, DataUnits::Nomad]) {
            let lines = data_file::parse(std::str::from_utf8(s).unwrap(), "seed", units).unwrap();
            assert_eq!(lines.len(), 2);
        }
        for s in world_toml() {
            deog_world::parse_world(std::str::from_utf8(&s).unwrap(), "seed").unwrap();
        }
        for s in rig_toml() {
            deog_rig::parse_rig(std::str::from_utf8(&s).unwrap(), "seed").unwrap();
        }
        deog_logs::CarmenLog::parse(CARMEN_HEAD, "seed").unwrap();
        for s in ros2_mcap() {
            let options = deog_recording::ImportOptions {
                first_sequence: 1,
                ..deog_recording::ImportOptions::default()
            };
            assert_eq!(
                deog_recording::read_recording(&s, &options)
                    .unwrap()
                    .frames
                    .len(),
                3
            );
        }
    }

    #[test]
    fn wire_seeds_pass_the_servers_checks() {
        let limits = deog_server::Limits::default();
        for s in update_batch() {
            let batch = pb::UpdateBatch::decode(s.as_slice()).unwrap();
            for t in &batch.tiles {
                deog_server::convert::tile_delta("tiles", t, TileSize::DEFAULT, &limits).unwrap();
            }
        }
        for s in publish_frames() {
            let request = pb::PublishFramesRequest::decode(s.as_slice()).unwrap();
            for f in &request.frames {
                deog_server::convert::sonar_frame("frames", f, &limits).unwrap();
            }
        }
        for s in pose_estimate() {
            let e = pb::PoseEstimate::decode(s.as_slice()).unwrap();
            deog_server::convert::pose_estimate(&e).unwrap();
        }
        for s in rig() {
            deog_proto::rig::rig_from_wire(&pb::Rig::decode(s.as_slice()).unwrap()).unwrap();
        }
    }
}
