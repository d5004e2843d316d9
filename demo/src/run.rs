//! The demo from start to end: the processes started through the
//! supervisor, the robots driving (localizers started, the kidnap made),
//! the cartographers and localizers draining their last frames, then the
//! judging and the reports. Any failure, or ctrl-c, returns an error, and
//! dropping the supervisor stops every process.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use deog_harness::{Role, Supervisor, connect, free_loopback_addr};
use deog_robot_client::{ClientConfig, MapClient, SimClient};

use crate::commands::{self, Addresses};
use crate::coverage::{CoverageCurve, CoverageJudge, CoverageSampler};
use crate::judge::judge;
use crate::kidnap::{KidnapDone, kidnap_robot};
use crate::markdown;
use crate::options::{DemoOptions, ExplorePose};
use crate::pacer::Pacer;
use crate::plan::DemoPlan;
use crate::progress::Progress;
use crate::report::{DemoOutcome, Driven, write_reports};
use crate::status_line::StatusLine;

/// How long the cartographers and localizers may take to drain their
/// frames after the wanderers stop, wall-clock.
const FINISH_TIMEOUT: Duration = Duration::from_secs(300);

/// Runs the demo as `options` say: checks them, starts every process,
/// waits for the robots to finish, judges the run and writes the map, the
/// plots and the reports to `--out`. Bad options are refused before
/// anything is written or started.
pub fn run(options: DemoOptions) -> Result<()> {
    let plan = DemoPlan::new(&options)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(demo(&plan))
}

/// How the robots drove: the kidnap, if one was made, each robot's
/// largest localizer lag, the coverage curve, the robots' time and bumps,
/// and the simulator's second at which each localizer started.
struct Drove {
    kidnap: Option<KidnapDone>,
    max_lags_s: Vec<(String, Option<f64>)>,
    coverage: CoverageCurve,
    driven: Driven,
    localizer_starts_s: Vec<f64>,
}

/// The running demo: its processes and its connections to them.
struct Demo<'a> {
    plan: &'a DemoPlan,
    children: Supervisor,
    addresses: Addresses,
    map_client: MapClient,
    sim: SimClient,
    status: StatusLine,
    pacer: Pacer,
}

async fn demo(plan: &DemoPlan) -> Result<()> {
    let started = Instant::now();
    let mut demo = Demo::start(plan).await?;
    let Drove {
        kidnap,
        max_lags_s,
        coverage,
        driven,
        localizer_starts_s,
    } = demo.drive().await?;
    demo.drain().await?;
    if plan.refit {
        demo.refit().await?;
    }
    demo.status.finish();

    let out = &plan.out;
    let judgement = judge(
        &demo.map_client,
        plan,
        &localizer_starts_s,
        kidnap.as_ref(),
        out,
    )
    .await?;
    let outcome = DemoOutcome {
        plan,
        judgement: &judgement,
        kidnap: kidnap.as_ref(),
        wall_s: started.elapsed().as_secs_f64(),
        max_lags_s,
        coverage: coverage.samples().to_vec(),
        commands: demo
            .children
            .command_lines()
            .map(|(name, line)| (name.to_string(), line.to_string()))
            .collect(),
        driven,
    };
    write_reports(&outcome, out)?;
    print!("{}", markdown::summary(&outcome));
    if plan.keep {
        let mut pids = Vec::new();
        for index in 0..plan.servers {
            let name = server_name(index);
            demo.children.keep(&name);
            pids.push(demo.children.pid(&name).unwrap_or_default().to_string());
        }
        let data = match &plan.store {
            Some(_) => "data in the --store database".to_string(),
            None => format!("data in {}", server_data(out).display()),
        };
        println!(
            "the map server keeps running at {} (process {}), {data}; stop it with: kill {}",
            demo.addresses.server_url(),
            pids.join(", "),
            pids.join(" "),
        );
        if let Some(pid) = demo.children.pid("view") {
            demo.children.keep("view");
            println!("the live view keeps running too (process {pid}); stop it with: kill {pid}");
        }
    }
    Ok(())
}

/// The address the view is asked for, or a free one when another
/// process holds it (a second demo, a view left running).
fn view_address(asked: std::net::SocketAddr) -> Result<std::net::SocketAddr> {
    match std::net::TcpListener::bind(asked) {
        Ok(_) => Ok(asked),
        Err(_) if asked.port() != 0 => free_loopback_addr(),
        Err(error) => Err(error).with_context(|| format!("--view {asked}")),
    }
}

/// The name of map server `index` among the demo's processes.
fn server_name(index: usize) -> String {
    match index {
        0 => "server".to_string(),
        _ => format!("server-{}", index + 1),
    }
}

