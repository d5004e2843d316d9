//! Progress of long work as a person sees it: a bar with its rate and the
//! time left when stderr is a terminal, an info log line every few seconds
//! (done/total, rate, time left) when it is not, nothing under `--quiet`.
//! Everything goes to stderr, so what a command prints on stdout (tables,
//! JSON) stays clean.
//!
//! ```
//! use deog_harness::progress::{Progress, ProgressMode};
//!
//! let progress = Progress::with_mode("importing frames", "frames", 3, ProgressMode::Hidden);
//! for _ in 0..3 {
//!     progress.inc(1);
//! }
//! assert_eq!(progress.done(), 3);
//! progress.finish();
//! ```
//!
//! Log lines written through [`stderr_writer`] (the binary's tracing
//! writer) clear the bars first and draw them again after, so a log line
//! never lands in the middle of a bar.

use std::fmt;
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

/// How often a log line reports progress when stderr is not a terminal.
pub const LOG_EVERY: Duration = Duration::from_secs(5);

/// Set once by the binary from `--quiet`.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Every bar drawn, so that log lines can be written above them.
fn bars() -> &'static MultiProgress {
    static BARS: OnceLock<MultiProgress> = OnceLock::new();
    BARS.get_or_init(|| MultiProgress::with_draw_target(ProgressDrawTarget::stderr()))
}

/// Hides every progress report made after this call (`--quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// How progress is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgressMode {
    /// A bar on stderr, redrawn in place.
    Bar,
    /// An info log line every [`LOG_EVERY`], and one at the end if any was
    /// written.
    Log,
    /// Nothing.
    Hidden,
}

impl ProgressMode {
    /// Hidden under `--quiet`, a bar on a terminal, log lines otherwise.
    pub fn for_stderr() -> Self {
        if QUIET.load(Ordering::Relaxed) {
            Self::Hidden
        } else if std::io::stderr().is_terminal() {
            Self::Bar
        } else {
            Self::Log
        }
    }
}

/// One piece of long work: `done` of `total` items. Cloning shares it, so
/// tasks and callbacks can each advance it. Dropping the last clone clears
/// the bar.
#[derive(Debug, Clone)]
pub struct Progress {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    what: String,
    unit: String,
    done: AtomicU64,
    /// 0: not known.
    total: AtomicU64,
    started: Instant,
    display: Display,
}

#[derive(Debug)]
enum Display {
    Bar(ProgressBar),
    /// When the last line was written, and whether any was.
    Log(Mutex<(Instant, bool)>),
    Hidden,
}

impl Progress {
    /// Progress of `what` ("importing frames"), counted in `unit`
    /// ("frames"), out of `total` (0: not known), shown as
    /// [`ProgressMode::for_stderr`] says.
    pub fn new(what: impl Into<String>, unit: impl Into<String>, total: u64) -> Self {
        Self::with_mode(what, unit, total, ProgressMode::for_stderr())
    }

    /// As [`Progress::new`], shown as `mode` says.
    pub fn with_mode(
        what: impl Into<String>,
        unit: impl Into<String>,
        total: u64,
        mode: ProgressMode,
    ) -> Self {
        let (what, unit) = (what.into(), unit.into());
        let started = Instant::now();
        let display = match mode {
            ProgressMode::Bar => {
                let bar = bars().add(ProgressBar::new(total));
                bar.set_style(bar_style(total, &unit));
                bar.set_message(what.clone());
                bar.enable_steady_tick(Duration::from_millis(200));
                Display::Bar(bar)
            }
            ProgressMode::Log => Display::Log(Mutex::new((started, false))),
            ProgressMode::Hidden => Display::Hidden,
        };
        Self {
            inner: Arc::new(Inner {
                what,
                unit,
                done: AtomicU64::new(0),
                total: AtomicU64::new(total),
                started,
                display,
            }),
        }
    }

    /// `n` more items done.
    pub fn inc(&self, n: u64) {
        self.inner.done.fetch_add(n, Ordering::Relaxed);
        self.shown();
    }

    /// `done` items done in all.
    pub fn set_done(&self, done: u64) {
        self.inner.done.store(done, Ordering::Relaxed);
        self.shown();
    }

    /// The total is now `total` items (0: not known).
    pub fn set_total(&self, total: u64) {
        let before = self.inner.total.swap(total, Ordering::Relaxed);
        if let Display::Bar(bar) = &self.inner.display {
            if (before == 0) != (total == 0) {
                bar.set_style(bar_style(total, &self.inner.unit));
            }
            bar.set_length(total);
        }
    }

    /// Items done so far.
    pub fn done(&self) -> u64 {
        self.inner.done.load(Ordering::Relaxed)
    }

    /// The work is over: the bar goes, and where log lines reported it, a
    /// last one says how much was done and how fast.
    pub fn finish(&self) {
        match &self.inner.display {
            Display::Bar(bar) => bar.finish_and_clear(),
            Display::Log(state) => {
                let wrote = state.lock().map(|s| s.1).unwrap_or(true);
                if wrote {
                    tracing::info!(
                        "{}",
                        finish_line(
                            &self.inner.what,
                            &self.inner.unit,
                            self.done(),
                            self.inner.started.elapsed()
                        )
                    );
                }
            }
            Display::Hidden => {}
        }
    }

