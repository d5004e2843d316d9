//! The server suite on the embedded default, sled: each file below is a
//! part of the suite, a real map server on 127.0.0.1 over a sled folder in
//! a temp dir (`common`). One test binary rather than one a file: each
//! would build and link `common` and the server again. `on_postgres` runs
//! the same files on PostgreSQL.

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
