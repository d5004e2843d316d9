//! Wire messages to checked domain values and back. Every refusal names the
//! field, as the proto spells it, so a client knows what to fix.

use crate::error::StoreError;
use crate::store::{MapRecord, MapSettings};
use deog_grid::{CellBox, CellIndex, ClampLimits, Resolution, Tile, TileDelta, TileKey, TileSize};
use deog_proto::names::{self, NameError};
use deog_proto::v1 as pb;

/// Limits the server puts on requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest encoded request message, bytes.
    pub max_message_bytes: usize,
    /// Largest |cell index| a tile may reach on either axis: a map is big,
    /// but a tile a continent away is a bug.
    pub max_abs_cell: i32,
    /// Most tiles in one update batch.
    pub max_tiles_per_batch: usize,
    /// Most frames in one publish request.
    pub max_frames_per_request: usize,
    /// Most range readings in one frame.
    pub max_ranges_per_frame: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_message_bytes: 8 << 20,
            // 2^24 cells is 839 km at 5 cm.
            max_abs_cell: 1 << 24,
            max_tiles_per_batch: 4096,
            max_frames_per_request: 10_000,
            max_ranges_per_frame: 1024,
        }
    }
}

impl Limits {
    /// Largest message the transport decodes at all, bytes. It is a backstop
    /// well above `max_message_bytes`, so that a message a little too large
    /// still reaches [`Limits::check_size`] and gets a refusal naming it;
    /// past this one the transport refuses it (RESOURCE_EXHAUSTED, ending an
    /// update stream).
    pub fn transport_message_bytes(&self) -> usize {
        self.max_message_bytes
            .saturating_mul(2)
            .saturating_add(1 << 20)
    }

    /// Refuses a message whose encoding exceeds the configured size.
    pub fn check_size(&self, what: &str, message: &impl prost::Message) -> Result<(), StoreError> {
        let len = message.encoded_len();
        if len > self.max_message_bytes {
            return Err(StoreError::TooLarge {
                field: what.to_string(),
                reason: format!(
                    "message of {len} bytes exceeds the server's limit of {} bytes",
                    self.max_message_bytes
                ),
            });
        }
        Ok(())
    }
}

/// A map name: 1 to 128 characters of `[A-Za-z0-9_.-]`
/// ([`names::check_map_name`]).
pub fn map_name(field: &str, value: &str) -> Result<String, StoreError> {
    names::check_map_name(value).map_err(|e| invalid_name(field, e))?;
    Ok(value.to_string())
}

/// A robot name, by the rule the simulator applies too
/// ([`names::check_robot_name`]).
pub fn robot_name(field: &str, value: &str) -> Result<String, StoreError> {
    names::check_robot_name(value).map_err(|e| invalid_name(field, e))?;
    Ok(value.to_string())
}

/// A client id: a name that may also hold `/` and `:`
/// ([`names::check_client_id`]).
pub fn client_id(field: &str, value: &str) -> Result<String, StoreError> {
    names::check_client_id(value).map_err(|e| invalid_name(field, e))?;
    Ok(value.to_string())
}

fn invalid_name(field: &str, error: NameError) -> StoreError {
    StoreError::invalid(field, error.to_string())
}

fn finite(field: &str, value: f64) -> Result<f64, StoreError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(StoreError::invalid(
            field,
            format!("must be a finite number, got {value}"),
        ))
    }
}

/// The settings of a new map, defaults filled in.
pub fn map_settings(request: &pb::CreateMapRequest) -> Result<MapSettings, StoreError> {
    let resolution = match finite("resolution_m", request.resolution_m)? {
        0.0 => Resolution::DEFAULT,
        r => Resolution::new(r).map_err(|e| StoreError::grid("resolution_m", e))?,
    };
    let tile_size = match request.tile_size {
        0 => TileSize::DEFAULT,
        t => TileSize::new(t).map_err(|e| StoreError::grid("tile_size", e))?,
    };
    let (default_min, default_max) = ClampLimits::DEFAULT_PROBABILITIES;
    let min = match finite("clamp_min_probability", request.clamp_min_probability)? {
        0.0 => default_min,
        p => p,
    };
    let max = match finite("clamp_max_probability", request.clamp_max_probability)? {
        0.0 => default_max,
        p => p,
    };
    MapSettings::new(resolution, tile_size, (min, max)).map_err(|e| {
        let field = match &e {
            deog_grid::GridError::OutOfRange { field, .. } => *field,
            _ => "clamp_min_probability",
        };
        StoreError::grid(field, e)
    })
}

