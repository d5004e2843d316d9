//! A recording's scans as the readings of frames, with the rig they
//! make: each LaserScan, or each round of Range messages in which every
//! sonar reported once.

use deog_rig::Rig;

use crate::error::RecordingError;
use crate::import::{ImportOptions, MountSource};
use crate::messages::{LaserScan, Range};
use crate::scan_rig::{
    LaserLayout, Mount, StaticTransforms, laser_layout, recorded_rig, sonar_sensor,
};
use crate::topics::{Topic, decode_on, stamp_seconds};

/// Tolerance on a scan's angles against the first scan's, radians.
const ANGLE_TOLERANCE: f64 = 1e-6;

/// Scans with their times, and the rig they make.
pub(crate) struct Scans {
    /// The rig the readings are in.
    pub(crate) rig: Rig,
    /// (seconds, ranges in the rig's order), in time order.
    pub(crate) scans: Vec<(f64, Vec<f64>)>,
    /// Messages read.
    pub(crate) messages: usize,
    /// Rounds of sonars left out unfinished.
    pub(crate) incomplete: usize,
    /// Where the mounts came from.
    pub(crate) mounts: MountSource,
}

/// Where the frame `frame_id` sits on the robot, and what that says of
/// the mounts.
pub(crate) fn find_mount(
    transforms: &StaticTransforms,
    base: &str,
    frame_id: &str,
) -> (Mount, MountSource) {
    match transforms.mount(base, frame_id) {
        Some(mount) => (mount, MountSource::StaticTransforms(base.to_owned())),
        None => (Mount::IDENTITY, MountSource::Identity),
    }
}

/// A reading as deog stores it: finite and non-negative. NaN, negative
/// and +inf readings (REP 117's "no valid return") become the beam's
/// no-echo value; -inf ("too close") its minimum range.
pub(crate) fn stored_range(value: f32, beam: &deog_rig::Beam) -> f64 {
    let value = f64::from(value);
    let no_echo = if beam.no_echo.at_or_beyond.is_finite() {
        beam.no_echo.at_or_beyond
    } else {
        beam.max_range
    };
    if value == f64::NEG_INFINITY {
        beam.min_range
    } else if value.is_nan() || value < 0.0 || !value.is_finite() {
        no_echo
    } else {
        value
    }
}

pub(crate) fn laser_scans(
    name: &str,
    topic: &Topic,
    transforms: &StaticTransforms,
    base: &str,
    options: &ImportOptions,
) -> Result<Scans, RecordingError> {
    let mut messages = Vec::with_capacity(topic.messages.len());
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let scan = decode_on::<LaserScan>(name, topic, index, bytes)?;
        messages.push((stamp_seconds(scan.header.stamp, *log_time), index, scan));
    }
    let Some((_, _, first)) = messages.first() else {
        return Err(RecordingError::Empty(format!("{name} holds no scan")));
    };
    let (mount, mut mounts) = find_mount(transforms, base, &first.header.frame_id);
    let layout: LaserLayout = laser_layout(first, mount);
    let rig = match &options.rig {
        Some(rig) => {
            mounts = MountSource::GivenRig;
            rig.clone()
        }
        None => recorded_rig("laser", vec![layout.sensor], name)?,
    };
    let (count, angle_min, increment) = (
        first.ranges.len(),
        f64::from(first.angle_min),
        f64::from(first.angle_increment),
    );
    let mut scans = Vec::with_capacity(messages.len());
    for (time, index, scan) in &messages {
        if scan.ranges.len() != count
            || (f64::from(scan.angle_min) - angle_min).abs() > ANGLE_TOLERANCE
            || (f64::from(scan.angle_increment) - increment).abs() > ANGLE_TOLERANCE
        {
            return Err(RecordingError::Geometry(format!(
                "scan {} on {name} has {} beams from {} rad {} rad apart; the first had {count} from {angle_min} rad {increment} rad apart",
                index + 1,
                scan.ranges.len(),
                scan.angle_min,
                scan.angle_increment
            )));
        }
        if scan.ranges.len() != rig.readings() {
            return Err(RecordingError::Geometry(format!(
                "scan {} on {name} has {} ranges; rig {} reads {}",
                index + 1,
                scan.ranges.len(),
                rig.name(),
                rig.readings()
            )));
        }
        let mut values: Vec<f32> = scan.ranges.clone();
        if layout.reversed && options.rig.is_none() {
            values.reverse();
        }
        let ranges: Vec<f64> = values
            .iter()
            .zip(rig.beams())
            .map(|(&v, beam)| stored_range(v, beam))
            .collect();
        check_ranges(&rig, &ranges, name, *index)?;
        scans.push((*time, ranges));
    }
    scans.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(Scans {
        rig,
        scans,
        messages: messages.len(),
        incomplete: 0,
        mounts,
    })
}

