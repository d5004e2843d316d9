//! The figures as the JSON `--out` writes: serde records whose field names
//! are the keys scripts read. Figures are rounded as the table shows them
//! (seconds to the millisecond, rates to a tenth).

use anyhow::{Context, Result};
use serde::Serialize;

use super::figures::{MapServerFigures, mb};
use super::workload::TILE_SIDE;

/// The whole file.
#[derive(Serialize)]
struct MapServerRecord {
    config: ConfigRecord,
    baseline: BaselineRecord,
    throughput: Vec<ThroughputRecord>,
    /// Absent when the memory test was skipped (`--cells 0`).
    #[serde(skip_serializing_if = "Option::is_none")]
    memory: Option<MemoryRecord>,
}

/// The settings of the run.
#[derive(Serialize)]
struct ConfigRecord {
    duration_s: u64,
    batch_tiles: usize,
    window: usize,
    region_tiles: i32,
    tile_side: u32,
    cache_mb: u64,
    /// `sled`, `postgres` (private) or `postgres-url`.
    store: &'static str,
    /// The `--servers` counts measured.
    servers: Vec<usize>,
    maps: usize,
}

/// The thesis's mapper on the store's engine.
#[derive(Serialize)]
struct BaselineRecord {
    /// `sled` or `postgres`.
    store: &'static str,
    cell_updates: u64,
    inserts: u64,
    rewrites: u64,
    flushes: u64,
    seconds: f64,
    cell_updates_per_s: f64,
}

/// One throughput measurement.
#[derive(Serialize)]
struct ThroughputRecord {
    servers: usize,
    clients: usize,
    maps: usize,
    cell_updates: u64,
    batches: u64,
    seconds: f64,
    cell_updates_per_s: f64,
    ratio_to_baseline: f64,
    server_cpu_s: f64,
    /// Null unless the bench started the PostgreSQL.
    database_cpu_s: Option<f64>,
    bench_cpu_s: f64,
}

/// The memory test; memory in MB of 1024 kB.
#[derive(Serialize)]
struct MemoryRecord {
    target_cells: u64,
    tiles: u64,
    cell_count: u64,
    tile_count: u64,
    seconds: f64,
    rss_before_mb: f64,
    peak_rss_sampled_mb: f64,
    samples: u64,
    vm_hwm_mb: f64,
    rss_after_mb: f64,
    /// Null when the bench does not know the folder.
    data_apparent_bytes: Option<u64>,
    data_allocated_bytes: Option<u64>,
    /// Null on sled.
    database_bytes: Option<u64>,
}

/// `x` rounded to `decimals` places.
fn round(x: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (x * scale).round() / scale
}

impl MapServerFigures<'_> {
    fn record(&self) -> MapServerRecord {
        let (o, b) = (self.options, &self.baseline);
        MapServerRecord {
            config: ConfigRecord {
                duration_s: o.duration_s,
                batch_tiles: o.batch_tiles,
                window: o.window,
                region_tiles: o.region_tiles,
                tile_side: TILE_SIDE,
                cache_mb: o.cache_mb,
                store: self.store,
                servers: o.servers.clone(),
                maps: o.maps,
            },
            baseline: BaselineRecord {
                store: b.engine,
                cell_updates: b.updates,
                inserts: b.inserts,
                rewrites: b.rewrites,
                flushes: b.flushes,
                seconds: round(b.seconds, 3),
                cell_updates_per_s: round(b.cells_per_s(), 1),
            },
            throughput: self
                .throughput
                .iter()
                .map(|t| ThroughputRecord {
                    servers: t.servers,
                    clients: t.clients,
                    maps: t.maps,
                    cell_updates: t.cells,
                    batches: t.batches,
                    seconds: round(t.seconds, 3),
                    cell_updates_per_s: round(t.cells_per_s(), 1),
                    ratio_to_baseline: round(t.cells_per_s() / b.cells_per_s(), 2),
                    server_cpu_s: round(t.server_cpu_s, 2),
                    database_cpu_s: t.database_cpu_s.map(|s| round(s, 2)),
                    bench_cpu_s: round(t.bench_cpu_s, 2),
                })
                .collect(),
            memory: self.memory.as_ref().map(|m| MemoryRecord {
                target_cells: m.target_cells,
                tiles: m.tiles,
                cell_count: m.cell_count,
                tile_count: m.tile_count,
                seconds: round(m.seconds, 3),
                rss_before_mb: round(mb(m.rss_before_kb), 1),
                peak_rss_sampled_mb: round(mb(m.peak_rss_sampled_kb), 1),
                samples: m.samples,
                vm_hwm_mb: round(mb(m.hwm_kb), 1),
                rss_after_mb: round(mb(m.rss_after_kb), 1),
                data_apparent_bytes: m.data_apparent_bytes,
                data_allocated_bytes: m.data_allocated_bytes,
                database_bytes: m.database_bytes,
            }),
        }
    }

    /// The figures as pretty-printed JSON, ending with a newline.
    pub fn json(&self) -> Result<String> {
        deog_evaluation::json::pretty_json(&self.record()).context("assembling the JSON")
    }
}

