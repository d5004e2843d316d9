//! The deog wire API, generated from `proto/deog/v1/*.proto`.
//!
//! # Layout
//! - [`v1`]: every message and both services, `MapService` (the map server)
//!   and `RobotService` (the simulator), with tonic clients and servers.
//! - [`names`]: what the API accepts as a robot or map name or a client id,
//!   the one rule every service and client checks.
//! - [`rig`]: sensor rigs to and from the wire, and what a frame that names
//!   no rig means.
//! - [`auth`]: [`auth::BearerAuth`], the optional bearer-token check both
//!   servers put in front of their service.
//! - [`health`]: the gRPC health service both servers serve, `Watch` on an
//!   unknown service streaming SERVICE_UNKNOWN as the protocol asks.
//! - [`reflection`]: gRPC server reflection, v1 and v1alpha from one
//!   table, errors answered inside the stream.
//! - [`tls`]: [`tls::TlsIdentity`], a server's certificate and key, read and
//!   checked so that a bad file is named with the reason.
//! - [`FILE_DESCRIPTOR_SET`]: the encoded descriptors, for the gRPC reflection
//!   service.

/// Version 1 of the API, package `deog.v1`.
#[allow(missing_docs, clippy::all, clippy::pedantic)]
pub mod v1 {
    tonic::include_proto!("deog.v1");
}

pub mod auth;
pub mod connection;
pub mod health;
pub mod names;
pub mod reflection;
pub mod rig;
pub mod tls;

/// The encoded `FileDescriptorSet` of every deog proto file.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/deog_descriptor.bin"));
