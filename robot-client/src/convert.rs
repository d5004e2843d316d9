//! Wire messages (`deog_proto::v1`) to the grid core's types and back, for
//! every client process: the one place a client turns a `pb::Pose2` into a
//! [`Pose2`], a tile key or box of cells into the grid's, or a tile's bytes
//! into cells. The orphan rule forbids `From` between the two crates' types,
//! so these are plain functions named for their direction.
//!
//! ```
//! use deog_grid::Pose2;
//! use deog_robot_client::convert::{pose_from_wire, pose_to_wire};
//!
//! let pose = Pose2::new(1.0, -2.0, 0.5);
//! assert_eq!(pose_from_wire(pose_to_wire(pose)), pose);
//! ```

use crate::error::ClientError;
use deog_grid::{CellBox, CellIndex, Pose2, Tile, TileDelta, TileKey, TileSize};
use deog_proto::v1 as pb;

/// A wire pose as the grid's. Every value converts: the map server and
/// the simulator check poses finite before they store or send them.
pub fn pose_from_wire(pose: pb::Pose2) -> Pose2 {
    Pose2::new(pose.x, pose.y, pose.theta)
}

/// A pose the message may leave out, read as the origin when it does:
/// what proto3 reads an unset message's fields as.
pub fn pose_or_origin(pose: Option<pb::Pose2>) -> Pose2 {
    pose.map(pose_from_wire).unwrap_or_default()
}

/// A pose on the wire.
pub fn pose_to_wire(pose: Pose2) -> pb::Pose2 {
    pb::Pose2 {
        x: pose.x,
        y: pose.y,
        theta: pose.theta,
    }
}

/// A pose the message must hold; `field` names it in the error when absent.
pub fn required_pose(field: &str, pose: Option<pb::Pose2>) -> Result<Pose2, ClientError> {
    pose.map(pose_from_wire)
        .ok_or_else(|| ClientError::wire(field, "is required"))
}

/// A wire tile key as the grid's.
pub fn tile_key_from_wire(key: pb::TileKey) -> TileKey {
    TileKey::new(key.x, key.y)
}

/// A tile key on the wire.
pub fn tile_key_to_wire(key: TileKey) -> pb::TileKey {
    pb::TileKey { x: key.x, y: key.y }
}

/// A wire box of cells as the grid's; `field` names it in the error when
/// its maximum lies below its minimum.
pub fn cell_box_from_wire(field: &str, cells: pb::CellBox) -> Result<CellBox, ClientError> {
    CellBox::new(
        CellIndex::new(cells.min_x, cells.min_y),
        CellIndex::new(cells.max_x, cells.max_y),
    )
    .ok_or_else(|| {
        ClientError::wire(
            field,
            format!(
                "max ({}, {}) lies below min ({}, {})",
                cells.max_x, cells.max_y, cells.min_x, cells.min_y
            ),
        )
    })
}

/// A box of cells on the wire.
pub fn cell_box_to_wire(cells: CellBox) -> pb::CellBox {
    pb::CellBox {
        min_x: cells.min.x,
        min_y: cells.min.y,
        max_x: cells.max.x,
        max_y: cells.max.y,
    }
}

/// A whole tile as the server sends it (dense cells): its key, version and
/// cells.
pub fn decode_tile(tile: &pb::Tile, size: TileSize) -> Result<(TileKey, u64, Tile), ClientError> {
    let key = tile
        .key
        .map(tile_key_from_wire)
        .ok_or_else(|| ClientError::Config("the server sent a tile without a key".into()))?;
    if tile.encoding != pb::CellEncoding::DenseI16Le as i32 {
        return Err(ClientError::Config(format!(
            "the server sent tile ({}, {}) in encoding {}, expected dense",
            key.x, key.y, tile.encoding
        )));
    }
    Ok((
        key,
        tile.version,
        Tile::from_dense_bytes(size, &tile.cells)?,
    ))
}

