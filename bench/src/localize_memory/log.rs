//! The localizer's log read as it grows: the cache size of its periodic
//! info lines, and its last line's figures.

use std::path::PathBuf;

/// What the localizer's last line says.
#[derive(Debug, Clone, Copy)]
pub(super) struct LocalizerSummary {
    /// Frames it read.
    pub frames: u64,
    /// Sensor updates it ran.
    pub sensor_updates: u64,
    /// Range tables it built.
    pub tables_built: u64,
    /// Its cache at the end, MiB.
    pub cache_mib: f64,
}

/// The localizer's last line: "R on M: N frames, U sensor updates, S frames
/// skipped to keep up, T range tables built, cache X MiB".
pub(super) fn parse_summary(log: &str) -> Option<LocalizerSummary> {
    let line = log
        .lines()
        .rev()
        .find(|l| l.contains(" range tables built, cache "))?;
    let (_, figures) = line.split_once(": ")?;
    let number = |label: &str| -> Option<f64> {
        figures
            .split(", ")
            .find_map(|part| part.strip_suffix(label))
            .and_then(|n| n.trim().parse().ok())
    };
    let cache = figures
        .split(", ")
        .find_map(|part| part.strip_prefix("cache "))?
        .strip_suffix(" MiB")?
        .parse()
        .ok()?;
    Some(LocalizerSummary {
        frames: number(" frames")? as u64,
        sensor_updates: number(" sensor updates")? as u64,
        tables_built: number(" range tables built")? as u64,
        cache_mib: cache,
    })
}

/// The largest `cache_mb` in the localizer's periodic info lines.
pub(super) fn logged_cache_max(log: &str) -> Option<f64> {
    log.lines().filter_map(line_cache_mb).reduce(f64::max)
}

/// The `cache_mb` field of one of the localizer's info lines, MiB.
pub(super) fn line_cache_mb(line: &str) -> Option<f64> {
    let (_, rest) = line.split_once("cache_mb=")?;
    rest.trim_start_matches('"')
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .next()?
        .parse::<f64>()
        .ok()
}

/// The lines a growing log file gained since the last call.
pub(super) struct LogFollower {
    /// The log file.
    pub path: PathBuf,
    offset: u64,
    partial: String,
}

impl LogFollower {
    /// Follows `path` from its start; it need not exist yet.
    pub fn new(path: PathBuf) -> Self {
        Self {
            path,
            offset: 0,
            partial: String::new(),
        }
    }

    /// Whole lines written since the last call; none if the file cannot
    /// be read (yet).
    pub fn new_lines(&mut self) -> Vec<String> {
        use std::io::{Read as _, Seek as _, SeekFrom};
        let Ok(mut file) = std::fs::File::open(&self.path) else {
            return Vec::new();
        };
        let mut bytes = Vec::new();
        if file.seek(SeekFrom::Start(self.offset)).is_err() || file.read_to_end(&mut bytes).is_err()
        {
            return Vec::new();
        }
        self.offset += bytes.len() as u64;
        self.partial.push_str(&String::from_utf8_lossy(&bytes));
        let Some(end) = self.partial.rfind('\n') else {
            return Vec::new();
        };
        let rest = self.partial.split_off(end + 1);
        let lines = std::mem::replace(&mut self.partial, rest);
        lines.lines().map(str::to_string).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_line_is_read() {
        let log = "2026 INFO estimate cache_mb=\"12.5\"\n\
                   2026 INFO estimate cache_mb=15.9 x=1\n\
                   scout-1 on bench: 3000 frames, 2900 sensor updates, 40 frames skipped to keep up, 57 range tables built, cache 15.2 MiB\n";
        let s = parse_summary(log).unwrap();
        assert_eq!(
            (s.frames, s.sensor_updates, s.tables_built),
            (3000, 2900, 57)
        );
        assert!((s.cache_mib - 15.2).abs() < 1e-9);
        assert_eq!(logged_cache_max(log), Some(15.9));
    }

    #[test]
    fn a_log_is_followed_line_by_line() {
        use std::io::Write as _;
        let dir = tempfile::tempdir().expect("a temporary folder");
        let path = dir.path().join("localize.log");
        let mut follower = LogFollower::new(path.clone());
        assert!(follower.new_lines().is_empty(), "no file yet");
        let mut file = std::fs::File::create(&path).expect("the log");
        write!(file, "one\ntw").expect("written");
        assert_eq!(follower.new_lines(), ["one"]);
        writeln!(file, "o").expect("written");
        assert_eq!(follower.new_lines(), ["two"]);
        assert!(follower.new_lines().is_empty());
    }
}
