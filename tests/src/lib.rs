//! End-to-end tests of deog live in `tests/tests/`; this library holds the
//! helpers they share.
//!
//! # Layout
//! - [`deog_binary`]: where the built `deog` executable is.

use std::path::PathBuf;

/// Path of the `deog` binary built alongside the tests, found next to the
/// test executable (`target/<profile>/deog`).
pub fn deog_binary() -> PathBuf {
    let mut dir = std::env::current_exe().unwrap_or_default();
    dir.pop();
    if dir.ends_with("deps") {
        dir.pop();
    }
    dir.join(format!("deog{}", std::env::consts::EXE_SUFFIX))
}
