//! The map_server YAML: a flat list of `key: value` lines, read by a small
//! hand-written parser.
//!
//! map_server's YAML never nests, so a full YAML parser would add a large
//! dependency for nothing. The parser takes one `key: value` per line;
//! values are numbers, strings (bare, `'single'` or `"double"` quoted) or a
//! one-line list `[a, b, c]`. `#` starts a comment (at a line's start or
//! after a space, outside quotes). Blank lines and the document markers
//! `---` / `...` are skipped. Unknown keys are ignored, as map_server does.

use crate::error::MapFileError;

/// How pixel values become occupancy, map_server's `mode` key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Occupied, free or unknown by the two thresholds (the default).
    #[default]
    Trinary,
    /// As trinary, but values between the thresholds become a probability
    /// (1..=99) rather than unknown.
    Scale,
    /// The pixel value is the occupancy (0..=100) itself.
    Raw,
}

impl Mode {
    /// The name map_server writes: `trinary`, `scale` or `raw`.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Trinary => "trinary",
            Mode::Scale => "scale",
            Mode::Raw => "raw",
        }
    }
}

/// The contents of a map_server YAML file, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct MapYaml {
    /// The image's path as written in the file (relative paths are relative
    /// to the YAML's folder).
    pub image: String,
    /// Metres per pixel, > 0.
    pub resolution: f64,
    /// The lower-left pixel's corner in the world: x and y in metres, yaw in
    /// radians counter-clockwise.
    pub origin: (f64, f64, f64),
    /// Whether white means occupied.
    pub negate: bool,
    /// Occupancy probability above which a pixel is occupied, in [0, 1].
    pub occupied_thresh: f64,
    /// Occupancy probability below which a pixel is free, in
    /// [0, `occupied_thresh`].
    pub free_thresh: f64,
    /// How pixels become occupancy.
    pub mode: Mode,
    /// 1-based line of each key read, to point errors found later (such as
    /// a rotated origin) at their line.
    lines: Vec<(String, usize)>,
}

/// A value on the right of `key:`.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    /// A scalar, quotes removed.
    Scalar(String),
    /// A one-line list of scalars.
    List(Vec<String>),
}

impl Value {
    /// The value as the file spelled it, for error messages.
    fn quoted(&self) -> String {
        match self {
            Value::Scalar(s) => format!("{s:?}"),
            Value::List(items) => format!("[{}]", items.join(", ")),
        }
    }
}

/// One `key: value` line.
struct Entry {
    key: String,
    value: Value,
    line: usize,
}

/// The keys map_server requires; `mode` is optional.
const REQUIRED: [&str; 6] = [
    "image",
    "resolution",
    "origin",
    "negate",
    "occupied_thresh",
    "free_thresh",
];

impl MapYaml {
    /// Parses and checks the YAML `text`; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, MapFileError> {
        let entries = parse_flat(text, file)?;
        let find = |key: &str| entries.iter().find(|e| e.key == key);
        let require = |key: &str| {
            find(key).ok_or_else(|| MapFileError::MissingKey {
                file: file.to_owned(),
                key: key.to_owned(),
            })
        };
        for key in REQUIRED {
            require(key)?;
        }
        let bad = |e: &Entry, reason: String| MapFileError::Yaml {
            file: file.to_owned(),
            line: e.line,
            field: e.key.clone(),
            reason,
        };

        let e = require("image")?;
        let image = match &e.value {
            Value::Scalar(s) if !s.is_empty() => s.clone(),
            v => return Err(bad(e, format!("must be a file name, got {}", v.quoted()))),
        };

        let e = require("resolution")?;
        let resolution = scalar_number(&e.value)
            .filter(|r| check_resolution(*r).is_ok())
            .ok_or_else(|| {
                bad(
                    e,
                    format!("must be a positive number, got {}", e.value.quoted()),
                )
            })?;

        let e = require("origin")?;
        let origin = match &e.value {
            Value::List(items) if items.len() == 3 => {
                let n: Vec<Option<f64>> = items.iter().map(|s| number(s)).collect();
                match (n[0], n[1], n[2]) {
                    (Some(x), Some(y), Some(yaw)) => Some((x, y, yaw)),
                    _ => None,
                }
            }
            _ => None,
        }
        .ok_or_else(|| {
            bad(
                e,
                format!(
                    "must be a list of 3 finite numbers [x, y, yaw], got {}",
                    e.value.quoted()
                ),
            )
        })?;

