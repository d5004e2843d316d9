//! `deog demo`: the whole system, each part its own OS process started from
//! this binary. A map server on a fresh sled folder, the simulator, and per
//! robot a wanderer and a cartographer building one shared map; once the
//! map has a head start, a localizer per robot that knows nothing of where
//! its robot is; half-way through, the first robot is kidnapped. When the
//! wanderers end, the demo waits for the cartographers and localizers to
//! drain their frames, judges the map and the estimates with the same code
//! as `deog eval`, and writes everything to `--out`.

use std::ffi::OsString;
use std::fmt::Write as _;
use std::future::Future;
use std::io::{IsTerminal, Write as _};
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use deog_evaluation::localization::{
    self as evaluation, EvalInput, EvalParams, LocalizationReport, PlotInput, RobotPath,
};
use deog_evaluation::map_quality::{
    DEFAULT_ROBOT_RADIUS_M, MapQuality, QualityInput, map_quality, verdict_png,
};
use deog_grid::{Pose2, TileMap};
use deog_mapfile::{to_png, write_map};
use deog_mapping::export_map;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_from_wire;
use deog_robot_client::{ClientConfig, MapClient, SimClient};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_world::{World, load_world_spec};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use deog_harness::run_reads::{read_map, read_robot, robot_starts};
use deog_harness::{Role, Supervisor, connect, free_loopback_addr, os};

/// Options of `deog demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// The world: map1, map2 or office (built in, as in worlds/), or a file:
    /// a .toml world or a ROS map_server .yaml map.
    #[arg(long, default_value = "map2")]
    world: String,
    /// Robots in the world, each with its wanderer, cartographer and
    /// localizer (1 to 8).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=8))]
    robots: u32,
    /// Seed of the simulator, the wanderers, the localizers and the kidnap.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds the robots drive.
    #[arg(long, default_value_t = 240.0)]
    duration: f64,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 4.0)]
    speed: f64,
    /// Simulated second at which the localizers start (default: a quarter of
    /// --duration), so that the map has a head start.
    #[arg(long)]
    localize_at: Option<f64>,
    /// Simulated second at which the first robot is kidnapped (default:
    /// half of --duration).
    #[arg(long, conflicts_with = "no_kidnap")]
    kidnap_at: Option<f64>,
    /// Kidnap nobody.
    #[arg(long)]
    no_kidnap: bool,
    /// Leave the map server running at the end, to look at the map and the
    /// robots' frames with other deog commands (its address and process id
    /// are printed).
    #[arg(long)]
    keep: bool,
    /// Folder for the map, the plots, report.md, report.json, the
    /// processes' logs and the server's data; its earlier demo files are
    /// replaced.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
}

/// The name of the shared map on the server.
const MAP: &str = "demo";
/// How long the cartographers and localizers may take to drain their
/// frames after the wanderers stop, wall-clock.
const FINISH_TIMEOUT: Duration = Duration::from_secs(300);
/// A cartographer or localizer ends once no frame came for this long.
const IDLE_EXIT_S: &str = "3";

/// The demo's settings, checked.
struct Plan {
    world: World,
    robots: Vec<String>,
    localize_at: f64,
    kidnap_at: Option<f64>,
}

impl Plan {
    fn new(args: &DemoArgs) -> Result<Self> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                bail!("{name} must be a positive number of seconds, got {v}")
            }
        };
        let duration = positive("--duration", args.duration)?;
        if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0) {
            bail!(
                "--speed must be above 0 and at most 100 simulated seconds per second, got {}",
                args.speed
            );
        }
        let localize_at = match args.localize_at {
            Some(t) if !(t.is_finite() && (0.0..duration).contains(&t)) => {
                bail!("--localize-at must be within 0 and --duration ({duration} s), got {t}")
            }
            Some(t) => t,
            None => duration / 4.0,
        };
        let kidnap_at = match (args.no_kidnap, args.kidnap_at) {
            (true, _) => None,
            (false, Some(t)) if !(t.is_finite() && t > localize_at && t < duration) => bail!(
                "--kidnap-at must come after --localize-at ({localize_at} s) and before --duration ({duration} s), got {t}"
            ),
            (false, Some(t)) => Some(t),
            (false, None) => Some(duration / 2.0),
        };
        let world = load_world_spec(&args.world)?;
        Ok(Self {
            world,
            robots: (1..=args.robots).map(|i| format!("scout-{i}")).collect(),
            localize_at,
            kidnap_at,
        })
    }
}

