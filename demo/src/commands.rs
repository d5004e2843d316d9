//! The command line of every process the demo starts, as `deog`
//! arguments: the same a person would type to run the parts by hand
//! (report.md lists them).

use std::ffi::OsString;
use std::net::SocketAddr;
use std::path::Path;

use deog_harness::os;
use deog_mapping::specular_sonar_mapping;

use crate::options::ExplorePose;
use crate::plan::{DemoPlan, PlannedRobot};
use deog_grid::RingFiring;
use deog_simulator::SonarPreset;
use deog_simulator::simulation::SimConfig;

/// The name of the shared map on the server.
pub(crate) const MAP: &str = "demo";
/// The map refitted to every frame once the robots stop, on the server.
pub(crate) const REFIT_MAP: &str = "demo-refit";
/// The refitted map's file stem in the output folder.
pub(crate) const REFIT_STEM: &str = "map-refit";
/// A cartographer or localizer ends once no frame came for this long,
/// seconds.
const IDLE_EXIT_S: &str = "3";

/// Where the demo's services listen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Addresses {
    /// The map servers (one, or several sharing a PostgreSQL store).
    pub servers: Vec<SocketAddr>,
    /// The simulator.
    pub sim: SocketAddr,
}

impl Addresses {
    /// The map servers' URLs, as clients take them (separated by commas).
    pub fn server_url(&self) -> String {
        self.servers
            .iter()
            .map(|addr| format!("http://{addr}"))
            .collect::<Vec<_>>()
            .join(",")
    }

    /// The simulator's URL, as clients take it.
    pub fn sim_url(&self) -> String {
        format!("http://{}", self.sim)
    }
}

/// Map server `index`: on a fresh sled store in `data`, or, given the
/// plan's PostgreSQL store, with no store flag: the URL (which may hold a
/// password) goes in `DEOG_STORE` ([`server_env`]), not on the command line.
pub(crate) fn server(
    plan: &DemoPlan,
    addresses: &Addresses,
    index: usize,
    data: &Path,
) -> Vec<OsString> {
    let listen = addresses
        .servers
        .get(index)
        .map(ToString::to_string)
        .unwrap_or_default();
    let store = match &plan.store {
        Some(_) => Vec::new(),
        None => vec![OsString::from("--data"), data.as_os_str().to_owned()],
    };
    os(&["server", "--listen", &listen])
        .into_iter()
        .chain(store)
        .collect()
}

/// The environment of a map server: `DEOG_STORE` on PostgreSQL.
pub(crate) fn server_env(plan: &DemoPlan) -> Vec<(&'static str, &str)> {
    plan.store
        .as_deref()
        .map(|url| ("DEOG_STORE", url))
        .into_iter()
        .collect()
}

/// The simulator, with the plan's world, speed, seed, rig and sonar (no
/// flag for the default sonar).
pub(crate) fn sim(plan: &DemoPlan, addresses: &Addresses) -> Vec<OsString> {
    let sonar = [OsString::from("--sonar"), OsString::from(plan.sonar.name())];
    let sonar = if plan.sonar == SonarPreset::Default {
        &sonar[..0]
    } else {
        &sonar[..]
    };
    os(&[
        "sim",
        "--world",
        &plan.world_spec,
        "--listen",
        &addresses.sim.to_string(),
        "--speed",
        &plan.schedule.speed.to_string(),
        "--seed",
        &plan.seed.to_string(),
        "--rig",
        &plan.rig_spec,
    ])
    .into_iter()
    .chain(sonar.iter().cloned())
    .collect()
}

/// The live view of the shared map, the robots and their estimates,
/// serving its page on `listen`.
pub(crate) fn view(
    addresses: &Addresses,
    listen: SocketAddr,
    foxglove: SocketAddr,
) -> Vec<OsString> {
    os(&[
        "view",
        "--listen",
        &listen.to_string(),
        "--foxglove",
        &foxglove.to_string(),
        "--map",
        MAP,
        "--server",
        &addresses.server_url(),
        "--sim",
        &addresses.sim_url(),
    ])
}

/// An explorer that spawns `robot` and drives it to the shared map's
/// frontiers until none is left or the plan's duration has passed, from
/// the plan's pose.
pub(crate) fn explore(
    plan: &DemoPlan,
    robot: &PlannedRobot,
    addresses: &Addresses,
) -> Vec<OsString> {
    let pose = match plan.explore_pose {
        ExplorePose::True => Vec::new(),
        ExplorePose::Estimate => os(&["--pose", "estimate"]),
    };
    os(&[
        "explore",
        "--robot",
        &robot.name,
        "--map",
        MAP,
        "--spawn",
        "--duration",
        &plan.schedule.duration_s.to_string(),
        "--sim",
        &addresses.sim_url(),
        "--server",
        &addresses.server_url(),
    ])
    .into_iter()
    .chain(pose)
    .collect()
}

