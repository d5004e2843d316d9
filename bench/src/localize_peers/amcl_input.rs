//! What amcl reads, in the files `bench/localize_peers_amcl.py` takes:
//! the sonar frames as laser beams from the robot's centre, and deog's map
//! as a ROS occupancy grid.
//!
//! The Scout's sonars face straight out from its centre, so a reading r of
//! the sonar mounted at radius R and angle a is a laser beam from the
//! centre at bearing a with range R + r. A reading that heard nothing is
//! amcl's "max range" reading: exactly the scan's `range_max`, the
//! longest sonar range plus its mount radius.
//!
//! Frames file, little-endian throughout:
//!
//! ```text
//! magic      8 bytes  "DEOGAF01"
//! frames     u32
//! beams      u32
//! range_max  f64      metres, from the centre
//! bearings   f64 per beam, radians, robot frame
//! per frame: time f64 (s), odometry x, y, theta f64, ranges f64 per beam
//! ```
//!
//! Grid file:
//!
//! ```text
//! magic      8 bytes  "DEOGAG01"
//! width, height   u32, u32
//! resolution      f64   metres per cell
//! origin x, y     f64   the lower-left corner of the lower-left cell
//! cells      i8 per cell, rows from the bottom up: 0 free, 100 occupied,
//!            -1 unknown
//! ```

use std::io::{self, Write};

use anyhow::{Result, ensure};
use deog_mapfile::MapImage;
use deog_mapping::map_export::{FREE_PIXEL, OCCUPIED_PIXEL};
use deog_rig::{Reading, Rig};

use super::recording::Frame;

/// The frames file's first eight bytes.
const FRAMES_MAGIC: &[u8; 8] = b"DEOGAF01";
/// The grid file's first eight bytes.
const GRID_MAGIC: &[u8; 8] = b"DEOGAG01";

/// A rig's sonars as beams from the robot's centre.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct CentreBeams {
    /// Each sonar's bearing, radians, robot frame.
    pub bearings: Vec<f64>,
    /// Each sonar's distance from the centre, metres.
    pub offsets: Vec<f64>,
    /// The scan's maximum range: the longest sonar range plus its offset.
    pub range_max: f64,
    rig: Rig,
}

impl CentreBeams {
    /// `rig`'s beams seen from the centre; an error unless every beam faces
    /// straight out from it (a beam off that line is no beam from the
    /// centre).
    pub fn new(rig: &Rig) -> Result<Self> {
        let mut bearings = Vec::new();
        let mut offsets = Vec::new();
        let mut range_max: f64 = 0.0;
        for (i, beam) in rig.beams().iter().enumerate() {
            let m = beam.mount;
            let radius = m.x.hypot(m.y);
            // The mount's position along its own heading: radial when the
            // sideways part is nothing.
            let sideways = -m.x * m.theta.sin() + m.y * m.theta.cos();
            let along = m.x * m.theta.cos() + m.y * m.theta.sin();
            ensure!(
                sideways.abs() < 1e-6 && along >= -1e-9,
                "beam {i} of rig {} does not face straight out from the robot's centre",
                rig.name()
            );
            bearings.push(m.theta);
            offsets.push(radius);
            range_max = range_max.max(radius + beam.max_range);
        }
        ensure!(!bearings.is_empty(), "rig {} has no beams", rig.name());
        Ok(Self {
            bearings,
            offsets,
            range_max,
            rig: rig.clone(),
        })
    }

    /// A frame's readings as ranges from the centre: offset plus reading,
    /// exactly [`Self::range_max`] where nothing was heard, NaN where the
    /// reading is no range at all (amcl skips a NaN beam).
    pub fn ranges(&self, readings: &[f64]) -> Result<Vec<f64>> {
        ensure!(
            readings.len() == self.bearings.len(),
            "a frame of {} readings for {} beams",
            readings.len(),
            self.bearings.len()
        );
        Ok(self
            .rig
            .beams()
            .iter()
            .zip(&self.offsets)
            .zip(readings)
            .map(|((beam, offset), &r)| match beam.classify(r) {
                Some(Reading::Echo(r)) => (offset + r).min(self.range_max),
                Some(Reading::NoEcho) => self.range_max,
                None => f64::NAN,
            })
            .collect())
    }
}

