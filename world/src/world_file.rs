//! World files: a [`World`] written by hand in TOML.
//!
//! Units are metres; x grows to the right, y upwards (the world frame of the
//! whole project). A file names the world, optionally gives a boundary, and
//! lists obstacles, each a rectangle, a polygon or a circle:
//!
//! ```toml
//! name = "map2"
//! # Robots live inside the boundary; its edges are walls. Optional.
//! boundary = [[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0]]
//! [[obstacle]]
//! name = "table"                    # optional
//! rect = { min = [2.0, 2.0], max = [3.0, 2.5] }
//! [[obstacle]]
//! name = "L"
//! points = [[6.0, 2.0], [8.0, 2.0], [8.0, 2.6], [6.6, 2.6], [6.6, 5.0], [6.0, 5.0]]
//! [[obstacle]]
//! circle = { center = [5.0, 5.0], radius = 0.3, sides = 16 }   # a polygon approximation
//! ```
//!
//! - `name` (required): 1 to 128 characters of `A-Z a-z 0-9 _ . -`.
//! - `boundary` (optional): at least 3 `[x, y]` points, in order; the last
//!   joins the first. Without it the world is unbounded and its extent is
//!   the obstacles' bounding box.
//! - `[[obstacle]]`, any number, each with exactly one shape:
//!   - `rect = { min = [x, y], max = [x, y] }`, min < max on both axes;
//!   - `points = [[x, y], ...]`, a simple polygon of at least 3 points
//!     enclosing some area (that its edges do not cross is up to the
//!     author: it is not checked);
//!   - `circle = { center = [x, y], radius = r, sides = n }`, r > 0, n in
//!     3..=256 (default 32): a regular n-gon with its vertices on the
//!     circle;
//!
//!   and an optional `name` (same rule as the world's), for people and
//!   error messages.
//!
//! Every number must be finite; TOML integers are taken as metres too.
//! Unknown keys are errors, so a misspelt key is not silently ignored. An
//! error names the file, the line and the field:
//! `worlds/map2.toml:9: obstacle[1].points: needs at least 3 points, got 2`
//! (obstacles are counted from 0, in file order).
//!
//! [`load_world_any`] also takes a ROS map_server map (`.yaml`), through
//! [`crate::world_image`]. `worlds/README.md` documents the same format.

use std::ops::Range;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use crate::error::WorldError;
use crate::geometry::{Point2, Polygon};
use crate::world::World;
use crate::world_image::{ImageWorldOptions, load_map_world};

/// A world file larger than this is refused: worlds are written by hand,
/// and every polygon costs time in every sonar cast.
pub const MAX_WORLD_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// Reads a world file (TOML); errors name `path` as given.
pub fn load_world(path: impl AsRef<Path>) -> Result<World, WorldError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let read_err = |source| WorldError::ReadWorld {
        file: file.clone(),
        source,
    };
    let len = std::fs::metadata(path).map_err(read_err)?.len();
    if len > MAX_WORLD_FILE_BYTES {
        return Err(read_err(std::io::Error::other(format!(
            "{len} bytes, more than the {MAX_WORLD_FILE_BYTES} a world file may have"
        ))));
    }
    let text = std::fs::read_to_string(path).map_err(read_err)?;
    parse_world(&text, &file)
}

/// Reads a world from a `.toml` world file or a `.yaml` map_server map (an
/// image world with the default [`ImageWorldOptions`]: unknown pixels are
/// obstacles).
pub fn load_world_any(path: impl AsRef<Path>) -> Result<World, WorldError> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("toml") => load_world(path),
        Some("yaml" | "yml") => load_map_world(path, &ImageWorldOptions::default()),
        _ => Err(WorldError::invalid(
            "world",
            format!(
                "{}: expected a .toml world file or a .yaml map_server map",
                path.display()
            ),
        )),
    }
}

/// Parses a world file's text; `origin_name` names it in errors (usually
/// its path).
pub fn parse_world(text: &str, origin_name: &str) -> Result<World, WorldError> {
    let ctx = Ctx {
        text,
        file: origin_name,
    };
    let doc: WorldDoc = toml::from_str(text).map_err(|e| ctx.toml_error(&e))?;

    let Some(name) = doc.name else {
        return Err(ctx.err(0..0, "name", "missing: every world needs a name".into()));
    };
    ctx.check_name(&name, "name")?;

    let boundary = match &doc.boundary {
        Some(points) => Some(ctx.polygon(points, "boundary")?),
        None => None,
    };

    let mut obstacles = Vec::with_capacity(doc.obstacle.len());
    for (i, obstacle) in doc.obstacle.iter().enumerate() {
        obstacles.push(ctx.obstacle(obstacle, &format!("obstacle[{i}]"))?);
    }

    World::new(name.get_ref().clone(), boundary, obstacles).map_err(|e| match e {
        WorldError::EmptyWorld(_) => ctx.err(
            0..0,
            "boundary",
            "a world needs a boundary or at least one obstacle".into(),
        ),
        other => other,
    })
}

