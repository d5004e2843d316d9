//! The command-line options of `deog demo` and their checks. The flags,
//! their defaults and help texts are the command's interface (README.md
//! lists them).

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use deog_simulator::SonarPreset;

/// The most robots a demo runs: each brings three processes.
pub(crate) const MAX_ROBOTS: u32 = 8;

/// Options of `deog demo`.
#[derive(Debug, Clone, Args)]
pub struct DemoOptions {
    /// The world: map1, map2 or office (built in, as in worlds/), or a file:
    /// a .toml world or a ROS map_server .yaml map.
    #[arg(long, default_value = "map2")]
    pub world: String,
    /// The rig every robot carries: a built-in name (scout, pioneer3dx,
    /// laser180) or a rig file.
    #[arg(long, default_value = deog_simulator::deog_rig::DEFAULT_RIG)]
    pub rig: String,
    /// The simulated sonar: default (every wall echoes), realistic (echoes
    /// lost past 30° of incidence, 2 % dropouts, 1 % crosstalk, sequential
    /// firing) or specular60 (lost past 60°, 2 % dropouts). With specular
    /// loss the localizers are told its angle (`--specular-angle`).
    #[arg(long, default_value_t = SonarPreset::Default)]
    pub sonar: SonarPreset,
    /// Robots in the world, each with its wanderer, cartographer and
    /// localizer (1 to 8).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_ROBOTS)))]
    pub robots: u32,
    /// Seed of the simulator, the wanderers, the localizers and the kidnap.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds the robots drive.
    #[arg(long, default_value_t = 240.0)]
    pub duration: f64,
    /// Simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 4.0)]
    pub speed: f64,
    /// Simulated second at which the localizers start (default: a quarter of
    /// --duration), so that the map has a head start.
    #[arg(long)]
    pub localize_at: Option<f64>,
    /// Simulated second at which the first robot is kidnapped (default:
    /// half of --duration).
    #[arg(long, conflicts_with = "no_kidnap")]
    pub kidnap_at: Option<f64>,
    /// Kidnap nobody.
    #[arg(long)]
    pub no_kidnap: bool,
    /// Start no localizer (and so kidnap nobody): the robots only build the
    /// map, for runs that measure the mapping or the exploring alone.
    #[arg(long, conflicts_with_all = ["localize_at", "kidnap_at", "every_frame"])]
    pub no_localize: bool,
    /// Leave the map server running at the end, to look at the map and the
    /// robots' frames with other deog commands (its address and process id
    /// are printed).
    #[arg(long)]
    pub keep: bool,
    /// With a specular sonar (`--sonar realistic` or `specular60`) the demo
    /// refits the map to every frame once the robots stop (`deog refit`),
    /// loads the result as map `demo-refit` and judges it beside the live
    /// map; this skips that.
    #[arg(long)]
    pub no_refit: bool,
    /// Where the live view (`deog view`) serves its page; when that port is
    /// taken, a free one (the address is printed).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8080")]
    pub view: std::net::SocketAddr,
    /// Start no live view.
    #[arg(long)]
    pub no_view: bool,
    /// Where the live view also serves Foxglove's WebSocket protocol (open
    /// it in Foxglove as a live connection); when that port is taken, a
    /// free one (the address is printed).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8765")]
    pub foxglove: std::net::SocketAddr,
    /// The robots explore: each drives to the shared map's frontiers
    /// (`deog explore`) instead of at random, and stops once none it can
    /// reach is left.
    #[arg(long)]
    pub explore: bool,
    /// The pose the explorers plan and steer from: `true` (the simulator's)
    /// or `estimate` (their localizers' converged estimates carried
    /// forward by odometry; each robot turns on the spot until its
    /// localizer has found it, and the localizers start at once unless
    /// --localize-at says otherwise).
    #[arg(long, value_enum, default_value_t = ExplorePose::True, requires = "explore")]
    pub explore_pose: ExplorePose,
    /// The localizers correct with every frame, however far behind their
    /// robots they fall (by default one that falls behind skips to the
    /// newest frame within a second): for a machine too slow for the
    /// demo's pace, where reaching a pose matters more than keeping time.
    #[arg(long)]
    pub every_frame: bool,
    /// The map servers' store: a PostgreSQL database, `postgres://USER@HOST/DB`,
    /// empty (no map, no robot), which every server shares. By default one
    /// server keeps a fresh sled store in --out.
    #[arg(long)]
    pub store: Option<String>,
    /// Map servers to start (1 to 4), all on --store, which more than one
    /// needs; every robot process is given all their addresses.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4))]
    pub servers: u32,
    /// Folder for the map, the plots, report.md, report.json, the
    /// processes' logs and the server's data; its earlier demo files are
    /// replaced.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
}

