//! `deog sim`: the simulator process, every robot carrying one rig.

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use deog_simulator::deog_rig::{BUILT_IN_RIGS, Rig, RigError, load_rig_spec};
use deog_simulator::serve::{SimServeConfig, serve_sim};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_simulator::sonar::{SonarParams, Specular};
use deog_simulator::{SonarFiring, SonarPreset};
use deog_world::load_world_spec;
use std::net::SocketAddr;
use std::path::PathBuf;

use crate::connection::{connection_limits, read_tls_identity, read_token_file};
use deog_proto::connection::ConnectionLimits;

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

/// When the sonars of a frame fire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FiringMode {
    /// All at once, at the frame's pose.
    Together,
    /// One at a time in ring order, spread over the sensor period.
    Sequential,
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
    /// The sonar's figures: default (every wall echoes), realistic
    /// (echoes lost past 30° of incidence, 2 % dropouts, 1 % crosstalk,
    /// sequential firing) or specular60 (lost past 60°, 2 % dropouts).
    /// The sonar flags below, when given, change the preset's figures.
    #[arg(long, default_value_t = SonarPreset::Default)]
    pub sonar: SonarPreset,
    /// Sonar range noise, a fraction of the range (uniform ±) [preset: 0.01].
    #[arg(long)]
    pub sonar_noise: Option<f64>,
    /// Specular reflection past --specular-angle [preset: off].
    #[arg(long, value_enum)]
    pub specular: Option<SpecularMode>,
    /// Incidence angle past which specular reflection sets in, degrees
    /// [preset's, or 60].
    #[arg(long)]
    pub specular_angle: Option<f64>,
    /// How much longer a specular echo comes back (with --specular long)
    /// [preset's, or 1.5].
    #[arg(long)]
    pub specular_factor: Option<f64>,
    /// Probability that a sonar reading is lost (reads the maximum range)
    /// [preset: 0].
    #[arg(long)]
    pub dropout: Option<f64>,
    /// Probability that a sonar hears a ring neighbour's shorter echo
    /// instead of its own [preset: 0].
    #[arg(long)]
    pub crosstalk: Option<f64>,
    /// When the sonars of a frame fire: together, or one at a time in ring
    /// order over the sensor period [preset: together].
    #[arg(long, value_enum)]
    pub sonar_firing: Option<FiringMode>,
    /// Laser range noise: standard deviation, metres (Gaussian).
    #[arg(long, default_value_t = 0.01)]
    pub laser_noise: f64,
    /// Scale of the odometry noise (0 turns it off, 1 is the default model).
    #[arg(long, default_value_t = 1.0)]
    pub odometry_noise: f64,
    /// Largest request message accepted, bytes (at least 1024).
    #[arg(long, env = "DEOG_SIM_MAX_MESSAGE_BYTES", default_value_t = SimServeConfig::default().max_message_bytes)]
    pub max_message_bytes: usize,
    /// Most robots the world holds (1 to 4096), --robots included; a spawn
    /// past it is refused with RESOURCE_EXHAUSTED.
    #[arg(long, env = "DEOG_SIM_MAX_ROBOTS", default_value_t = SimServeConfig::default().max_robots)]
    pub max_robots: usize,
    /// Most WatchState streams open at once (1 to 65536); a watch past it
    /// is refused with RESOURCE_EXHAUSTED.
    #[arg(long, env = "DEOG_SIM_MAX_WATCHERS", default_value_t = SimServeConfig::default().max_watchers)]
    pub max_watchers: usize,
    /// Connections held at once; one more is closed as soon as it is
    /// accepted.
    #[arg(long, env = "DEOG_SIM_MAX_CONNECTIONS", default_value_t = ConnectionLimits::default().max_connections)]
    pub max_connections: usize,
    /// Seconds a new connection has to start speaking (HTTP/2 or TLS)
    /// before it is closed.
    #[arg(long, env = "DEOG_SIM_HANDSHAKE_TIMEOUT_S", default_value_t = ConnectionLimits::default().handshake_timeout.as_secs_f64())]
    pub handshake_timeout_s: f64,
    /// Calls open at once on one connection; a client asking more waits.
    #[arg(long, env = "DEOG_SIM_MAX_STREAMS_PER_CONNECTION", default_value_t = SimServeConfig::default().max_streams_per_connection)]
    pub max_streams_per_connection: u32,
    /// File holding the bearer token every RobotService call must carry
    /// (health and reflection stay open).
    #[arg(long, env = "DEOG_SIM_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// TLS certificate chain (PEM); needs --tls-key.
    #[arg(long, env = "DEOG_SIM_TLS_CERT", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// TLS private key (PEM); needs --tls-cert.
    #[arg(long, env = "DEOG_SIM_TLS_KEY", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
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
    config.sonar = sonar_params(args)?;
    config.odometry = config
        .odometry
        .scaled(args.odometry_noise)
        .context("--odometry-noise")?;
    Ok(config)
}

