//! A whole log: its scans in file order with their raw odometry and
//! reference poses, and the geometry of each laser.

use deog_grid::Pose2;

use crate::error::LogError;
use crate::geometry::{LaserGeometry, LaserSource, default_fan, front_mount, rear_mount};
use crate::odometry::{Chain, find_anchors, rebase, relative};
use crate::record::{Device, LaserLine, Record};

/// Where a log's reference poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceSource {
    /// `TRUEPOS` lines (a simulator's ground truth): a scan's reference is
    /// the last true pose before it in the file; scans before the first
    /// have none.
    TruePos,
    /// A corrected log (recognised by its re-anchoring `ODOM` lines): a
    /// scan's reference is the corrected robot pose its line states
    /// (`odom_*` of `FLASER`/`RLASER`, equal to their `x y theta` in the
    /// Intel and ACES logs; `robot_*` of `ROBOTLASER1`).
    Corrected,
    /// Neither: no scan has a reference.
    Absent,
}

/// One laser scan of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct LogScan {
    /// The 1-based line it came from.
    pub line: usize,
    /// Which laser.
    pub source: LaserSource,
    /// The line's IPC timestamp, seconds. Not monotonic in every log: order
    /// by position (`line`), never by time.
    pub time_s: f64,
    /// Metres, in the laser's beam order; see [`LaserGeometry`].
    pub ranges: Vec<f64>,
    /// The robot's raw wheel odometry, chained from the first scan: the
    /// motion between two scans' `odometry` is what the wheels measured.
    /// Starts at the first scan's reference pose when it has one.
    pub odometry: Pose2,
    /// Where the robot really was, world frame, when the log knows
    /// (see [`ReferenceSource`]).
    pub reference: Option<Pose2>,
}

/// A CARMEN log read whole: scans in file order, each laser's geometry,
/// and where the reference poses come from.
#[derive(Debug, Clone, PartialEq)]
pub struct CarmenLog {
    origin: String,
    scans: Vec<LogScan>,
    geometry: [Option<LaserGeometry>; 3],
    reference_source: ReferenceSource,
    anchors: usize,
}

impl CarmenLog {
    /// Where the log came from (the path, or the origin given to `parse`).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// Every scan, in file order.
    pub fn scans(&self) -> &[LogScan] {
        &self.scans
    }

    /// The scans, taken.
    pub fn into_scans(self) -> Vec<LogScan> {
        self.scans
    }

    /// The scans of one laser, in file order.
    pub fn scans_from(&self, source: LaserSource) -> impl Iterator<Item = &LogScan> {
        self.scans.iter().filter(move |s| s.source == source)
    }

    /// The lasers that have scans, front, rear, robot laser in that order.
    pub fn sources(&self) -> Vec<LaserSource> {
        LaserSource::ALL
            .into_iter()
            .filter(|s| self.geometry[s.index()].is_some())
            .collect()
    }

    /// One laser's geometry, if the log has its scans.
    pub fn geometry(&self, source: LaserSource) -> Option<&LaserGeometry> {
        self.geometry[source.index()].as_ref()
    }

    /// Where the scans' reference poses come from.
    pub fn reference_source(&self) -> ReferenceSource {
        self.reference_source
    }

    /// How many re-anchoring `ODOM` lines the log has (0 unless corrected).
    pub fn anchors(&self) -> usize {
        self.anchors
    }