/// Which pose the demo's explorers drive from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExplorePose {
    /// The simulator's true pose.
    True,
    /// The localizer's converged estimates, carried forward by odometry.
    Estimate,
}

impl ExplorePose {
    /// The flag's value, as report.json records it.
    pub fn name(self) -> &'static str {
        match self {
            Self::True => "true",
            Self::Estimate => "estimate",
        }
    }
}

/// The demo's times, checked: when the robots stop, how fast the simulator
/// runs, when the localizers start and when the kidnap comes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Schedule {
    /// Simulated seconds the robots drive; positive.
    pub duration_s: f64,
    /// Simulated seconds per wall-clock second; above 0, at most 100.
    pub speed: f64,
    /// Simulated second the first localizer starts (the others follow,
    /// [`Schedule::localizer_start_s`]); within `0..duration_s`.
    pub localize_at_s: f64,
    /// Simulated second the first robot is kidnapped, after `localize_at_s`
    /// and before `duration_s`; `None` for no kidnap.
    pub kidnap_at_s: Option<f64>,
}

/// Most simulated seconds between the starts of two robots' localizers.
const LOCALIZER_STAGGER_S: f64 = 4.0;

impl Schedule {
    /// Simulated second the localizer of robot `index` (of `robots`)
    /// starts: one after another, a few seconds apart (a global start
    /// builds the whole map's range tables and weighs its widest particle
    /// set; several at once on a small machine would each fall behind
    /// their robot), all of them within the first half of what is left of
    /// the run after `localize_at_s`.
    pub(crate) fn localizer_start_s(&self, index: usize, robots: usize) -> f64 {
        let room = (self.duration_s - self.localize_at_s) / 2.0 / robots.max(1) as f64;
        self.localize_at_s + LOCALIZER_STAGGER_S.min(room) * index as f64
    }
}

