//! `deog demo`: the options and the whole run live in deog-demo; the
//! binary hands it the parsed options.

pub use deog_demo::{DemoOptions, run};
