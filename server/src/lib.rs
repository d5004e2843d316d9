//! The map server: the central storage of deog (the thesis's Centralized
//! Storage System, section 7.1), served over gRPC.
//!
//! # Layout
//! - [`store`]: the [`Store`] trait and its embedded default on sled
//!   ([`SledStore`]); records and their byte encodings.
//! - [`writer`]: the group-commit writer thread, the one place the store
//!   changes: batches are applied in arrival order, once, and acknowledged
//!   after one flush per group.
//! - [`events`]: bounded broadcast channels for watchers and subscribers.
//! - [`convert`]: wire messages to checked domain values; request [`Limits`].
//! - [`rigs`]: [`RigRegistry`], the rigs frames may name (built in or
//!   stored), against which every published frame is checked.
//! - [`read_streams`]: the capped, shared places of read streams, and the
//!   sink their producers send through.
//! - [`service`]: the thin `MapService` handlers.
//! - `update_stream`: one `ApplyUpdates` stream, read as fast as the client
//!   sends into a byte-bounded queue, then checked, written, acknowledged.
//! - [`auth`]: the optional bearer-token check (shared with the simulator,
//!   from `deog-proto`).
//! - [`connection`]: accepted connections the server can cut when a
//!   shutdown's grace period runs out.
//! - [`serve`](mod@serve): [`serve()`] with health, reflection and TLS, until a
//!   shutdown future resolves.
//! - [`error`]: [`StoreError`] and its one mapping to a gRPC status.

pub mod convert;
pub mod error;
pub mod events;
mod foreign;
pub mod read_streams;
pub mod rigs;
pub mod serve;
pub mod service;
pub mod store;
mod update_stream;
pub mod writer;

pub use convert::Limits;
pub use deog_proto::auth;
pub use deog_proto::connection::{self, ConnectionLimits};
pub use deog_proto::tls::{TlsError, TlsIdentity};
pub use error::StoreError;
pub use read_streams::ReadStreamLimits;
pub use rigs::RigRegistry;
pub use serve::{MAP_SERVICE_NAME, ServeError, ServerConfig, serve};
pub use store::{PostgresConfig, PostgresStore, SledConfig, SledStore, Store};