/// The wire form of a map's record.
pub fn map_info(record: &MapRecord) -> pb::MapInfo {
    let s = &record.settings;
    let resolution = s.resolution.metres();
    let bounds_m = record.bounds.map(|b| pb::WorldBox {
        min_x: f64::from(b.min.x) * resolution,
        min_y: f64::from(b.min.y) * resolution,
        max_x: (f64::from(b.max.x) + 1.0) * resolution,
        max_y: (f64::from(b.max.y) + 1.0) * resolution,
    });
    pb::MapInfo {
        name: record.name.clone(),
        resolution_m: resolution,
        tile_size: s.tile_size.cells(),
        clamp_min_probability: s.clamp_probabilities.0,
        clamp_max_probability: s.clamp_probabilities.1,
        tile_count: record.tile_count,
        cell_count: record.cell_count,
        bounds_cells: record.bounds.map(cell_box_to_wire),
        bounds_m,
        width_cells: record.bounds.map_or(0, |b| b.width()),
        height_cells: record.bounds.map_or(0, |b| b.height()),
        version: record.version,
    }
}

fn cell_box_to_wire(b: CellBox) -> pb::CellBox {
    pb::CellBox {
        min_x: b.min.x,
        min_y: b.min.y,
        max_x: b.max.x,
        max_y: b.max.y,
    }
}

/// A box of cells; absent means a required field is missing.
pub fn cell_box(field: &str, value: Option<&pb::CellBox>) -> Result<CellBox, StoreError> {
    let b = value.ok_or_else(|| StoreError::invalid(field, "is required"))?;
    CellBox::new(
        CellIndex::new(b.min_x, b.min_y),
        CellIndex::new(b.max_x, b.max_y),
    )
    .ok_or_else(|| StoreError::invalid(field, "max_x and max_y must not be below min_x and min_y"))
}

/// A tile key within the map's addressable range and the server's extent.
pub fn tile_key(
    field: &str,
    value: Option<&pb::TileKey>,
    size: TileSize,
    limits: &Limits,
) -> Result<TileKey, StoreError> {
    let k = value.ok_or_else(|| StoreError::invalid(field, "is required"))?;
    let key = size
        .check(TileKey::new(k.x, k.y))
        .map_err(|e| StoreError::grid(field, e))?;
    let cells = size.cell_box(key).map_err(|e| StoreError::grid(field, e))?;
    let reach = [cells.min.x, cells.min.y, cells.max.x, cells.max.y]
        .iter()
        .map(|c| i64::from(*c).abs())
        .max()
        .unwrap_or(0);
    if reach > i64::from(limits.max_abs_cell) {
        return Err(StoreError::invalid(
            field,
            format!(
                "tile ({}, {}) reaches cell index {reach}, past the server's limit of {}",
                k.x, k.y, limits.max_abs_cell
            ),
        ));
    }
    Ok(key)
}

/// One tile's deltas, decoded to dense form.
pub fn tile_delta(
    field: &str,
    value: &pb::TileDelta,
    size: TileSize,
    limits: &Limits,
) -> Result<TileDelta, StoreError> {
    let key = tile_key(&format!("{field}.key"), value.key.as_ref(), size, limits)?;
    let cells_field = format!("{field}.cells");
    let delta = match pb::CellEncoding::try_from(value.encoding) {
        Ok(pb::CellEncoding::DenseI16Le) => TileDelta::from_dense_bytes(key, size, &value.cells),
        Ok(pb::CellEncoding::SparseI16Le) => TileDelta::from_sparse_bytes(key, size, &value.cells),
        _ => {
            return Err(StoreError::invalid(
                format!("{field}.encoding"),
                format!(
                    "must be DENSE_I16_LE or SPARSE_I16_LE, got {}",
                    value.encoding
                ),
            ));
        }
    }
    .map_err(|e| StoreError::grid(&cells_field, e))?;
    if delta.raw().contains(&i16::MIN) {
        return Err(StoreError::invalid(
            cells_field,
            "-32768 marks an unknown cell and is not a delta",
        ));
    }
    Ok(delta)
}

