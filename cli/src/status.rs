//! `deog status`: what a running system is doing, read from the map
//! server: its health, maps, robots and localizers, with rates over an
//! interval. The rows come from `deog_harness::status`; this file gathers
//! the samples over gRPC and prints them.

use std::collections::HashMap;
use std::io::{IsTerminal, Write as _};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::task::JoinHandle;

use anyhow::{Context, Result};
use clap::Args;
use deog_harness::status::{
    Bounds, EstimateSample, MapSample, RobotSample, Sample, ServerRow, status_rows, status_table,
};
use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

use crate::connection::{ConnectTimeoutArgs, ConnectionArgs};

/// How far behind its robot's newest frame an estimate may be and still be
/// read: 3,000 frames, five minutes of a robot firing at 10 Hz.
const ESTIMATE_WINDOW_FRAMES: u64 = 3_000;

/// Options of `deog status`.
#[derive(Debug, Args)]
pub struct StatusArgs {
    #[command(flatten)]
    pub connection: ConnectionArgs,
    /// Seconds between the two samples rates are measured over (and between
    /// redraws with --watch).
    #[arg(long, default_value_t = 1.0)]
    pub interval_s: f64,
    /// Redraw every interval until ctrl-c.
    #[arg(long)]
    pub watch: bool,
    /// Print one JSON object per sample instead of tables.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub timeout: ConnectTimeoutArgs,
}

/// When estimates and frames last arrived, by the status's own clock,
/// filled by the streams it follows between samples.
#[derive(Debug, Default)]
struct Arrivals {
    frames: HashMap<String, Instant>,
    estimates: HashMap<(String, String), Instant>,
}

/// The map server as status reads it: the client, its health client, and
/// the streams that time arrivals.
struct Sampler {
    client: MapClient,
    health: HealthClient<tonic::transport::Channel>,
    address: String,
    started: Instant,
    arrivals: Arc<Mutex<Arrivals>>,
    /// The task timing estimates; followed again once it ends (the server
    /// went away and came back).
    estimate_follower: Option<JoinHandle<()>>,
    /// The tasks timing each robot's frames, likewise.
    frame_followers: HashMap<String, JoinHandle<()>>,
}

/// Runs `deog status`.
pub fn run(args: StatusArgs) -> Result<()> {
    anyhow::ensure!(
        args.interval_s.is_finite() && (0.05..=3600.0).contains(&args.interval_s),
        "--interval-s must be within 0.05 and 3600 seconds, got {}",
        args.interval_s
    );
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async {
        tokio::select! {
            result = watch(&args) => result,
            () = deog_harness::shutdown_signal() => Ok(()),
        }
    })
}

async fn watch(args: &StatusArgs) -> Result<()> {
    let address = args.connection.server.clone();
    let config = args.timeout.apply(args.connection.client_config()?)?;
    let timeout = Duration::from_secs_f64(args.timeout.connect_timeout);
    // Unreachable, it says so itself, with the reason and a hint.
    let mut sampler = Sampler::connect(config, address.clone()).await?;
    let mut before = tokio::time::timeout(timeout, sampler.sample())
        .await
        .map_err(|_| {
            anyhow::anyhow!(
                "the map server at {address} did not answer within {:.1} s",
                args.timeout.connect_timeout
            )
        })?
        .with_context(|| format!("reading the status of {address}"))?;

    let interval = Duration::from_secs_f64(args.interval_s);
    let clear = args.watch && !args.json && std::io::stdout().is_terminal();
    loop {
        tokio::time::sleep(interval).await;
        let health = sampler.health(timeout).await;
        let after = match tokio::time::timeout(timeout, sampler.sample()).await {
            Ok(Ok(sample)) => sample,
            Ok(Err(error)) if args.watch => {
                // What was asked and the root cause: tonic's own chain
                // repeats itself over a whole screen line.
                print_block(&format!("error: {error}: {}", error.root_cause()), clear)?;
                continue;
            }
            Err(_) if args.watch => {
                print_block(&format!("error: {address} did not answer in time"), clear)?;
                continue;
            }
            Ok(Err(error)) => return Err(error),
            Err(_) => anyhow::bail!("the map server at {address} did not answer in time"),
        };
        let status = status_rows(
            ServerRow {
                address: address.clone(),
                health,
            },
            &before,
            &after,
        );
        let text = if args.json {
            serde_json::to_string(&status).context("writing the status as JSON")?
        } else {
            status_table(&status, after.at_s)
        };
        if !print_block(&text, clear)? || !args.watch {
            return Ok(());
        }
        before = after;
    }
}

