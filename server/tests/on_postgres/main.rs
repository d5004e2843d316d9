//! The whole server suite again, unchanged, on PostgreSQL: each file below
//! is the sled suite's own, and its `common` module opens every store on a
//! private PostgreSQL server this test process starts (see
//! `common::on_postgres`).

// Each suite file declares `mod common` for itself, as it does when built
// alone; here that loads the helpers once per file.
#![allow(clippy::duplicate_mod)]

#[path = "../bad_input.rs"]
mod bad_input;
#[path = "../frames_and_poses.rs"]
mod frames_and_poses;
#[path = "../map_service.rs"]
mod map_service;
#[path = "../read_streams.rs"]
mod read_streams;
#[path = "../security.rs"]
mod security;
#[path = "../sequences.rs"]
mod sequences;
#[path = "../unreadable_batches.rs"]
mod unreadable_batches;
