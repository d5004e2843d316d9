//! The robot-side client of the map server.
//!
//! # Layout
//! This crate will hold the typed async client every robot process uses
//! (connect with retry, batched updates, resend after reconnect, a versioned
//! tile cache). It holds no code yet.