        let e = require("negate")?;
        let negate = match &e.value {
            Value::Scalar(s) => match s.as_str() {
                "0" | "false" | "False" | "FALSE" => Some(false),
                "1" | "true" | "True" | "TRUE" => Some(true),
                _ => None,
            },
            Value::List(_) => None,
        }
        .ok_or_else(|| {
            bad(
                e,
                format!("must be 0, 1, true or false, got {}", e.value.quoted()),
            )
        })?;

        let threshold = |key: &str| -> Result<(f64, &Entry), MapFileError> {
            let e = require(key)?;
            let t = scalar_number(&e.value)
                .filter(|t| check_threshold(*t).is_ok())
                .ok_or_else(|| {
                    bad(
                        e,
                        format!("must be a number in [0, 1], got {}", e.value.quoted()),
                    )
                })?;
            Ok((t, e))
        };
        let (occupied_thresh, _) = threshold("occupied_thresh")?;
        let (free_thresh, free_entry) = threshold("free_thresh")?;
        if let Err(reason) = check_order(occupied_thresh, free_thresh) {
            return Err(bad(free_entry, reason));
        }

        let mode = match find("mode") {
            None => Mode::Trinary,
            Some(e) => match &e.value {
                Value::Scalar(s) if s == "trinary" => Mode::Trinary,
                Value::Scalar(s) if s == "scale" => Mode::Scale,
                Value::Scalar(s) if s == "raw" => Mode::Raw,
                v => {
                    return Err(bad(
                        e,
                        format!("must be trinary, scale or raw, got {}", v.quoted()),
                    ));
                }
            },
        };

        Ok(Self {
            image,
            resolution,
            origin,
            negate,
            occupied_thresh,
            free_thresh,
            mode,
            lines: entries.into_iter().map(|e| (e.key, e.line)).collect(),
        })
    }

    /// The 1-based line `key` was read from, if it was.
    pub fn line_of(&self, key: &str) -> Option<usize> {
        self.lines.iter().find(|(k, _)| k == key).map(|(_, l)| *l)
    }
}

/// Resolution: finite and > 0.
pub(crate) fn check_resolution(r: f64) -> Result<(), String> {
    if r.is_finite() && r > 0.0 {
        Ok(())
    } else {
        Err(format!("must be a positive number, got {r}"))
    }
}

/// A threshold: in [0, 1] (NaN fails both comparisons).
pub(crate) fn check_threshold(t: f64) -> Result<(), String> {
    if (0.0..=1.0).contains(&t) {
        Ok(())
    } else {
        Err(format!("must be a number in [0, 1], got {t}"))
    }
}

/// `free_thresh` must not exceed `occupied_thresh`: otherwise a pixel could
/// be both free and occupied. Equal thresholds are allowed (no unknown band).
pub(crate) fn check_order(occupied: f64, free: f64) -> Result<(), String> {
    if free <= occupied {
        Ok(())
    } else {
        Err(format!(
            "must not exceed occupied_thresh ({occupied}), got {free}"
        ))
    }
}

/// A finite number from a scalar value.
fn scalar_number(v: &Value) -> Option<f64> {
    match v {
        Value::Scalar(s) => number(s),
        Value::List(_) => None,
    }
}

/// A finite number. Rust's parser also takes `inf` and `nan`, which no map
/// can use, hence the finiteness check.
fn number(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Splits `text` into `key: value` entries, 1-based lines. Rejects nesting,
/// lines without a key, unterminated quotes or lists and duplicate keys.
fn parse_flat(text: &str, file: &str) -> Result<Vec<Entry>, MapFileError> {
    let syntax = |line: usize, reason: String| MapFileError::YamlSyntax {
        file: file.to_owned(),
        line,
        reason,
    };
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut entries: Vec<Entry> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = strip_comment(raw);
        let trimmed = content.trim();
        if trimmed.is_empty() || trimmed == "---" || trimmed == "..." {
            continue;
        }
        if content.starts_with([' ', '\t']) {
            return Err(syntax(
                line,
                "indented line: nested YAML is not supported in a map file".into(),
            ));
        }
        let Some((key, rest)) = trimmed.split_once(':') else {
            return Err(syntax(
                line,
                format!("expected `key: value`, got {trimmed:?}"),
            ));
        };
        let key = key.trim();
        let valid_key = !key.is_empty()
            && key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !valid_key {
            return Err(syntax(line, format!("bad key {key:?}")));
        }
        let value = parse_value(rest.trim()).map_err(|reason| MapFileError::Yaml {
            file: file.to_owned(),
            line,
            field: key.to_owned(),
            reason,
        })?;
        if let Some(first) = entries.iter().find(|e| e.key == key) {
            return Err(MapFileError::Yaml {
                file: file.to_owned(),
                line,
                field: key.to_owned(),
                reason: format!("duplicate key (first on line {})", first.line),
            });
        }
        entries.push(Entry {
            key: key.to_owned(),
            value,
            line,
        });
    }
    Ok(entries)
}

