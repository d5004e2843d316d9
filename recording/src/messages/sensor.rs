//! `sensor_msgs/LaserScan` and `sensor_msgs/Range`: a planar laser's scan
//! and one ranger's reading.

use super::{Header, RosMessage};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

/// `sensor_msgs/LaserScan`: beam `i` along `angle_min + i *
/// angle_increment` from the sensor's x axis, counter-clockwise.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserScan {
    /// When the first beam was taken, and the laser's frame.
    pub header: Header,
    /// The first beam's angle, radians.
    pub angle_min: f32,
    /// The last beam's angle, radians.
    pub angle_max: f32,
    /// Between beams, radians.
    pub angle_increment: f32,
    /// Between beams' measurements, seconds.
    pub time_increment: f32,
    /// Between scans, seconds.
    pub scan_time: f32,
    /// The shortest valid range, metres.
    pub range_min: f32,
    /// The longest valid range, metres.
    pub range_max: f32,
    /// One range per beam, metres.
    pub ranges: Vec<f32>,
    /// One intensity per beam, or none.
    pub intensities: Vec<f32>,
}

impl RosMessage for LaserScan {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/LaserScan";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32_sequence(&self.ranges);
        w.f32_sequence(&self.intensities);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            angle_min: r.f32("angle_min")?,
            angle_max: r.f32("angle_max")?,
            angle_increment: r.f32("angle_increment")?,
            time_increment: r.f32("time_increment")?,
            scan_time: r.f32("scan_time")?,
            range_min: r.f32("range_min")?,
            range_max: r.f32("range_max")?,
            ranges: r.f32_sequence("ranges")?,
            intensities: r.f32_sequence("intensities")?,
        })
    }
}

/// `sensor_msgs/Range`: one ranger's reading, a cone of `field_of_view`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Range {
    /// When, and the ranger's frame (its x axis is the cone's axis).
    pub header: Header,
    /// [`Range::ULTRASOUND`] or [`Range::INFRARED`].
    pub radiation_type: u8,
    /// The cone's whole opening angle, radians.
    pub field_of_view: f32,
    /// The shortest range reported, metres.
    pub min_range: f32,
    /// The longest range reported, metres.
    pub max_range: f32,
    /// The reading, metres (+inf: nothing detected).
    pub range: f32,
}

impl Range {
    /// `radiation_type` of a sonar.
    pub const ULTRASOUND: u8 = 0;
    /// `radiation_type` of an infrared ranger.
    pub const INFRARED: u8 = 1;
}

impl RosMessage for Range {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Range";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u8(self.radiation_type);
        w.f32(self.field_of_view);
        w.f32(self.min_range);
        w.f32(self.max_range);
        w.f32(self.range);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            radiation_type: r.u8("radiation_type")?,
            field_of_view: r.f32("field_of_view")?,
            min_range: r.f32("min_range")?,
            max_range: r.f32("max_range")?,
            range: r.f32("range")?,
        })
    }
}
