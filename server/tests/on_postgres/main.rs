//! The whole server suite (`../suite`) again, unchanged, on PostgreSQL: its
//! `common` module opens every store on a private PostgreSQL server this
//! test process starts (see `common::on_postgres`).

#[path = "../suite/mod.rs"]
mod suite;

use suite::common;
