//! The line that tells a person watching how the demo goes: rewritten in
//! place on a terminal, printed every ten seconds otherwise (a log file
//! would fill with carriage returns), with notes that stay above it.

use std::io::{IsTerminal, Write as _};
use std::time::{Duration, Instant};

/// How often the line is printed when stderr is not a terminal.
const PRINT_EVERY: Duration = Duration::from_secs(10);

/// A status line on stderr.
#[derive(Debug)]
pub(crate) struct StatusLine {
    terminal: bool,
    last_printed: Option<Instant>,
    shown: bool,
}

impl StatusLine {
    /// A line on this process's stderr.
    pub fn new() -> Self {
        Self {
            terminal: std::io::stderr().is_terminal(),
            last_printed: None,
            shown: false,
        }
    }

    /// Shows `line` in place of the last one.
    pub fn show(&mut self, line: &str) {
        let mut err = std::io::stderr().lock();
        // A status line that cannot be written is no reason to stop the demo.
        if self.terminal {
            let _ = write!(err, "\r\x1b[2K{line}");
            let _ = err.flush();
            self.shown = true;
        } else if self.last_printed.is_none_or(|t| t.elapsed() >= PRINT_EVERY) {
            let _ = writeln!(err, "{line}");
            self.last_printed = Some(Instant::now());
        }
    }

    /// A line that stays, printed above the status line.
    pub fn note(&mut self, text: &str) {
        self.finish();
        eprintln!("{text}");
    }

    /// Ends the status line, so that what is printed next starts on a
    /// line of its own.
    pub fn finish(&mut self) {
        if self.shown {
            eprintln!();
            self.shown = false;
        }
    }
}
