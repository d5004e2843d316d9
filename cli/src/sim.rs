//! `deog sim`: the simulator process, every robot carrying one rig.

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use deog_simulator::deog_rig::{BUILT_IN_RIGS, Rig, RigError, load_rig_spec};
use deog_simulator::serve::{SimServeConfig, serve_sim};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::sonar::Specular;
use deog_world::load_world_spec;
use std::net::SocketAddr;

/// What a wall struck past the specular angle does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SpecularMode {
    /// Every wall echoes.
    Off,
    /// No echo from that wall.
    Lost,
    /// The echo comes back long.
    Long,
}

/// Options of `deog sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// World: a built-in name (map1, map2, office), a world file (.toml) or
    /// a map_server map (.yaml).
    #[arg(long, env = "DEOG_WORLD", default_value = "map2")]
    pub world: String,
    /// Address to serve RobotService on.
    #[arg(long, env = "DEOG_SIM_LISTEN", default_value = "127.0.0.1:50052")]
    pub listen: SocketAddr,
    /// Simulated seconds per wall-clock second.
    #[arg(long, env = "DEOG_SIM_SPEED", default_value_t = 1.0)]
    pub speed: f64,
    /// Seed of every random choice (noise, spawn poses).
    #[arg(long, env = "DEOG_SEED", default_value_t = 1)]
    pub seed: u64,
    /// Robots to place at random free poses at start, named scout-1 ...
    /// (more can be spawned over gRPC).
    #[arg(long, default_value_t = 0)]
    pub robots: usize,
    /// The sensor rig every robot carries: a built-in name (scout,
    /// pioneer3dx, laser180) or a rig file (.toml). Its body radius is the
    /// robots'.
    #[arg(long, env = "DEOG_RIG", default_value = deog_simulator::deog_rig::DEFAULT_RIG)]
    pub rig: String,
    /// Sonar range noise, a fraction of the range (uniform ±).
    #[arg(long, default_value_t = 0.01)]
    pub sonar_noise: f64,
    /// Specular reflection past --specular-angle.
    #[arg(long, value_enum, default_value_t = SpecularMode::Off)]
    pub specular: SpecularMode,
    /// Incidence angle past which specular reflection sets in, degrees.
    #[arg(long, default_value_t = 60.0)]
    pub specular_angle: f64,
    /// How much longer a specular echo comes back (with --specular long).
    #[arg(long, default_value_t = 1.5)]
    pub specular_factor: f64,
    /// Probability that a sonar reading is lost (reads the maximum range).
    #[arg(long, default_value_t = 0.0)]
    pub dropout: f64,
    /// Laser range noise: standard deviation, metres (Gaussian).
    #[arg(long, default_value_t = 0.01)]
    pub laser_noise: f64,
    /// Scale of the odometry noise (0 turns it off, 1 is the default model).
    #[arg(long, default_value_t = 1.0)]
    pub odometry_noise: f64,
    /// Largest request message accepted, bytes (at least 1024).
    #[arg(long, env = "DEOG_SIM_MAX_MESSAGE_BYTES", default_value_t = SimServeConfig::default().max_message_bytes)]
    pub max_message_bytes: usize,
}

/// The rig `--rig` names, or a one-line error naming it and listing the
/// built-in rigs.
pub fn load_rig(spec: &str) -> Result<Rig> {
    load_rig_spec(spec).map_err(|error| {
        let error = match error {
            // Already lists the built-in names.
            RigError::Unknown { .. } => error.to_string(),
            other => {
                let names: Vec<&str> = BUILT_IN_RIGS.iter().map(|(n, _)| *n).collect();
                format!("{other} (built-in rigs: {})", names.join(", "))
            }
        };
        // A TOML error spans lines (the line quoted, a caret under it).
        let one_line = error.split_whitespace().collect::<Vec<_>>().join(" ");
        anyhow::anyhow!("--rig {spec}: {one_line}")
    })
}

/// The simulation's figures from the options.
pub fn sim_config(args: &SimArgs) -> Result<SimConfig> {
    let mut config = SimConfig {
        rig: load_rig(&args.rig)?,
        ..SimConfig::default()
    };
    config.laser.noise_sigma = args.laser_noise;
    config.laser.validate().context("--laser-noise")?;
    config.sonar.noise_fraction = args.sonar_noise;
    config.sonar.dropout_probability = args.dropout;
    if !(0.0..=90.0).contains(&args.specular_angle) {
        bail!(
            "--specular-angle must be within 0 to 90 degrees, got {}",
            args.specular_angle
        );
    }
    let max_incidence = args.specular_angle.to_radians();
    config.sonar.specular = match args.specular {
        SpecularMode::Off => Specular::Off,
        SpecularMode::Lost => Specular::Lost { max_incidence },
        SpecularMode::Long => Specular::Long {
            max_incidence,
            factor: args.specular_factor,
        },
    };
    config.sonar.validate().context("sonar options")?;
    config.odometry = config
        .odometry
        .scaled(args.odometry_noise)
        .context("--odometry-noise")?;
    Ok(config)
}

/// Runs the simulator until ctrl-c or SIGTERM.
pub fn run(args: SimArgs) -> Result<()> {
    let world = load_world_spec(&args.world)?;
    let config = sim_config(&args)?;
    let mut sim = Simulation::new(world, config, args.seed).context("setting up the simulation")?;
    for i in 1..=args.robots {
        let name = format!("scout-{i}");
        let state = sim
            .spawn(&name, None)
            .with_context(|| format!("placing {name}"))?;
        tracing::info!(robot = %name, x = state.true_pose.x, y = state.true_pose.y, "robot placed");
    }
    let serve_config = SimServeConfig {
        speed: args.speed,
        max_message_bytes: args.max_message_bytes,
        ..SimServeConfig::default()
    };
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("binding {}", args.listen))?;
        let addr = listener.local_addr()?;
        let rig = sim.rig();
        tracing::info!(
            rig = %rig.name(),
            readings = rig.readings(),
            body_radius_m = rig.body_radius(),
            "every robot carries this rig"
        );
        tracing::info!(%addr, world = %sim.world().name(), rig = %rig.name(), speed = args.speed, robots = sim.robot_count(), "simulator listening");
        serve_sim(sim, listener, serve_config, deog_harness::shutdown_signal()).await?;
        Ok(())
    })
}
