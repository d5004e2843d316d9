//! What a demo will run, decided before anything starts: the world, the
//! robots with their seeds, the times, and where the output goes. Bad
//! options stop the demo here, before a folder is written or a process
//! started.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use deog_simulator::SonarPreset;
use deog_simulator::deog_rig::{Rig, load_rig_spec};
use deog_world::{World, load_world_spec};

use crate::options::{DemoOptions, ExplorePose, MAX_ROBOTS, Schedule};

/// One robot of the demo.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct PlannedRobot {
    /// Its name: its rig's and its number, `scout-1`, `scout-2`, ...
    pub name: String,
    /// The seed of its wanderer and its localizer.
    pub seed: u64,
}

/// The demo's settings, checked.
#[derive(Debug, Clone)]
pub(crate) struct DemoPlan {
    /// The world as the user named it, handed on to the simulator.
    pub world_spec: String,
    /// That world, loaded: the kidnap and the map's judging use it.
    pub world: World,
    /// The rig as the user named it, handed on to the simulator.
    pub rig_spec: String,
    /// That rig, loaded: the map's judging takes the robots' size from it.
    pub rig: Rig,
    /// The simulated sonar, handed on to the simulator (and its specular
    /// angle to the localizers).
    pub sonar: SonarPreset,
    /// The robots, in order; the first is the one kidnapped.
    pub robots: Vec<PlannedRobot>,
    /// Seed of the simulator and the kidnap.
    pub seed: u64,
    /// The times.
    pub schedule: Schedule,
    /// The output folder.
    pub out: PathBuf,
    /// Whether the map server is left running at the end.
    pub keep: bool,
    /// Whether the localizers correct with every frame.
    pub every_frame: bool,
    /// Where the live view is asked to serve; `None` for no view.
    pub view: Option<std::net::SocketAddr>,
    /// Where the view is asked to serve Foxglove's protocol.
    pub foxglove: std::net::SocketAddr,
    /// Whether explorers drive the robots rather than wanderers.
    pub explore: bool,
    /// The pose the explorers drive from.
    pub explore_pose: ExplorePose,
    /// Whether localizers run.
    pub localize: bool,
    /// The PostgreSQL database the servers share; `None` for a sled store
    /// in the output folder.
    pub store: Option<String>,
    /// How many map servers run.
    pub servers: usize,
    /// Whether the map is refitted to every frame once the robots stop:
    /// with a specular sonar, unless `--no-refit`.
    pub refit: bool,
}

impl DemoPlan {
    /// Checks `options` and loads the world.
    pub fn new(options: &DemoOptions) -> Result<Self> {
        // The times first: their errors are cheaper to find than a world's.
        let schedule = options.schedule()?;
        // clap already holds the flag to this range; options built in code
        // are not.
        if !(1..=MAX_ROBOTS).contains(&options.robots) {
            bail!("--robots must be 1 to {MAX_ROBOTS}, got {}", options.robots);
        }
        if let Some(store) = &options.store
            && !(store.starts_with("postgres://") || store.starts_with("postgresql://"))
        {
            bail!(
                "--store takes a PostgreSQL URL, postgres://USER@HOST/DB, got {store:?} \
                 (without --store the demo keeps a sled store in --out)"
            );
        }
        if options.servers > 1 && options.store.is_none() {
            bail!(
                "--servers {} needs a --store postgres://USER@HOST/DB that the servers share \
                 (a sled store belongs to one server)",
                options.servers
            );
        }
        let world = load_world_spec(&options.world)?;
        let rig = load_rig_spec(&options.rig).context("--rig")?;
        Ok(Self {
            world_spec: options.world.clone(),
            world,
            rig_spec: options.rig.clone(),
            sonar: options.sonar,
            robots: (1..=options.robots)
                .map(|i| PlannedRobot {
                    name: format!("{}-{i}", rig.name()),
                    seed: robot_seed(options.seed, i),
                })
                .collect(),
            rig,
            seed: options.seed,
            schedule,
            out: options.out.clone(),
            keep: options.keep,
            every_frame: options.every_frame,
            view: (!options.no_view).then_some(options.view),
            foxglove: options.foxglove,
            explore: options.explore,
            explore_pose: options.explore_pose,
            localize: !options.no_localize,
            store: options.store.clone(),
            servers: options.servers.max(1) as usize,
            refit: options.sonar.specular_angle_deg().is_some() && !options.no_refit,
        })
    }

    /// The prefix of the names of the processes that drive the robots.
    pub fn driver_prefix(&self) -> &'static str {
        if self.explore { "explore-" } else { "wander-" }
    }

    /// The robots' names, in order.
    pub fn robot_names(&self) -> impl Iterator<Item = &str> {
        self.robots.iter().map(|r| r.name.as_str())
    }
}

/// The seed of robot `number` (counted from 1): distinct per robot and per
/// demo seed, wrapping rather than failing for huge seeds.
fn robot_seed(seed: u64, number: u32) -> u64 {
    seed.wrapping_mul(1000).wrapping_add(u64::from(number))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{options, plan};

    #[test]
    fn robots_are_named_and_seeded_in_order() {
        let plan = plan(&["--robots", "3", "--seed", "7"]).expect("valid options");
        let robots: Vec<(&str, u64)> = plan
            .robots
            .iter()
            .map(|r| (r.name.as_str(), r.seed))
            .collect();
        assert_eq!(
            robots,
            [("scout-1", 7001), ("scout-2", 7002), ("scout-3", 7003)]
        );
        assert_eq!(plan.world.name(), "map2");
        assert_eq!(plan.world_spec, "map2");
    }

    #[test]
    fn a_huge_seed_wraps() {
        assert_eq!(robot_seed(u64::MAX, 1), u64::MAX.wrapping_mul(1000) + 1);
    }

    #[test]
    fn robots_out_of_range_are_an_error_even_without_clap() {
        let mut options = options(&[]).expect("defaults");
        options.robots = 0;
        let error = DemoPlan::new(&options).expect_err("refused");
        assert!(error.to_string().starts_with("--robots"), "{error}");
        options.robots = 9;
        assert!(DemoPlan::new(&options).is_err());
    }

    #[test]
    fn an_unknown_world_is_an_error() {
        let error = plan(&["--world", "no-such-world"]).expect_err("refused");
        assert!(error.to_string().contains("no world"), "{error}");
    }

    #[test]
    fn bad_times_are_refused_before_the_world_is_read() {
        let error = plan(&["--world", "no-such-world", "--duration", "0"]).expect_err("refused");
        assert!(error.to_string().starts_with("--duration"), "{error}");
    }
}