    /// Runs `f` (a `println!` of a result line, say) with every bar
    /// cleared, then draws them again: stdout and stderr share a terminal.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        suspend(f)
    }

    fn shown(&self) {
        match &self.inner.display {
            Display::Bar(bar) => bar.set_position(self.done()),
            Display::Log(_) => {
                if let Some(line) = self.due_line(Instant::now()) {
                    tracing::info!("{line}");
                }
            }
            Display::Hidden => {}
        }
    }

    /// Where log lines report the work: the line to write at `now`, if
    /// [`LOG_EVERY`] has passed since the last one (or the start).
    fn due_line(&self, now: Instant) -> Option<String> {
        let Display::Log(state) = &self.inner.display else {
            return None;
        };
        // A poisoned lock only means another thread panicked while
        // logging: go on without the line.
        let mut state = state.lock().ok()?;
        if now.saturating_duration_since(state.0) < LOG_EVERY {
            return None;
        }
        *state = (now, true);
        Some(log_line(
            &self.inner.what,
            &self.inner.unit,
            self.done(),
            self.inner.total.load(Ordering::Relaxed),
            now.saturating_duration_since(self.inner.started),
        ))
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        if let Display::Bar(bar) = &self.display {
            bar.finish_and_clear();
            bars().remove(bar);
        }
    }
}