/// The kidnap as it happened.
struct KidnapDone {
    robot: String,
    time_s: f64,
    from: Pose2,
    to: Pose2,
}

/// Runs the demo.
pub fn run(args: DemoArgs) -> Result<()> {
    let plan = Plan::new(&args)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(demo(&args, &plan))
}

async fn demo(args: &DemoArgs, plan: &Plan) -> Result<()> {
    let started = Instant::now();
    let out = &args.out;
    prepare_out(out)?;
    let data = out.join("server-data");
    let mut children = Supervisor::new(&out.join("logs"))?;
    let server_addr = free_loopback_addr()?;
    let sim_addr = free_loopback_addr()?;
    let server_url = format!("http://{server_addr}");
    let sim_url = format!("http://{sim_addr}");
    let seed = args.seed.to_string();

    println!(
        "deog demo: {} with {} robots for {} simulated s at {}x; writing to {}",
        plan.world.name(),
        plan.robots.len(),
        args.duration,
        args.speed,
        out.display()
    );
    children.start(
        "server",
        Role::Service,
        &os(&["server", "--listen", &server_addr.to_string()])
            .into_iter()
            .chain([OsString::from("--data"), data.clone().into_os_string()])
            .collect::<Vec<_>>(),
    )?;
    children.start(
        "sim",
        Role::Service,
        &os(&[
            "sim",
            "--world",
            &args.world,
            "--listen",
            &sim_addr.to_string(),
            "--speed",
            &args.speed.to_string(),
            "--seed",
            &seed,
        ]),
    )?;
    let map_client = connect(&mut children, "map server", || {
        MapClient::connect(ClientConfig::new(server_url.clone()))
    })
    .await?;
    let sim = connect(&mut children, "simulator", || {
        SimClient::connect(ClientConfig::new(sim_url.clone()))
    })
    .await?;

    for (i, robot) in plan.robots.iter().enumerate() {
        let robot_seed = robot_seed(args.seed, i);
        children.start(
            &format!("wander-{robot}"),
            Role::Task,
            &os(&[
                "wander",
                "--robot",
                robot,
                "--spawn",
                "--seed",
                &robot_seed,
                "--duration",
                &args.duration.to_string(),
                "--sim",
                &sim_url,
                "--server",
                &server_url,
            ]),
        )?;
        children.start(
            &format!("map-{robot}"),
            Role::Task,
            &os(&[
                "map",
                "--robot",
                robot,
                "--map",
                MAP,
                "--idle-exit",
                IDLE_EXIT_S,
                "--server",
                &server_url,
            ]),
        )?;
    }

    let mut status = StatusLine::new();
    let mut pacer = Pacer::new();
    let mut localizing = false;
    let mut kidnap: Option<KidnapDone> = None;
    let mut follow = vec![Follow::default(); plan.robots.len()];
    // Driving: until every wanderer has finished its simulated time.
    loop {
        pacer.next(&mut status).await?;
        children.check()?;
        let states = sim.robots().await.context("asking the simulator")?;
        let now = states.iter().map(|s| s.time_s).fold(0.0, f64::max);
        if !localizing && now >= plan.localize_at && states.len() == plan.robots.len() {
            for (i, robot) in plan.robots.iter().enumerate() {
                let robot_seed = robot_seed(args.seed, i);
                children.start(
                    &format!("localize-{robot}"),
                    Role::Task,
                    &os(&[
                        "localize",
                        "--robot",
                        robot,
                        "--map",
                        MAP,
                        "--idle-exit",
                        IDLE_EXIT_S,
                        "--seed",
                        &robot_seed,
                        "--server",
                        &server_url,
                    ]),
                )?;
            }
            localizing = true;
            status.note(&format!(
                "{now:.0} s: localizers started, knowing nothing of where their robots are"
            ));
        }
        if let Some(at) = plan.kidnap_at
            && kidnap.is_none()
            && now >= at
            && let Some(state) = states.iter().find(|s| s.name == plan.robots[0])
        {
            let done = kidnap_robot(&sim, &plan.world, state, args.seed).await?;
            status.note(&format!(
                "{:.0} s: {} kidnapped from ({:.2}, {:.2}) to ({:.2}, {:.2})",
                done.time_s, done.robot, done.from.x, done.from.y, done.to.x, done.to.y
            ));
            kidnap = Some(done);
        }
        let line = progress(&map_client, &plan.robots, &mut follow, now, args.duration).await;
        status.show(&line);
        if children.all_done("wander-") {
            break;
        }
    }
    // Draining: the cartographers and localizers end once idle.
    let finishing = Instant::now();
    while !(children.all_done("map-") && children.all_done("localize-")) {
        pacer.next(&mut status).await?;
        children.check()?;
        let mut waiting = children.running("map-");
        waiting.extend(children.running("localize-"));
        if finishing.elapsed() > FINISH_TIMEOUT {
            bail!(
                "{} still had frames to work through {} s after the robots stopped",
                waiting.join(", "),
                FINISH_TIMEOUT.as_secs()
            );
        }
        status.show(&format!(
            "robots stopped; {} working through their last frames",
            waiting.join(", ")
        ));
    }
    status.finish();
    children.check()?;

    let results = judge(&map_client, plan, out).await?;
    let wall_s = started.elapsed().as_secs_f64();
    let report = Report {
        args,
        plan,
        results: &results,
        kidnap: kidnap.as_ref(),
        wall_s,
        commands: children
            .command_lines()
            .map(|(name, line)| (name.to_string(), line.to_string()))
            .collect(),
    };
    std::fs::write(out.join("report.md"), report.markdown())
        .with_context(|| format!("writing {}", out.join("report.md").display()))?;
    std::fs::write(out.join("report.json"), report.json()?)
        .with_context(|| format!("writing {}", out.join("report.json").display()))?;
    print!("{}", report.summary());
    if args.keep {
        children.keep("server");
        println!(
            "the map server keeps running at {server_url} (process {}), data in {}; stop it with: kill {}",
            children.pid("server").unwrap_or_default(),
            data.display(),
            children.pid("server").unwrap_or_default()
        );
    }
    Ok(())
}