/// Prints one block, after clearing the terminal when asked; false once
/// the reader has gone (a closed pipe).
fn print_block(text: &str, clear: bool) -> Result<bool> {
    let mut stdout = std::io::stdout().lock();
    let written = if clear {
        write!(stdout, "\x1b[2J\x1b[H{text}")
    } else {
        writeln!(stdout, "{text}")
    };
    match written.and_then(|()| stdout.flush()) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
        Err(e) => Err(e).context("writing to standard output"),
    }
}

impl Sampler {
    async fn connect(config: ClientConfig, address: String) -> Result<Self> {
        let client = MapClient::connect(config).await?;
        let mut sampler = Self {
            health: HealthClient::new(client.channel()),
            client,
            address,
            started: Instant::now(),
            arrivals: Arc::default(),
            estimate_follower: None,
            frame_followers: HashMap::new(),
        };
        sampler.follow_estimates().await?;
        Ok(sampler)
    }

    /// The health service's word on the map service, or why there is none.
    async fn health(&mut self, timeout: Duration) -> String {
        let request = tonic_health::pb::HealthCheckRequest {
            service: "deog.v1.MapService".into(),
        };
        match tokio::time::timeout(timeout, self.health.check(request)).await {
            Ok(Ok(reply)) => ServingStatus::try_from(reply.into_inner().status)
                .map_or("UNKNOWN", |s| s.as_str_name())
                .to_string(),
            Ok(Err(status)) => format!("unreachable ({})", status.code()),
            Err(_) => "unreachable (no answer)".to_string(),
        }
    }

    /// Times every estimate that arrives from now on, whatever its robot.
    async fn follow_estimates(&mut self) -> Result<()> {
        if self
            .estimate_follower
            .as_ref()
            .is_some_and(|task| !task.is_finished())
        {
            return Ok(());
        }
        let mut stream = self
            .client
            .raw()
            .watch_poses(pb::WatchPosesRequest {
                robot: String::new(),
            })
            .await
            .with_context(|| format!("following the estimates on {}", self.address))?
            .into_inner();
        let arrivals = Arc::clone(&self.arrivals);
        self.estimate_follower = Some(tokio::spawn(async move {
            while let Ok(Some(estimate)) = stream.message().await {
                if let Ok(mut arrivals) = arrivals.lock() {
                    arrivals
                        .estimates
                        .insert((estimate.robot, estimate.map), Instant::now());
                }
            }
        }));
        Ok(())
    }

    /// Times the frames of `robot` that arrive from now on.
    async fn follow_frames(&mut self, robot: &str) -> Result<()> {
        if self
            .frame_followers
            .get(robot)
            .is_some_and(|task| !task.is_finished())
        {
            return Ok(());
        }
        let mut stream = self.client.subscribe_frames(robot, 0).await?;
        let arrivals = Arc::clone(&self.arrivals);
        let name = robot.to_string();
        let task = tokio::spawn(async move {
            while let Ok(Some(_)) = stream.message().await {
                if let Ok(mut arrivals) = arrivals.lock() {
                    arrivals.frames.insert(name.clone(), Instant::now());
                }
            }
        });
        self.frame_followers.insert(robot.to_string(), task);
        Ok(())
    }

    fn clock_s(&self, instant: Instant) -> f64 {
        instant
            .saturating_duration_since(self.started)
            .as_secs_f64()
    }

