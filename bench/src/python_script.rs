//! A peer's side run as a child Python process: the script, built into
//! the binary, written to a work directory and run by an interpreter the
//! options name. Every such script answers `--probe` with its versions as
//! JSON, or exits with [`MISSING_EXIT`] when a module it needs is missing.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use anyhow::{Context, Result};
use serde::de::DeserializeOwned;

/// A script's exit code when a module it needs is missing.
pub(crate) const MISSING_EXIT: i32 = 3;

/// The interpreter with one script written into a work directory.
pub(crate) struct PythonScript {
    python: OsString,
    script: PathBuf,
    /// Whose side the script runs, for messages ("amcl's side").
    side: &'static str,
    /// The pip command that installs what it needs.
    install_hint: &'static str,
}

impl PythonScript {
    /// Writes `text` as `file_name` into `work` (a temporary directory)
    /// for `python`.
    pub fn new(
        python: impl Into<OsString>,
        work: &Path,
        file_name: &str,
        text: &str,
        side: &'static str,
        install_hint: &'static str,
    ) -> Result<Self> {
        let script = work.join(file_name);
        std::fs::write(&script, text).with_context(|| format!("writing {}", script.display()))?;
        Ok(Self {
            python: python.into(),
            script,
            side,
            install_hint,
        })
    }

    /// The versions the script prints, or why it cannot run: no such
    /// interpreter, or a module missing (the reason then says how to
    /// install it).
    pub fn probe<V: DeserializeOwned>(&self) -> Result<V, String> {
        let python = self.python.to_string_lossy();
        let output = self
            .command()
            .arg("--probe")
            .output()
            .map_err(|e| format!("cannot run {python}: {e}"))?;
        if output.status.code() == Some(MISSING_EXIT) {
            return Err(format!(
                "{python} lacks what {} needs ({}); install it with `{python} -m {}`",
                self.side,
                String::from_utf8_lossy(&output.stderr).trim(),
                self.install_hint,
            ));
        }
        if !output.status.success() {
            return Err(failure("the probe", &output));
        }
        serde_json::from_slice(&output.stdout)
            .map_err(|e| format!("the probe printed no versions: {e}"))
    }

    /// The interpreter's name, for messages.
    pub fn python(&self) -> std::borrow::Cow<'_, str> {
        self.python.to_string_lossy()
    }

    /// The interpreter running the script; arguments follow.
    pub fn command(&self) -> Command {
        let mut command = Command::new(&self.python);
        command.arg(&self.script);
        command
    }
}

/// A failed child's exit status and the end of what it wrote on stderr.
pub(crate) fn failure(what: &str, output: &Output) -> String {
    let stderr = String::from_utf8_lossy(&output.stderr);
    let tail: Vec<&str> = stderr.lines().rev().take(10).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    format!("{what} failed ({}):\n{}", output.status, tail.join("\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_interpreter_is_a_reason_not_a_panic() {
        let work = tempfile::tempdir().expect("a temporary directory");
        let script = PythonScript::new(
            "/nonexistent/python3",
            work.path(),
            "probe.py",
            "print('{}')\n",
            "a peer's side",
            "pip install nothing",
        )
        .expect("the script is written");
        assert!(work.path().join("probe.py").exists());
        let reason = script
            .probe::<serde_json::Value>()
            .expect_err("no interpreter");
        assert!(
            reason.starts_with("cannot run /nonexistent/python3"),
            "{reason}"
        );
    }
}