/// The seed of robot `index`'s wanderer and localizer.
fn robot_seed(seed: u64, index: usize) -> String {
    seed.wrapping_mul(1000)
        .wrapping_add(index as u64 + 1)
        .to_string()
}

/// The demo's clock: a tick every quarter second, and ctrl-c or SIGTERM.
struct Pacer {
    tick: tokio::time::Interval,
    shutdown: Pin<Box<dyn Future<Output = ()> + Send>>,
}

impl Pacer {
    fn new() -> Self {
        Self {
            tick: tokio::time::interval(Duration::from_millis(250)),
            shutdown: Box::pin(crate::signal::shutdown()),
        }
    }

    /// Waits for the next tick. An interrupt is an error: on its way out
    /// the supervisor stops every process.
    async fn next(&mut self, status: &mut StatusLine) -> Result<()> {
        tokio::select! {
            () = &mut self.shutdown => {
                status.finish();
                bail!("interrupted: every process of the demo was stopped");
            }
            _ = self.tick.tick() => Ok(()),
        }
    }
}

/// Creates `out` and clears what an earlier demo left in it.
fn prepare_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for folder in ["server-data", "logs"] {
        let path = out.join(folder);
        if path.exists() {
            std::fs::remove_dir_all(&path)
                .with_context(|| format!("clearing {} of an earlier demo", path.display()))?;
        }
    }
    Ok(())
}

/// Carries `state`'s robot to a random free pose at least 2 m away, with
/// another heading; its odometry does not notice.
async fn kidnap_robot(
    sim: &SimClient,
    world: &World,
    state: &pb::RobotState,
    seed: u64,
) -> Result<KidnapDone> {
    let from = state
        .true_pose
        .map(pose_from_wire)
        .context("the simulator gave no true pose")?;
    let sampler = Simulation::new(world.clone(), SimConfig::default(), seed)
        .context("setting up the kidnap")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6b69_646e_6170);
    let mut to = sampler.random_free_pose(&mut rng)?;
    for _ in 0..1000 {
        if (to.x - from.x).hypot(to.y - from.y) >= 2.0 {
            break;
        }
        to = sampler.random_free_pose(&mut rng)?;
    }
    let after = sim
        .teleport(&state.name, to)
        .await
        .with_context(|| format!("kidnapping {}", state.name))?;
    Ok(KidnapDone {
        robot: state.name.clone(),
        time_s: after.time_s,
        from,
        to,
    })
}

/// What the status line last learnt of one robot's localizer.
#[derive(Debug, Clone, Copy, Default)]
struct Follow {
    /// The frame of the latest estimate read; reading goes on from there.
    cursor: u64,
    /// That estimate's position error, metres, and the filter's flag.
    error: Option<(f64, bool)>,
}

