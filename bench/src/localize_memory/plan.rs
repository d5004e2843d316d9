//! The run's settings checked, and the city sized so that the map, held
//! whole in the localizer, is at least `--min-ratio` times the cache.

use deog_localizer::range_table::ConeGeometry;
use deog_world::city::{MIN_SIDE_M, RESOLUTION_M};

use super::{LocalizeMemoryOptions, TILE_SIDE};
use crate::option_error::{OptionError, require};

/// Largest map side, metres: the image and the server's import must fit
/// comfortably in memory.
const MAX_SIDE_M: f64 = 500.0;

/// The city a run of `deog bench localize-memory` drives in, sized
/// against the localizer's cache budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CityPlan {
    /// The cache budget, bytes.
    pub budget_bytes: usize,
    /// Pixels (cells) a side of the city.
    pub side_px: u32,
    /// Bytes one tile costs the localizer: cells, reference bits, table.
    pub tile_bytes: usize,
    /// Tiles the city covers.
    pub tiles: u64,
}

impl CityPlan {
    /// Checks the options and sizes the city: `--side-m` if given, else
    /// the smallest whole number of tiles a side that makes the ratio.
    pub fn new(options: &LocalizeMemoryOptions) -> Result<Self, OptionError> {
        require(
            (16..=1 << 20).contains(&options.cache_mb),
            "--cache-mb",
            || {
                format!(
                    "--cache-mb must be in [16, 1048576] MiB (what deog localize takes), got {}",
                    options.cache_mb
                )
            },
        )?;
        let rig = deog_rig::load_rig_spec(&options.rig).map_err(|e| e.to_string());
        require(rig.is_ok(), "--rig", || {
            format!(
                "--rig {}: {}",
                options.rig,
                rig.clone().err().unwrap_or_default()
            )
        })?;
        require(
            (1..=10_000_000).contains(&options.max_particles),
            "--max-particles",
            || {
                format!(
                    "--max-particles must be in [1, 10000000] (what deog localize takes), got {}",
                    options.max_particles
                )
            },
        )?;
        require(
            options.min_ratio.is_finite() && options.min_ratio > 0.0,
            "--min-ratio",
            || {
                format!(
                    "--min-ratio must be a positive number, got {}",
                    options.min_ratio
                )
            },
        )?;
        require(
            options.duration.is_finite() && options.duration >= 10.0,
            "--duration",
            || {
                format!(
                    "--duration must be at least 10 simulated seconds, got {}",
                    options.duration
                )
            },
        )?;
        require(
            options.speed.is_finite() && options.speed > 0.0 && options.speed <= 100.0,
            "--speed",
            || {
                format!(
                    "--speed must be above 0 and at most 100 simulated seconds per second, got {}",
                    options.speed
                )
            },
        )?;
        require(
            options.robot_speed.is_finite()
                && options.robot_speed > 0.0
                && options.robot_speed <= 1.0,
            "--robot-speed",
            || {
                format!(
                    "--robot-speed must be above 0 and at most 1 m/s, got {}",
                    options.robot_speed
                )
            },
        )?;
        let budget_bytes = options.cache_mb << 20;
        let tile_bytes = localizer_tile_bytes();
        let side_px = match options.side_m {
            Some(side) => {
                require(
                    side.is_finite() && (MIN_SIDE_M..=MAX_SIDE_M).contains(&side),
                    "--side-m",
                    || {
                        format!(
                            "--side-m must be within {MIN_SIDE_M} and {MAX_SIDE_M} m, got {side}"
                        )
                    },
                )?;
                (side / RESOLUTION_M).round() as u32
            }
            None => {
                let needed = (options.min_ratio * budget_bytes as f64 / tile_bytes as f64).ceil();
                let tiles_a_side = needed.sqrt().ceil().max(1.0);
                let side_px = tiles_a_side * f64::from(TILE_SIDE);
                let side_m = side_px * RESOLUTION_M;
                require(side_m <= MAX_SIDE_M, "--min-ratio", || {
                    format!(
                        "a map {:.0} times a {} MiB cache would be {side_m:.0} m a side, more than {MAX_SIDE_M} m: lower --cache-mb or --min-ratio",
                        options.min_ratio, options.cache_mb
                    )
                })?;
                (side_px as u32).max((MIN_SIDE_M / RESOLUTION_M) as u32)
            }
        };
        let tiles = u64::from(side_px.div_ceil(TILE_SIDE)).pow(2);
        let ratio = (tiles * tile_bytes as u64) as f64 / budget_bytes as f64;
        require(ratio >= options.min_ratio, "--side-m", || {
            format!(
                "a city {:.1} m a side has {tiles} tiles, {:.0} MiB in the localizer: {ratio:.1} times the {} MiB cache, under --min-ratio {}; make --side-m larger",
                f64::from(side_px) * RESOLUTION_M,
                (tiles * tile_bytes as u64) as f64 / f64::from(1 << 20),
                options.cache_mb,
                options.min_ratio
            )
        })?;
        Ok(Self {
            budget_bytes,
            side_px,
            tile_bytes,
            tiles,
        })
    }

