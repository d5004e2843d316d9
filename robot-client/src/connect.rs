//! Reaching the map server or the simulator: address, TLS, token, and
//! retry with backoff.

use crate::error::{ClientError, is_transient};
use deog_proto::v1::map_service_client::MapServiceClient;
use std::time::Duration;
use tonic::metadata::MetadataValue;
use tonic::service::Interceptor;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint};

/// Exponential backoff between attempts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetryPolicy {
    /// Wait after the first failure.
    pub initial: Duration,
    /// Longest wait between attempts.
    pub max: Duration,
    /// Attempts before giving up; `None` retries for ever.
    pub max_attempts: Option<u32>,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            initial: Duration::from_millis(50),
            max: Duration::from_secs(2),
            max_attempts: Some(40),
        }
    }
}

impl RetryPolicy {
    /// The wait before attempt `attempt` (1-based; the first has none).
    pub fn delay(&self, attempt: u32) -> Duration {
        if attempt <= 1 {
            return Duration::ZERO;
        }
        let factor = 2u32.saturating_pow((attempt - 2).min(16));
        self.initial.saturating_mul(factor).min(self.max)
    }

    /// Whether `attempt` (1-based) may still be made.
    pub fn allows(&self, attempt: u32) -> bool {
        self.max_attempts.is_none_or(|max| attempt <= max)
    }
}

/// Where and how to reach the map server, or the simulator
/// ([`SimClient`](crate::SimClient) takes the same).
#[derive(Clone, Default)]
pub struct ClientConfig {
    /// `http://host:port`, `https://host:port`, or `host:port` (plain).
    pub endpoint: String,
    /// Bearer token sent with every call.
    pub token: Option<String>,
    /// CA certificate (PEM) to trust for TLS; setting it turns TLS on.
    pub tls_ca_pem: Option<Vec<u8>>,
    /// Server name to check the certificate against (default: the host).
    pub tls_domain: Option<String>,
    /// Retry policy for connecting and for transient failures.
    pub retry: RetryPolicy,
}

impl std::fmt::Debug for ClientConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClientConfig")
            .field("endpoint", &self.endpoint)
            .field("token", &self.token.as_ref().map(|_| "<set>"))
            .field("tls", &self.tls_ca_pem.is_some())
            .field("retry", &self.retry)
            .finish()
    }
}

impl ClientConfig {
    /// A plain connection to `endpoint` with default retries.
    pub fn new(endpoint: impl Into<String>) -> Self {
        Self {
            endpoint: endpoint.into(),
            ..Self::default()
        }
    }

    fn url(&self) -> String {
        if self.endpoint.contains("://") {
            self.endpoint.clone()
        } else if self.tls_ca_pem.is_some() {
            format!("https://{}", self.endpoint)
        } else {
            format!("http://{}", self.endpoint)
        }
    }

    fn endpoint(&self) -> Result<Endpoint, ClientError> {
        let mut endpoint = Endpoint::from_shared(self.url())
            .map_err(|e| ClientError::Config(format!("endpoint {:?}: {e}", self.endpoint)))?
            .connect_timeout(Duration::from_secs(5))
            .tcp_nodelay(true)
            .http2_keep_alive_interval(Duration::from_secs(20))
            .keep_alive_while_idle(true);
        if let Some(ca) = &self.tls_ca_pem {
            let mut tls = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca));
            if let Some(domain) = &self.tls_domain {
                tls = tls.domain_name(domain.clone());
            }
            endpoint = endpoint
                .tls_config(tls)
                .map_err(|e| ClientError::Config(format!("TLS: {e}")))?;
        }
        Ok(endpoint)
    }
}

/// Adds the bearer token to every call.
#[derive(Clone)]
pub struct TokenInterceptor {
    header: Option<MetadataValue<tonic::metadata::Ascii>>,
}

impl std::fmt::Debug for TokenInterceptor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TokenInterceptor").finish_non_exhaustive()
    }
}

impl Interceptor for TokenInterceptor {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(header) = &self.header {
            request
                .metadata_mut()
                .insert("authorization", header.clone());
        }
        Ok(request)
    }
}

/// The generated map-service client with the token interceptor.
pub type RawMapClient = MapServiceClient<InterceptedService<Channel, TokenInterceptor>>;

/// Connects, retrying with backoff while the server is not up yet.
pub async fn connect(config: &ClientConfig) -> Result<(Channel, TokenInterceptor), ClientError> {
    let endpoint = config.endpoint()?;
    let header = config
        .token
        .as_ref()
        .map(|t| {
            format!("Bearer {}", t.trim()).parse().map_err(|_| {
                ClientError::Config("the token holds characters not allowed in a header".into())
            })
        })
        .transpose()?;
    let mut attempt = 1;
    loop {
        tokio::time::sleep(config.retry.delay(attempt)).await;
        match endpoint.connect().await {
            Ok(channel) => return Ok((channel, TokenInterceptor { header })),
            Err(error) => {
                let last_error = error_chain(&error);
                tracing::debug!(attempt, %last_error, endpoint = %config.endpoint, "server not reachable yet");
                if !config.retry.allows(attempt + 1) {
                    return Err(ClientError::Unreachable {
                        endpoint: config.endpoint.clone(),
                        attempts: attempt,
                        last_error,
                    });
                }
            }
        }
        attempt += 1;
    }
}

fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        text.push_str(": ");
        text.push_str(&e.to_string());
        source = e.source();
    }
    text
}

/// Runs `call` until it succeeds, fails for a reason retrying cannot fix, or
/// the policy runs out.
pub async fn with_retry<T, F, Fut>(policy: &RetryPolicy, mut call: F) -> Result<T, ClientError>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, tonic::Status>>,
{
    let mut attempt = 1;
    loop {
        tokio::time::sleep(policy.delay(attempt)).await;
        match call().await {
            Ok(value) => return Ok(value),
            Err(status) if is_transient(&status) && policy.allows(attempt + 1) => {
                tracing::debug!(attempt, %status, "transient failure; retrying");
            }
            Err(status) => return Err(status.into()),
        }
        attempt += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_up_to_the_cap() {
        let policy = RetryPolicy {
            initial: Duration::from_millis(100),
            max: Duration::from_millis(500),
            max_attempts: Some(5),
        };
        let delays: Vec<u64> = (1..=6)
            .map(|a| policy.delay(a).as_millis() as u64)
            .collect();
        assert_eq!(delays, [0, 100, 200, 400, 500, 500]);
        assert!(policy.allows(5));
        assert!(!policy.allows(6));
    }

    #[test]
    fn plain_addresses_get_a_scheme() {
        assert_eq!(ClientConfig::new("127.0.0.1:1").url(), "http://127.0.0.1:1");
        let tls = ClientConfig {
            tls_ca_pem: Some(Vec::new()),
            ..ClientConfig::new("h:1")
        };
        assert_eq!(tls.url(), "https://h:1");
        assert_eq!(ClientConfig::new("https://h:2").url(), "https://h:2");
    }
}
