//! The server suite: each file a part of it, run against a real map server
//! on 127.0.0.1 (`common`). `on_sled` and `on_postgres` each run the whole
//! of it, on their store.

mod bad_input;
pub mod common;
mod frames_and_poses;
mod map_service;
mod pipelined_batches;
mod read_streams;
mod security;
mod sequences;
mod unreadable_batches;