    /// The log from its lines, each paired with its 1-based line number.
    pub(crate) fn from_records(
        origin: &str,
        lines: Vec<(usize, Record)>,
    ) -> Result<Self, LogError> {
        let (numbers, records): (Vec<usize>, Vec<Record>) = lines.into_iter().unzip();
        let offsets = mount_params(origin, &numbers, &records)?;
        let anchor_flags = find_anchors(&records);
        let anchors = anchor_flags.iter().filter(|&&a| a).count();
        let has_odom = records.iter().any(|r| matches!(r, Record::Odom(_)));
        let reference_source = if records.iter().any(|r| matches!(r, Record::TruePos(_))) {
            ReferenceSource::TruePos
        } else if anchors > 0 {
            ReferenceSource::Corrected
        } else {
            ReferenceSource::Absent
        };

        let mut scans = Vec::new();
        let mut lasers: [Option<LaserSeen>; 3] = [None, None, None];
        let mut chain = Chain::default();
        let mut true_pose = None;
        for ((line, record), anchor) in numbers.into_iter().zip(records).zip(anchor_flags) {
            match record {
                Record::Odom(pose) if anchor => chain.anchor(pose),
                Record::Odom(pose) => chain.odom(pose),
                Record::TruePos(pose) => true_pose = Some(pose),
                Record::Laser(scan) => {
                    let seen = &mut lasers[scan.source.index()];
                    match seen {
                        None => *seen = Some(LaserSeen::first(line, &scan)),
                        Some(seen) => seen
                            .add(&scan)
                            .map_err(|reason| LogError::malformed(origin, line, reason))?,
                    }
                    if !has_odom {
                        chain.odom(scan.robot_pose);
                    }
                    let odometry = chain.at_scan(scan.robot_pose);
                    let reference = match reference_source {
                        ReferenceSource::TruePos => true_pose,
                        ReferenceSource::Corrected => Some(scan.robot_pose),
                        ReferenceSource::Absent => None,
                    };
                    scans.push(LogScan {
                        line,
                        source: scan.source,
                        time_s: scan.time_s,
                        ranges: scan.ranges,
                        odometry,
                        reference,
                    });
                }
                Record::Param { .. } | Record::Skip => {}
            }
        }
        let Some(first) = scans.first() else {
            return Err(LogError::NoScans {
                origin: origin.to_owned(),
            });
        };
        let start = first.reference.unwrap_or(first.odometry);
        let mut odometry: Vec<Pose2> = scans.iter().map(|s| s.odometry).collect();
        rebase(&mut odometry, start);
        for (scan, pose) in scans.iter_mut().zip(odometry) {
            scan.odometry = pose;
        }
        let geometry = lasers.map(|seen| seen.map(|s| s.geometry(&offsets)));
        Ok(Self {
            origin: origin.to_owned(),
            scans,
            geometry,
            reference_source,
            anchors,
        })
    }
}

/// The lasers' mount offsets from `PARAM` lines, metres: (front, rear).
/// The last value in the log wins; absent means 0.
fn mount_params(
    origin: &str,
    numbers: &[usize],
    records: &[Record],
) -> Result<(f64, f64), LogError> {
    let mut offsets = (0.0, 0.0);
    for (&line, record) in numbers.iter().zip(records) {
        let Record::Param { name, value } = record else {
            continue;
        };
        let slot = match name.as_str() {
            "robot_frontlaser_offset" => &mut offsets.0,
            "robot_rearlaser_offset" => &mut offsets.1,
            _ => continue,
        };
        *slot = value
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                LogError::malformed(
                    origin,
                    line,
                    format!("PARAM {name}: {value:?} is not a finite number"),
                )
            })?;
    }
    Ok(offsets)
}

/// What the scans of one laser have shown so far.
struct LaserSeen {
    source: LaserSource,
    first_line: usize,
    beam_count: usize,
    device: Option<Device>,
    /// `ROBOTLASER1`: the laser's pose on the robot, from its first line.
    mount: Pose2,
    largest: f64,
}

impl LaserSeen {
    fn first(line: usize, scan: &LaserLine) -> Self {
        Self {
            source: scan.source,
            first_line: line,
            beam_count: scan.ranges.len(),
            device: scan.device,
            mount: relative(&scan.robot_pose, &scan.laser_pose),
            largest: scan.ranges.iter().copied().fold(0.0, f64::max),
        }
    }

    /// A later scan: the same number of readings and the same device, or
    /// the laser has no one geometry.
    fn add(&mut self, scan: &LaserLine) -> Result<(), String> {
        let tag = self.source.tag();
        if scan.ranges.len() != self.beam_count {
            return Err(format!(
                "{tag} with {} readings, but the {tag} on line {} has {}",
                scan.ranges.len(),
                self.first_line,
                self.beam_count
            ));
        }
        if scan.device != self.device {
            return Err(format!(
                "{tag} start_angle, field_of_view, angular_resolution or maximum_range \
                 differ from the {tag} on line {}",
                self.first_line
            ));
        }
        self.largest = scan.ranges.iter().copied().fold(self.largest, f64::max);
        Ok(())
    }

    fn geometry(self, offsets: &(f64, f64)) -> LaserGeometry {
        // Counts fit: a line holds fewer fields than u32::MAX in practice,
        // and the rig refuses counts beyond its own limit anyway.
        let beam_count = u32::try_from(self.beam_count).unwrap_or(u32::MAX);
        match (self.source, self.device) {
            (_, Some(device)) => LaserGeometry {
                first_angle: device.start_angle,
                angle_step: device.resolution,
                beam_count,
                max_range: device.max_range,
                mount: self.mount,
            },
            (source, None) => {
                let (first_angle, angle_step) = default_fan(beam_count);
                LaserGeometry {
                    first_angle,
                    angle_step,
                    beam_count,
                    max_range: self.largest,
                    mount: match source {
                        LaserSource::Rear => rear_mount(offsets.1),
                        _ => front_mount(offsets.0),
                    },
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