impl DemoOptions {
    /// Checks the times against each other, filling in the defaults; the
    /// error names the flag at fault.
    pub(crate) fn schedule(&self) -> Result<Schedule> {
        if !(self.duration.is_finite() && self.duration > 0.0) {
            bail!(
                "--duration must be a positive number of seconds, got {}",
                self.duration
            );
        }
        let duration = self.duration;
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 100.0) {
            bail!(
                "--speed must be above 0 and at most 100 simulated seconds per second, got {}",
                self.speed
            );
        }
        if self.explore_pose == ExplorePose::Estimate && self.no_localize {
            bail!(
                "--explore-pose estimate drives from the localizers' estimates: it cannot go with --no-localize"
            );
        }
        let localize_at = match self.localize_at {
            Some(t) if !(t.is_finite() && (0.0..duration).contains(&t)) => {
                bail!("--localize-at must be within 0 and --duration ({duration} s), got {t}")
            }
            Some(t) => t,
            // Explorers that drive from their estimates wait for them.
            None if self.explore_pose == ExplorePose::Estimate => 0.0,
            None => duration / 4.0,
        };
        let kidnap_at = match (self.no_kidnap || self.no_localize, self.kidnap_at) {
            (true, _) => None,
            (false, Some(t)) if !(t.is_finite() && t > localize_at && t < duration) => bail!(
                "--kidnap-at must come after --localize-at ({localize_at} s) and before --duration ({duration} s), got {t}"
            ),
            (false, Some(t)) => Some(t),
            (false, None) => Some(duration / 2.0),
        };
        Ok(Schedule {
            duration_s: duration,
            speed: self.speed,
            localize_at_s: localize_at,
            kidnap_at_s: kidnap_at,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::options as parse;

    fn refused(args: &[&str]) -> String {
        let options = parse(args).expect("clap accepts the flags");
        options
            .schedule()
            .expect_err("the schedule is refused")
            .to_string()
    }

    #[test]
    fn defaults_are_three_robots_in_map2_for_240_s_at_4x() {
        let options = parse(&[]).expect("no flag is needed");
        assert_eq!(options.world, "map2");
        assert_eq!(options.robots, 3);
        assert_eq!(options.seed, 1);
        assert_eq!(options.out, PathBuf::from("demo-out"));
        assert_eq!(options.sonar, SonarPreset::Default);
        assert_eq!(
            parse(&["--sonar", "realistic"]).expect("valid").sonar,
            SonarPreset::Realistic
        );
        assert!(parse(&["--sonar", "loud"]).is_err());
        assert!(!options.keep && !options.no_kidnap);
        let schedule = options.schedule().expect("the defaults are valid");
        assert_eq!(
            schedule,
            Schedule {
                duration_s: 240.0,
                speed: 4.0,
                localize_at_s: 60.0,
                kidnap_at_s: Some(120.0),
            }
        );
    }

    #[test]
    fn localizers_start_apart_and_all_within_the_run() {
        let schedule = parse(&[]).expect("defaults").schedule().expect("valid");
        let starts: Vec<f64> = (0..3).map(|i| schedule.localizer_start_s(i, 3)).collect();
        assert_eq!(starts, vec![60.0, 64.0, 68.0]);
        // A short run squeezes them into the first half of what is left.
        let short = parse(&["--duration", "20", "--localize-at", "14"])
            .expect("valid flags")
            .schedule()
            .expect("valid times");
        let last = short.localizer_start_s(7, 8);
        assert!(last > 14.0 && last <= 17.0, "last localizer at {last} s");
    }

    #[test]
    fn given_times_are_kept() {
        let options = parse(&[
            "--duration",
            "100",
            "--speed",
            "2.5",
            "--localize-at",
            "0",
            "--kidnap-at",
            "99",
        ])
        .expect("valid flags");
        let schedule = options.schedule().expect("valid times");
        assert_eq!(schedule.duration_s, 100.0);
        assert_eq!(schedule.speed, 2.5);
        assert_eq!(schedule.localize_at_s, 0.0);
        assert_eq!(schedule.kidnap_at_s, Some(99.0));
    }

    #[test]
    fn no_kidnap_means_none_and_conflicts_with_kidnap_at() {
        let options = parse(&["--no-kidnap"]).expect("valid flag");
        assert_eq!(options.schedule().expect("valid").kidnap_at_s, None);
        assert!(parse(&["--no-kidnap", "--kidnap-at", "100"]).is_err());
    }

    #[test]
    fn robots_must_be_1_to_8() {
        assert!(parse(&["--robots", "0"]).is_err());
        assert!(parse(&["--robots", "9"]).is_err());
        assert_eq!(parse(&["--robots", "8"]).expect("valid").robots, 8);
    }

    #[test]
    fn bad_times_are_errors_naming_the_flag() {
        for (args, flag) in [
            (&["--duration", "0"][..], "--duration"),
            (&["--duration=-5"][..], "--duration"),
            (&["--duration", "inf"][..], "--duration"),
            (&["--duration", "NaN"][..], "--duration"),
            (&["--speed", "0"][..], "--speed"),
            (&["--speed", "101"][..], "--speed"),
            (&["--speed", "NaN"][..], "--speed"),
            (&["--localize-at", "240"][..], "--localize-at"),
            (&["--localize-at=-1"][..], "--localize-at"),
            (&["--localize-at", "NaN"][..], "--localize-at"),
            (&["--kidnap-at", "60"][..], "--kidnap-at"),
            (&["--kidnap-at", "240"][..], "--kidnap-at"),
            (
                &["--kidnap-at", "10", "--localize-at", "20"][..],
                "--kidnap-at",
            ),
        ] {
            let message = refused(args);
            assert!(message.starts_with(flag), "{args:?}: {message}");
        }
    }
}
