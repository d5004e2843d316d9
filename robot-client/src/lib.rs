//! The robot-side client of the map server.
//!
//! # Layout
//! - [`connect`]: address, TLS, bearer token, and retry with exponential
//!   backoff ([`ClientConfig`], [`RetryPolicy`]).
//! - [`client`]: [`MapClient`], typed calls for every map-server RPC a
//!   process makes (maps, frames, poses, tiles, watches).
//! - [`updates`]: [`UpdateSender`], batched and pipelined tile updates that
//!   are resent after a reconnect and applied exactly once.
//! - [`sim_client`]: [`SimClient`], the simulator's `RobotService` (spawn,
//!   drive, state, teleport, watch).
//! - [`convert`]: wire messages to the grid core's types and back (poses,
//!   tile keys, boxes of cells, tiles and deltas).
//! - [`tile_cache`]: [`TileCache`], a versioned copy of a map's tiles,
//!   which [`MapClient::download`] fills.
//! - [`tile_watch`]: [`TileWatch`], a map's tile events as the changes
//!   they mean to a copy of some of its tiles.
//! - [`error`]: [`ClientError`], and which failures are worth a retry.

pub mod client;
pub mod connect;
pub mod convert;
pub mod error;
pub mod sim_client;
pub mod tile_cache;
pub mod tile_watch;
pub mod updates;

pub use client::MapClient;
pub use connect::{ClientConfig, RawMapClient, RetryPolicy};
pub use convert::{decode_tile, encode_delta};
pub use error::{ClientError, Peer, code_words, status_line};
pub use sim_client::SimClient;
pub use tile_cache::TileCache;
pub use tile_watch::{TileChange, TileWatch};
pub use updates::{AckState, UpdateSender, UpdateSenderConfig};
