//! `deog import --carmen LOG --robot R`: a CARMEN log's laser scans become
//! the robot's frames, with its raw odometry and its reference poses.

use std::path::Path;

use anyhow::{Context, Result, bail};
use deog_logs::{CarmenLog, LaserSource, ReferenceSource};
use deog_proto::names::check_robot_name;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_to_wire;

use super::{ImportArgs, LaserChoice, connect, publish_all};
use crate::rig_args::{load_rig, publish_rig};

/// Imports the CARMEN log `file` as `robot`'s frames. The whole log is read
/// and checked against the rig before anything is stored.
pub fn import(args: &ImportArgs, robot: &str, file: &Path) -> Result<()> {
    check_robot_name(robot).context("--robot")?;
    if args.first_sequence == 0 {
        bail!("--first-sequence must be at least 1");
    }
    let log = CarmenLog::load(file)?;
    let source = pick_laser(&log, args.laser)?;
    let rig = match &args.rig {
        Some(spec) => load_rig(spec)?,
        None => log.rig(source, &log_rig_name(&log, source))?,
    };
    log.check_rig(source, &rig)?;
    let scans: Vec<_> = log.scans_from(source).collect();
    // A log's clock can step back (the Intel log's does, four times);
    // frames keep file order, and their times never go back.
    let mut clock = f64::NEG_INFINITY;
    let frames: Vec<pb::SonarFrame> = scans
        .iter()
        .enumerate()
        .map(|(i, scan)| pb::SonarFrame {
            robot: robot.to_owned(),
            sequence: args.first_sequence + i as u64,
            time_s: {
                clock = clock.max(scan.time_s);
                clock
            },
            odometry: Some(pose_to_wire(scan.odometry)),
            true_pose: None,
            ranges: scan.ranges.clone(),
            rig: rig.name().to_owned(),
            reference_pose: scan.reference.map(pose_to_wire),
        })
        .collect();
    let count = frames.len();
    tracing::info!(
        log = %file.display(),
        laser = %source,
        scans = count,
        rig = rig.name(),
        readings = rig.readings(),
        reference = ?log.reference_source(),
        "read the log"
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    let (stored, duplicates) = runtime.block_on(async {
        let client = connect(args).await?;
        publish_rig(&client, &rig).await?;
        publish_all(&client, &frames).await
    })?;
    let reference = match log.reference_source() {
        ReferenceSource::TruePos => "TRUEPOS lines",
        ReferenceSource::Corrected => "the log's corrected poses",
        ReferenceSource::Absent => "none",
    };
    println!(
        "{}: {count} {source} scans read, {stored} stored, {duplicates} already there (robot {robot}, rig {}, {} readings each, sequences {}..={}; reference poses: {reference})",
        file.display(),
        rig.name(),
        rig.readings(),
        args.first_sequence,
        args.first_sequence + count as u64 - 1
    );
    if log.reference_source() != ReferenceSource::Absent {
        println!(
            "next: deog map --robot {robot} --map {robot} --pose reference --to {last}, then \
             deog localize --robot {robot} --map {robot} --from {first} --to {last} --initial-pose reference --preset real-laser",
            first = args.first_sequence,
            last = args.first_sequence + count as u64 - 1
        );
    }
    Ok(())
}

/// The laser asked for, or the front one, or the log's only one.
fn pick_laser(log: &CarmenLog, choice: Option<LaserChoice>) -> Result<LaserSource> {
    let sources = log.sources();
    let wanted = match choice {
        Some(LaserChoice::Front) => LaserSource::Front,
        Some(LaserChoice::Rear) => LaserSource::Rear,
        Some(LaserChoice::Robot) => LaserSource::RobotLaser,
        None if sources.contains(&LaserSource::Front) || sources.len() != 1 => LaserSource::Front,
        None => sources[0],
    };
    if !sources.contains(&wanted) {
        let has: Vec<String> = sources.iter().map(ToString::to_string).collect();
        bail!(
            "{} has no {wanted} scans (it has {})",
            log.origin(),
            if has.is_empty() {
                "none".to_owned()
            } else {
                has.join(", ")
            }
        );
    }
    Ok(wanted)
}

/// The name of the rig a log's laser makes: its kind of line, beam count
/// and no-return range, so that logs of one laser share a rig and logs of
/// different ones never collide.
fn log_rig_name(log: &CarmenLog, source: LaserSource) -> String {
    let (beams, max) = log
        .geometry(source)
        .map_or((0, 0.0), |g| (g.beam_count, g.max_range));
    format!(
        "carmen-{}-{beams}-{}",
        source.tag().to_ascii_lowercase(),
        format!("{max}").replace('.', "_")
    )
}
