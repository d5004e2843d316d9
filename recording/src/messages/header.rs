//! `builtin_interfaces/Time` and `std_msgs/Header`: when and in which
//! coordinate frame.

use super::RosMessage;
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

/// A time: whole seconds and nanoseconds after them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 1e9.
    pub nanosec: u32,
}

impl Time {
    /// `seconds` (non-negative, finite, below 2^31) to the nearest
    /// nanosecond.
    pub fn from_seconds(seconds: f64) -> Result<Self, RecordingError> {
        if !(seconds.is_finite() && (0.0..f64::from(i32::MAX)).contains(&seconds)) {
            return Err(RecordingError::Unrecordable(format!(
                "time {seconds} s is not within [0, 2^31) seconds"
            )));
        }
        let nanos = (seconds * 1e9).round() as u64;
        Self::from_nanos(nanos)
    }

    /// A time from nanoseconds since zero.
    pub fn from_nanos(nanos: u64) -> Result<Self, RecordingError> {
        let sec = i32::try_from(nanos / 1_000_000_000).map_err(|_| {
            RecordingError::Unrecordable(format!("time {nanos} ns is past 2^31 seconds"))
        })?;
        Ok(Self {
            sec,
            nanosec: (nanos % 1_000_000_000) as u32,
        })
    }

    /// Nanoseconds since zero; `None` before it.
    pub fn nanos(self) -> Option<u64> {
        let sec = u64::try_from(self.sec).ok()?;
        Some(sec * 1_000_000_000 + u64::from(self.nanosec))
    }

    /// Seconds, as a float.
    pub fn seconds(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    /// Whether both fields are zero (a stamp never set).
    pub fn is_zero(self) -> bool {
        self.sec == 0 && self.nanosec == 0
    }
}

impl RosMessage for Time {
    const TYPE_NAME: &'static str = "builtin_interfaces/msg/Time";

    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            sec: r.i32("stamp.sec")?,
            nanosec: r.u32("stamp.nanosec")?,
        })
    }
}

/// A stamp and the coordinate frame the data is in.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// The coordinate frame (`map`, `odom`, `base_link`, a sensor's).
    pub frame_id: String,
}

impl Header {
    /// A header from its parts.
    pub fn new(stamp: Time, frame_id: &str) -> Self {
        Self {
            stamp,
            frame_id: frame_id.to_owned(),
        }
    }
}

impl RosMessage for Header {
    const TYPE_NAME: &'static str = "std_msgs/msg/Header";

    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            stamp: Time::read(r)?,
            frame_id: r.string("header.frame_id")?,
        })
    }
}