/// A wanderer that spawns `robot` and drives it for the plan's duration.
pub(crate) fn wander(
    plan: &DemoPlan,
    robot: &PlannedRobot,
    addresses: &Addresses,
) -> Vec<OsString> {
    os(&[
        "wander",
        "--robot",
        &robot.name,
        "--spawn",
        "--seed",
        &robot.seed.to_string(),
        "--duration",
        &plan.schedule.duration_s.to_string(),
        "--sim",
        &addresses.sim_url(),
        "--server",
        &addresses.server_url(),
    ])
}

/// `--firing-period` for a cartographer or localizer of frames from
/// `sonar`, whose ring fires in turn over the simulator's sensor period:
/// each reading placed where its sonar fired. Nothing for a ring that
/// fires together.
fn firing_period(sonar: SonarPreset) -> Vec<OsString> {
    let config = SimConfig {
        sonar: sonar.params(),
        ..SimConfig::default()
    };
    match config.ring_firing() {
        RingFiring::Sequential { period_s } => os(&["--firing-period", &period_s.to_string()]),
        RingFiring::Together => Vec::new(),
    }
}

/// A cartographer adding `robot`'s frames to the shared map; with a
/// specular sonar, evidence is kept by direction, no-echo readings (mostly
/// lost echoes) are ignored and empty evidence reaches 2 m, the best sonar
/// maps measured on such readings (BENCHMARKS.md, sonar mapping).
pub(crate) fn map(plan: &DemoPlan, robot: &PlannedRobot, addresses: &Addresses) -> Vec<OsString> {
    let specular = if plan.sonar.specular_angle_deg().is_some() {
        let (_, params) = specular_sonar_mapping();
        firing_period(plan.sonar)
            .into_iter()
            .chain(os(&[
                "--sonar-method",
                "directional",
                "--no-echo-free-range",
                &params.no_echo_free_range.to_string(),
                "--max-free-range",
                &params.max_free_range.to_string(),
            ]))
            .collect()
    } else {
        Vec::new()
    };
    os(&[
        "map",
        "--robot",
        &robot.name,
        "--map",
        MAP,
        "--idle-exit",
        IDLE_EXIT_S,
        "--server",
        &addresses.server_url(),
    ])
    .into_iter()
    .chain(specular)
    .collect()
}

/// Seconds of the robots' time between two refreshes of a localizer's
/// map.
const LOCALIZER_REFRESH_S: f64 = 5.0;

/// A localizer for `robot` on the shared map, with no initial pose
/// (but for explorers driving from its estimates: their start, within the
/// localizer's default spread), expecting no echo past the plan's sonar's
/// specular angle, if any.
pub(crate) fn localize(
    plan: &DemoPlan,
    robot: &PlannedRobot,
    addresses: &Addresses,
) -> Vec<OsString> {
    let mut extra: Vec<OsString> = match plan.sonar.specular_angle_deg() {
        Some(angle) => os(&["--specular-angle", &angle.to_string()]),
        None => Vec::new(),
    };
    extra.extend(firing_period(plan.sonar));
    // The map is taken in as often in the robots' time as a real robot's
    // localizer takes it in (`deog localize`'s 5 s): at the default
    // period the demo's pace would make it every 20 simulated seconds,
    // and the filter would judge frames against walls the map has since
    // moved (BENCHMARKS.md, the growing-map bench).
    extra.extend(os(&[
        "--refresh-s",
        &(LOCALIZER_REFRESH_S / plan.schedule.speed).to_string(),
    ]));
    if plan.every_frame {
        extra.push("--every-frame".into());
    }
    if plan.explore && plan.explore_pose == ExplorePose::Estimate {
        // A robot that drives from its estimates starts where it is known
        // to be, within the default spread: on a map that is still empty
        // there is nothing to find it by.
        extra.extend(os(&["--initial-pose", "true"]));
    }
    os(&[
        "localize",
        "--robot",
        &robot.name,
        "--map",
        MAP,
        "--idle-exit",
        IDLE_EXIT_S,
        "--seed",
        &robot.seed.to_string(),
        "--server",
        &addresses.server_url(),
    ])
    .into_iter()
    .chain(extra)
    .collect()
}

