//! A ROS map_server map (YAML + PGM) as a [`World`].
//!
//! Solid pixels become obstacles: occupied ones always, unknown ones too
//! unless [`ImageWorldOptions::unknown_is_free`], since a robot must not
//! drive into space nobody has seen. To keep the polygon count (and so the
//! cost of every sonar cast) low, each row's runs of solid pixels become
//! rectangles, and a run repeated exactly in the rows above grows that
//! rectangle upwards rather than starting a new one. The boundary is the
//! image's rectangle, so the map's edge is a wall. Rotated maps (origin yaw
//! other than 0) are refused.

use std::path::Path;

use deog_mapfile::{Cell, MapImage};

use crate::error::WorldError;
use crate::geometry::{Point2, Polygon};
use crate::world::World;

/// How a map image becomes a world.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ImageWorldOptions {
    /// Treat unknown pixels as free space instead of obstacles (default
    /// false: unknown is solid).
    pub unknown_is_free: bool,
}

/// Loads a map_server map and turns it into a world named after the YAML's
/// file stem (`maps/lab.yaml` gives `lab`).
pub fn load_map_world(
    yaml_path: impl AsRef<Path>,
    options: &ImageWorldOptions,
) -> Result<World, WorldError> {
    let yaml_path = yaml_path.as_ref();
    let map = MapImage::load_axis_aligned(yaml_path)?;
    let name = yaml_path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "map".to_owned());
    world_from_map(name, &map, options)
}

/// The world of `map`: its solid pixels merged into rectangles, inside the
/// image's rectangle.
pub fn world_from_map(
    name: impl Into<String>,
    map: &MapImage,
    options: &ImageWorldOptions,
) -> Result<World, WorldError> {
    let ((x0, y0), (x1, y1)) = map.world_bounds()?;
    let res = map.resolution;
    if !(res.is_finite() && res > 0.0 && x0.is_finite() && y0.is_finite()) {
        return Err(WorldError::invalid(
            "map",
            format!("resolution {res} and origin ({x0}, {y0}) must be finite, resolution > 0"),
        ));
    }
    let boundary = Polygon::rectangle(Point2::new(x0, y0), Point2::new(x1, y1));
    let obstacles = solid_rectangles(map, options)
        .into_iter()
        .map(|r| {
            let corner = |col: u32, row: u32| {
                Point2::new(x0 + f64::from(col) * res, y0 + f64::from(row) * res)
            };
            Polygon::rectangle(corner(r.col, r.row), corner(r.col_end, r.row_end))
        })
        .collect();
    World::new(name, Some(boundary), obstacles)
}

/// A block of solid pixels: columns `col..col_end`, rows from the bottom
/// `row..row_end`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PixelRect {
    col: u32,
    col_end: u32,
    row: u32,
    row_end: u32,
}

/// The solid pixels of `map` as few rectangles: runs along each row,
/// stacked while the rows above repeat the same run.
fn solid_rectangles(map: &MapImage, options: &ImageWorldOptions) -> Vec<PixelRect> {
    let solid = |col, row| match map.occupancy(col, row) {
        Cell::Occupied => true,
        Cell::Unknown => !options.unknown_is_free,
        Cell::Free => false,
    };
    let mut done = Vec::new();
    // Rectangles still growing: (col, col_end, first row), sorted by col.
    let mut open: Vec<(u32, u32, u32)> = Vec::new();
    let mut runs: Vec<(u32, u32)> = Vec::new();
    for row in 0..map.height {
        runs.clear();
        let mut col = 0;
        while col < map.width {
            if solid(col, row) {
                let start = col;
                while col < map.width && solid(col, row) {
                    col += 1;
                }
                runs.push((start, col));
            } else {
                col += 1;
            }
        }
        // Both lists are sorted and their runs disjoint, so one pass
        // matches each run with an open rectangle of exactly its columns.
        let mut next = Vec::with_capacity(runs.len());
        let mut k = 0;
        for &(c0, c1) in &runs {
            while k < open.len() && open[k].0 < c0 {
                let (col, col_end, first) = open[k];
                done.push(PixelRect {
                    col,
                    col_end,
                    row: first,
                    row_end: row,
                });
                k += 1;
            }
            if k < open.len() && open[k].0 == c0 && open[k].1 == c1 {
                next.push(open[k]);
                k += 1;
            } else {
                next.push((c0, c1, row));
            }
        }
        for &(col, col_end, first) in &open[k..] {
            done.push(PixelRect {
                col,
                col_end,
                row: first,
                row_end: row,
            });
        }
        open = next;
    }
    for (col, col_end, first) in open {
        done.push(PixelRect {
            col,
            col_end,
            row: first,
            row_end: map.height,
        });
    }
    done
}

#[cfg(test)]
mod tests {
    use super::*;
    use deog_mapfile::Mode;

    /// A map from rows written top first: `#` occupied, `?` unknown, `.` free.
    fn map(rows: &[&str]) -> MapImage {
        let pixels = rows
            .iter()
            .flat_map(|r| r.bytes())
            .map(|b| match b {
                b'#' => 0,
                b'?' => 205,
                _ => 254,
            })
            .collect();
        MapImage {
            width: rows[0].len() as u32,
            height: rows.len() as u32,
            resolution: 0.5,
            origin: (-1.0, 1.0, 0.0),
            negate: false,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode: Mode::Trinary,
            pixels,
        }
    }

    #[test]
    fn identical_runs_stack_into_one_rectangle() {
        let m = map(&["..##.", "..##.", "#.##.", "....#"]);
        let rects = solid_rectangles(&m, &ImageWorldOptions::default());
        assert_eq!(
            rects,
            vec![
                PixelRect {
                    col: 4,
                    col_end: 5,
                    row: 0,
                    row_end: 1
                },
                PixelRect {
                    col: 0,
                    col_end: 1,
                    row: 1,
                    row_end: 2
                },
                PixelRect {
                    col: 2,
                    col_end: 4,
                    row: 1,
                    row_end: 4
                },
            ]
        );
    }

    #[test]
    fn unknown_is_solid_unless_asked() {
        let m = map(&["??.", "..#"]);
        assert_eq!(solid_rectangles(&m, &ImageWorldOptions::default()).len(), 2);
        let free = ImageWorldOptions {
            unknown_is_free: true,
        };
        assert_eq!(solid_rectangles(&m, &free).len(), 1);
    }

    #[test]
    fn pixels_land_where_map_server_puts_them() {
        let m = map(&["#..", "..."]);
        let w = world_from_map("t", &m, &ImageWorldOptions::default()).expect("world");
        // Column 0 of the top row: x in [-1, -0.5], y in [1.5, 2].
        assert!(!w.is_free(Point2::new(-0.75, 1.75)));
        assert!(w.is_free(Point2::new(-0.25, 1.75)));
        assert!(w.is_free(Point2::new(-0.75, 1.25)));
        assert!(!w.is_free(Point2::new(0.75, 1.25)), "outside the image");
        assert_eq!(w.bounds(), (Point2::new(-1.0, 1.0), Point2::new(0.5, 2.0)));
    }

    #[test]
    fn a_rotated_map_is_refused_naming_origin() {
        let mut m = map(&["#."]);
        m.origin.2 = 0.1;
        let e = world_from_map("t", &m, &ImageWorldOptions::default()).expect_err("rotated");
        assert!(e.to_string().starts_with("origin: yaw must be 0"), "{e}");
    }
}