pub(crate) fn check_ranges(
    rig: &Rig,
    ranges: &[f64],
    name: &str,
    index: usize,
) -> Result<(), RecordingError> {
    rig.check_frame(ranges).map_err(|error| {
        RecordingError::Geometry(format!("scan {} on {name}: {error}", index + 1))
    })?;
    Ok(())
}

pub(crate) fn sonar_scans(
    name: &str,
    topic: &Topic,
    transforms: &StaticTransforms,
    base: &str,
    options: &ImportOptions,
) -> Result<Scans, RecordingError> {
    let mut messages = Vec::with_capacity(topic.messages.len());
    for (index, (log_time, bytes)) in topic.messages.iter().enumerate() {
        let range = decode_on::<Range>(name, topic, index, bytes)?;
        messages.push((stamp_seconds(range.header.stamp, *log_time), index, range));
    }
    if messages.is_empty() {
        return Err(RecordingError::Empty(format!("{name} holds no reading")));
    }
    messages.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The sonars, in the order they first report.
    let mut sonars: Vec<&Range> = Vec::new();
    for (_, _, range) in &messages {
        if !sonars
            .iter()
            .any(|s| s.header.frame_id == range.header.frame_id)
        {
            sonars.push(range);
        }
    }
    let mut mounts = MountSource::StaticTransforms(base.to_owned());
    let mut sensors = Vec::with_capacity(sonars.len());
    for sonar in &sonars {
        let (mount, source) = find_mount(transforms, base, &sonar.header.frame_id);
        if source == MountSource::Identity {
            mounts = MountSource::Identity;
        }
        sensors.push(sonar_sensor(sonar, mount));
    }
    let rig = match &options.rig {
        Some(rig) => {
            mounts = MountSource::GivenRig;
            rig.clone()
        }
        None => recorded_rig("sonar", sensors, name)?,
    };
    if rig.readings() != sonars.len() {
        return Err(RecordingError::Geometry(format!(
            "{name} has {} sonars; rig {} reads {}",
            sonars.len(),
            rig.name(),
            rig.readings()
        )));
    }
    // A round is one reading of each sonar; a sonar heard twice before
    // the round is whole ends it unfinished.
    let mut scans = Vec::new();
    let mut incomplete = 0;
    let mut round: Vec<Option<f32>> = vec![None; sonars.len()];
    let mut round_time = f64::NEG_INFINITY;
    for (time, index, range) in &messages {
        let Some(slot) = sonars
            .iter()
            .position(|s| s.header.frame_id == range.header.frame_id)
        else {
            continue;
        };
        if round[slot].is_some() {
            incomplete += 1;
            round.iter_mut().for_each(|r| *r = None);
            round_time = f64::NEG_INFINITY;
        }
        round[slot] = Some(range.range);
        round_time = round_time.max(*time);
        if round.iter().all(Option::is_some) {
            let ranges: Vec<f64> = round
                .iter()
                .zip(rig.beams())
                .map(|(v, beam)| stored_range(v.unwrap_or(f32::NAN), beam))
                .collect();
            check_ranges(&rig, &ranges, name, *index)?;
            scans.push((round_time, ranges));
            round.iter_mut().for_each(|r| *r = None);
            round_time = f64::NEG_INFINITY;
        }
    }
    if round.iter().any(Option::is_some) {
        incomplete += 1;
    }
    Ok(Scans {
        rig,
        scans,
        messages: messages.len(),
        incomplete,
        mounts,
    })
}
