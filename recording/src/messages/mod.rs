//! The ROS 2 messages deog records and reads, as plain structs with their
//! CDR encoding. Field names and order are the ROS 2 definitions' (the
//! `.msg` texts are in [`crate::schemas`]).
//!
//! - [`header`]: `builtin_interfaces/Time`, `std_msgs/Header`.
//! - [`geometry`]: `geometry_msgs` (points, quaternions, poses, twists,
//!   transforms, stamped poses).
//! - [`sensor`]: `sensor_msgs/LaserScan`, `sensor_msgs/Range`.
//! - [`nav`]: `nav_msgs/Odometry`, `nav_msgs/OccupancyGrid`.
//! - [`tf`]: `tf2_msgs/TFMessage`, transforms between frames.

pub mod geometry;
pub mod header;
pub mod nav;
pub mod sensor;
pub mod tf;

use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

pub use geometry::{
    Point, Pose, PoseStamped, PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, Transform,
    TransformStamped, Twist, TwistWithCovariance, Vector3,
};
pub use header::{Header, Time};
pub use nav::{MapMetaData, OccupancyGrid, Odometry};
pub use sensor::{LaserScan, Range};
pub use tf::TfMessage;

/// A ROS 2 message type: its name and its CDR fields.
pub trait RosMessage: Sized {
    /// The type's full name as rosbag2 names a schema
    /// (`sensor_msgs/msg/LaserScan`).
    const TYPE_NAME: &'static str;

    /// Appends the fields, in definition order.
    fn write(&self, w: &mut CdrWriter);

    /// Reads the fields, in definition order.
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError>;
}

/// `message` as a CDR message (encapsulation header included).
pub fn encode<M: RosMessage>(message: &M) -> Vec<u8> {
    let mut w = CdrWriter::new();
    message.write(&mut w);
    w.into_bytes()
}

/// A message of type `M` from its CDR bytes.
pub fn decode<M: RosMessage>(bytes: &[u8]) -> Result<M, RecordingError> {
    M::read(&mut CdrReader::new(bytes)?)
}

/// Whether a schema name (`sensor_msgs/msg/LaserScan`, or the older
/// `sensor_msgs/LaserScan`) names the type `M`.
pub fn names_type<M: RosMessage>(schema_name: &str) -> bool {
    schema_name == M::TYPE_NAME || schema_name == M::TYPE_NAME.replacen("/msg/", "/", 1)
}

/// Writes a fixed-size `float64[N]`.
fn write_f64_array(w: &mut CdrWriter, values: &[f64]) {
    for &v in values {
        w.f64(v);
    }
}

/// Reads a fixed-size `float64[N]`.
fn read_f64_array<const N: usize>(
    r: &mut CdrReader<'_>,
    what: &str,
) -> Result<[f64; N], RecordingError> {
    let mut out = [0.0; N];
    for v in &mut out {
        *v = r.f64(what)?;
    }
    Ok(out)
}