/// The status line: simulated time, frames, map cells, and each robot's
/// latest position error, with how many frames its localizer is behind.
async fn progress(
    client: &MapClient,
    robots: &[String],
    follow: &mut [Follow],
    now: f64,
    duration: f64,
) -> String {
    let mut line = format!("{now:5.0}/{duration:.0} s");
    let listed = client.robots().await.unwrap_or_default();
    let frames: u64 = listed.iter().map(|r| r.frame_count).sum();
    let _ = write!(line, " | {frames} frames");
    if let Ok(info) = client.map_info(MAP).await {
        let _ = write!(line, " | map {} cells", info.cell_count);
    }
    for (robot, follow) in robots.iter().zip(follow.iter_mut()) {
        let last = listed
            .iter()
            .find(|r| &r.robot == robot)
            .map_or(0, |r| r.last_sequence);
        if let Some((sequence, error)) = latest_error(client, robot, follow.cursor).await {
            *follow = Follow {
                cursor: sequence,
                error: Some(error),
            };
        }
        let _ = write!(line, " | {robot} ");
        match follow.error {
            Some((metres, converged)) => {
                let flag = if converged { "" } else { "?" };
                let _ = write!(line, "{metres:.2} m{flag}");
                let behind = last.saturating_sub(follow.cursor);
                if behind > 10 {
                    let _ = write!(line, " ({behind} frames behind)");
                }
            }
            None => line.push('-'),
        }
    }
    line
}

/// The frame and position error of a robot's latest estimate after frame
/// `after`, and whether the filter called itself converged.
async fn latest_error(client: &MapClient, robot: &str, after: u64) -> Option<(u64, (f64, bool))> {
    let poses = client.read_poses(robot, after + 1, 0).await.ok()?;
    let estimate = poses.iter().rev().find(|p| p.map == MAP)?;
    let frame = client
        .read_frames(robot, estimate.frame_sequence, estimate.frame_sequence)
        .await
        .ok()?;
    let truth = frame.first()?.true_pose?;
    let pose = estimate.pose?;
    let metres = (pose.x - truth.x).hypot(pose.y - truth.y);
    Some((estimate.frame_sequence, (metres, estimate.converged)))
}

/// A status line rewritten in place on a terminal, printed every ten
/// seconds otherwise.
struct StatusLine {
    terminal: bool,
    last_printed: Option<Instant>,
    shown: bool,
}

impl StatusLine {
    fn new() -> Self {
        Self {
            terminal: std::io::stderr().is_terminal(),
            last_printed: None,
            shown: false,
        }
    }

    fn show(&mut self, line: &str) {
        let mut err = std::io::stderr().lock();
        if self.terminal {
            let _ = write!(err, "\r\x1b[2K{line}");
            let _ = err.flush();
            self.shown = true;
        } else if self
            .last_printed
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(10))
        {
            let _ = writeln!(err, "{line}");
            self.last_printed = Some(Instant::now());
        }
    }

    /// A line that stays, printed above the status line.
    fn note(&mut self, text: &str) {
        self.finish();
        eprintln!("{text}");
    }

    fn finish(&mut self) {
        if self.shown {
            eprintln!();
            self.shown = false;
        }
    }
}

/// One robot's figures and its plot's file name.
struct RobotResult {
    report: LocalizationReport,
    plot: String,
}

/// What the judging found.
struct Results {
    robots: Vec<RobotResult>,
    quality: MapQuality,
    map_png: String,
    map_yaml: String,
}

