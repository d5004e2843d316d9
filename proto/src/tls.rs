//! A server's TLS identity (certificate chain and private key, PEM), read
//! and checked the same way by both servers, so that a bad file is named
//! with what is wrong with it rather than reported as a transport error.

use std::path::Path;

use rustls_pki_types::pem::{self, PemObject as _};
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use thiserror::Error;
use tonic::transport::{Identity, ServerTlsConfig};

/// What is wrong with a TLS identity.
#[derive(Debug, Error)]
pub enum TlsError {
    /// A file could not be read.
    #[error("reading TLS {what} file {file}: {source}")]
    Read {
        /// `certificate` or `key`.
        what: &'static str,
        /// The file, as given.
        file: String,
        /// Why it could not be read.
        source: std::io::Error,
    },
    /// The certificate chain or the key does not parse.
    #[error("TLS {what} {origin}: {reason}")]
    Parse {
        /// `certificate` or `key`.
        what: &'static str,
        /// `file <path>`, or `PEM` when it was given in memory.
        origin: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The transport refused the identity (a key that does not belong to
    /// the certificate, say); the transport's reasons, innermost last.
    #[error("TLS setup failed: {0}")]
    Setup(String),
}

/// A certificate chain and private key, PEM.
#[derive(Clone)]
pub struct TlsIdentity {
    /// Certificate chain, PEM.
    pub cert_pem: Vec<u8>,
    /// Private key, PEM.
    pub key_pem: Vec<u8>,
}

impl std::fmt::Debug for TlsIdentity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the key.
        f.debug_struct("TlsIdentity").finish_non_exhaustive()
    }
}

impl TlsIdentity {
    /// Reads the certificate chain and key from PEM files and checks that
    /// each parses; errors name the file and the reason.
    pub fn from_files(cert: &Path, key: &Path) -> Result<Self, TlsError> {
        let read = |what, path: &Path| {
            std::fs::read(path).map_err(|source| TlsError::Read {
                what,
                file: path.display().to_string(),
                source,
            })
        };
        let identity = Self {
            cert_pem: read("certificate", cert)?,
            key_pem: read("key", key)?,
        };
        identity.check_certificate(&format!("file {}", cert.display()))?;
        identity.check_key(&format!("file {}", key.display()))?;
        Ok(identity)
    }

    /// Checks that the certificate chain and the key parse.
    pub fn check(&self) -> Result<(), TlsError> {
        self.check_certificate("PEM")?;
        self.check_key("PEM")
    }

    fn check_certificate(&self, origin: &str) -> Result<(), TlsError> {
        let parse = |reason: String| TlsError::Parse {
            what: "certificate",
            origin: origin.to_string(),
            reason,
        };
        let certificates = CertificateDer::pem_slice_iter(&self.cert_pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| parse(pem_reason(&e)))?;
        if certificates.is_empty() {
            return Err(parse("holds no `BEGIN CERTIFICATE` section".to_string()));
        }
        Ok(())
    }

    fn check_key(&self, origin: &str) -> Result<(), TlsError> {
        PrivateKeyDer::from_pem_slice(&self.key_pem)
            .map(drop)
            .map_err(|e| TlsError::Parse {
                what: "key",
                origin: origin.to_string(),
                reason: match e {
                    pem::Error::NoItemsFound => "holds no private key (expected a PEM \
                        `PRIVATE KEY`, `RSA PRIVATE KEY` or `EC PRIVATE KEY` section)"
                        .to_string(),
                    other => pem_reason(&other),
                },
            })
    }

    /// The transport's TLS configuration for this identity, checked first.
    pub fn server_config(&self) -> Result<ServerTlsConfig, TlsError> {
        self.check()?;
        Ok(ServerTlsConfig::new().identity(Identity::from_pem(&self.cert_pem, &self.key_pem)))
    }
}

fn pem_reason(error: &pem::Error) -> String {
    match error {
        pem::Error::NoItemsFound => "holds no PEM section".to_string(),
        other => format!("not valid PEM ({other})"),
    }
}

/// `error` and each of its sources, joined by `: `; the transport's own
/// message is only "transport error", its reason is in the sources.
pub fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        text.push_str(": ");
        text.push_str(&e.to_string());
        source = e.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_or_empty_file_is_named_with_the_reason() {
        let dir = std::env::temp_dir().join(format!("deog-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, b"").expect("write");
        let missing = dir.join("missing.pem");
        let error = TlsIdentity::from_files(&missing, &empty).expect_err("no file");
        let text = error.to_string();
        assert!(
            text.contains("missing.pem") && text.contains("certificate"),
            "{text}"
        );
        let error = TlsIdentity::from_files(&empty, &empty).expect_err("empty");
        let text = error.to_string();
        assert!(text.contains("empty.pem") && text.contains("no"), "{text}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn garbage_is_refused_in_memory_too() {
        let identity = TlsIdentity {
            cert_pem: b"-----BEGIN CERTIFICATE-----\n!!!\n-----END CERTIFICATE-----\n".to_vec(),
            key_pem: b"not a key".to_vec(),
        };
        let text = identity.check().expect_err("garbage").to_string();
        assert!(text.starts_with("TLS certificate PEM"), "{text}");
    }
}