/// Writes `frames` as amcl's scans from the centre, in the layout above.
pub(super) fn write_frames(
    mut out: impl Write,
    beams: &CentreBeams,
    frames: &[Frame],
) -> Result<()> {
    out.write_all(FRAMES_MAGIC)?;
    out.write_all(&count_u32(frames.len())?.to_le_bytes())?;
    out.write_all(&count_u32(beams.bearings.len())?.to_le_bytes())?;
    out.write_all(&beams.range_max.to_le_bytes())?;
    for b in &beams.bearings {
        out.write_all(&b.to_le_bytes())?;
    }
    for frame in frames {
        let o = frame.odometry;
        for v in [frame.time_s, o.x, o.y, o.theta] {
            out.write_all(&v.to_le_bytes())?;
        }
        for r in beams.ranges(&frame.ranges)? {
            out.write_all(&r.to_le_bytes())?;
        }
    }
    out.flush()?;
    Ok(())
}

/// A map_server pixel as a ROS occupancy grid's cell: 100 occupied, 0
/// free, -1 unknown.
pub(super) fn grid_cell(pixel: u8) -> i8 {
    match pixel {
        OCCUPIED_PIXEL => 100,
        FREE_PIXEL => 0,
        _ => -1,
    }
}

/// Writes a trinary map image (as `deog_mapping::export_map` makes it) as
/// an occupancy grid, in the layout above.
pub(super) fn write_grid(mut out: impl Write, image: &MapImage) -> Result<()> {
    let (width, height) = (image.width as usize, image.height as usize);
    ensure!(
        image.pixels.len() == width * height,
        "an image of {} pixels for {width} x {height}",
        image.pixels.len()
    );
    out.write_all(GRID_MAGIC)?;
    out.write_all(&image.width.to_le_bytes())?;
    out.write_all(&image.height.to_le_bytes())?;
    for v in [image.resolution, image.origin.0, image.origin.1] {
        out.write_all(&v.to_le_bytes())?;
    }
    // The image's first row is the top; the grid's is the bottom.
    let mut row = Vec::with_capacity(width);
    for r in (0..height).rev() {
        row.clear();
        row.extend(
            image.pixels[r * width..(r + 1) * width]
                .iter()
                .map(|&p| grid_cell(p).to_le_bytes()[0]),
        );
        out.write_all(&row)?;
    }
    out.flush()?;
    Ok(())
}

fn count_u32(n: usize) -> io::Result<u32> {
    u32::try_from(n).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{n} is too many for the file's u32 count"),
        )
    })
}

#[cfg(test)]
mod tests {
    use approx::assert_abs_diff_eq;
    use deog_grid::{Pose2, SCOUT_RING_RADIUS_M};
    use deog_mapfile::Mode;

    use super::*;

    fn f64_at(bytes: &[u8], at: usize) -> f64 {
        f64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"))
    }

    fn u32_at(bytes: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"))
    }

    #[test]
    fn a_scout_reading_is_a_beam_from_the_centre_with_the_ring_radius_added() {
        let rig = deog_rig::scout();
        let beams = CentreBeams::new(&rig).expect("the Scout's sonars face outwards");
        assert_eq!(beams.bearings.len(), 16);
        assert_abs_diff_eq!(
            beams.bearings[4],
            std::f64::consts::FRAC_PI_2,
            epsilon = 1e-12
        );
        let max = rig.beams()[0].max_range;
        assert_abs_diff_eq!(beams.range_max, SCOUT_RING_RADIUS_M + max, epsilon = 1e-12);
        let mut readings = vec![2.0; 16];
        readings[3] = max; // no echo
        readings[5] = 0.01; // nearer than the sonar reads: its minimum
        readings[7] = f64::NAN;
        let ranges = beams.ranges(&readings).expect("16 readings");
        assert_abs_diff_eq!(ranges[0], SCOUT_RING_RADIUS_M + 2.0, epsilon = 1e-12);
        assert_eq!(ranges[3], beams.range_max, "no echo is exactly max range");
        let min = rig.beams()[5].min_range;
        assert_abs_diff_eq!(ranges[5], SCOUT_RING_RADIUS_M + min, epsilon = 1e-12);
        assert!(ranges[7].is_nan());
        assert!(beams.ranges(&readings[..15]).is_err());
    }

