//! The shutdown signal of long-running subcommands: the one the harness
//! gives the runs it supervises, so ctrl-c means the same everywhere.

pub use deog_harness::shutdown_signal as shutdown;
