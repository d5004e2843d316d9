//! The generated API encodes compactly and carries its descriptors.

use deog_proto::FILE_DESCRIPTOR_SET;
use deog_proto::v1::{CellEncoding, TileDelta, TileKey, UpdateBatch};
use prost::Message;

#[test]
fn a_dense_tile_costs_two_bytes_a_cell() {
    let batch = UpdateBatch {
        map: "m".into(),
        client_id: "c".into(),
        sequence: 1,
        tiles: vec![TileDelta {
            key: Some(TileKey { x: -1, y: 2 }),
            encoding: CellEncoding::DenseI16Le.into(),
            cells: vec![0; 64 * 64 * 2],
        }],
    };
    let bytes = batch.encode_to_vec();
    assert!(bytes.len() < 64 * 64 * 2 + 32, "{} bytes", bytes.len());
    assert_eq!(UpdateBatch::decode(bytes.as_slice()).unwrap(), batch);
}

#[test]
fn descriptor_set_names_both_services() {
    let text = String::from_utf8_lossy(FILE_DESCRIPTOR_SET);
    for name in [
        "MapService",
        "RobotService",
        "ApplyUpdates",
        "WatchTiles",
        "Teleport",
    ] {
        assert!(
            text.contains(name),
            "{name} missing from the descriptor set"
        );
    }
}
