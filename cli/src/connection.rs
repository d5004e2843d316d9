//! How robot-side processes reach the map server: address, token, TLS.

use anyhow::{Context, Result};
use clap::Args;
use deog_robot_client::ClientConfig;
use std::path::PathBuf;

/// Options naming the map server and how to authenticate to it.
#[derive(Debug, Clone, Args)]
pub struct ConnectionArgs {
    /// The map server's address (host:port or a URL).
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
        let token = self
            .token_file
            .as_ref()
            .map(|path| {
                std::fs::read_to_string(path)
                    .with_context(|| format!("reading token file {}", path.display()))
                    .map(|t| t.trim().to_string())
            })
            .transpose()?;
        let tls_ca_pem = self
            .tls_ca
            .as_ref()
            .map(|path| std::fs::read(path).with_context(|| format!("reading {}", path.display())))
            .transpose()?;
        Ok(ClientConfig {
            token,
            tls_ca_pem,
            tls_domain: self.tls_domain.clone(),
            ..ClientConfig::new(self.server.clone())
        })
    }
}