/// A tile on the wire: its key and version, and its cells when given.
pub fn tile_to_wire(key: TileKey, version: u64, cells: Option<&Tile>) -> pb::Tile {
    pb::Tile {
        key: Some(pb::TileKey { x: key.x, y: key.y }),
        version,
        encoding: match cells {
            Some(_) => pb::CellEncoding::DenseI16Le as i32,
            None => pb::CellEncoding::Unspecified as i32,
        },
        cells: cells.map(Tile::to_dense_bytes).unwrap_or_default(),
    }
}

/// What a frame may hold, so that every consumer can use what is stored:
/// positions within a thousand kilometres of the origin (a map of the
/// finest cells, 1 cm, reaches 21,000 km) …
pub const FRAME_MAX_COORDINATE_M: f64 = 1e6;
/// … ranges of at most 10 km (no range sensor reads farther; a log marks
/// no return with its sensor's largest value, 82 m at most in ours) …
pub const FRAME_MAX_RANGE_M: f64 = 1e4;
/// … and times from 0 to 10^10 s (the year 2286 in Unix time).
pub const FRAME_MAX_TIME_S: f64 = 1e10;

fn pose(field: &str, value: Option<&pb::Pose2>) -> Result<(), StoreError> {
    let p = value.ok_or_else(|| StoreError::invalid(field, "is required"))?;
    finite(&format!("{field}.x"), p.x)?;
    finite(&format!("{field}.y"), p.y)?;
    finite(&format!("{field}.theta"), p.theta)?;
    Ok(())
}