fn bar_style(total: u64, unit: &str) -> ProgressStyle {
    let template = if total == 0 {
        format!("{{spinner}} {{msg}}: {{human_pos}} {unit}, {{rate}}, {{elapsed}}")
    } else {
        format!(
            "{{msg}} [{{wide_bar}}] {{human_pos}}/{{human_len}} {unit}, {{rate}}, {{left}} left"
        )
    };
    let rate_unit = unit.to_owned();
    // The templates above are fixed and valid; a bad one would only lose
    // the layout, so fall back to the default rather than fail the work.
    ProgressStyle::with_template(&template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .with_key(
            "rate",
            move |state: &ProgressState, out: &mut dyn fmt::Write| {
                // A write into the bar's own buffer cannot fail.
                let _ = out.write_str(&format_rate(state.per_sec(), &rate_unit));
            },
        )
        .with_key("left", |state: &ProgressState, out: &mut dyn fmt::Write| {
            let _ = out.write_str(&format_duration(state.eta()));
        })
        .progress_chars("=> ")
}

/// A progress log line: `what: done/total unit (percent), rate, time left`,
/// or without the total and the time left when the total is not known (0).
pub fn log_line(what: &str, unit: &str, done: u64, total: u64, elapsed: Duration) -> String {
    let rate = rate_per_s(done, elapsed);
    if total == 0 {
        return format!("{what}: {done} {unit}, {}", format_rate(rate, unit));
    }
    let percent = 100.0 * done.min(total) as f64 / total as f64;
    let left = match remaining(done, total, rate) {
        Some(left) => format!("{} left", format_duration(left)),
        None => "time left unknown".to_owned(),
    };
    format!(
        "{what}: {done}/{total} {unit} ({percent:.0}%), {}, {left}",
        format_rate(rate, unit)
    )
}

/// The last line of a piece of work: how much and how fast.
pub fn finish_line(what: &str, unit: &str, done: u64, elapsed: Duration) -> String {
    format!(
        "{what}: done, {done} {unit} in {}, {}",
        format_duration(elapsed),
        format_rate(rate_per_s(done, elapsed), unit)
    )
}

/// Items per second; 0 before any time has passed.
fn rate_per_s(done: u64, elapsed: Duration) -> f64 {
    let seconds = elapsed.as_secs_f64();
    if seconds > 0.0 {
        done as f64 / seconds
    } else {
        0.0
    }
}

/// Time left at `rate`; `None` while nothing is done (no rate yet).
fn remaining(done: u64, total: u64, rate: f64) -> Option<Duration> {
    if rate <= 0.0 {
        return None;
    }
    let left = total.saturating_sub(done) as f64 / rate;
    Duration::try_from_secs_f64(left).ok()
}

/// `1234 frames/s`; one decimal below 10, so slow work does not read 0.
pub fn format_rate(rate: f64, unit: &str) -> String {
    if rate < 10.0 {
        format!("{rate:.1} {unit}/s")
    } else {
        format!("{rate:.0} {unit}/s")
    }
}

/// `42 s`, `3 min 05 s`, `2 h 07 min`: whole seconds, the two largest
/// units.
pub fn format_duration(duration: Duration) -> String {
    let seconds = duration.as_secs_f64().round() as u64;
    match seconds {
        0..60 => format!("{seconds} s"),
        60..3600 => format!("{} min {:02} s", seconds / 60, seconds % 60),
        _ => format!("{} h {:02} min", seconds / 3600, seconds % 3600 / 60),
    }
}

/// Runs `f` with every bar cleared, then draws them again.
pub fn suspend<R>(f: impl FnOnce() -> R) -> R {
    bars().suspend(f)
}

/// `println!` with every bar cleared first and drawn again after, so a
/// result line printed on stdout while a bar runs on the same terminal
/// never lands inside the bar.
#[macro_export]
macro_rules! println_above_bars {
    ($($arg:tt)*) => {
        $crate::progress::suspend(|| println!($($arg)*))
    };
}

/// `print!` as [`println_above_bars!`] does `println!`.
#[macro_export]
macro_rules! print_above_bars {
    ($($arg:tt)*) => {
        $crate::progress::suspend(|| print!($($arg)*))
    };
}

/// `eprintln!` as [`println_above_bars!`] does `println!`.
#[macro_export]
macro_rules! eprintln_above_bars {
    ($($arg:tt)*) => {
        $crate::progress::suspend(|| eprintln!($($arg)*))
    };
}

/// `eprint!` as [`println_above_bars!`] does `println!`.
#[macro_export]
macro_rules! eprint_above_bars {
    ($($arg:tt)*) => {
        $crate::progress::suspend(|| eprint!($($arg)*))
    };
}

/// Writes to stderr with every bar cleared first and drawn again after:
/// the writer for the binary's log lines.
pub fn stderr_writer() -> StderrAboveBars {
    StderrAboveBars
}

/// See [`stderr_writer`].
#[derive(Debug, Clone, Copy)]
pub struct StderrAboveBars;

impl Write for StderrAboveBars {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        bars().suspend(|| std::io::stderr().write(buf))
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        bars().suspend(|| std::io::stderr().write_all(buf))
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_line_gives_count_percent_rate_and_time_left() {
        // 300 of 1000 frames in 10 s: 30 frames/s, 700 left take 23.3 s.
        let line = log_line(
            "importing frames",
            "frames",
            300,
            1000,
            Duration::from_secs(10),
        );
        assert_eq!(
            line,
            "importing frames: 300/1000 frames (30%), 30 frames/s, 23 s left"
        );
    }

    #[test]
    fn a_slow_rate_keeps_a_decimal_and_long_times_read_in_minutes_and_hours() {
        let line = log_line("copying tiles", "tiles", 5, 1000, Duration::from_secs(2));
        // 2.5 tiles/s, 995 left: 398 s.
        assert_eq!(
            line,
            "copying tiles: 5/1000 tiles (0%), 2.5 tiles/s, 6 min 38 s left"
        );
        assert_eq!(format_duration(Duration::from_secs(7_620)), "2 h 07 min");
        assert_eq!(format_duration(Duration::from_secs(59)), "59 s");
    }

    #[test]
    fn nothing_done_yet_has_no_time_left_and_an_unknown_total_no_percent() {
        let line = log_line("replaying", "frames", 0, 50, Duration::from_secs(3));
        assert_eq!(
            line,
            "replaying: 0/50 frames (0%), 0.0 frames/s, time left unknown"
        );
        let line = log_line("replaying", "frames", 40, 0, Duration::from_secs(4));
        assert_eq!(line, "replaying: 40 frames, 10 frames/s");
        let line = log_line("replaying", "frames", 40, 50, Duration::ZERO);
        assert_eq!(
            line,
            "replaying: 40/50 frames (80%), 0.0 frames/s, time left unknown"
        );
    }

    #[test]
    fn the_last_line_says_how_much_and_how_fast() {
        let line = finish_line("exporting tiles", "tiles", 600, Duration::from_secs(75));
        assert_eq!(
            line,
            "exporting tiles: done, 600 tiles in 1 min 15 s, 8.0 tiles/s"
        );
    }

    #[test]
    fn off_a_terminal_a_line_is_due_every_few_seconds() {
        let progress = Progress::with_mode("copying tiles", "tiles", 400, ProgressMode::Log);
        let start = progress.inner.started;
        progress.inner.done.store(100, Ordering::Relaxed);
        assert_eq!(progress.due_line(start + Duration::from_secs(1)), None);
        let first = start + LOG_EVERY;
        assert_eq!(
            progress.due_line(first).as_deref(),
            Some("copying tiles: 100/400 tiles (25%), 20 tiles/s, 15 s left")
        );
        // Not again until another interval has passed.
        assert_eq!(progress.due_line(first + Duration::from_secs(2)), None);
        progress.inner.done.store(400, Ordering::Relaxed);
        assert_eq!(
            progress.due_line(first + LOG_EVERY).as_deref(),
            Some("copying tiles: 400/400 tiles (100%), 40 tiles/s, 0 s left")
        );
        // A bar or nothing writes no line.
        let hidden = Progress::with_mode("x", "items", 1, ProgressMode::Hidden);
        assert_eq!(hidden.due_line(Instant::now() + LOG_EVERY), None);
    }

    #[test]
    fn clones_share_one_count() {
        let progress = Progress::with_mode("work", "items", 10, ProgressMode::Log);
        let other = progress.clone();
        progress.inc(3);
        other.inc(4);
        assert_eq!(progress.done(), 7);
        other.set_done(9);
        assert_eq!(progress.done(), 9);
        progress.set_total(20);
        assert_eq!(progress.inner.total.load(Ordering::Relaxed), 20);
        progress.finish();
    }
}
