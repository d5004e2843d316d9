//! How processes reach the map server and the simulator (address, token,
//! TLS), and how both servers read their own token and TLS files: one set
//! of rules for the two.

use anyhow::{Context, Result};
use clap::Args;
use deog_proto::connection::ConnectionLimits;
use deog_proto::tls::TlsIdentity;
use deog_robot_client::{ClientConfig, Peer};
use std::path::{Path, PathBuf};

/// Options naming the map server and how to authenticate to it.
#[derive(Debug, Clone, Args)]
pub struct ConnectionArgs {
    /// The map server's address (host:port or a URL); several, separated
    /// by commas, for map servers sharing one PostgreSQL store: calls are
    /// spread over them and go around one that is down.
    #[arg(long, env = "DEOG_SERVER", default_value = "127.0.0.1:50051")]
    pub server: String,
    /// File holding the bearer token the map server expects.
    #[arg(long, env = "DEOG_TOKEN_FILE")]
    pub token_file: Option<PathBuf>,
    /// CA certificate (PEM) to trust the map server's TLS certificate with;
    /// turns TLS on.
    #[arg(long, env = "DEOG_TLS_CA")]
    pub tls_ca: Option<PathBuf>,
    /// Name the server's certificate is for, when it differs from the host
    /// in --server.
    #[arg(long, env = "DEOG_TLS_DOMAIN")]
    pub tls_domain: Option<String>,
}

impl ConnectionArgs {
    /// The robot client's configuration.
    pub fn client_config(&self) -> Result<ClientConfig> {
        client_config(
            Peer::MapServer,
            &self.server,
            self.token_file.as_deref(),
            self.tls_ca.as_deref(),
            self.tls_domain.as_deref(),
        )
    }
}

/// Options naming the simulator and how to authenticate to it.
#[derive(Debug, Clone, Args)]
pub struct SimConnectionArgs {
    /// The simulator's address (host:port or a URL).
    #[arg(long, env = "DEOG_SIM", default_value = "127.0.0.1:50052")]
    pub sim: String,
    /// File holding the bearer token the simulator expects.
    #[arg(long, env = "DEOG_SIM_TOKEN_FILE")]
    pub sim_token_file: Option<PathBuf>,
    /// CA certificate (PEM) to trust the simulator's TLS certificate with;
    /// turns TLS on.
    #[arg(long, env = "DEOG_SIM_TLS_CA")]
    pub sim_tls_ca: Option<PathBuf>,
    /// Name the simulator's certificate is for, when it differs from the
    /// host in --sim.
    #[arg(long, env = "DEOG_SIM_TLS_DOMAIN")]
    pub sim_tls_domain: Option<String>,
}

impl SimConnectionArgs {
    /// The simulator client's configuration.
    pub fn client_config(&self) -> Result<ClientConfig> {
        client_config(
            Peer::Simulator,
            &self.sim,
            self.sim_token_file.as_deref(),
            self.sim_tls_ca.as_deref(),
            self.sim_tls_domain.as_deref(),
        )
    }
}

fn client_config(
    peer: Peer,
    endpoint: &str,
    token_file: Option<&Path>,
    tls_ca: Option<&Path>,
    tls_domain: Option<&str>,
) -> Result<ClientConfig> {
    let token = token_file.map(read_token_file).transpose()?;
    let tls_ca_pem = tls_ca
        .map(|path| std::fs::read(path).with_context(|| format!("reading {}", path.display())))
        .transpose()?;
    Ok(ClientConfig {
        token,
        tls_ca_pem,
        tls_domain: tls_domain.map(str::to_string),
        peer,
        // A person's command says what it waits for.
        announce: true,
        ..ClientConfig::new(endpoint.to_string())
    })
}

/// How long a command that does one thing and ends waits for its server.
#[derive(Debug, Clone, Args)]
pub struct ConnectTimeoutArgs {
    /// Seconds to keep trying to reach the server before giving up.
    #[arg(long, env = "DEOG_CONNECT_TIMEOUT", default_value_t = 5.0)]
    pub connect_timeout: f64,
}

impl ConnectTimeoutArgs {
    /// `config`, giving up after the timeout.
    pub fn apply(&self, config: ClientConfig) -> Result<ClientConfig> {
        anyhow::ensure!(
            self.connect_timeout.is_finite() && (0.1..=3600.0).contains(&self.connect_timeout),
            "--connect-timeout must be within 0.1 and 3600 seconds, got {}",
            self.connect_timeout
        );
        Ok(config.one_shot(std::time::Duration::from_secs_f64(self.connect_timeout)))
    }
}

/// The token in `path`, trimmed; an empty one is refused, since it would
/// let through anyone who sends an empty bearer token.
pub fn read_token_file(path: &Path) -> Result<String> {
    let token = std::fs::read_to_string(path)
        .with_context(|| format!("reading token file {}", path.display()))?;
    let token = token.trim().to_string();
    anyhow::ensure!(!token.is_empty(), "token file {} is empty", path.display());
    Ok(token)
}

/// A server's TLS identity from `--tls-cert` and `--tls-key`, both or
/// neither (clap's `requires` sees to that); a file that cannot be read or
/// does not hold what it should is named with the reason.
pub fn read_tls_identity(cert: Option<&Path>, key: Option<&Path>) -> Result<Option<TlsIdentity>> {
    match (cert, key) {
        (Some(cert), Some(key)) => Ok(Some(TlsIdentity::from_files(cert, key)?)),
        _ => Ok(None),
    }
}

/// The connection limits a serving process was given, checked:
/// `--max-connections` and `--handshake-timeout-s` as both servers take
/// them.
pub fn connection_limits(
    max_connections: usize,
    handshake_timeout_s: f64,
) -> Result<ConnectionLimits> {
    anyhow::ensure!(
        max_connections >= 1,
        "--max-connections must be at least 1, got {max_connections}"
    );
    anyhow::ensure!(
        handshake_timeout_s.is_finite() && (0.1..=3600.0).contains(&handshake_timeout_s),
        "--handshake-timeout-s must be within 0.1 and 3600 seconds, got {handshake_timeout_s}"
    );
    Ok(ConnectionLimits {
        max_connections,
        handshake_timeout: std::time::Duration::from_secs_f64(handshake_timeout_s),
    })
}

/// What a person may do about an error whose words alone do not say: a
/// plain HTTP/2 client talking to a TLS port gets only a transport or
/// protocol error.
pub fn hint_for(error: &str) -> Option<&'static str> {
    ["h2 protocol error", "http2 error", "transport error"]
        .iter()
        .any(|words| error.contains(words))
        .then_some(
            "if the server serves TLS, a plain client gets only this: give --tls-ca, or --sim-tls-ca for the simulator",
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_protocol_error_gets_the_tls_hint_and_others_none() {
        assert!(
            hint_for("teleporting t: h2 protocol error: http2 error (unknown error)")
                .is_some_and(|h| h.contains("--tls-ca"))
        );
        assert_eq!(hint_for("map \"x\" does not exist (not found)"), None);
    }
}