/// Judges the map against the world and each localizer against its
/// robot's true poses; writes the map files and the path plots.
async fn judge(client: &MapClient, plan: &Plan, out: &Path) -> Result<Results> {
    let map = read_map(client, MAP).await?;
    let seeds = robot_starts(client).await?;
    let input = QualityInput {
        map: &map,
        world: &plan.world,
        seeds: &seeds,
        robot_radius_m: DEFAULT_ROBOT_RADIUS_M,
    };
    let quality = map_quality(&input).context("judging the map against the world")?;
    let (map_yaml, map_png) = write_map_files(&map, out)?;
    let png = verdict_png(&input).context("drawing where the map is right and wrong")?;
    std::fs::write(out.join(VERDICT_PNG), png)
        .with_context(|| format!("writing {}", out.join(VERDICT_PNG).display()))?;
    let mut robots = Vec::with_capacity(plan.robots.len());
    for name in &plan.robots {
        // Judge from the first frame the localizer saw, not from the
        // mapping head start before it ran.
        let first = client
            .read_poses(name, 0, 0)
            .await
            .with_context(|| format!("reading the estimates of {name}"))?
            .iter()
            .filter(|p| p.map == MAP)
            .map(|p| p.frame_sequence)
            .min()
            .with_context(|| format!("the localizer of {name} published no estimate"))?;
        let samples = read_robot(client, name, Some(MAP), first, 0).await?;
        let report = evaluation::evaluate(&EvalInput {
            robot: name,
            map: Some(MAP),
            truth: &samples.truth,
            estimates: &samples.estimates,
            params: EvalParams::default(),
            known_kidnaps: &[],
        })
        .with_context(|| format!("judging the estimates of {name}"))?;
        let plot = format!("{name}.png");
        let raster = evaluation::render_plot(&PlotInput {
            map: Some(&map),
            robots: &[RobotPath {
                truth: &samples.truth,
                estimates: &samples.estimates,
                kidnaps: &report.kidnaps,
            }],
        })
        .with_context(|| format!("drawing the paths of {name}"))?;
        let png = raster.to_png().context("encoding the plot")?;
        std::fs::write(out.join(&plot), png)
            .with_context(|| format!("writing {}", out.join(&plot).display()))?;
        robots.push(RobotResult { report, plot });
    }
    Ok(Results {
        robots,
        quality,
        map_png,
        map_yaml,
    })
}

/// Where the map is right and wrong, drawn over the world.
const VERDICT_PNG: &str = "map-verdict.png";

/// The map as map_server files and a PNG; returns the YAML and PNG names.
fn write_map_files(map: &TileMap, out: &Path) -> Result<(String, String)> {
    let export = export_map(map).context("exporting the map")?;
    write_map(out, "map", &export.image)?;
    to_png(out.join("map.png"), &export.image)?;
    Ok(("map.yaml".to_string(), "map.png".to_string()))
}

/// Everything the report files say.
struct Report<'a> {
    args: &'a DemoArgs,
    plan: &'a Plan,
    results: &'a Results,
    kidnap: Option<&'a KidnapDone>,
    wall_s: f64,
    commands: Vec<(String, String)>,
}