/// A number as an error message shows it: in exponent form when it is
/// huge or tiny (1e300 printed whole is 301 digits).
fn shown(v: f64) -> String {
    if v != 0.0 && !(1e-4..1e7).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A frame's pose: finite, and within [`FRAME_MAX_COORDINATE_M`].
fn frame_pose(field: &str, value: Option<&pb::Pose2>) -> Result<(), StoreError> {
    pose(field, value)?;
    let p = value.ok_or_else(|| StoreError::invalid(field, "is required"))?;
    for (axis, v) in [("x", p.x), ("y", p.y)] {
        if v.abs() > FRAME_MAX_COORDINATE_M {
            return Err(StoreError::invalid(
                format!("{field}.{axis}"),
                format!(
                    "must be within [-{FRAME_MAX_COORDINATE_M}, {FRAME_MAX_COORDINATE_M}] m, got {}",
                    shown(v)
                ),
            ));
        }
    }
    Ok(())
}

/// A batch's or a frame's sequence: 1 to `u64::MAX - 1`. 0 means "none" on
/// the wire, and nothing can follow `u64::MAX`: a batch numbered so would
/// lock its client out of the map for good, a frame would leave its robot no
/// later frame.
pub fn sequence(field: &str, value: u64) -> Result<u64, StoreError> {
    if value == 0 {
        return Err(StoreError::invalid(field, "must be at least 1"));
    }
    if value == u64::MAX {
        return Err(StoreError::invalid(
            field,
            format!("must be below {value} (u64::MAX): no later sequence could follow it"),
        ));
    }
    Ok(value)
}

/// Checks a sonar frame.
pub fn sonar_frame(field: &str, frame: &pb::SonarFrame, limits: &Limits) -> Result<(), StoreError> {
    robot_name(&format!("{field}.robot"), &frame.robot)?;
    sequence(&format!("{field}.sequence"), frame.sequence)?;
    let time = finite(&format!("{field}.time_s"), frame.time_s)?;
    if !(0.0..=FRAME_MAX_TIME_S).contains(&time) {
        return Err(StoreError::invalid(
            format!("{field}.time_s"),
            format!(
                "must be within [0, {FRAME_MAX_TIME_S}] s, got {}",
                shown(time)
            ),
        ));
    }
    frame_pose(&format!("{field}.odometry"), frame.odometry.as_ref())?;
    if frame.true_pose.is_some() {
        frame_pose(&format!("{field}.true_pose"), frame.true_pose.as_ref())?;
    }
    if frame.reference_pose.is_some() {
        frame_pose(
            &format!("{field}.reference_pose"),
            frame.reference_pose.as_ref(),
        )?;
    }
    if frame.ranges.is_empty() || frame.ranges.len() > limits.max_ranges_per_frame {
        return Err(StoreError::invalid(
            format!("{field}.ranges"),
            format!(
                "must hold 1 to {} readings, got {}",
                limits.max_ranges_per_frame,
                frame.ranges.len()
            ),
        ));
    }
    for (i, &r) in frame.ranges.iter().enumerate() {
        let f = format!("{field}.ranges[{i}]");
        if finite(&f, r)? < 0.0 {
            return Err(StoreError::invalid(
                f,
                format!("must not be negative, got {r}"),
            ));
        }
        if r > FRAME_MAX_RANGE_M {
            return Err(StoreError::invalid(
                f,
                format!("must be at most {FRAME_MAX_RANGE_M} m, got {}", shown(r)),
            ));
        }
    }
    Ok(())
}

/// Checks an explorer's goal: names as everywhere, finite numbers.
pub fn exploration_goal(goal: &pb::ExplorationGoal) -> Result<(), StoreError> {
    robot_name("robot", &goal.robot)?;
    map_name("map", &goal.map)?;
    finite("x", goal.x)?;
    finite("y", goal.y)?;
    finite("time_s", goal.time_s)?;
    Ok(())
}

/// Checks a pose estimate.
pub fn pose_estimate(estimate: &pb::PoseEstimate) -> Result<(), StoreError> {
    robot_name("robot", &estimate.robot)?;
    map_name("map", &estimate.map)?;
    sequence("frame_sequence", estimate.frame_sequence)?;
    finite("time_s", estimate.time_s)?;
    pose("pose", estimate.pose.as_ref())?;
    if !(estimate.covariance.is_empty() || estimate.covariance.len() == 9) {
        return Err(StoreError::invalid(
            "covariance",
            format!(
                "must hold 9 values (3 x 3, row-major) or none, got {}",
                estimate.covariance.len()
            ),
        ));
    }
    for (i, &c) in estimate.covariance.iter().enumerate() {
        finite(&format!("covariance[{i}]"), c)?;
    }
    let lost = finite("lost_score", estimate.lost_score)?;
    if !(0.0..=1.0).contains(&lost) {
        return Err(StoreError::invalid(
            "lost_score",
            format!("must be within [0, 1], got {lost}"),
        ));
    }
    let sample = &estimate.particle_sample;
    if sample.len() % 3 != 0 || sample.len() > 3 * MAX_PARTICLE_SAMPLE {
        return Err(StoreError::invalid(
            "particle_sample",
            format!(
                "must hold (x, y, theta) of at most {MAX_PARTICLE_SAMPLE} particles, got {} values",
                sample.len()
            ),
        ));
    }
    if let Some(i) = sample.iter().position(|v| !v.is_finite()) {
        return Err(StoreError::invalid(
            format!("particle_sample[{i}]"),
            format!("must be finite, got {}", sample[i]),
        ));
    }
    Ok(())
}

/// The most particles an estimate's sample may hold: a picture for viewers,
/// not the filter.
pub const MAX_PARTICLE_SAMPLE: usize = 5_000;

/// An inclusive sequence range where 0 means open.
pub fn sequence_range(from: u64, to: u64) -> Result<(u64, u64), StoreError> {
    let to = if to == 0 { u64::MAX } else { to };
    if from > to {
        return Err(StoreError::invalid(
            "to_sequence",
            format!("must not be below from_sequence ({from}), got {to}"),
        ));
    }
    Ok((from, to))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_name_is_refused_naming_the_field() {
        let refused = |e: StoreError| match e {
            StoreError::InvalidArgument { .. } => e.to_string(),
            other => panic!("expected an invalid argument, got {other:?}"),
        };
        assert_eq!(
            refused(map_name("name", "").unwrap_err()),
            "name: must be 1 to 128 characters, got 0"
        );
        assert_eq!(
            refused(robot_name("frames[2].robot", "a b").unwrap_err()),
            "frames[2].robot: character ' ' is not allowed (use A-Z a-z 0-9 _ . -)"
        );
        assert_eq!(
            refused(map_name("map", "a/b").unwrap_err()),
            "map: character '/' is not allowed (use A-Z a-z 0-9 _ . -)"
        );
        assert_eq!(client_id("client_id", "carto/a:1").unwrap(), "carto/a:1");
        // A client id's refusal lists the two marks it may hold beyond a name's.
        assert_eq!(
            refused(client_id("client_id", "carto a").unwrap_err()),
            "client_id: character ' ' is not allowed (use A-Z a-z 0-9 _ . - / :)"
        );
        assert_eq!(robot_name("robot", "scout-1").unwrap(), "scout-1");
    }
}