/// The map server's store in the output folder.
fn server_data(out: &Path) -> PathBuf {
    out.join("server-data")
}

/// A demo judges what its own robots wrote: a database that already holds
/// maps or frames would mix in another run's.
async fn refuse_a_used_database(client: &MapClient) -> Result<()> {
    let maps = client.maps().await.context("listing the maps")?;
    let robots = client.robots().await.context("listing the robots")?;
    if !maps.is_empty() || !robots.is_empty() {
        bail!(
            "the --store database already holds {} maps and {} robots' frames: the demo needs an \
             empty one (createdb a new database, or deog copy this one elsewhere and drop it)",
            maps.len(),
            robots.len()
        );
    }
    Ok(())
}

impl<'a> Demo<'a> {
    /// Clears the output folder, starts the map server and the simulator
    /// and connects to them, then starts each robot's wanderer and
    /// cartographer.
    async fn start(plan: &'a DemoPlan) -> Result<Self> {
        let out = &plan.out;
        deog_harness::prepare_run_folder(out)?;
        let mut children = Supervisor::new(&out.join("logs"))?;
        let addresses = Addresses {
            servers: (0..plan.servers)
                .map(|_| free_loopback_addr())
                .collect::<Result<_>>()?,
            sim: free_loopback_addr()?,
        };
        println!(
            "deog demo: {} with {} robots for {} simulated s at {}x; writing to {}",
            plan.world.name(),
            plan.robots.len(),
            plan.schedule.duration_s,
            plan.schedule.speed,
            out.display()
        );
        for index in 0..plan.servers {
            children.start_with_env(
                &server_name(index),
                Role::Service,
                &commands::server(plan, &addresses, index, &server_data(out)),
                &commands::server_env(plan),
            )?;
        }
        children.start("sim", Role::Service, &commands::sim(plan, &addresses))?;
        // Every server up before anyone is given them all: a client's
        // calls are spread over the addresses it has.
        if addresses.servers.len() > 1 {
            for addr in &addresses.servers {
                let url = format!("http://{addr}");
                connect(&mut children, "map server", || {
                    MapClient::connect(ClientConfig::new(url.clone()))
                })
                .await?;
            }
        }
        let server_url = addresses.server_url();
        let map_client = connect(&mut children, "map server", || {
            MapClient::connect(ClientConfig::new(server_url.clone()))
        })
        .await?;
        if plan.store.is_some() {
            refuse_a_used_database(&map_client).await?;
        }
        let sim_url = addresses.sim_url();
        let sim = connect(&mut children, "simulator", || {
            SimClient::connect(ClientConfig::new(sim_url.clone()))
        })
        .await?;
        if let Some(asked) = plan.view {
            let listen = view_address(asked)?;
            let foxglove = view_address(plan.foxglove)?;
            children.start(
                "view",
                Role::Service,
                &commands::view(&addresses, listen, foxglove),
            )?;
            println!("deog demo: watch it live at http://{listen}/ (in Foxglove: ws://{foxglove})");
        }
        for robot in &plan.robots {
            let driver = if plan.explore {
                commands::explore(plan, robot, &addresses)
            } else {
                commands::wander(plan, robot, &addresses)
            };
            children.start(
                &format!("{}{}", plan.driver_prefix(), robot.name),
                Role::Task,
                &driver,
            )?;
            children.start(
                &format!("map-{}", robot.name),
                Role::Task,
                &commands::map(plan, robot, &addresses),
            )?;
        }
        Ok(Self {
            plan,
            children,
            addresses,
            map_client,
            sim,
            status: StatusLine::new(),
            pacer: Pacer::new(),
        })
    }
}

