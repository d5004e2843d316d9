//! The figures of `deog bench localize-memory` as the table it prints.

use std::fmt::Write as _;

use deog_evaluation::tracking::LostStretch;
use deog_world::city::RESOLUTION_M;

use super::figures::{LocalizerMemoryFigures, mib};
use super::{SAMPLE_EVERY, TILE_SIDE};

impl LocalizerMemoryFigures {
    /// The figures as a Markdown table, a line on the run before it and
    /// the verdict on the requirement after.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let m = &self.memory;
        let side_m = f64::from(self.side_px) * RESOLUTION_M;
        let _ = writeln!(
            out,
            "\nlocalizer memory: one robot, {:.0} simulated s at {}x, cruising at {} m/s, seed {}",
            self.duration_s, self.speed, self.robot_speed, self.seed
        );
        let _ = writeln!(out, "\n| figure | value |");
        let _ = writeln!(out, "|---|---|");
        let _ = writeln!(
            out,
            "| map | city {side_m:.1} m a side ({} px at {RESOLUTION_M} m), {} blocks, {} tiles of {TILE_SIDE}x{TILE_SIDE} |",
            self.side_px, self.blocks, self.tiles
        );
        let _ = writeln!(
            out,
            "| map in the localizer's representation | {:.2} GiB ({} tiles x {:.1} KiB: cells, occupied bits, range table) |",
            self.map_bytes() as f64 / f64::from(1 << 30),
            self.tiles,
            self.tile_bytes as f64 / 1024.0
        );
        let _ = writeln!(out, "| cache budget (--cache-mb) | {} MiB |", self.cache_mb);
        let _ = writeln!(
            out,
            "| the localizer's --max-particles | {} |",
            self.max_particles
        );
        let _ = writeln!(out, "| map / budget | {:.1} |", self.ratio());
        let _ = writeln!(
            out,
            "| localizer RSS baseline (first tiles built, {:.1} simulated s) | {:.1} MiB |",
            self.baseline_time_s,
            mib(self.baseline_kb)
        );
        let _ = writeln!(
            out,
            "| localizer peak RSS (VmHWM) | {:.1} MiB |",
            mib(m.hwm_kb)
        );
        let _ = writeln!(
            out,
            "| localizer peak VmRSS sampled ({} samples, every {} ms) | {:.1} MiB |",
            m.samples,
            SAMPLE_EVERY.as_millis(),
            mib(m.peak_rss_kb)
        );
        let _ = writeln!(
            out,
            "| localizer RSS at the end | {:.1} MiB |",
            mib(m.last_rss_kb)
        );
        let _ = writeln!(
            out,
            "| peak - baseline | {:.1} MiB (budget {} MiB) |",
            mib(self.peak_kb().saturating_sub(self.baseline_kb)),
            self.cache_mb
        );
        let _ = writeln!(
            out,
            "| peak within baseline + budget ({:.1} MiB) | {} |",
            mib(self.allowed_kb()),
            if self.within() { "yes" } else { "no" }
        );
        let b = &self.beyond_cache;
        match (b.first, b.first_kb()) {
            (Some((rss, cache)), Some(first)) => {
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache at the first logged cache size | {:.1} MiB (RSS {:.1} MiB, cache {cache:.1} MiB) |",
                    mib(first),
                    mib(rss)
                );
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache, largest over {} logged cache sizes | {:.1} MiB |",
                    b.count,
                    mib(b.max_kb)
                );
                let strict = first + (self.budget_bytes / 1024) as u64;
                let _ = writeln!(
                    out,
                    "| peak within that first RSS beyond the cache + budget ({:.1} MiB) | {} |",
                    mib(strict),
                    if self.peak_kb() <= strict {
                        "yes"
                    } else {
                        "no"
                    }
                );
            }
            _ => {
                let _ = writeln!(
                    out,
                    "| RSS beyond the cache | - (no cache_mb in the localizer's log: RUST_LOG hides its info lines) |"
                );
            }
        }
        let _ = writeln!(
            out,
            "| path | {:.1} m driven, {} frames, {} tiles crossed ({} up to the localizer's last estimate) |",
            self.distance_m, self.frames_on_server, self.tiles_crossed, self.tiles_estimated
        );
        match &self.summary {
            Some(s) => {
                let _ = writeln!(
                    out,
                    "| localizer | {} frames, {} sensor updates, {} range tables built, {:.1} CPU s, most {} frames behind |",
                    s.frames, s.sensor_updates, s.tables_built, m.cpu_s, self.max_lag_frames
                );
                let _ = writeln!(
                    out,
                    "| cache at the end (largest logged) | {:.1} MiB ({}) |",
                    s.cache_mib,
                    self.logged_cache_max_mib
                        .map_or("-".to_string(), |c| format!("{c:.1} MiB"))
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "| localizer | DID NOT KEEP UP ({}): its last estimate was for frame {} of {}; {:.1} CPU s |",
                    self.gave_up.as_deref().unwrap_or("stopped"),
                    self.filter.last_frame,
                    self.frames_on_server,
                    m.cpu_s
                );
                let _ = writeln!(
                    out,
                    "| largest cache logged | {} |",
                    self.logged_cache_max_mib
                        .map_or("-".to_string(), |c| format!("{c:.1} MiB"))
                );
            }
        }
        let f = &self.filter;
        let _ = writeln!(
            out,
            "| filter particles | {} at the start; once fewer, at most {} |",
            f.first_particles,
            f.max_particles_later
                .map_or("-".to_string(), |(n, frame)| format!("{n} (frame {frame})")),
        );
        let t = &self.tracking;
        let _ = writeln!(
            out,
            "| tracking, every estimate | position error mean {:.1} cm, max {:.1} cm; {} of {} within 0.25 m and 0.25 rad |",
            100.0 * t.mean_m,
            100.0 * t.max_m,
            t.within,
            t.paired
        );
        match t.longest_lost {
            Some(LostStretch {
                from_s: from,
                duration_s: seconds,
                estimates: n,
            }) => {
                let _ = writeln!(
                    out,
                    "| outside those bounds | {} stretches, the longest {n} estimates ({seconds:.1} s) from {from:.1} s; last estimate {} |",
                    t.lost_stretches,
                    if t.last_within { "within" } else { "outside" }
                );
            }
            None => {
                let _ = writeln!(out, "| outside those bounds | never |");
            }
        }
        match &self.report.stats {
            Some(st) => {
                let _ = writeln!(
                    out,
                    "| error after convergence (deog eval localize) | mean {:.1} cm x, {:.1} cm y, {:.2} deg; RMS {:.1} cm, max {:.1} cm |",
                    100.0 * st.x_m.mean_abs,
                    100.0 * st.y_m.mean_abs,
                    st.theta_rad.mean_abs.to_degrees(),
                    100.0 * st.rms_position_m,
                    100.0 * st.max_position_m
                );
            }
            None => {
                let _ = writeln!(
                    out,
                    "| error after convergence (deog eval localize) | - (not within the bounds at the end) |"
                );
            }
        }
        let _ = writeln!(out, "| wall-clock time | {:.0} s |", self.wall_s);
        let _ = writeln!(
            out,
            "\nrequirement (memory within the cache setting on a map >= 100x the cache): {}",
            if self.ratio() < 100.0 {
                "not tested (map under 100x the cache)"
            } else if !self.within() {
                "NOT met"
            } else if self.summary.is_none() {
                "not shown (the localizer did not finish the run)"
            } else {
                "met"
            }
        );
        if let Some(work) = &self.work {
            let _ = writeln!(
                out,
                "work folder (map files, server data, logs): {}",
                work.display()
            );
        }
        out
    }
}
