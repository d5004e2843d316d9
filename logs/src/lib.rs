//! CARMEN robot logs read into laser scans: each with the robot's raw
//! wheel odometry, a reference pose when the log knows one, and the
//! geometry of the laser that made it, from which a [`deog_rig::Rig`] is
//! built.
//!
//! Lines are taken in file order, never sorted by timestamp (the Intel
//! log's timestamps step back in places). `FLASER`, `RLASER` and
//! `ROBOTLASER1` lines are scans; `ODOM` lines are odometry; `TRUEPOS`
//! lines are ground truth; `PARAM` lines give the lasers' mount offsets;
//! `#` comments, `NEFF`, `SYNC`, `RAWLASER1`..`4` and unknown lines are
//! skipped. Corrected logs (the output of a SLAM run) re-anchor their
//! odometry at every scan; the reader recognises that and keeps the raw
//! motion apart from the correction (see [`odometry`]).
//!
//! # Layout
//! - [`log`]: [`CarmenLog`], its [`LogScan`]s and [`ReferenceSource`]; a
//!   log assembled from its lines.
//! - [`read`]: [`CarmenLog::parse`] (any reader), [`CarmenLog::load`] (a
//!   file, plain or gzip).
//! - `record` (private): one line split and checked, naming the field at
//!   fault.
//! - [`odometry`]: the raw odometry chain, the re-anchoring `ODOM` lines,
//!   [`relative`] and [`inverse`] of poses.
//! - [`geometry`]: [`LaserSource`], [`LaserGeometry`] and CARMEN's default
//!   laser fan and mounts.
//! - [`rig`]: [`CarmenLog::rig`] and [`CarmenLog::check_rig`].
//! - [`error`]: the one error type, [`LogError`].
//!
//! # Example
//! A two-scan corrected log: the second scan's odometry moved by what the
//! wheels measured (0.5 m ahead), not by the correction (1 m).
//! ```
//! use deog_logs::{CarmenLog, LaserSource, ReferenceSource};
//!
//! let text = "\
//! PARAM robot_frontlaser_offset 0.0 nohost 0
//! ODOM 0 0 0 0 0 0 0.1 pippo 0.1
//! FLASER 4 1.0 2.0 50.0 3.0 0 0 0 0 0 0 0.2 pippo 0.2
//! ODOM 0 0 0 0 0 0 0 pippo 0
//! ODOM 0.5 0 0 0 0 0 0.3 pippo 0.3
//! FLASER 4 1.0 2.0 50.0 3.0 1 0 0 1 0 0 0.4 pippo 0.4
//! ODOM 1 0 0 0 0 0 0 pippo 0
//! ";
//! let log = CarmenLog::parse_str(text, "example")?;
//! assert_eq!(log.reference_source(), ReferenceSource::Corrected);
//! let scans = log.scans();
//! assert_eq!((scans[0].line, scans[1].line), (3, 6));
//! assert_eq!(scans[1].odometry.x, 0.5);
//! assert_eq!(scans[1].reference.map(|p| p.x), Some(1.0));
//!
//! let rig = log.rig(LaserSource::Front, "example-laser")?;
//! assert_eq!(rig.readings(), 4);
//! assert_eq!(rig.max_range(), 50.0);
//! log.check_rig(LaserSource::Front, &rig)?;
//! # Ok::<(), deog_logs::LogError>(())
//! ```

pub mod error;
pub mod geometry;
pub mod log;
pub mod odometry;
pub mod read;
mod record;
pub mod rig;

pub use error::LogError;
pub use geometry::{LaserGeometry, LaserSource, default_fan, front_mount, rear_mount};
pub use log::{CarmenLog, LogScan, ReferenceSource};
pub use odometry::{ANCHOR_TOLERANCE, inverse, relative};
pub use rig::{LOG_BODY_RADIUS_M, LOG_MIN_RANGE_M};
