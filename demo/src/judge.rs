//! The run judged once the processes have stopped, with the same code as
//! `deog eval`: the map against the world's ground truth, each localizer
//! against its robot's true poses. Writes the pictures: the map, where it
//! is right and wrong, and each robot's paths.

use std::path::Path;

use anyhow::{Context, Result};
use deog_evaluation::localization::{
    EvalInput, EvalParams, LocalizationReport, PlotInput, RobotPath, evaluate, render_plot,
};
use deog_evaluation::map_quality::{
    DEFAULT_ROBOT_RADIUS_M, MapQuality, QualityInput, map_quality, verdict_png,
};
use deog_grid::TileMap;
use deog_harness::run_reads::{read_map, read_robot, robot_starts};
use deog_mapfile::{to_png_with_scale_bar, write_map};
use deog_mapping::export_map;
use deog_robot_client::MapClient;
use deog_world::Point2;

use crate::commands::{MAP, REFIT_MAP, REFIT_STEM};
use crate::kidnap::KidnapDone;
use crate::plan::DemoPlan;

/// Where the map is right and wrong, drawn over the world.
pub(crate) const VERDICT_PNG: &str = "map-verdict.png";
/// The same for the refitted map.
pub(crate) const REFIT_VERDICT_PNG: &str = "map-refit-verdict.png";

/// One robot's figures and its plot's file name.
#[derive(Debug, Clone)]
pub(crate) struct RobotJudgement {
    /// Its localizer against its true poses.
    pub report: LocalizationReport,
    /// The file of its path plot, in the output folder.
    pub plot: String,
}

/// What the judging found.
#[derive(Debug, Clone)]
pub(crate) struct Judgement {
    /// The robots, in the plan's order.
    pub robots: Vec<RobotJudgement>,
    /// The map against the world.
    pub quality: MapQuality,
    /// The map's picture, in the output folder.
    pub map_png: String,
    /// The map's map_server YAML file, in the output folder.
    pub map_yaml: String,
    /// The map refitted to every frame, when the plan refits.
    pub refit: Option<RefitJudgement>,
}

/// The refitted map (`deog refit`, loaded as [`REFIT_MAP`]) judged.
#[derive(Debug, Clone)]
pub(crate) struct RefitJudgement {
    /// The refitted map against the world.
    pub quality: MapQuality,
    /// Its picture, in the output folder.
    pub map_png: String,
    /// Its map_server YAML file, in the output folder.
    pub map_yaml: String,
}

/// Judges the map against the world and each localizer against its
/// robot's true poses; writes the map files and the path plots to `out`.
/// Each localizer is judged from the simulator's second it was started
/// at (`localizer_starts_s`, in the plan's order); the kidnap the demo
/// made is one the judge knows of, whatever the jump.
pub(crate) async fn judge(
    client: &MapClient,
    plan: &DemoPlan,
    localizer_starts_s: &[f64],
    kidnap: Option<&KidnapDone>,
    out: &Path,
) -> Result<Judgement> {
    let map = read_map(client, MAP).await?;
    let seeds = robot_starts(client).await?;
    let quality = judge_map(&map, plan, &seeds, out, VERDICT_PNG)?;
    let (map_yaml, map_png) = write_map_files(&map, out)?;
    let refit = if plan.refit {
        let refitted = read_map(client, REFIT_MAP).await?;
        Some(RefitJudgement {
            quality: judge_map(&refitted, plan, &seeds, out, REFIT_VERDICT_PNG)?,
            map_png: format!("{REFIT_STEM}.png"),
            map_yaml: format!("{REFIT_STEM}.yaml"),
        })
    } else {
        None
    };
    let mut robots = Vec::with_capacity(plan.robots.len());
    if plan.localize {
        let names: Vec<_> = plan.robot_names().collect();
        for (index, name) in names.iter().enumerate() {
            let started_s = localizer_starts_s
                .get(index)
                .copied()
                .unwrap_or_else(|| plan.schedule.localizer_start_s(index, names.len()));
            let kidnapped_at = kidnap.filter(|k| k.robot == *name).map(|k| k.time_s);
            robots.push(judge_robot(client, &map, name, started_s, kidnapped_at, out).await?);
        }
    }
    Ok(Judgement {
        robots,
        quality,
        map_png,
        map_yaml,
        refit,
    })
}

