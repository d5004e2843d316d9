//! `tf2_msgs/TFMessage`: transforms between coordinate frames, on `/tf`
//! (moving) and `/tf_static` (fixed, such as sensor mounts).

use super::{RosMessage, TransformStamped};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// The fewest bytes a `TransformStamped` takes (two empty frame ids,
/// seven float64), to bound a corrupt count.
const MIN_TRANSFORM_BYTES: usize = 8 + 2 * 4 + 7 * 8;

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    fn write(&self, w: &mut CdrWriter) {
        w.sequence_len(self.transforms.len());
        for t in &self.transforms {
            t.write(w);
        }
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        let len = r.sequence_len("transforms", MIN_TRANSFORM_BYTES)?;
        let transforms = (0..len)
            .map(|_| TransformStamped::read(r))
            .collect::<Result<_, _>>()?;
        Ok(Self { transforms })
    }
}
