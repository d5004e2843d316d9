//! The shutdown signal of long-running subcommands: one copy, in
//! deog-harness. This name stays for the benchmark subcommands, which
//! still call it.

pub use deog_harness::shutdown_signal as shutdown;
