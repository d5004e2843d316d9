//! Everything `deog bench map-server` measured, as the table it prints.

use std::fmt::Write as _;

use super::MapServerOptions;
use super::baseline::BaselineRun;
use super::memory::MemoryRun;
use super::throughput::ThroughputRun;
use super::workload::TILE_SIDE;

/// The figures of one run of the bench, with the options it ran with.
pub(super) struct MapServerFigures<'a> {
    /// The options of the run.
    pub options: &'a MapServerOptions,
    /// The store, as [`super::StoreChoice::label`] names it.
    pub store: &'static str,
    /// The thesis's mapper on the store's engine.
    pub baseline: BaselineRun,
    /// One measurement per `--servers` count and `--clients` count, in
    /// that order.
    pub throughput: Vec<ThroughputRun>,
    /// The memory test, unless `--cells` was 0.
    pub memory: Option<MemoryRun>,
}

/// `x` in millions, as the table shows rates; small rates (the thesis's
/// mapper on PostgreSQL) with the digits that tell them apart.
fn millions(x: f64) -> String {
    if x < 1e5 {
        format!("{:.4} M", x / 1e6)
    } else {
        format!("{:.2} M", x / 1e6)
    }
}

/// kB as MB (of 1024 kB), as the table and the JSON show memory.
pub(super) fn mb(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

impl MapServerFigures<'_> {
    /// The figures as Markdown tables, with a line on the settings first.
    pub fn table(&self) -> String {
        let b = &self.baseline;
        let o = self.options;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "\nmap server bench on {}: {} s per measurement, batches of {} tiles of {TILE_SIDE}x{TILE_SIDE}, window {}, region {}x{} tiles",
            self.store, o.duration_s, o.batch_tiles, o.window, o.region_tiles, o.region_tiles
        );
        let _ = writeln!(
            out,
            "\n| measure | cell updates/s | vs baseline | cells | seconds | server CPU s | database CPU s | bench CPU s |"
        );
        let _ = writeln!(out, "|---|---|---|---|---|---|---|---|");
        let _ = writeln!(
            out,
            "| thesis Fig. 7.1 on {}, 1 thread (baseline) | {} | 1.0x | {} | {:.2} | - | - | - |",
            b.engine,
            millions(b.cells_per_s()),
            b.updates,
            b.seconds
        );
        for t in &self.throughput {
            let _ = writeln!(
                out,
                "| {} map server(s), {} client(s){}, durable | {} | {:.1}x | {} | {:.2} | {:.2} | {} | {:.2} |",
                t.servers,
                t.clients,
                if t.maps > 1 {
                    format!(" on {} maps", t.maps)
                } else {
                    String::new()
                },
                millions(t.cells_per_s()),
                t.cells_per_s() / b.cells_per_s(),
                t.cells,
                t.seconds,
                t.server_cpu_s,
                t.database_cpu_s
                    .map_or_else(|| "-".to_string(), |s| format!("{s:.2}")),
                t.bench_cpu_s
            );
        }
        let _ = writeln!(
            out,
            "\nbaseline: {} inserts, {} rewrites, {} flushes",
            b.inserts, b.rewrites, b.flushes
        );
        for t in &self.throughput {
            let _ = writeln!(
                out,
                "{} server(s), {} client(s): {} batches acknowledged as applied, map version {}",
                t.servers, t.clients, t.batches, t.map_version
            );
        }
        if let Some(m) = &self.memory {
            memory_table(&mut out, m);
        }
        out
    }
}

/// The memory test's table.
fn memory_table(out: &mut String, m: &MemoryRun) {
    let _ = writeln!(out, "\n| memory | value |");
    let _ = writeln!(out, "|---|---|");
    let _ = writeln!(
        out,
        "| target cells | {} ({} tiles) |",
        m.target_cells, m.tiles
    );
    let _ = writeln!(
        out,
        "| map cell_count / tile_count | {} / {} |",
        m.cell_count, m.tile_count
    );
    let _ = writeln!(
        out,
        "| growth time | {:.1} s ({} new cells/s) |",
        m.seconds,
        millions(m.target_cells as f64 / m.seconds)
    );
    let _ = writeln!(
        out,
        "| server VmRSS before | {:.1} MB |",
        mb(m.rss_before_kb)
    );
    let _ = writeln!(
        out,
        "| server peak VmRSS sampled (100 ms, {} samples) | {:.1} MB |",
        m.samples,
        mb(m.peak_rss_sampled_kb)
    );
    let _ = writeln!(
        out,
        "| server VmHWM at the end (whole run) | {:.1} MB |",
        mb(m.hwm_kb)
    );
    let _ = writeln!(out, "| server VmRSS after | {:.1} MB |", mb(m.rss_after_kb));
    if let (Some(apparent), Some(allocated)) = (m.data_apparent_bytes, m.data_allocated_bytes) {
        let _ = writeln!(
            out,
            "| data directory (apparent / allocated) | {:.1} MB / {:.1} MB |",
            apparent as f64 / 1e6,
            allocated as f64 / 1e6
        );
    }
    if let Some(bytes) = m.database_bytes {
        let _ = writeln!(
            out,
            "| database size (pg_database_size) | {:.1} MB |",
            bytes as f64 / 1e6
        );
    }
}