impl Report<'_> {
    /// report.json: the robots' and the map's figures, with the run's
    /// settings.
    fn json(&self) -> Result<String> {
        let robots = self
            .results
            .robots
            .iter()
            .map(|r| serde_json::from_str::<serde_json::Value>(&r.report.to_json()))
            .collect::<Result<Vec<_>, _>>()
            .context("assembling report.json")?;
        let map: serde_json::Value = serde_json::from_str(&self.results.quality.to_json())
            .context("assembling report.json")?;
        let kidnap = self.kidnap.map(|k| {
            serde_json::json!({
                "robot": k.robot,
                "time_s": k.time_s,
                "from": {"x": k.from.x, "y": k.from.y, "theta": k.from.theta},
                "to": {"x": k.to.x, "y": k.to.y, "theta": k.to.theta},
            })
        });
        let report = serde_json::json!({
            "robots": robots,
            "map": map,
            "duration_s": self.wall_s,
            "simulated_s": self.args.duration,
            "speed": self.args.speed,
            "world": self.plan.world.name(),
            "seed": self.args.seed,
            "localize_at_s": self.plan.localize_at,
            "kidnap": kidnap,
        });
        let mut text = serde_json::to_string_pretty(&report).context("assembling report.json")?;
        text.push('\n');
        Ok(text)
    }

    /// The short table printed at the end.
    fn summary(&self) -> String {
        let mut out = String::new();
        let q = &self.results.quality;
        let _ = writeln!(
            out,
            "\nmap: {} cells observed, {:.1}% classified right, occupied precision {}, recall {}",
            q.cells_observed(),
            100.0 * q.fraction_correct(),
            percent(q.occupied_precision()),
            percent(q.occupied_recall()),
        );
        for robot in &self.results.robots {
            let _ = writeln!(out, "{}", robot_line(&robot.report));
        }
        let _ = writeln!(
            out,
            "{:.0} s in all; wrote {} (report.md, report.json, {}, the plots, logs/)",
            self.wall_s,
            self.args.out.display(),
            self.results.map_yaml
        );
        out
    }

    /// report.md: the thesis-style tables and the figures of the run.
    fn markdown(&self) -> String {
        let mut md = String::new();
        let args = self.args;
        let _ = writeln!(md, "# deog demo: {}\n", self.plan.world.name());
        let _ = writeln!(
            md,
            "{} robots drove {} simulated seconds at {}x (seed {}), in {:.0} s of wall-clock time. \
             Each robot had its own wanderer, cartographer and localizer process; the \
             localizers started at {:.0} s with no idea where their robots were.",
            self.plan.robots.len(),
            args.duration,
            args.speed,
            args.seed,
            self.wall_s,
            self.plan.localize_at,
        );
        match self.kidnap {
            Some(k) => {
                let _ = writeln!(
                    md,
                    "At {:.1} s {} was kidnapped: carried from ({:.2}, {:.2}) to ({:.2}, {:.2}) \
                     without its odometry noticing.",
                    k.time_s, k.robot, k.from.x, k.from.y, k.to.x, k.to.y
                );
            }
            None => {
                let _ = writeln!(md, "No robot was kidnapped.");
            }
        }
        let _ = writeln!(md, "\n## Localization\n");
        let _ = writeln!(
            md,
            "| robot | converged after | mean abs. error x | y | heading | RMS position | kidnapped | recovered after |"
        );
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---|---:|");
        for robot in &self.results.robots {
            let r = &robot.report;
            let stats = r.stats.as_ref();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} |",
                r.robot,
                seconds(r.converge_s()),
                metres(stats.map(|s| s.x_m.mean_abs)),
                metres(stats.map(|s| s.y_m.mean_abs)),
                stats.map_or("-".to_string(), |s| format!(
                    "{:.2}°",
                    s.theta_rad.mean_abs.to_degrees()
                )),
                metres(stats.map(|s| s.rms_position_m)),
                if r.kidnapped() { "yes" } else { "no" },
                match r.recovered() {
                    None => "-".to_string(),
                    Some(false) => "not recovered".to_string(),
                    Some(true) => seconds(r.recover_s()),
                },
            );
        }
        for robot in &self.results.robots {
            let _ = writeln!(md, "\n### {}\n", robot.report.robot);
            let _ = writeln!(
                md,
                "True path red, estimate green; a kidnap is marked.\n\n![{}]({})\n",
                robot.report.robot, robot.plot
            );
            let _ = writeln!(md, "```\n{}```", robot.report.table());
        }
        let _ = writeln!(md, "\n## Map\n");
        let _ = writeln!(
            md,
            "![map]({})\n\nExported as ROS map_server files: `{}` with its `.pgm`. \
             Judged against the world's ground truth:\n",
            self.results.map_png, self.results.map_yaml
        );
        let _ = writeln!(md, "{}", self.results.quality.table());
        let _ = writeln!(
            md,
            "Where it is right and wrong (white free and black occupied: right; yellow free \
             but uncertain, red free but occupied, blue occupied but free, purple occupied \
             but uncertain; light grey never observed, dark grey the world's walls):\n\n\
             ![where the map is right]({VERDICT_PNG})\n"
        );
        let _ = writeln!(md, "## The processes\n");
        let _ = writeln!(
            md,
            "Each ran as its own process; the logs are in `logs/`. By hand, the same \
             commands (with the addresses of your server and simulator):\n"
        );
        let _ = writeln!(md, "```");
        for (name, line) in &self.commands {
            let _ = writeln!(md, "# {name}\n{line}");
        }
        let _ = writeln!(md, "```");
        md
    }
}

fn robot_line(r: &LocalizationReport) -> String {
    let mut line = format!("{}: ", r.robot);
    match r.converge_s() {
        Some(s) => {
            let _ = write!(line, "converged after {s:.1} s");
        }
        None => line.push_str("never converged"),
    }
    if let Some(s) = &r.stats {
        let _ = write!(
            line,
            ", mean error {:.1} cm x, {:.1} cm y, {:.2}°",
            100.0 * s.x_m.mean_abs,
            100.0 * s.y_m.mean_abs,
            s.theta_rad.mean_abs.to_degrees()
        );
    }
    match r.recovered() {
        Some(true) => {
            let _ = write!(
                line,
                "; kidnapped, found again after {}",
                seconds(r.recover_s())
            );
        }
        Some(false) => line.push_str("; kidnapped, not found again"),
        None => {}
    }
    line
}

fn seconds(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |s| format!("{s:.1} s"))
}

fn metres(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |m| format!("{:.1} cm", 100.0 * m))
}

fn percent(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |p| format!("{:.1}%", 100.0 * p))
}