/// The file as written. Numbers are plain `f64` (TOML integers convert);
/// points are `Vec<f64>` rather than `[f64; 2]` so a wrong count gets a
/// message naming the point.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldDoc {
    name: Option<Spanned<String>>,
    boundary: Option<Spanned<Vec<Spanned<Vec<f64>>>>>,
    #[serde(default)]
    obstacle: Vec<Spanned<ObstacleDoc>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleDoc {
    name: Option<Spanned<String>>,
    rect: Option<Spanned<RectDoc>>,
    points: Option<Spanned<Vec<Spanned<Vec<f64>>>>>,
    circle: Option<Spanned<CircleDoc>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RectDoc {
    min: Spanned<Vec<f64>>,
    max: Spanned<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CircleDoc {
    center: Spanned<Vec<f64>>,
    radius: Spanned<f64>,
    sides: Option<Spanned<i64>>,
}

/// Sides of a circle when the file gives none.
const DEFAULT_SIDES: i64 = 32;

/// The file's text and name, to turn byte spans into `file:line:` errors.
struct Ctx<'a> {
    text: &'a str,
    file: &'a str,
}

impl Ctx<'_> {
    /// The 1-based line holding byte `offset`.
    fn line(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        self.text.as_bytes()[..end]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    fn err(&self, span: Range<usize>, field: &str, reason: String) -> WorldError {
        WorldError::WorldFile {
            file: self.file.to_owned(),
            line: self.line(span.start),
            field: field.to_owned(),
            reason,
        }
    }

    /// A TOML syntax or type error, with the field guessed from the text
    /// around it: toml reports a span and a message, not a key path.
    fn toml_error(&self, e: &toml::de::Error) -> WorldError {
        let span = e.span().unwrap_or(0..0);
        let reason = e.message().trim().to_owned();
        self.err(span.clone(), &self.field_at(span.start), reason)
    }

    /// The key path at byte `offset`: the `[[obstacle]]` it is under (counted
    /// from 0) and the `key =` its line starts with.
    fn field_at(&self, offset: usize) -> String {
        let end = offset.min(self.text.len());
        let before = &self.text.as_bytes()[..end];
        let line_start = before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        let mut table: Option<String> = None;
        let mut obstacles = 0usize;
        for line in self.text[..line_start].lines().chain(
            // The error's own line may be a table header.
            self.text[line_start..].lines().take(1),
        ) {
            let t = line.trim_start();
            if t.starts_with("[[") {
                let name = t
                    .trim_start_matches('[')
                    .split(']')
                    .next()
                    .unwrap_or("")
                    .trim();
                if name == "obstacle" {
                    table = Some(format!("obstacle[{obstacles}]"));
                    obstacles += 1;
                } else {
                    table = Some(name.to_owned());
                }
            } else if t.starts_with('[') {
                let name = t
                    .trim_start_matches('[')
                    .split(']')
                    .next()
                    .unwrap_or("")
                    .trim();
                table = Some(name.to_owned());
            }
        }
        let this_line = self.text[line_start..].lines().next().unwrap_or("");
        let key = this_line
            .split_once('=')
            .map(|(k, _)| k.trim())
            .filter(|k| {
                !k.is_empty()
                    && k.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "_-.\"' ".contains(c))
            });
        match (table, key) {
            (Some(t), Some(k)) => format!("{t}.{k}"),
            (Some(t), None) => t,
            (None, Some(k)) => k.to_owned(),
            (None, None) => "(file)".to_owned(),
        }
    }

    /// Names: 1 to 128 of `A-Z a-z 0-9 _ . -`, so they are safe in file
    /// names, logs and URLs.
    fn check_name(&self, name: &Spanned<String>, field: &str) -> Result<(), WorldError> {
        let n = name.get_ref();
        let ok = (1..=128).contains(&n.chars().count())
            && n.chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-'));
        if ok {
            Ok(())
        } else {
            Err(self.err(
                name.span(),
                field,
                format!("must be 1 to 128 characters of A-Z a-z 0-9 _ . -, got {n:?}"),
            ))
        }
    }

    /// A point: exactly two finite numbers.
    fn point(&self, p: &Spanned<Vec<f64>>, field: &str) -> Result<Point2, WorldError> {
        match p.get_ref().as_slice() {
            &[x, y] if x.is_finite() && y.is_finite() => Ok(Point2::new(x, y)),
            &[x, y] => Err(self.err(
                p.span(),
                field,
                format!("must be finite numbers, got [{x}, {y}]"),
            )),
            other => Err(self.err(
                p.span(),
                field,
                format!("a point is [x, y], got {} numbers", other.len()),
            )),
        }
    }

    /// A polygon of at least 3 finite points enclosing some area.
    fn polygon(
        &self,
        points: &Spanned<Vec<Spanned<Vec<f64>>>>,
        field: &str,
    ) -> Result<Polygon, WorldError> {
        let list = points.get_ref();
        if list.len() < 3 {
            return Err(self.err(
                points.span(),
                field,
                format!("needs at least 3 points, got {}", list.len()),
            ));
        }
        let vertices = list
            .iter()
            .enumerate()
            .map(|(i, p)| self.point(p, &format!("{field}[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
        // Shoelace area: a polygon whose points all lie on a line has no
        // inside, so it could never stop a robot.
        let n = vertices.len();
        let twice_area: f64 = (0..n)
            .map(|i| {
                let (a, b) = (vertices[i], vertices[(i + 1) % n]);
                a.x * b.y - b.x * a.y
            })
            .sum();
        if !twice_area.is_finite() {
            return Err(self.err(
                points.span(),
                field,
                "its coordinates are too large to compute its area".into(),
            ));
        }
        if twice_area.abs() < 1e-12 {
            return Err(self.err(
                points.span(),
                field,
                "encloses no area (its points lie on one line)".into(),
            ));
        }
        Polygon::new(vertices)
            .ok_or_else(|| self.err(points.span(), field, "is not a valid polygon".into()))
    }

    fn obstacle(&self, o: &Spanned<ObstacleDoc>, field: &str) -> Result<Polygon, WorldError> {
        let doc = o.get_ref();
        if let Some(name) = &doc.name {
            self.check_name(name, &format!("{field}.name"))?;
        }
        let given: Vec<&str> = [
            doc.rect.as_ref().map(|_| "rect"),
            doc.points.as_ref().map(|_| "points"),
            doc.circle.as_ref().map(|_| "circle"),
        ]
        .into_iter()
        .flatten()
        .collect();
        if given.len() != 1 {
            let got = if given.is_empty() {
                "none".to_owned()
            } else {
                given.join(" and ")
            };
            return Err(self.err(
                o.span(),
                field,
                format!("needs exactly one of rect, points, circle; got {got}"),
            ));
        }
        if let Some(rect) = &doc.rect {
            let r = rect.get_ref();
            let min = self.point(&r.min, &format!("{field}.rect.min"))?;
            let max = self.point(&r.max, &format!("{field}.rect.max"))?;
            if !(min.x < max.x && min.y < max.y) {
                return Err(self.err(
                    rect.span(),
                    &format!("{field}.rect"),
                    format!(
                        "min must be below max on both axes, got min [{}, {}], max [{}, {}]",
                        min.x, min.y, max.x, max.y
                    ),
                ));
            }
            return Ok(Polygon::rectangle(min, max));
        }
        if let Some(points) = &doc.points {
            return self.polygon(points, &format!("{field}.points"));
        }
        if let Some(circle) = &doc.circle {
            return self.circle(circle.get_ref(), &format!("{field}.circle"));
        }
        // `given.len() == 1` above, so one of the three returned.
        Err(self.err(o.span(), field, "has no shape".into()))
    }

    fn circle(&self, c: &CircleDoc, field: &str) -> Result<Polygon, WorldError> {
        let center = self.point(&c.center, &format!("{field}.center"))?;
        let r = *c.radius.get_ref();
        if !(r.is_finite() && r > 0.0) {
            return Err(self.err(
                c.radius.span(),
                &format!("{field}.radius"),
                format!("must be a finite number > 0, got {r}"),
            ));
        }
        let sides = match &c.sides {
            None => DEFAULT_SIDES,
            Some(s) => {
                let n = *s.get_ref();
                if !(3..=256).contains(&n) {
                    return Err(self.err(
                        s.span(),
                        &format!("{field}.sides"),
                        format!("must be 3 to 256, got {n}"),
                    ));
                }
                n
            }
        };
        let vertices = (0..sides)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / sides as f64;
                Point2::new(center.x + r * a.cos(), center.y + r * a.sin())
            })
            .collect();
        Polygon::new(vertices)
            .ok_or_else(|| self.err(c.radius.span(), field, "is too large to represent".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"name = "map2"
# Robots live inside the boundary; its edges are walls. Optional.
boundary = [[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0]]
[[obstacle]]
name = "table"                    # optional
rect = { min = [2.0, 2.0], max = [3.0, 2.5] }
[[obstacle]]
name = "L"
points = [[6.0, 2.0], [8.0, 2.0], [8.0, 2.6], [6.6, 2.6], [6.6, 5.0], [6.0, 5.0]]
[[obstacle]]
circle = { center = [5.0, 5.0], radius = 0.3, sides = 16 }   # a polygon approximation
"#;

    fn err(text: &str) -> String {
        match parse_world(text, "worlds/map2.toml") {
            Ok(w) => panic!("parsed {w:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_documented_example_parses() {
        let w = parse_world(EXAMPLE, "example.toml").expect("world");
        assert_eq!(w.name(), "map2");
        assert_eq!(w.obstacles().len(), 3);
        assert_eq!(w.obstacles()[1].vertices().len(), 6);
        assert_eq!(w.obstacles()[2].vertices().len(), 16);
        assert!(!w.is_free(Point2::new(2.5, 2.2)));
        assert!(!w.is_free(Point2::new(6.3, 4.0)));
        assert!(!w.is_free(Point2::new(5.0, 5.0)));
        assert!(w.is_free(Point2::new(7.5, 4.0)));
        assert_eq!(w.bounds(), (Point2::new(0.0, 0.0), Point2::new(10.0, 8.0)));
    }

    #[test]
    fn the_module_doc_example_is_the_same_text() {
        // The format's documentation shows EXAMPLE; keep the two in step.
        let doc = include_str!("world_file.rs");
        for line in EXAMPLE.lines() {
            assert!(
                doc.contains(&format!("//! {line}").trim_end().to_owned()),
                "{line}"
            );
        }
    }

    #[test]
    fn too_few_points_names_line_and_obstacle() {
        let text = EXAMPLE.replace(
            "points = [[6.0, 2.0], [8.0, 2.0], [8.0, 2.6], [6.6, 2.6], [6.6, 5.0], [6.0, 5.0]]",
            "points = [[6.0, 2.0], [8.0, 2.0]]",
        );
        assert_eq!(
            err(&text),
            "worlds/map2.toml:9: obstacle[1].points: needs at least 3 points, got 2"
        );
    }

    #[test]
    fn numbers_must_be_finite() {
        let text = EXAMPLE.replace("[8.0, 2.6]", "[nan, 2.6]");
        assert_eq!(
            err(&text),
            "worlds/map2.toml:9: obstacle[1].points[2]: must be finite numbers, got [NaN, 2.6]"
        );
        let text = EXAMPLE.replace("[10.0, 8.0]", "[inf, 8.0]");
        assert!(err(&text).starts_with("worlds/map2.toml:3: boundary[2]: must be finite"));
        let text = EXAMPLE.replace("[8.0, 2.6]", "[8.0, 2.6, 1.0]");
        assert_eq!(
            err(&text),
            "worlds/map2.toml:9: obstacle[1].points[2]: a point is [x, y], got 3 numbers"
        );
    }

    #[test]
    fn a_rect_needs_min_below_max() {
        let text = EXAMPLE.replace("max = [3.0, 2.5]", "max = [3.0, 2.0]");
        assert_eq!(
            err(&text),
            "worlds/map2.toml:6: obstacle[0].rect: min must be below max on both axes, got min [2, 2], max [3, 2]"
        );
    }

    #[test]
    fn circles_are_checked() {
        let text = EXAMPLE.replace("radius = 0.3", "radius = 0");
        assert!(err(&text).starts_with(
            "worlds/map2.toml:11: obstacle[2].circle.radius: must be a finite number > 0, got 0"
        ));
        let text = EXAMPLE.replace("sides = 16", "sides = 2");
        assert_eq!(
            err(&text),
            "worlds/map2.toml:11: obstacle[2].circle.sides: must be 3 to 256, got 2"
        );
        let text = EXAMPLE.replace("sides = 16", "sides = 1000");
        assert!(err(&text).contains("must be 3 to 256, got 1000"));
        let text = EXAMPLE.replace(", sides = 16", "");
        let w = parse_world(&text, "m").expect("default sides");
        assert_eq!(w.obstacles()[2].vertices().len(), DEFAULT_SIDES as usize);
    }

    #[test]
    fn exactly_one_shape_per_obstacle() {
        let text = EXAMPLE.replace(
            "name = \"L\"\n",
            "name = \"L\"\nrect = { min = [0, 0], max = [1, 1] }\n",
        );
        assert!(
            err(&text).contains(
                "obstacle[1]: needs exactly one of rect, points, circle; got rect and points"
            ),
            "{}",
            err(&text)
        );
        let text = format!("{EXAMPLE}[[obstacle]]\nname = \"ghost\"\n");
        let e = err(&text);
        assert!(
            e.starts_with("worlds/map2.toml:12: obstacle[3]: needs exactly one"),
            "{e}"
        );
        assert!(e.ends_with("got none"), "{e}");
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let text = EXAMPLE.replace("name = \"table\"", "name = \"table\"\ncolour = \"red\"");
        let e = err(&text);
        assert!(
            e.starts_with("worlds/map2.toml:6: obstacle[0].colour: "),
            "{e}"
        );
        assert!(e.contains("unknown field `colour`"), "{e}");
        let text = EXAMPLE.replace("radius = 0.3", "radius = 0.3, height = 1");
        let e = err(&text);
        assert!(
            e.starts_with("worlds/map2.toml:11: obstacle[2].circle: "),
            "{e}"
        );
        assert!(e.contains("unknown field `height`"), "{e}");
        let e = err(&format!("scale = 2\n{EXAMPLE}"));
        assert!(e.starts_with("worlds/map2.toml:1: scale: "), "{e}");
    }

    #[test]
    fn names_are_checked() {
        let e = err(&EXAMPLE.replace("name = \"map2\"\n", ""));
        assert_eq!(
            e,
            "worlds/map2.toml:1: name: missing: every world needs a name"
        );
        let e = err(&EXAMPLE.replace("\"map2\"", "\"map 2\""));
        assert!(
            e.starts_with("worlds/map2.toml:1: name: must be 1 to 128 characters"),
            "{e}"
        );
        let e = err(&EXAMPLE.replace("\"map2\"", "\"\""));
        assert!(e.contains("got \"\""), "{e}");
        let long = "x".repeat(129);
        assert!(err(&EXAMPLE.replace("map2", &long)).contains("name: must be"));
        let e = err(&EXAMPLE.replace("\"table\"", "\"t/able\""));
        assert!(
            e.starts_with("worlds/map2.toml:5: obstacle[0].name: must be"),
            "{e}"
        );
    }

    #[test]
    fn syntax_and_type_errors_have_lines() {
        let e = err(&EXAMPLE.replace("radius = 0.3", "radius = \"big\""));
        assert!(
            e.starts_with("worlds/map2.toml:11: obstacle[2].circle"),
            "{e}"
        );
        let e = err(&EXAMPLE.replace("[[obstacle]]\nname = \"L\"", "[[obstacle]\nname = \"L\""));
        assert!(e.starts_with("worlds/map2.toml:7: "), "{e}");
        let e = err("name = \"a\"\nboundary = [[0,0],[1,0],[1,1]]\nboundary = 3\n");
        assert!(e.starts_with("worlds/map2.toml:3: "), "{e}");
    }

    #[test]
    fn degenerate_and_empty_worlds_are_errors() {
        let e = err("name = \"flat\"\nboundary = [[0, 0], [1, 1], [2, 2]]\n");
        assert_eq!(
            e,
            "worlds/map2.toml:2: boundary: encloses no area (its points lie on one line)"
        );
        let e = err("name = \"void\"\n");
        assert_eq!(
            e,
            "worlds/map2.toml:1: boundary: a world needs a boundary or at least one obstacle"
        );
        // Without a boundary the obstacles bound the world.
        let w = parse_world(
            "name = \"open\"\n[[obstacle]]\nrect = { min = [0, 0], max = [1, 2] }\n",
            "m",
        )
        .expect("world");
        assert!(w.boundary().is_none());
    }

    #[test]
    fn odd_input_never_panics() {
        for text in [
            "",
            "=",
            "[[obstacle]]",
            "name = 1",
            "\u{feff}name = \"a\"",
            "name = \"é\"",
            "name = \"a\"\n[[obstacle]]\npoints = []",
            "name = \"a\"\n[[obstacle]]\npoints = [[]]",
            "name = \"a\"\n[obstacle]\nrect = 1",
            "name = \"a\"\nboundary = [[1e308, 1e308], [-1e308, 1e308], [0, -1e308]]",
            "name = \"a\"\n[[obstacle]]\ncircle = { center = [0, 0], radius = 1e308 }",
            "name = \"a\"\n[[obstacle]]\ncircle = { center = [0, 0], radius = 1, sides = -9223372036854775808 }",
            "[a.b.c]\nx = 1",
            "name = \"a\"\n\n\n[[obstacle]]\n[[obstacle]]\nfoo = 1",
        ] {
            let _ = parse_world(text, "f.toml");
        }
    }
}
