//! How much of the world's reachable free space the shared map has seen,
//! sampled as the robots drive, beside the demo's control loop: the curve
//! report.json gives, and the simulated seconds to 95% and 99%.

use std::sync::Arc;

use anyhow::{Context, Result};
use deog_evaluation::map_quality::{QualityInput, map_quality};
use deog_harness::run_reads::robot_starts;
use deog_robot_client::MapClient;
use deog_world::World;
use serde::Serialize;
use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::commands::MAP;
use crate::plan::DemoPlan;

/// Simulated seconds between two samples.
pub(crate) const SAMPLE_EVERY_S: f64 = 10.0;

/// One sample of the curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CoverageSample {
    /// Simulated seconds since the robots started.
    pub simulated_s: f64,
    /// Reachable free cells the map classifies free, over all of them.
    pub fraction: f64,
}

/// The samples taken so far and when the next is due.
#[derive(Debug, Default)]
pub(crate) struct CoverageCurve {
    samples: Vec<CoverageSample>,
    next_s: f64,
}

/// What the map's coverage is measured against: the world and the size
/// of the robots that must reach its free space.
#[derive(Debug, Clone)]
pub(crate) struct CoverageJudge {
    world: Arc<World>,
    robot_radius_m: f64,
}

impl CoverageJudge {
    /// The plan's world and robots.
    pub fn of(plan: &DemoPlan) -> Self {
        Self {
            world: Arc::new(plan.world.clone()),
            robot_radius_m: deog_evaluation::map_quality::DEFAULT_ROBOT_RADIUS_M
                .max(plan.rig.body_radius()),
        }
    }
}

impl CoverageCurve {
    /// Samples the map now, at simulated second `now_s`: the map read
    /// from the server, its coverage worked out on a blocking thread (a
    /// building's flood fill takes a while).
    pub async fn sample(
        &mut self,
        client: &MapClient,
        judge: &CoverageJudge,
        now_s: f64,
    ) -> Result<()> {
        let map = match client.download(MAP).await {
            Ok((_, map)) if map.observed_count() > 0 => map,
            // No map yet, or one made but not written: nothing seen.
            _ => {
                self.samples.push(CoverageSample {
                    simulated_s: now_s,
                    fraction: 0.0,
                });
                return Ok(());
            }
        };
        let seeds = robot_starts(client).await?;
        let (world, robot_radius_m) = (judge.world.clone(), judge.robot_radius_m);
        let quality = tokio::task::spawn_blocking(move || {
            map_quality(&QualityInput {
                map: &map,
                world: &world,
                seeds: &seeds,
                robot_radius_m,
            })
        })
        .await
        .context("measuring the map's coverage")?
        .context("measuring the map's coverage")?;
        self.samples.push(CoverageSample {
            simulated_s: now_s,
            fraction: quality.coverage().unwrap_or(0.0),
        });
        Ok(())
    }

    /// The samples, in time order.
    pub fn samples(&self) -> &[CoverageSample] {
        &self.samples
    }
}

/// The curve sampled beside the demo's control loop, so that however
/// long a sample of a large world takes, localizers start, the kidnap
/// happens and the robots stop when the plan says.
pub(crate) struct CoverageSampler {
    clock: watch::Sender<Tick>,
    task: JoinHandle<Result<CoverageCurve>>,
}

/// The demo's simulated second, and whether the robots have stopped.
#[derive(Debug, Clone, Copy, Default)]
struct Tick {
    now_s: f64,
    last: bool,
}

impl CoverageSampler {
    /// Starts sampling every [`SAMPLE_EVERY_S`] of the times it is told
    /// ([`Self::tick`]); within the runtime.
    pub fn spawn(client: MapClient, judge: CoverageJudge) -> Self {
        let (clock, mut ticks) = watch::channel(Tick::default());
        let task = tokio::spawn(async move {
            let mut curve = CoverageCurve::default();
            // A sample that takes long lets ticks pass: the next is of the
            // newest time.
            while ticks.changed().await.is_ok() {
                let tick = *ticks.borrow_and_update();
                if tick.last {
                    curve.sample(&client, &judge, tick.now_s).await?;
                    break;
                }
                if tick.now_s >= curve.next_s {
                    curve.next_s = tick.now_s + SAMPLE_EVERY_S;
                    curve.sample(&client, &judge, tick.now_s).await?;
                }
            }
            Ok(curve)
        });
        Self { clock, task }
    }

    /// The demo's simulated second now: a sample is taken if one is due.
    pub fn tick(&self, now_s: f64) {
        // The task gone means it failed: `finish` tells why.
        let _ = self.clock.send(Tick { now_s, last: false });
    }

    /// The last sample, at `now_s` once the robots stopped, and the curve.
    pub async fn finish(self, now_s: f64) -> Result<CoverageCurve> {
        let _ = self.clock.send(Tick { now_s, last: true });
        self.task.await.context("sampling the map's coverage")?
    }
}

/// The first simulated second at which the coverage reached `fraction`.
pub fn time_to(samples: &[CoverageSample], fraction: f64) -> Option<f64> {
    samples
        .iter()
        .find(|s| s.fraction >= fraction)
        .map(|s| s.simulated_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_to_a_coverage_is_its_first_sample_at_or_past_it() {
        let samples: Vec<CoverageSample> = [
            (0.0, 0.1),
            (10.0, 0.5),
            (20.0, 0.96),
            (30.0, 0.94),
            (40.0, 0.995),
        ]
        .iter()
        .map(|&(simulated_s, fraction)| CoverageSample {
            simulated_s,
            fraction,
        })
        .collect();
        assert_eq!(time_to(&samples, 0.95), Some(20.0));
        assert_eq!(time_to(&samples, 0.99), Some(40.0));
        assert_eq!(time_to(&samples, 0.999), None);
    }
}
