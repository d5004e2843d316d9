//! The thesis's wanderer data file: one line per sonar frame,
//! `x y theta s1 ... s16`, whitespace-separated (section 7.3).
//!
//! Two unit systems: SI (metres, radians, metres), the default, and the
//! Nomad API's (x and y in tenths of an inch, theta in tenths of a degree,
//! ranges in inches), for files written by the original software. Blank
//! lines and lines starting with `#` are skipped.

use deog_grid::Pose2;

use crate::error::SimError;

/// Metres per tenth of an inch.
const TENTH_INCH_M: f64 = 0.00254;
/// Metres per inch.
const INCH_M: f64 = 0.0254;

/// Units of a data file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DataUnits {
    /// Metres, radians, metres.
    #[default]
    Si,
    /// Tenths of an inch, tenths of a degree, inches.
    Nomad,
}

impl std::str::FromStr for DataUnits {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "si" => Ok(Self::Si),
            "nomad" => Ok(Self::Nomad),
            other => Err(format!("unknown units {other:?}: use si or nomad")),
        }
    }
}

/// One line: a pose and its frame's ranges (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct DataLine {
    /// 1-based line number in the file.
    pub line: usize,
    /// The pose the frame was taken at.
    pub pose: Pose2,
    /// Ranges, metres, sonar 0 first.
    pub ranges: Vec<f64>,
}

/// A line of the file for `pose` and `ranges` (SI in), newline-terminated.
pub fn format_line(pose: &Pose2, ranges: &[f64], units: DataUnits) -> String {
    let mut line = match units {
        DataUnits::Si => format!("{:.6} {:.6} {:.6}", pose.x, pose.y, pose.theta),
        DataUnits::Nomad => format!(
            "{:.1} {:.1} {:.1}",
            pose.x / TENTH_INCH_M,
            pose.y / TENTH_INCH_M,
            pose.theta.to_degrees() * 10.0
        ),
    };
    for r in ranges {
        match units {
            DataUnits::Si => line.push_str(&format!(" {r:.4}")),
            DataUnits::Nomad => line.push_str(&format!(" {:.2}", r / INCH_M)),
        }
    }
    line.push('\n');
    line
}

/// Parses a whole file's text; `origin` names it in errors. Every line must
/// hold the same number of ranges (at least one).
pub fn parse(text: &str, origin: &str, units: DataUnits) -> Result<Vec<DataLine>, SimError> {
    let mut lines = Vec::new();
    let mut sonars = None;
    for (i, raw) in text.lines().enumerate() {
        let number = i + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let at = |field: &str, reason: String| SimError::DataFile {
            file: origin.to_string(),
            line: number,
            field: field.to_string(),
            reason,
        };
        let mut values = Vec::new();
        for (column, word) in trimmed.split_whitespace().enumerate() {
            let field = match column {
                0 => "x".to_string(),
                1 => "y".to_string(),
                2 => "theta".to_string(),
                n => format!("s{}", n - 2),
            };
            let value: f64 = word
                .parse()
                .map_err(|_| at(&field, format!("not a number: {word:?}")))?;
            if !value.is_finite() {
                return Err(at(&field, format!("must be finite, got {word}")));
            }
            if column >= 3 && value < 0.0 {
                return Err(at(
                    &field,
                    format!("a range must not be negative, got {word}"),
                ));
            }
            values.push(value);
        }
        if values.len() < 4 {
            return Err(at(
                "s1",
                format!(
                    "a line needs x, y, theta and at least one range; got {} values",
                    values.len()
                ),
            ));
        }
        let count = values.len() - 3;
        match sonars {
            None => sonars = Some(count),
            Some(expected) if expected != count => {
                return Err(at(
                    "ranges",
                    format!("expected {expected} ranges as on the first line, got {count}"),
                ));
            }
            Some(_) => {}
        }
        let (pose, ranges) = match units {
            DataUnits::Si => (
                Pose2::new(values[0], values[1], values[2]),
                values[3..].to_vec(),
            ),
            DataUnits::Nomad => (
                Pose2::new(
                    values[0] * TENTH_INCH_M,
                    values[1] * TENTH_INCH_M,
                    (values[2] / 10.0).to_radians(),
                ),
                values[3..].iter().map(|r| r * INCH_M).collect(),
            ),
        };
        lines.push(DataLine {
            line: number,
            pose,
            ranges,
        });
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_round_trip_in_both_units() {
        let pose = Pose2::new(1.25, -3.5, 0.75);
        let ranges: Vec<f64> = (0..16).map(|i| 0.5 + i as f64 * 0.25).collect();
        for units in [DataUnits::Si, DataUnits::Nomad] {
            let text = format!("# a comment\n\n{}", format_line(&pose, &ranges, units));
            let parsed = parse(&text, "run.dat", units).expect("parse");
            assert_eq!(parsed.len(), 1);
            assert_eq!(parsed[0].line, 3);
            let tolerance = if units == DataUnits::Si { 1e-6 } else { 3e-3 };
            assert!((parsed[0].pose.x - pose.x).abs() < tolerance);
            assert!((parsed[0].pose.y - pose.y).abs() < tolerance);
            assert!((parsed[0].pose.theta - pose.theta).abs() < tolerance);
            for (a, b) in parsed[0].ranges.iter().zip(&ranges) {
                assert!((a - b).abs() < tolerance, "{a} {b}");
            }
        }
    }

    #[test]
    fn errors_name_the_file_line_and_field() {
        let ok = format_line(&Pose2::new(0.0, 0.0, 0.0), &[1.0; 16], DataUnits::Si);
        let cases = [
            (format!("{ok}1 2 x 4\n"), "run.dat:2: theta: not a number"),
            (format!("{ok}1 2 3\n"), "run.dat:2: s1:"),
            (format!("{ok}1 2 3 4 5\n"), "run.dat:2: ranges: expected 16"),
            (
                "1 2 3 -4\n".to_string(),
                "run.dat:1: s1: a range must not be negative",
            ),
            ("1 2 3 inf\n".to_string(), "run.dat:1: s1: must be finite"),
            ("NaN 2 3 4\n".to_string(), "run.dat:1: x: must be finite"),
        ];
        for (text, expected) in cases {
            let error = parse(&text, "run.dat", DataUnits::Si).expect_err(&text);
            assert!(
                error.to_string().starts_with(expected),
                "{error} should start with {expected}"
            );
        }
    }
}