/// The line up to a `#` that starts a comment: at the start or after
/// whitespace, and not inside quotes (a `#` inside a file name is kept).
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut prev_space = true;
    for (i, c) in line.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' && prev_space => return &line[..i],
            None => {}
        }
        prev_space = c.is_whitespace();
    }
    line
}

/// A value: a list `[a, b]`, a quoted or a bare scalar.
fn parse_value(s: &str) -> Result<Value, String> {
    if s.is_empty() {
        return Err("has no value".into());
    }
    if let Some(inner) = s.strip_prefix('[') {
        let Some(inner) = inner.strip_suffix(']') else {
            return Err(format!("unterminated list {s:?}"));
        };
        if inner.trim().is_empty() {
            return Ok(Value::List(Vec::new()));
        }
        let items = inner
            .split(',')
            .map(|item| {
                let item = item.trim();
                if item.starts_with('[') || item.ends_with(']') {
                    Err(format!("nested lists are not supported, got {s:?}"))
                } else if item.is_empty() {
                    Err(format!("empty list item in {s:?}"))
                } else {
                    parse_scalar(item)
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(Value::List(items));
    }
    if s.starts_with('{') {
        return Err(format!("nested maps are not supported, got {s:?}"));
    }
    parse_scalar(s).map(Value::Scalar)
}

/// A scalar with its quotes removed: `"..."` (with `\"` and `\\` escapes),
/// `'...'` (with `''` for a quote) or bare.
fn parse_scalar(s: &str) -> Result<String, String> {
    if let Some(inner) = s.strip_prefix('"') {
        let Some(inner) = inner.strip_suffix('"').filter(|_| s.len() >= 2) else {
            return Err(format!("unterminated string {s:?}"));
        };
        let mut out = String::with_capacity(inner.len());
        let mut chars = inner.chars();
        while let Some(c) = chars.next() {
            if c == '\\' {
                match chars.next() {
                    Some('"') => out.push('"'),
                    Some('\\') => out.push('\\'),
                    Some('/') => out.push('/'),
                    other => {
                        return Err(format!(
                            "unsupported escape \\{} in {s:?}",
                            other.map(String::from).unwrap_or_default()
                        ));
                    }
                }
            } else {
                out.push(c);
            }
        }
        return Ok(out);
    }
    if let Some(inner) = s.strip_prefix('\'') {
        let Some(inner) = inner.strip_suffix('\'').filter(|_| s.len() >= 2) else {
            return Err(format!("unterminated string {s:?}"));
        };
        return Ok(inner.replace("''", "'"));
    }
    Ok(s.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "image: lse_arena.pgm\nresolution: 0.050000\norigin: [0.000000, 0.000000, 0.000000]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n\n";

    fn err(text: &str) -> String {
        match MapYaml::parse(text, "map.yaml") {
            Ok(y) => panic!("parsed {y:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn parses_a_map_saver_file() {
        let y = MapYaml::parse(GOOD, "map.yaml").expect("parse");
        assert_eq!(y.image, "lse_arena.pgm");
        assert_eq!(y.resolution, 0.05);
        assert_eq!(y.origin, (0.0, 0.0, 0.0));
        assert!(!y.negate);
        assert_eq!(y.occupied_thresh, 0.65);
        assert_eq!(y.free_thresh, 0.196);
        assert_eq!(y.mode, Mode::Trinary);
        assert_eq!(y.line_of("origin"), Some(3));
    }

    #[test]
    fn takes_quotes_comments_and_mode() {
        let text = "# a map\n---\nimage: \"my map #1.pgm\"  # the image\nresolution: 0.1\norigin: [-1, 2.5, 0]\nnegate: true\noccupied_thresh: '0.7'\nfree_thresh: 0.2\nmode: scale\nunknown_key: ignored\n";
        let y = MapYaml::parse(text, "map.yaml").expect("parse");
        assert_eq!(y.image, "my map #1.pgm");
        assert_eq!(y.origin, (-1.0, 2.5, 0.0));
        assert!(y.negate);
        assert_eq!(y.occupied_thresh, 0.7);
        assert_eq!(y.mode, Mode::Scale);
    }

    #[test]
    fn a_bad_number_names_file_line_and_field() {
        let text = GOOD.replace("occupied_thresh: 0.65", "occupied_thresh: x");
        assert_eq!(
            err(&text),
            "map.yaml:5: occupied_thresh: must be a number in [0, 1], got \"x\""
        );
        let text = GOOD.replace("resolution: 0.050000", "resolution: -1");
        assert_eq!(
            err(&text),
            "map.yaml:2: resolution: must be a positive number, got \"-1\""
        );
        let text = GOOD.replace("resolution: 0.050000", "resolution: nan");
        assert!(err(&text).starts_with("map.yaml:2: resolution:"));
        let text = GOOD.replace("[0.000000, 0.000000, 0.000000]", "[0, 0]");
        assert_eq!(
            err(&text),
            "map.yaml:3: origin: must be a list of 3 finite numbers [x, y, yaw], got [0, 0]"
        );
        let text = GOOD.replace("negate: 0", "negate: 2");
        assert_eq!(
            err(&text),
            "map.yaml:4: negate: must be 0, 1, true or false, got \"2\""
        );
        let text = format!("{GOOD}mode: fancy\n");
        assert_eq!(
            err(&text),
            "map.yaml:8: mode: must be trinary, scale or raw, got \"fancy\""
        );
    }

    #[test]
    fn a_threshold_out_of_range_is_rejected() {
        let text = GOOD.replace("free_thresh: 0.196", "free_thresh: 1.5");
        assert_eq!(
            err(&text),
            "map.yaml:6: free_thresh: must be a number in [0, 1], got \"1.5\""
        );
    }

    #[test]
    fn thresholds_out_of_order_are_rejected() {
        let text = GOOD.replace("free_thresh: 0.196", "free_thresh: 0.9");
        assert_eq!(
            err(&text),
            "map.yaml:6: free_thresh: must not exceed occupied_thresh (0.65), got 0.9"
        );
    }

    #[test]
    fn a_missing_key_is_named() {
        let text = GOOD.replace("negate: 0\n", "");
        assert_eq!(err(&text), "map.yaml: missing key `negate`");
        assert_eq!(err(""), "map.yaml: missing key `image`");
    }

    #[test]
    fn malformed_lines_are_syntax_errors() {
        assert_eq!(
            err("image map.pgm\n"),
            "map.yaml:1: expected `key: value`, got \"image map.pgm\""
        );
        assert!(err("image: a.pgm\n  nested: 1\n").starts_with("map.yaml:2: indented line"));
        assert_eq!(
            err("origin: [1, 2\n"),
            "map.yaml:1: origin: unterminated list \"[1, 2\""
        );
        assert_eq!(
            err("image: \"a.pgm\n"),
            "map.yaml:1: image: unterminated string \"\\\"a.pgm\""
        );
        assert_eq!(
            err("image: a.pgm\nimage: b.pgm\n"),
            "map.yaml:2: image: duplicate key (first on line 1)"
        );
        assert_eq!(err("image:\n"), "map.yaml:1: image: has no value");
    }

    #[test]
    fn odd_input_never_panics() {
        for text in [
            "\"",
            "'",
            ":",
            "[",
            "]",
            "a: [",
            "a: ]",
            "a: [,]",
            "a: [[1]]",
            "a: {b: 1}",
            "a: \"\\",
            "a: \"\\q\"",
            "\u{feff}image: x",
            "é: 1",
            "a: 'x''y'",
            "#",
            " #",
        ] {
            let _ = MapYaml::parse(text, "f.yaml");
        }
    }
}
