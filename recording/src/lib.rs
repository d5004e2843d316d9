//! ROS 2 recordings: a robot's frames, a localizer's estimates and a map
//! written as MCAP with the message types ROS 2 and Foxglove tools read,
//! and a ROS 2 recording's laser scans or sonar ranges with odometry read
//! back into frames and the rig that made them.
//!
//! Pure: the MCAP bytes come from and go to the caller (any `Write +
//! Seek` when writing, a byte slice when reading); no file or network I/O.
//!
//! # Layout
//! - [`cdr`]: the CDR byte layout of ROS 2 messages, [`CdrWriter`] and
//!   [`CdrReader`].
//! - [`messages`]: the message types (LaserScan, Range, Odometry, poses,
//!   transforms, OccupancyGrid) with their CDR encoding.
//! - [`schemas`]: their `.msg` definitions as rosbag2 writes a schema.
//! - [`frame`]: what is recorded, in deog's terms: [`Frame`],
//!   [`Estimate`].
//! - [`occupancy`]: a map's tiles as an OccupancyGrid.
//! - [`record`]: frames, estimates and a map written to MCAP
//!   ([`write_recording`]), and the topics and coordinate frames used.
//! - [`pose_track`]: poses over time, interpolated between samples.
//! - [`scan_rig`]: the rig a recording's scans and `/tf_static` describe.
//! - [`topics`]: a recording's channels by topic, and the topics an
//!   import takes.
//! - [`scans`]: scans (LaserScan, or rounds of Range) as frames' readings
//!   and the rig they make.
//! - [`import`]: a recording read into frames ([`read_recording`]).
//! - [`error`]: the one error type, [`RecordingError`].
//!
//! ```
//! use deog_grid::Pose2;
//! use deog_recording::{Frame, ImportOptions, Recording, read_recording, write_recording};
//!
//! let rig = deog_rig::built_in_rig("laser180").unwrap();
//! let frames: Vec<Frame> = (0..3)
//!     .map(|i| Frame {
//!         sequence: i + 1,
//!         time_s: 1.0 + i as f64 * 0.1,
//!         odometry: Pose2::new(0.1 * i as f64, 0.0, 0.0),
//!         true_pose: None,
//!         reference_pose: None,
//!         ranges: vec![2.5; rig.readings()],
//!     })
//!     .collect();
//! let mut bytes = std::io::Cursor::new(Vec::new());
//! let recording = Recording { rig: &rig, frames: &frames, estimates: &[], map: None };
//! let counts = write_recording(&mut bytes, &recording).unwrap();
//! assert_eq!(counts["/scan"], 3);
//!
//! let options = ImportOptions { first_sequence: 1, ..ImportOptions::default() };
//! let back = read_recording(bytes.get_ref(), &options).unwrap();
//! assert_eq!(back.frames.len(), 3);
//! assert_eq!(back.frames[2].odometry, frames[2].odometry);
//! assert_eq!(back.rig.readings(), rig.readings());
//! ```

pub mod cdr;
pub mod error;
pub mod frame;
pub mod import;
pub mod messages;
pub mod occupancy;
pub mod pose_track;
pub mod record;
pub mod scan_rig;
pub mod scans;
pub mod schemas;
pub mod topics;

pub use cdr::{CdrReader, CdrWriter};
pub use error::RecordingError;
pub use frame::{Estimate, Frame};
pub use import::{ImportOptions, ImportedRecording, MountSource, read_recording};
pub use occupancy::occupancy_grid;
pub use pose_track::PoseTrack;
pub use record::{Recording, TopicCounts, write_recording};
pub use schemas::schema_text;