/// `map` against the world's ground truth, its verdict drawn to file
/// `verdict` in `out`.
fn judge_map(
    map: &TileMap,
    plan: &DemoPlan,
    seeds: &[Point2],
    out: &Path,
    verdict: &str,
) -> Result<MapQuality> {
    let input = QualityInput {
        map,
        world: &plan.world,
        seeds,
        // The Scout's figure for the Scout, so its figures stay; a larger
        // robot reaches less.
        robot_radius_m: DEFAULT_ROBOT_RADIUS_M.max(plan.rig.body_radius()),
    };
    let quality = map_quality(&input).context("judging the map against the world")?;
    let png = verdict_png(&input).context("drawing where the map is right and wrong")?;
    write(out, verdict, &png)?;
    Ok(quality)
}

/// Judges robot `name`'s localizer, started at simulated second
/// `started_s` (and its robot kidnapped at `kidnapped_at`), and draws its
/// paths over `map`.
async fn judge_robot(
    client: &MapClient,
    map: &TileMap,
    name: &str,
    started_s: f64,
    kidnapped_at: Option<f64>,
    out: &Path,
) -> Result<RobotJudgement> {
    // Judge from the localizer's start, not from the mapping head start
    // before it ran: a localizer that searches publishes its first
    // estimate only once the robot's frames outline where it is, and that
    // wait counts towards its time to converge.
    let first = client
        .read_poses(name, 0, 0)
        .await
        .with_context(|| format!("reading the estimates of {name}"))?
        .iter()
        .filter(|p| p.map == MAP)
        .map(|p| p.frame_sequence)
        .min()
        .with_context(|| format!("the localizer of {name} published no estimate"))?;
    let mut samples = read_robot(client, name, Some(MAP), 0, 0).await?;
    let first_time = samples
        .truth
        .iter()
        .find(|t| t.sequence == first)
        .map_or(started_s, |t| t.time_s);
    samples
        .truth
        .retain(|t| t.time_s >= started_s.min(first_time));
    // The first frame at or after the simulator's kidnap.
    let known: Vec<u64> = kidnapped_at
        .and_then(|at| samples.truth.iter().find(|t| t.time_s >= at))
        .map(|t| t.sequence)
        .into_iter()
        .collect();
    let report = evaluate(&EvalInput {
        robot: name,
        map: Some(MAP),
        truth: &samples.truth,
        estimates: &samples.estimates,
        params: EvalParams::default(),
        known_kidnaps: &known,
    })
    .with_context(|| format!("judging the estimates of {name}"))?;
    let plot = format!("{name}.png");
    let raster = render_plot(&PlotInput {
        map: Some(map),
        robots: &[RobotPath {
            truth: &samples.truth,
            estimates: &samples.estimates,
            kidnaps: &report.kidnaps,
            convergence: report.convergence,
        }],
    })
    .with_context(|| format!("drawing the paths of {name}"))?;
    let png = raster.to_png().context("encoding the plot")?;
    write(out, &plot, &png)?;
    Ok(RobotJudgement { report, plot })
}

/// The map as map_server files and a PNG; returns the YAML and PNG names.
fn write_map_files(map: &TileMap, out: &Path) -> Result<(String, String)> {
    let export = export_map(map).context("exporting the map")?;
    write_map(out, "map", &export.image)?;
    to_png_with_scale_bar(out.join("map.png"), &export.image)?;
    Ok(("map.yaml".to_string(), "map.png".to_string()))
}

/// Writes `bytes` to file `name` in `out`.
fn write(out: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    let path = out.join(name);
    std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))
}