/// The shared map refitted to every robot's frames through the specular
/// sonar's forward model, written to `out` as map_server files.
pub(crate) fn refit(plan: &DemoPlan, addresses: &Addresses, out: &Path) -> Vec<OsString> {
    let robots = plan.robot_names().collect::<Vec<_>>().join(",");
    // A sonar whose every wall echoes has no specular angle: 90° says so.
    let critical = plan.sonar.specular_angle_deg().unwrap_or(90.0);
    let mut args = os(&[
        "refit",
        "--map",
        MAP,
        "--robots",
        &robots,
        "--critical-incidence-deg",
        &critical.to_string(),
    ]);
    args.extend(firing_period(plan.sonar));
    args.extend(os(&["--name", REFIT_STEM, "--out"]));
    args.push(out.as_os_str().to_owned());
    args.extend(os(&["--server", &addresses.server_url()]));
    args
}

/// The refitted map's files, written by [`refit`] to `out`, loaded on the
/// server as map [`REFIT_MAP`].
pub(crate) fn import_refit(addresses: &Addresses, out: &Path) -> Vec<OsString> {
    let mut args = os(&["import", "--map", REFIT_MAP]);
    args.push(out.join(format!("{REFIT_STEM}.yaml")).into_os_string());
    args.extend(os(&["--server", &addresses.server_url()]));
    args
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::plan;

    fn line(args: &[OsString]) -> String {
        args.iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect::<Vec<_>>()
            .join(" ")
    }

    #[test]
    fn every_process_gets_the_flags_of_the_plan() {
        let plan = plan(&[
            "--seed",
            "2",
            "--robots",
            "2",
            "--duration",
            "100",
            "--speed",
            "4",
        ])
        .expect("valid options");
        let addresses = Addresses {
            servers: vec!["127.0.0.1:5001".parse().expect("address")],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        let robot = &plan.robots[1];
        assert_eq!(
            line(&server(&plan, &addresses, 0, Path::new("out/server-data"))),
            "server --listen 127.0.0.1:5001 --data out/server-data"
        );
        assert_eq!(
            line(&sim(&plan, &addresses)),
            "sim --world map2 --listen 127.0.0.1:5002 --speed 4 --seed 2 --rig scout"
        );
        assert_eq!(
            line(&wander(&plan, robot, &addresses)),
            "wander --robot scout-2 --spawn --seed 2002 --duration 100 \
             --sim http://127.0.0.1:5002 --server http://127.0.0.1:5001"
        );
        assert_eq!(
            line(&map(&plan, robot, &addresses)),
            "map --robot scout-2 --map demo --idle-exit 3 --server http://127.0.0.1:5001"
        );
        assert_eq!(
            line(&localize(&plan, robot, &addresses)),
            "localize --robot scout-2 --map demo --idle-exit 3 --seed 2002 \
             --server http://127.0.0.1:5001 --refresh-s 1.25"
        );
    }

    #[test]
    fn servers_sharing_a_database_are_all_given_to_every_robot_process() {
        let plan =
            plan(&["--store", "postgres://deog@db/maps", "--servers", "2"]).expect("valid options");
        let addresses = Addresses {
            servers: vec![
                "127.0.0.1:5001".parse().expect("address"),
                "127.0.0.1:5003".parse().expect("address"),
            ],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        assert_eq!(
            line(&server(&plan, &addresses, 1, Path::new("unused"))),
            "server --listen 127.0.0.1:5003"
        );
        assert_eq!(
            server_env(&plan),
            [("DEOG_STORE", "postgres://deog@db/maps")]
        );
        assert_eq!(
            line(&map(&plan, &plan.robots[0], &addresses)),
            "map --robot scout-1 --map demo --idle-exit 3 \
             --server http://127.0.0.1:5001,http://127.0.0.1:5003"
        );
        let error = plan_error(&["--servers", "2"]);
        assert!(error.contains("needs a --store"), "{error}");
        let error = plan_error(&["--store", "deog-data"]);
        assert!(error.contains("PostgreSQL URL"), "{error}");
    }

    fn plan_error(args: &[&str]) -> String {
        match plan(args) {
            Ok(_) => panic!("{args:?} must be refused"),
            Err(error) => error.to_string(),
        }
    }

    #[test]
    fn explorers_drive_from_the_estimates_when_asked() {
        let addresses = Addresses {
            servers: vec!["127.0.0.1:5001".parse().expect("address")],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        let by_truth = plan(&["--explore"]).expect("valid");
        assert_eq!(
            line(&explore(&by_truth, &by_truth.robots[0], &addresses)),
            "explore --robot scout-1 --map demo --spawn --duration 240 \
             --sim http://127.0.0.1:5002 --server http://127.0.0.1:5001"
        );
        let by_estimate = plan(&["--explore", "--explore-pose", "estimate"]).expect("valid");
        let command = line(&explore(&by_estimate, &by_estimate.robots[0], &addresses));
        assert!(command.ends_with(" --pose estimate"), "{command}");
        let command = line(&localize(&by_estimate, &by_estimate.robots[0], &addresses));
        assert!(command.ends_with(" --initial-pose true"), "{command}");
        let command = line(&localize(&by_truth, &by_truth.robots[0], &addresses));
        assert!(!command.contains("--initial-pose"), "{command}");
        // Their localizers start with them, unless told otherwise.
        assert_eq!(by_estimate.schedule.localize_at_s, 0.0);
        let later = plan(&[
            "--explore",
            "--explore-pose",
            "estimate",
            "--localize-at",
            "20",
        ])
        .expect("valid");
        assert_eq!(later.schedule.localize_at_s, 20.0);
        let error = plan_error(&["--explore", "--explore-pose", "estimate", "--no-localize"]);
        assert!(error.contains("--no-localize"), "{error}");
        assert!(plan(&["--explore-pose", "estimate"]).is_err());
    }

    #[test]
    fn every_frame_goes_to_the_localizers() {
        let addresses = Addresses {
            servers: vec!["127.0.0.1:5001".parse().expect("address")],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        let every = plan(&["--every-frame"]).expect("valid");
        let command = line(&localize(&every, &every.robots[0], &addresses));
        assert!(command.ends_with(" --every-frame"), "{command}");
        let keeping_up = plan(&[]).expect("valid");
        let command = line(&localize(&keeping_up, &keeping_up.robots[0], &addresses));
        assert!(!command.contains("--every-frame"), "{command}");
    }

    #[test]
    fn a_realistic_sonar_goes_to_the_simulator_the_cartographers_and_the_localizers() {
        let plan = plan(&["--sonar", "realistic"]).expect("valid options");
        let addresses = Addresses {
            servers: vec!["127.0.0.1:5001".parse().expect("address")],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        assert_eq!(
            line(&sim(&plan, &addresses)),
            "sim --world map2 --listen 127.0.0.1:5002 --speed 4 --seed 1 --rig scout \
             --sonar realistic"
        );
        assert_eq!(
            line(&map(&plan, &plan.robots[0], &addresses)),
            "map --robot scout-1 --map demo --idle-exit 3 --server http://127.0.0.1:5001 \
             --firing-period 0.1 --sonar-method directional --no-echo-free-range 0 \
             --max-free-range 2"
        );
        assert_eq!(
            line(&localize(&plan, &plan.robots[0], &addresses)),
            "localize --robot scout-1 --map demo --idle-exit 3 --seed 1001 \
             --server http://127.0.0.1:5001 --specular-angle 30 --firing-period 0.1 \
             --refresh-s 1.25"
        );
    }

    #[test]
    fn a_specular_sonar_map_is_refitted_and_loaded_as_a_map_of_its_own() {
        let addresses = Addresses {
            servers: vec!["127.0.0.1:5001".parse().expect("address")],
            sim: "127.0.0.1:5002".parse().expect("address"),
        };
        let realistic = plan(&["--sonar", "realistic", "--robots", "2"]).expect("valid");
        assert!(realistic.refit);
        let out = Path::new("demo-out");
        assert_eq!(
            line(&refit(&realistic, &addresses, out)),
            "refit --map demo --robots scout-1,scout-2 --critical-incidence-deg 30 \
             --firing-period 0.1 --name map-refit --out demo-out --server http://127.0.0.1:5001"
        );
        assert_eq!(
            line(&import_refit(&addresses, out)),
            "import --map demo-refit demo-out/map-refit.yaml --server http://127.0.0.1:5001"
        );
        let together = plan(&["--sonar", "specular60"]).expect("valid");
        assert_eq!(
            line(&refit(&together, &addresses, out)),
            "refit --map demo --robots scout-1,scout-2,scout-3 --critical-incidence-deg 60 \
             --name map-refit --out demo-out --server http://127.0.0.1:5001"
        );
        // Every wall echoes: the cartographers' map is the one to keep.
        assert!(!plan(&[]).expect("valid").refit);
        let skipped = plan(&["--sonar", "realistic", "--no-refit"]).expect("valid");
        assert!(!skipped.refit);
    }
}