    /// Bytes the whole map takes in the localizer's representation.
    pub fn map_bytes(&self) -> u64 {
        self.tiles * self.tile_bytes as u64
    }
}

/// What one tile costs the localizer when it holds all of it, as
/// `LocalMap` counts it against the budget: a byte per cell, the bitmap of
/// its occupied cells, and its expected-range table.
fn localizer_tile_bytes() -> usize {
    let area = (TILE_SIDE * TILE_SIDE) as usize;
    area + area.div_ceil(64) * 8 + ConeGeometry::default().table_bytes(area)
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        options: LocalizeMemoryOptions,
    }

    /// The options as `deog bench localize-memory` parses them, with `args`.
    fn parse(args: &[&str]) -> LocalizeMemoryOptions {
        Cli::try_parse_from(std::iter::once("localize-memory").chain(args.iter().copied()))
            .expect("options parse")
            .options
    }

    #[test]
    fn default_city_is_a_hundred_times_the_smallest_cache() {
        let options = parse(&[]);
        assert_eq!(options.validate(), Ok(()));
        let plan = CityPlan::new(&options).unwrap();
        assert!(plan.map_bytes() >= 100 * (16 << 20));
        assert_eq!(plan.side_px % TILE_SIDE, 0);
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        let cases: [(&str, &[&str]); 8] = [
            ("--cache-mb", &["--cache-mb", "8"]),
            ("--rig", &["--rig", "no-such-rig"]),
            ("--max-particles", &["--max-particles", "0"]),
            ("--min-ratio", &["--min-ratio", "NaN"]),
            ("--duration", &["--duration", "5"]),
            ("--speed", &["--speed", "0"]),
            ("--robot-speed", &["--robot-speed", "2"]),
            ("--side-m", &["--side-m", "1000"]),
        ];
        for (flag, args) in cases {
            let err = CityPlan::new(&parse(args)).expect_err(flag);
            assert_eq!(err.flag, flag, "{err}");
            assert!(err.to_string().starts_with(flag), "{flag}: {err}");
        }
    }

    #[test]
    fn any_rig_deog_knows_is_taken() {
        for rig in ["scout", "pioneer3dx", "laser180"] {
            assert_eq!(parse(&["--rig", rig]).validate(), Ok(()), "{rig}");
        }
    }

    #[test]
    fn a_city_too_large_for_the_ratio_is_refused() {
        let err = CityPlan::new(&parse(&["--cache-mb", "1024"])).expect_err("too large");
        assert_eq!(err.flag, "--min-ratio");
        assert!(
            err.to_string().contains("lower --cache-mb or --min-ratio"),
            "{err}"
        );
    }

    #[test]
    fn a_city_too_small_for_the_ratio_is_refused() {
        let err = CityPlan::new(&parse(&["--side-m", "50"])).expect_err("too small");
        assert_eq!(err.flag, "--side-m");
        assert!(err.to_string().contains("make --side-m larger"), "{err}");
    }
}
