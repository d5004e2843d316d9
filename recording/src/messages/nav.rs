//! `nav_msgs/Odometry` and `nav_msgs/OccupancyGrid`.

use super::{Header, Pose, PoseWithCovariance, RosMessage, Time, TwistWithCovariance};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

/// `nav_msgs/Odometry`: the pose of `child_frame_id` in `header.frame_id`
/// (usually `base_link` in `odom`) and its velocity in the child frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Odometry {
    /// When, and the frame the pose is in.
    pub header: Header,
    /// The robot's frame.
    pub child_frame_id: String,
    /// The pose.
    pub pose: PoseWithCovariance,
    /// The velocity, in the child frame.
    pub twist: TwistWithCovariance,
}

impl RosMessage for Odometry {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Odometry";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        self.pose.write(w);
        self.twist.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.string("child_frame_id")?,
            pose: PoseWithCovariance::read(r)?,
            twist: TwistWithCovariance::read(r)?,
        })
    }
}

/// `nav_msgs/MapMetaData`: a grid's size and where it lies.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MapMetaData {
    /// When the map was loaded.
    pub map_load_time: Time,
    /// Metres per cell.
    pub resolution: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// The corner of cell (0, 0), map frame.
    pub origin: Pose,
}

/// `nav_msgs/OccupancyGrid`: row-major cells from the origin's corner,
/// each 0 (free) to 100 (occupied), or -1 unknown.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OccupancyGrid {
    /// When, and the map's frame.
    pub header: Header,
    /// Size and placement.
    pub info: MapMetaData,
    /// `width * height` cells, row 0 first.
    pub data: Vec<i8>,
}

impl RosMessage for MapMetaData {
    const TYPE_NAME: &'static str = "nav_msgs/msg/MapMetaData";
    fn write(&self, w: &mut CdrWriter) {
        self.map_load_time.write(w);
        w.f32(self.resolution);
        w.u32(self.width);
        w.u32(self.height);
        self.origin.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            map_load_time: Time::read(r)?,
            resolution: r.f32("info.resolution")?,
            width: r.u32("info.width")?,
            height: r.u32("info.height")?,
            origin: Pose::read(r)?,
        })
    }
}

impl RosMessage for OccupancyGrid {
    const TYPE_NAME: &'static str = "nav_msgs/msg/OccupancyGrid";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.info.write(w);
        w.i8_sequence(&self.data);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            info: MapMetaData::read(r)?,
            data: r.i8_sequence("data")?,
        })
    }
}
