//! The status as text: aligned columns, units in the headers.

use std::fmt::Write as _;

use super::{Status, WriterRow};

/// The status as aligned text tables, units in the headers; `watched_s`
/// is how long the sampler has watched, shown where an age is unknown.
pub fn status_table(status: &Status, watched_s: f64) -> String {
    let unseen = format!(">{watched_s:.1}");
    let opt = |value: Option<f64>, digits: usize| {
        value.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$}"))
    };
    let age = |value: Option<f64>| value.map_or_else(|| unseen.clone(), |v| format!("{v:.1}"));
    let mut out = format!(
        "server {}  health {}\n",
        status.server.address, status.server.health
    );

    out.push('\n');
    if status.maps.is_empty() {
        out.push_str("no maps\n");
    } else {
        let rows = status.maps.iter().map(|m| {
            let bounds = m.bounds.map_or_else(
                || "empty".to_string(),
                |b| {
                    format!(
                        "{:.1},{:.1} .. {:.1},{:.1}",
                        b.min_x, b.min_y, b.max_x, b.max_y
                    )
                },
            );
            vec![
                m.name.clone(),
                m.cells.to_string(),
                m.tiles.to_string(),
                bounds,
                m.version.to_string(),
                opt(m.writes_per_s, 1),
                writers(&m.writers),
            ]
        });
        table(
            &mut out,
            &[
                "map",
                "cells",
                "tiles",
                "bounds (m)",
                "version",
                "writes/s",
                "writers (batches/s)",
            ],
            rows,
        );
    }

    out.push('\n');
    if status.robots.is_empty() {
        out.push_str("no robots with frames\n");
    } else {
        let rows = status.robots.iter().map(|r| {
            vec![
                r.name.clone(),
                r.frames.to_string(),
                opt(r.frames_per_s, 1),
                age(r.last_frame_age_s),
            ]
        });
        table(
            &mut out,
            &["robot", "frames", "frames/s", "last frame age (s)"],
            rows,
        );
    }

    out.push('\n');
    if status.localizers.is_empty() {
        out.push_str("no pose estimates\n");
    } else {
        let rows = status.localizers.iter().map(|l| {
            vec![
                l.robot.clone(),
                l.map.clone(),
                if l.converged { "yes" } else { "no" }.to_string(),
                format!("{:.2}", l.lost_score),
                age(l.last_estimate_age_s),
                opt(l.lag_s, 2),
                l.lag_frames.to_string(),
                opt(l.error_m, 2),
            ]
        });
        table(
            &mut out,
            &[
                "localizer",
                "map",
                "converged",
                "lost",
                "last estimate age (s)",
                "lag (s)",
                "lag (frames)",
                "error (m)",
            ],
            rows,
        );
    }
    out
}

/// A map's writers on one line: each client id with its batch rate.
fn writers(writers: &[WriterRow]) -> String {
    if writers.is_empty() {
        return "-".to_string();
    }
    let named: Vec<String> = writers
        .iter()
        .map(|w| match w.batches_per_s {
            Some(rate) => format!("{} ({rate:.1})", w.client_id),
            None => w.client_id.clone(),
        })
        .collect();
    named.join(", ")
}

/// Appends `headers` and `rows` with columns aligned: the first left, the
/// others right, as numbers read best.
fn table(out: &mut String, headers: &[&str], rows: impl Iterator<Item = Vec<String>>) {
    let rows: Vec<Vec<String>> = rows.collect();
    let widths: Vec<usize> = headers
        .iter()
        .enumerate()
        .map(|(i, h)| {
            rows.iter()
                .map(|r| r[i].chars().count())
                .chain([h.chars().count()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let header_cells: Vec<String> = headers.iter().map(|h| h.to_string()).collect();
    for cells in std::iter::once(&header_cells).chain(&rows) {
        let mut line = String::new();
        for (i, (cell, width)) in cells.iter().zip(&widths).enumerate() {
            if i == 0 {
                let _ = write!(line, "{cell:<width$}");
            } else {
                let _ = write!(line, "  {cell:>width$}");
            }
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::status::{MapRow, ServerRow};

    fn map(name: &str) -> MapRow {
        MapRow {
            name: name.into(),
            cells: 100,
            tiles: 2,
            bounds: None,
            version: 1,
            writes_per_s: Some(2.0),
            writers: vec![WriterRow {
                client_id: "carto/r1".into(),
                last_sequence: 1,
                batches_per_s: Some(2.0),
            }],
        }
    }

    #[test]
    fn the_table_aligns_columns_and_names_units() {
        let status = Status {
            server: ServerRow {
                address: "127.0.0.1:1".into(),
                health: "SERVING".into(),
            },
            maps: vec![map("a-long-name"), map("b")],
            robots: Vec::new(),
            localizers: Vec::new(),
        };
        let text = status_table(&status, 1.0);
        assert!(text.contains("writes/s"), "{text}");
        assert!(text.contains("carto/r1 (2.0)"), "{text}");
        assert!(text.contains("no robots with frames"), "{text}");
        let lines: Vec<&str> = text.lines().filter(|l| l.contains("empty")).collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert_eq!(lines[0].find("empty"), lines[1].find("empty"), "{text}");
    }
}