    #[test]
    fn a_beam_off_the_radial_line_is_refused() {
        // pioneer3dx's sonars sit on two arcs, not facing out from the centre.
        let rig = deog_rig::load_rig_spec("pioneer3dx").expect("built in");
        let err = CentreBeams::new(&rig).expect_err("not radial");
        assert!(err.to_string().contains("straight out"), "{err}");
    }

    #[test]
    fn the_frames_file_holds_the_header_bearings_and_each_frame() {
        let rig = deog_rig::scout();
        let beams = CentreBeams::new(&rig).expect("radial");
        let frames = vec![
            Frame {
                time_s: 0.1,
                odometry: Pose2::new(1.0, 2.0, 0.5),
                true_pose: Pose2::new(0.0, 0.0, 0.0),
                ranges: vec![1.0; 16],
            },
            Frame {
                time_s: 0.2,
                odometry: Pose2::new(1.5, 2.5, -0.5),
                true_pose: Pose2::new(0.0, 0.0, 0.0),
                ranges: vec![rig.beams()[0].max_range; 16],
            },
        ];
        let mut bytes = Vec::new();
        write_frames(&mut bytes, &beams, &frames).expect("written");
        assert_eq!(&bytes[..8], FRAMES_MAGIC);
        assert_eq!((u32_at(&bytes, 8), u32_at(&bytes, 12)), (2, 16));
        assert_eq!(f64_at(&bytes, 16), beams.range_max);
        let first = 24 + 16 * 8;
        let frame_len = 8 * (4 + 16);
        assert_eq!(bytes.len(), first + 2 * frame_len);
        assert_eq!(f64_at(&bytes, 24 + 8), beams.bearings[1]);
        let second = first + frame_len;
        assert_eq!(
            [0, 8, 16, 24].map(|o| f64_at(&bytes, second + o)),
            [0.2, 1.5, 2.5, -0.5]
        );
        assert_abs_diff_eq!(
            f64_at(&bytes, first + 32),
            SCOUT_RING_RADIUS_M + 1.0,
            epsilon = 1e-12
        );
        assert_eq!(f64_at(&bytes, second + 32 + 15 * 8), beams.range_max);
    }

    #[test]
    fn the_grid_file_is_bottom_row_first_in_ros_values() {
        let image = MapImage {
            width: 3,
            height: 2,
            resolution: 0.05,
            origin: (-1.0, 2.0, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: Mode::Trinary,
            // Top row first: occupied, free, unknown / free, free, occupied.
            pixels: vec![0, 254, 205, 254, 254, 0],
        };
        let mut bytes = Vec::new();
        write_grid(&mut bytes, &image).expect("written");
        assert_eq!(&bytes[..8], GRID_MAGIC);
        assert_eq!((u32_at(&bytes, 8), u32_at(&bytes, 12)), (3, 2));
        assert_eq!([16, 24, 32].map(|o| f64_at(&bytes, o)), [0.05, -1.0, 2.0]);
        let cells: Vec<i8> = bytes[40..].iter().map(|&b| b as i8).collect();
        assert_eq!(cells, [0, 0, 100, 100, 0, -1]);
        let short = MapImage {
            pixels: vec![0; 5],
            ..image
        };
        assert!(write_grid(&mut Vec::new(), &short).is_err());
    }
}
