//! End-to-end tests of deog live in `tests/tests/`; this library holds the
//! helpers they share.
//!
//! # Layout
//! - [`deog_binary`]: the `deog` executable, built once per test run.

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// Path of a freshly built `deog` binary (the debug profile), building it
/// with the same cargo that runs the tests on first use. Panics with cargo's
/// output if the build fails: the tests cannot run without it.
pub fn deog_binary() -> PathBuf {
    static BINARY: OnceLock<PathBuf> = OnceLock::new();
    BINARY
        .get_or_init(|| {
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let output = Command::new(cargo)
                .args(["build", "--quiet", "-p", "deog", "--bin", "deog"])
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .output()
                .expect("cargo runs");
            assert!(
                output.status.success(),
                "building deog failed:\n{}",
                String::from_utf8_lossy(&output.stderr)
            );
            let target = std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"));
            target
                .join("debug")
                .join(format!("deog{}", std::env::consts::EXE_SUFFIX))
        })
        .clone()
}