impl Demo<'_> {
    /// Until every wanderer has finished its simulated time: starts the
    /// localizers and makes the kidnap when their times come, and keeps
    /// the status line. The plan's times count from the moment every
    /// robot stands in the world (processes started on a busy machine
    /// spawn their robots late); the coverage is sampled beside this
    /// loop, so a slow sample delays nothing.
    async fn drive(&mut self) -> Result<Drove> {
        let plan = self.plan;
        let mut progress = Progress::new(plan.robot_names());
        let mut localizer_starts_s = Vec::new();
        let mut kidnap: Option<KidnapDone> = None;
        let coverage = CoverageSampler::spawn(self.map_client.clone(), CoverageJudge::of(plan));
        // The simulator's second at which the last robot spawned.
        let mut zero_s: Option<f64> = None;
        loop {
            self.pacer.next(&mut self.status).await?;
            self.children.check()?;
            let states = self.sim.robots().await.context("asking the simulator")?;
            let sim_now = states.iter().map(|s| s.time_s).fold(0.0, f64::max);
            if zero_s.is_none() && states.len() == plan.robots.len() {
                zero_s = Some(sim_now);
            }
            let now = zero_s.map_or(0.0, |zero| sim_now - zero);
            while plan.localize
                && zero_s.is_some()
                && localizer_starts_s.len() < plan.robots.len()
                && now
                    >= plan
                        .schedule
                        .localizer_start_s(localizer_starts_s.len(), plan.robots.len())
            {
                let robot = &plan.robots[localizer_starts_s.len()];
                self.children.start(
                    &format!("localize-{}", robot.name),
                    Role::Task,
                    &commands::localize(plan, robot, &self.addresses),
                )?;
                localizer_starts_s.push(sim_now);
                let knowing = if plan.explore && plan.explore_pose == ExplorePose::Estimate {
                    "knowing where the robot started"
                } else {
                    "knowing nothing of where the robot is"
                };
                self.status.note(&format!(
                    "{now:.0} s: {}'s localizer started, {knowing}",
                    robot.name
                ));
            }
            if let Some(at) = plan.schedule.kidnap_at_s
                && kidnap.is_none()
                && zero_s.is_some()
                && now >= at
                && let Some(first) = plan.robots.first()
                && let Some(state) = states.iter().find(|s| s.name == first.name)
            {
                let done = kidnap_robot(&self.sim, &plan.world, state, plan.seed).await?;
                self.status.note(&format!(
                    "{:.0} s: {} kidnapped from ({:.2}, {:.2}) to ({:.2}, {:.2})",
                    done.time_s - zero_s.unwrap_or(0.0),
                    done.robot,
                    done.from.x,
                    done.from.y,
                    done.to.x,
                    done.to.y
                ));
                kidnap = Some(done);
            }
            let clocks: Vec<_> = states.iter().map(|s| (s.name.as_str(), s.time_s)).collect();
            let line = progress
                .line(&self.map_client, now, plan.schedule.duration_s, &clocks)
                .await;
            self.status.show(&line);
            if zero_s.is_some() {
                coverage.tick(now);
            }
            if self.children.all_done(plan.driver_prefix()) {
                let coverage = coverage.finish(now).await?;
                let max_lags_s = progress
                    .max_lags()
                    .map(|(robot, lag)| (robot.to_string(), lag))
                    .collect();
                let driven = Driven {
                    simulated_s: now,
                    bumps: plan
                        .robot_names()
                        .map(|name| {
                            let bumps = states
                                .iter()
                                .find(|s| s.name == name)
                                .map_or(0, |s| s.bumps);
                            (name.to_string(), bumps)
                        })
                        .collect(),
                };
                return Ok(Drove {
                    kidnap,
                    max_lags_s,
                    coverage,
                    driven,
                    localizer_starts_s,
                });
            }
        }
    }

    /// Until the cartographers and localizers, idle once the robots
    /// stopped, have ended.
    async fn drain(&mut self) -> Result<()> {
        let finishing = Instant::now();
        while !(self.children.all_done("map-") && self.children.all_done("localize-")) {
            self.pacer.next(&mut self.status).await?;
            self.children.check()?;
            let mut waiting = self.children.running("map-");
            waiting.extend(self.children.running("localize-"));
            if waiting.is_empty() {
                continue;
            }
            if finishing.elapsed() > FINISH_TIMEOUT {
                bail!(
                    "{} still had frames to work through {} s after the robots stopped",
                    waiting.join(", "),
                    FINISH_TIMEOUT.as_secs()
                );
            }
            self.status.show(&format!(
                "robots stopped; {} working through their last frames",
                waiting.join(", ")
            ));
        }
        self.children.check()
    }

    /// The map refitted to every robot's frames (`deog refit`) once the
    /// cartographers have ended, and loaded on the server as a map of its
    /// own (`deog import`), the live map left as it is.
    async fn refit(&mut self) -> Result<()> {
        let out = &self.plan.out;
        let refit = commands::refit(self.plan, &self.addresses, out);
        self.run_to_end("refit", &refit, "refitting the map to every frame")
            .await?;
        let import = commands::import_refit(&self.addresses, out);
        self.run_to_end("import-refit", &import, "loading the refitted map")
            .await
    }

    /// Runs task `name` to its end, `doing` on the status line.
    async fn run_to_end(&mut self, name: &str, command: &[OsString], doing: &str) -> Result<()> {
        self.children.start(name, Role::Task, command)?;
        while !self.children.all_done(name) {
            self.pacer.next(&mut self.status).await?;
            self.children.check()?;
            self.status.show(doing);
        }
        self.children.check()
    }
}