#[cfg(test)]
mod tests {
    use super::super::MapServerOptions;
    use super::super::baseline::BaselineRun;
    use super::super::memory::MemoryRun;
    use super::super::throughput::ThroughputRun;
    use super::*;

    fn options() -> MapServerOptions {
        MapServerOptions {
            duration_s: 2,
            clients: vec![1],
            cells: 1000,
            out: None,
            batch_tiles: 16,
            window: 32,
            region_tiles: 32,
            cache_mb: 64,
            store: "sled".into(),
            servers: vec![1],
            maps: 1,
        }
    }

    fn figures(options: &MapServerOptions, memory: bool) -> MapServerFigures<'_> {
        MapServerFigures {
            options,
            store: "sled",
            baseline: BaselineRun {
                engine: "sled",
                updates: 300,
                inserts: 300,
                rewrites: 0,
                flushes: 2,
                seconds: 2.0004,
            },
            throughput: vec![ThroughputRun {
                servers: 1,
                clients: 1,
                maps: 1,
                cells: 4096,
                batches: 1,
                seconds: 2.0,
                server_cpu_s: 0.5,
                database_cpu_s: None,
                bench_cpu_s: 0.25,
                map_version: 1,
            }],
            memory: memory.then_some(MemoryRun {
                target_cells: 1000,
                tiles: 1,
                cell_count: 1000,
                tile_count: 1,
                seconds: 0.1,
                rss_before_kb: 1024,
                peak_rss_sampled_kb: 2048,
                samples: 2,
                hwm_kb: 2048,
                rss_after_kb: 1536,
                data_apparent_bytes: Some(10),
                data_allocated_bytes: Some(4096),
                database_bytes: None,
            }),
        }
    }

    fn keys(value: &serde_json::Value) -> Vec<&str> {
        value
            .as_object()
            .expect("an object")
            .keys()
            .map(String::as_str)
            .collect()
    }

    #[test]
    fn the_json_keeps_the_keys_scripts_read() {
        let options = options();
        let json = figures(&options, true).json().expect("JSON");
        let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
        let expected: [(&serde_json::Value, &[&str]); 5] = [
            (&value, &["baseline", "config", "memory", "throughput"]),
            (
                &value["config"],
                &[
                    "batch_tiles",
                    "cache_mb",
                    "duration_s",
                    "maps",
                    "region_tiles",
                    "servers",
                    "store",
                    "tile_side",
                    "window",
                ],
            ),
            (
                &value["baseline"],
                &[
                    "cell_updates",
                    "cell_updates_per_s",
                    "flushes",
                    "inserts",
                    "rewrites",
                    "seconds",
                    "store",
                ],
            ),
            (
                &value["throughput"][0],
                &[
                    "batches",
                    "bench_cpu_s",
                    "cell_updates",
                    "cell_updates_per_s",
                    "clients",
                    "database_cpu_s",
                    "maps",
                    "ratio_to_baseline",
                    "seconds",
                    "server_cpu_s",
                    "servers",
                ],
            ),
            (
                &value["memory"],
                &[
                    "cell_count",
                    "data_allocated_bytes",
                    "data_apparent_bytes",
                    "database_bytes",
                    "peak_rss_sampled_mb",
                    "rss_after_mb",
                    "rss_before_mb",
                    "samples",
                    "seconds",
                    "target_cells",
                    "tile_count",
                    "tiles",
                    "vm_hwm_mb",
                ],
            ),
        ];
        for (object, names) in expected {
            let mut found = keys(object);
            found.sort_unstable();
            assert_eq!(found, names);
        }
        assert_eq!(value["baseline"]["seconds"], 2.0);
        assert_eq!(value["baseline"]["cell_updates_per_s"], 150.0);
        assert_eq!(value["throughput"][0]["ratio_to_baseline"], 13.66);
        assert_eq!(value["memory"]["rss_after_mb"], 1.5);
        assert_eq!(value["memory"]["vm_hwm_mb"], 2.0);
    }

    #[test]
    fn a_skipped_memory_test_leaves_no_memory_key() {
        let options = options();
        let json = figures(&options, false).json().expect("JSON");
        let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
        assert!(value.get("memory").is_none());
    }
}
