//! The robot-side client of the map server.
//!
//! # Layout
//! - [`connect`]: address, TLS, bearer token, and retry with exponential
//!   backoff ([`ClientConfig`], [`RetryPolicy`]).
//! - [`client`]: [`MapClient`], typed calls (maps, frames, poses, tiles).
//! - [`updates`]: [`UpdateSender`], batched and pipelined tile updates that
//!   are resent after a reconnect and applied exactly once.
//! - [`sim_client`]: [`SimClient`], the simulator's `RobotService` (spawn,
//!   drive, state, teleport, watch).
//! - [`tile_cache`]: [`TileCache`], a versioned copy of a map's tiles.
//! - [`error`]: [`ClientError`], and which failures are worth a retry.

pub mod client;
pub mod connect;
pub mod error;
pub mod sim_client;
pub mod tile_cache;
pub mod updates;

pub use client::{MapClient, decode_tile};
pub use connect::{ClientConfig, RawMapClient, RetryPolicy};
pub use error::ClientError;
pub use sim_client::SimClient;
pub use tile_cache::TileCache;
pub use updates::{AckState, UpdateSender, UpdateSenderConfig, encode_delta};
