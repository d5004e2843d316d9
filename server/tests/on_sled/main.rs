//! The server suite (`../suite`) on the embedded default, sled: a real map
//! server on 127.0.0.1 over a sled folder in a temp dir. One test binary
//! rather than one a file: each would build and link `common` and the
//! server again. `on_postgres` runs the same suite on PostgreSQL.

#[path = "../suite/mod.rs"]
mod suite;

use suite::common;
