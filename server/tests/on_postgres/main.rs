//! The whole server suite again, unchanged, on PostgreSQL: each file below
//! is the one `on_sled` runs, and its `common` module opens every store on
//! a private PostgreSQL server this test process starts (see
//! `common::on_postgres`).

#[path = "../suite/bad_input.rs"]
mod bad_input;
#[path = "../suite/common/mod.rs"]
mod common;
#[path = "../suite/frames_and_poses.rs"]
mod frames_and_poses;
#[path = "../suite/map_service.rs"]
mod map_service;
#[path = "../suite/read_streams.rs"]
mod read_streams;
#[path = "../suite/security.rs"]
mod security;
#[path = "../suite/sequences.rs"]
mod sequences;
#[path = "../suite/unreadable_batches.rs"]
mod unreadable_batches;
