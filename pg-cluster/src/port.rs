//! Picking a free loopback port.

use std::net::{Ipv4Addr, TcpListener};

use crate::ClusterError;

/// A port on 127.0.0.1 that was free a moment ago: the kernel picks one for
/// a listener that is then closed. Another process may take it before the
/// server binds, so the caller retries with a fresh one on "address already
/// in use".
pub(crate) fn free_port() -> Result<u16, ClusterError> {
    let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
        .map_err(|e| ClusterError::io("binding 127.0.0.1:0 to find a free port", e))?;
    let port = listener
        .local_addr()
        .map_err(|e| ClusterError::io("reading the port of a listener on 127.0.0.1:0", e))?
        .port();
    Ok(port)
}