/// A tile's deltas on the wire: the sparse form when it is smaller, else
/// the dense one.
pub fn encode_delta(delta: &TileDelta) -> pb::TileDelta {
    let key = Some(tile_key_to_wire(delta.key));
    let sparse = (delta.nonzero_count() * 4 < delta.raw().len() * 2)
        .then(|| delta.to_sparse_bytes())
        .flatten();
    match sparse {
        Some(cells) => pb::TileDelta {
            key,
            encoding: pb::CellEncoding::SparseI16Le as i32,
            cells,
        },
        None => pb::TileDelta {
            key,
            encoding: pb::CellEncoding::DenseI16Le as i32,
            cells: delta.to_dense_bytes(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_grid::LogOdds;

    fn size() -> TileSize {
        TileSize::new(8).unwrap()
    }

    #[test]
    fn poses_cross_the_wire_unchanged() {
        let pose = Pose2::new(-3.25, 7.5, -2.0);
        let wire = pose_to_wire(pose);
        assert_eq!((wire.x, wire.y, wire.theta), (-3.25, 7.5, -2.0));
        assert_eq!(pose_from_wire(wire), pose);
    }

    #[test]
    fn an_absent_pose_reads_as_the_origin() {
        assert_eq!(pose_or_origin(None), Pose2::new(0.0, 0.0, 0.0));
        let pose = Pose2::new(1.5, -0.5, 3.0);
        assert_eq!(pose_or_origin(Some(pose_to_wire(pose))), pose);
    }

    #[test]
    fn a_missing_required_pose_names_its_field() {
        assert_eq!(
            required_pose("odometry", Some(pose_to_wire(Pose2::new(1.0, 2.0, 3.0)))).unwrap(),
            Pose2::new(1.0, 2.0, 3.0)
        );
        let error = required_pose("frames[4].odometry", None).unwrap_err();
        assert_eq!(error.to_string(), "frames[4].odometry: is required");
    }

    #[test]
    fn tile_keys_cross_the_wire_unchanged() {
        for key in [
            TileKey::new(0, 0),
            TileKey::new(-5, 9),
            TileKey::new(i32::MIN, i32::MAX),
        ] {
            assert_eq!(tile_key_from_wire(tile_key_to_wire(key)), key);
        }
    }

    #[test]
    fn cell_boxes_cross_the_wire_and_an_inverted_one_is_refused() {
        let cells = CellBox::new(CellIndex::new(-4, -3), CellIndex::new(10, 2)).unwrap();
        let wire = cell_box_to_wire(cells);
        assert_eq!(
            (wire.min_x, wire.min_y, wire.max_x, wire.max_y),
            (-4, -3, 10, 2)
        );
        assert_eq!(cell_box_from_wire("bounds_cells", wire).unwrap(), cells);
        let inverted = pb::CellBox {
            min_x: 0,
            min_y: 5,
            max_x: 3,
            max_y: 4,
        };
        let error = cell_box_from_wire("bounds_cells", inverted).unwrap_err();
        assert_eq!(
            error.to_string(),
            "bounds_cells: max (3, 4) lies below min (0, 5)"
        );
    }

    #[test]
    fn a_dense_tile_decodes_to_its_key_version_and_cells() {
        let mut cells = vec![LogOdds::UNKNOWN_RAW; size().area()];
        cells[9] = 250;
        let bytes = cells.iter().flat_map(|c| c.to_le_bytes()).collect();
        let tile = pb::Tile {
            key: Some(pb::TileKey { x: 3, y: -1 }),
            version: 42,
            encoding: pb::CellEncoding::DenseI16Le as i32,
            cells: bytes,
        };
        let (key, version, decoded) = decode_tile(&tile, size()).unwrap();
        assert_eq!((key, version), (TileKey::new(3, -1), 42));
        assert_eq!(decoded.to_dense_bytes(), tile.cells);
    }

    #[test]
    fn a_tile_without_key_or_in_another_encoding_is_refused() {
        let keyless = pb::Tile {
            key: None,
            version: 1,
            encoding: pb::CellEncoding::DenseI16Le as i32,
            cells: Vec::new(),
        };
        assert_eq!(
            decode_tile(&keyless, size()).unwrap_err().to_string(),
            "invalid client configuration: the server sent a tile without a key"
        );
        let sparse = pb::Tile {
            key: Some(pb::TileKey { x: 1, y: 2 }),
            encoding: pb::CellEncoding::SparseI16Le as i32,
            ..keyless
        };
        assert_eq!(
            decode_tile(&sparse, size()).unwrap_err().to_string(),
            "invalid client configuration: the server sent tile (1, 2) in encoding 2, expected dense"
        );
    }

    #[test]
    fn a_delta_goes_sparse_only_when_that_is_smaller() {
        let mut delta = TileDelta::zero(TileKey::new(-2, 7), size());
        delta.raw_mut()[5] = 100;
        let wire = encode_delta(&delta);
        assert_eq!(wire.key, Some(pb::TileKey { x: -2, y: 7 }));
        assert_eq!(wire.encoding, pb::CellEncoding::SparseI16Le as i32);
        assert_eq!(wire.cells, delta.to_sparse_bytes().unwrap());

        for i in 0..size().area() {
            delta.raw_mut()[i] += 1;
        }
        let wire = encode_delta(&delta);
        assert_eq!(wire.encoding, pb::CellEncoding::DenseI16Le as i32);
        assert_eq!(wire.cells, delta.to_dense_bytes());
    }
}