    /// Reads maps, robots and the newest estimates once.
    async fn sample(&mut self) -> Result<Sample> {
        let maps = self
            .client
            .raw()
            .list_maps(pb::ListMapsRequest {})
            .await
            .context("listing the maps")?
            .into_inner()
            .maps;
        let mut map_samples = Vec::new();
        for info in &maps {
            let writers = self
                .client
                .update_cursors(&info.name)
                .await
                .with_context(|| format!("listing the writers of map {}", info.name))?;
            map_samples.push(map_sample(
                info,
                writers
                    .into_iter()
                    .map(|c| (c.client_id, c.last_sequence))
                    .collect(),
            ));
        }
        let robots = self.client.robots().await.context("listing the robots")?;
        self.follow_estimates().await?;
        for robot in &robots {
            self.follow_frames(&robot.robot)
                .await
                .with_context(|| format!("following the frames of {}", robot.robot))?;
        }

        let mut robot_samples = Vec::new();
        let mut estimates = Vec::new();
        for robot in &robots {
            let newest = self
                .client
                .read_frames(&robot.robot, robot.last_sequence, robot.last_sequence)
                .await
                .with_context(|| format!("reading the newest frame of {}", robot.robot))?;
            estimates.extend(self.newest_estimates(robot).await?);
            robot_samples.push(RobotSample {
                name: robot.robot.clone(),
                frames: robot.frame_count,
                last_sequence: robot.last_sequence,
                last_frame_time_s: newest.first().map(|f| f.time_s),
                last_arrival_s: None,
            });
        }

        let at = Instant::now();
        let arrivals = self
            .arrivals
            .lock()
            .map_err(|_| anyhow::anyhow!("a stream follower panicked"))?;
        for robot in &mut robot_samples {
            robot.last_arrival_s = arrivals.frames.get(&robot.name).map(|&t| self.clock_s(t));
        }
        for estimate in &mut estimates {
            let key = (estimate.robot.clone(), estimate.map.clone());
            estimate.last_arrival_s = arrivals.estimates.get(&key).map(|&t| self.clock_s(t));
        }
        Ok(Sample {
            at_s: self.clock_s(at),
            maps: map_samples,
            robots: robot_samples,
            estimates,
        })
    }

    /// The newest estimate of `robot` on each map it is localized on,
    /// among those of its recent frames, with the truth its frame carries.
    async fn newest_estimates(&self, robot: &pb::RobotFrames) -> Result<Vec<EstimateSample>> {
        let from = robot
            .last_sequence
            .saturating_sub(ESTIMATE_WINDOW_FRAMES)
            .max(1);
        let poses = self
            .client
            .read_poses(&robot.robot, from, 0)
            .await
            .with_context(|| format!("reading the estimates of {}", robot.robot))?;
        let mut newest: HashMap<&str, &pb::PoseEstimate> = HashMap::new();
        for pose in &poses {
            let slot = newest.entry(pose.map.as_str()).or_insert(pose);
            if pose.frame_sequence >= slot.frame_sequence {
                *slot = pose;
            }
        }
        let mut samples = Vec::new();
        for estimate in newest.into_values() {
            let frame = self
                .client
                .read_frames(
                    &robot.robot,
                    estimate.frame_sequence,
                    estimate.frame_sequence,
                )
                .await
                .with_context(|| format!("reading a frame of {}", robot.robot))?;
            let pose = estimate.pose.unwrap_or_default();
            samples.push(EstimateSample {
                robot: estimate.robot.clone(),
                map: estimate.map.clone(),
                frame_sequence: estimate.frame_sequence,
                frame_time_s: estimate.time_s,
                converged: estimate.converged,
                lost_score: estimate.lost_score,
                position: (pose.x, pose.y),
                true_position: frame.first().and_then(|f| f.true_pose).map(|p| (p.x, p.y)),
                last_arrival_s: None,
            });
        }
        Ok(samples)
    }
}

fn map_sample(info: &pb::MapInfo, writers: Vec<(String, u64)>) -> MapSample {
    MapSample {
        name: info.name.clone(),
        cells: info.cell_count,
        tiles: info.tile_count,
        bounds: info.bounds_m.map(|b| Bounds {
            min_x: b.min_x,
            min_y: b.min_y,
            max_x: b.max_x,
            max_y: b.max_y,
        }),
        version: info.version,
        writers,
    }
}
