//! `deog frames`: what the map server holds of the robots' sonar frames:
//! each robot's count and range, or one robot's frames, followed live.

use anyhow::{Context, Result, bail};

use crate::frame_queue::FrameQueue;
use clap::Args;
use deog_proto::v1 as pb;
use deog_robot_client::MapClient;

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// Options of `deog frames`.
#[derive(Debug, Args)]
pub struct FramesArgs {
    /// Print this robot's frames, one line each; without it, list robots.
    #[arg(long)]
    pub robot: Option<String>,
    /// First sequence number to print.
    #[arg(long, default_value_t = 1)]
    pub from: u64,
    /// Keep printing frames as they arrive, until ctrl-c.
    #[arg(long, requires = "robot")]
    pub follow: bool,
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// One frame: its rig, its best pose (true, else reference, else
/// odometry, named) and its ranges.
fn line(frame: &pb::SonarFrame) -> String {
    let (which, pose) = match (frame.true_pose, frame.reference_pose) {
        (Some(p), _) => ("pose", p),
        (None, Some(p)) => ("reference", p),
        (None, None) => ("odometry", frame.odometry.unwrap_or_default()),
    };
    let ranges: Vec<String> = frame.ranges.iter().map(|r| format!("{r:.2}")).collect();
    format!(
        "{} #{} t={:.2}s rig={} {which}=({:.3}, {:.3}, {:.3}) ranges=[{}]",
        frame.robot,
        frame.sequence,
        frame.time_s,
        deog_proto::rig::frame_rig_name(&frame.rig),
        pose.x,
        pose.y,
        pose.theta,
        ranges.join(" ")
    )
}

/// Prints one line; false once the reader has gone (a closed pipe, as
/// `deog frames | head` closes it), which ends the listing quietly.
fn print(text: &str) -> Result<bool> {
    use std::io::Write as _;
    match writeln!(std::io::stdout().lock(), "{text}") {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
        Err(e) => Err(e).context("writing to standard output"),
    }
}

/// Runs the listing.
pub fn run(args: FramesArgs) -> Result<()> {
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async {
        // Deaf to the signal no more while it connects and waits to start:
        // until the loop below listens, the signal ends the process.
        let until_running = deog_harness::ExitOnSignal::during("connecting or waiting for the first frames", &tokio::runtime::Handle::current());
        let config = args.connection.client_config()?;
        let config = if args.follow {
            config.retrying_forever()
        } else {
            args.timeout.apply(config)?
        };
        let map = MapClient::connect(config).await?;
        let Some(robot) = &args.robot else {
            let robots = map.robots().await?;
            if robots.is_empty() {
                print("no frames stored yet")?;
            }
            for r in robots {
                let listed = format!(
                    "{}: {} frames, sequences {}..={}",
                    r.robot, r.frame_count, r.first_sequence, r.last_sequence
                );
                if !print(&listed)? {
                    break;
                }
            }
            return Ok(());
        };
        if !args.follow {
            let frames = map.read_frames(robot, args.from, 0).await?;
            if frames.is_empty() {
                let robots = map.robots().await?;
                let held = robots.iter().find(|r| &r.robot == robot);
                match held {
                    Some(r) => bail!(
                        "robot {robot} has no frame from sequence {}: its frames run {}..={}",
                        args.from,
                        r.first_sequence,
                        r.last_sequence
                    ),
                    None if robots.is_empty() => bail!(
                        "robot {robot} has published no frames: no robot has (--follow waits for them)"
                    ),
                    None => bail!(
                        "robot {robot} has published no frames (--follow waits for them); robots with frames: {}",
                        robots.iter().map(|r| r.robot.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                }
            }
            for frame in frames {
                if !print(&line(&frame))? {
                    break;
                }
            }
            return Ok(());
        }
        let mut frames = FrameQueue::follow(&map, robot, args.from, 0.0).await?;
        let shutdown = deog_harness::shutdown_signal();
        tokio::pin!(shutdown);
        drop(until_running);
        loop {
            tokio::select! {
                () = &mut shutdown => return Ok(()),
                frame = frames.next() => match frame? {
                    Some(frame) => if !print(&line(&frame))? {
                        return Ok(());
                    },
                    None => return Ok(()),
                },
            }
        }
    })
}
