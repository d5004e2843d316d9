//! The client against a real map server in-process on 127.0.0.1 over a
//! sled directory in a temp dir (`common`): one test binary, so the server
//! is built and linked once for all of them.

mod common;
mod frames;
mod tile_cache;
mod update_errors;