/// The sonar figures: `--sonar`'s preset, then each sonar flag given.
pub fn sonar_params(args: &SimArgs) -> Result<SonarParams> {
    let mut sonar = args.sonar.params();
    if let Some(noise) = args.sonar_noise {
        sonar.noise_fraction = noise;
    }
    if let Some(dropout) = args.dropout {
        sonar.dropout_probability = dropout;
    }
    if let Some(crosstalk) = args.crosstalk {
        sonar.crosstalk_probability = crosstalk;
    }
    if let Some(firing) = args.sonar_firing {
        sonar.firing = match firing {
            FiringMode::Together => SonarFiring::Together,
            FiringMode::Sequential => SonarFiring::Sequential,
        };
    }
    if let Some(angle) = args.specular_angle.filter(|a| !(0.0..=90.0).contains(a)) {
        bail!("--specular-angle must be within 0 to 90 degrees, got {angle}");
    }
    // The preset's figures where no flag gives them.
    let (preset_incidence, preset_factor) = match sonar.specular {
        Specular::Off => (None, None),
        Specular::Lost { max_incidence } => (Some(max_incidence), None),
        Specular::Long {
            max_incidence,
            factor,
        } => (Some(max_incidence), Some(factor)),
    };
    let max_incidence = args
        .specular_angle
        .map(f64::to_radians)
        .or(preset_incidence)
        .unwrap_or(60f64.to_radians());
    let factor = args.specular_factor.or(preset_factor).unwrap_or(1.5);
    let mode = args.specular.unwrap_or(match sonar.specular {
        Specular::Off => SpecularMode::Off,
        Specular::Lost { .. } => SpecularMode::Lost,
        Specular::Long { .. } => SpecularMode::Long,
    });
    sonar.specular = match mode {
        SpecularMode::Off => Specular::Off,
        SpecularMode::Lost => Specular::Lost { max_incidence },
        SpecularMode::Long => Specular::Long {
            max_incidence,
            factor,
        },
    };
    sonar.validate().context("sonar options")?;
    Ok(sonar)
}

/// Runs the simulator until ctrl-c or SIGTERM.
pub fn run(args: SimArgs) -> Result<()> {
    let serve_config = SimServeConfig {
        speed: args.speed,
        max_message_bytes: args.max_message_bytes,
        max_robots: args.max_robots,
        max_watchers: args.max_watchers,
        token: args
            .token_file
            .as_deref()
            .map(read_token_file)
            .transpose()?,
        tls: read_tls_identity(args.tls_cert.as_deref(), args.tls_key.as_deref())?,
        connections: connection_limits(args.max_connections, args.handshake_timeout_s)?,
        max_streams_per_connection: args.max_streams_per_connection,
        ..SimServeConfig::default()
    };
    serve_config.validate()?;
    if args.robots > args.max_robots {
        bail!(
            "--robots {} is more than --max-robots {}",
            args.robots,
            args.max_robots
        );
    }
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
        tracing::info!(
            %addr,
            world = %sim.world().name(),
            rig = %rig.name(),
            speed = args.speed,
            robots = sim.robot_count(),
            tls = serve_config.tls.is_some(),
            auth = serve_config.token.is_some(),
            "simulator listening"
        );
        serve_sim(sim, listener, serve_config, deog_harness::shutdown_signal()).await?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: SimArgs,
    }

    fn sonar(args: &[&str]) -> Result<SonarParams> {
        let cli = Cli::try_parse_from(std::iter::once("sim").chain(args.iter().copied()))?;
        sonar_params(&cli.args)
    }

    #[test]
    fn the_default_preset_is_the_default_sonar() {
        assert_eq!(sonar(&[]).expect("valid"), SonarParams::default());
        assert_eq!(
            sonar(&["--sonar", "default"]).expect("valid"),
            SonarParams::default()
        );
        // --specular-angle alone leaves specular loss off, as before.
        assert_eq!(
            sonar(&["--specular-angle", "30"]).expect("valid"),
            SonarParams::default()
        );
        let lost = sonar(&["--specular", "lost"]).expect("valid");
        assert_eq!(
            lost.specular,
            Specular::Lost {
                max_incidence: 60f64.to_radians()
            }
        );
    }

    #[test]
    fn the_realistic_preset_and_flags_that_change_it() {
        assert_eq!(
            sonar(&["--sonar", "realistic"]).expect("valid"),
            SonarParams::realistic()
        );
        let changed = sonar(&[
            "--sonar",
            "realistic",
            "--specular-angle",
            "40",
            "--dropout",
            "0",
            "--crosstalk",
            "0.5",
            "--sonar-firing",
            "together",
        ])
        .expect("valid");
        assert_eq!(
            changed.specular,
            Specular::Lost {
                max_incidence: 40f64.to_radians()
            }
        );
        assert_eq!(changed.dropout_probability, 0.0);
        assert_eq!(changed.crosstalk_probability, 0.5);
        assert_eq!(changed.firing, SonarFiring::Together);
        let long = sonar(&["--sonar", "realistic", "--specular", "long"]).expect("valid");
        assert_eq!(
            long.specular,
            Specular::Long {
                max_incidence: 30f64.to_radians(),
                factor: 1.5
            }
        );
        let off = sonar(&["--sonar", "realistic", "--specular", "off"]).expect("valid");
        assert_eq!(off.specular, Specular::Off);
    }

    #[test]
    fn bad_sonar_options_are_refused() {
        assert!(sonar(&["--sonar", "loud"]).is_err());
        assert!(sonar(&["--specular-angle", "100"]).is_err());
        let err = sonar(&["--crosstalk", "2"]).expect_err("out of range");
        assert!(
            format!("{err:#}").contains("crosstalk_probability"),
            "{err:#}"
        );
        assert!(sonar(&["--dropout", "-1"]).is_err());
    }
}
