//! How much of the world's reachable free space the shared map has seen,
//! sampled as the robots drive: the curve report.json gives, and the
//! simulated seconds to 95% and 99%.

use anyhow::{Context, Result};
use deog_evaluation::map_quality::{QualityInput, map_quality};
use deog_harness::run_reads::robot_starts;
use deog_robot_client::MapClient;
use serde::Serialize;

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

impl CoverageCurve {
    /// Samples the map if one is due at simulated second `now_s`.
    pub async fn sample_if_due(
        &mut self,
        client: &MapClient,
        plan: &DemoPlan,
        now_s: f64,
    ) -> Result<()> {
        if now_s < self.next_s {
            return Ok(());
        }
        self.next_s = now_s + SAMPLE_EVERY_S;
        self.sample(client, plan, now_s).await
    }

    /// Samples the map now.
    pub async fn sample(&mut self, client: &MapClient, plan: &DemoPlan, now_s: f64) -> Result<()> {
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
        let quality = map_quality(&QualityInput {
            map: &map,
            world: &plan.world,
            seeds: &seeds,
            robot_radius_m: deog_evaluation::map_quality::DEFAULT_ROBOT_RADIUS_M
                .max(plan.rig.body_radius()),
        })
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
