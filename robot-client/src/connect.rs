//! Reaching the map server or the simulator: address, TLS, token, and
//! retry with backoff.

use crate::error::{ClientError, Peer, is_transient};
use deog_proto::v1::map_service_client::MapServiceClient;
use std::time::{Duration, Instant};
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
    /// `http://host:port`, `https://host:port`, or `host:port` (plain);
    /// several, separated by commas, reach map servers that share one
    /// store: calls are spread over them and go around those that are down.
    pub endpoint: String,
    /// Bearer token sent with every call.
    pub token: Option<String>,
    /// CA certificate (PEM) to trust for TLS; setting it turns TLS on.
    pub tls_ca_pem: Option<Vec<u8>>,
    /// Server name to check the certificate against (default: the host).
    pub tls_domain: Option<String>,
    /// Retry policy for connecting and for transient failures.
    pub retry: RetryPolicy,
    /// What is being reached, for messages and hints.
    pub peer: Peer,
    /// Give up connecting after this long, whatever the retry policy
    /// allows (one-shot commands); `None` follows the policy alone.
    pub connect_timeout: Option<Duration>,
    /// Say what it connects to and, while it cannot, why (at info and
    /// warn), as a person's command should; otherwise only at debug, for
    /// processes that start their own server and wait for it.
    pub announce: bool,
}

/// How long an unanswered first attempt goes before the client says it is
/// still waiting, and how often it repeats that it cannot reach the peer.
const FIRST_NOTICE: Duration = Duration::from_secs(1);
const NOTICE_EVERY: Duration = Duration::from_secs(5);

impl std::fmt::Debug for ClientConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClientConfig")
            .field("endpoint", &self.endpoint)
            .field("token", &self.token.as_ref().map(|_| "<set>"))
            .field("tls", &self.tls_ca_pem.is_some())
            .field("retry", &self.retry)
            .field("peer", &self.peer)
            .field("connect_timeout", &self.connect_timeout)
            .field("announce", &self.announce)
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

    /// The same, for the simulator.
    pub fn simulator(endpoint: impl Into<String>) -> Self {
        Self {
            peer: Peer::Simulator,
            ..Self::new(endpoint)
        }
    }

    /// Gives up connecting after `timeout` (a command that does one thing
    /// and ends).
    pub fn one_shot(mut self, timeout: Duration) -> Self {
        self.connect_timeout = Some(timeout);
        // A call that keeps failing for want of the server gives up as
        // soon: as many attempts as the backoff fits in the timeout.
        let mut attempts = 1;
        let mut waited = Duration::ZERO;
        while waited < timeout && attempts < 1000 {
            attempts += 1;
            waited += self.retry.delay(attempts);
        }
        self.retry.max_attempts = Some(attempts);
        self
    }

    /// Keeps trying for as long as it takes (a process that follows the
    /// server for hours rides out its restarts).
    pub fn retrying_forever(mut self) -> Self {
        self.retry.max_attempts = None;
        self.connect_timeout = None;
        self
    }

    /// The addresses `endpoint` names: one, or several separated by
    /// commas (servers sharing one store).
    fn addresses(&self) -> Vec<&str> {
        self.endpoint
            .split(',')
            .map(str::trim)
            .filter(|a| !a.is_empty())
            .collect()
    }

    fn url(&self, address: &str) -> String {
        if address.contains("://") {
            address.to_string()
        } else if self.tls_ca_pem.is_some() {
            format!("https://{address}")
        } else {
            format!("http://{address}")
        }
    }

    fn endpoints(&self) -> Result<Vec<Endpoint>, ClientError> {
        let addresses = self.addresses();
        if addresses.is_empty() {
            return Err(ClientError::Config("no server address given".into()));
        }
        addresses
            .into_iter()
            .map(|address| self.endpoint(address))
            .collect()
    }

    fn endpoint(&self, address: &str) -> Result<Endpoint, ClientError> {
        let mut endpoint = Endpoint::from_shared(self.url(address))
            .map_err(|e| ClientError::Config(format!("endpoint {address:?}: {e}")))?
            .connect_timeout(Duration::from_secs(5))
            .tcp_nodelay(true)
            .http2_keep_alive_interval(Duration::from_secs(20))
            .keep_alive_while_idle(true)
            // The servers' windows, for the same reason: h2 closes the
            // connection of a client whose unread small frames (the acks
            // and watch events it has not taken yet) outgrow its budget.
            .initial_stream_window_size(deog_proto::connection::STREAM_WINDOW_BYTES)
            .initial_connection_window_size(deog_proto::connection::CONNECTION_WINDOW_BYTES);
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

/// A channel to the first of `endpoints` that answers; given several, a
/// channel over all of them that spreads calls and routes around those
/// that are down (servers sharing one store), once one answered.
async fn reach(endpoints: &[Endpoint]) -> Result<Channel, tonic::transport::Error> {
    let mut last_error = None;
    for endpoint in endpoints {
        match endpoint.connect().await {
            Ok(channel) if endpoints.len() == 1 => return Ok(channel),
            Ok(_) => return Ok(Channel::balance_list(endpoints.iter().cloned())),
            Err(error) => last_error = Some(error),
        }
    }
    match last_error {
        Some(error) => Err(error),
        // `endpoints` is never empty; an empty list would wait here.
        None => std::future::pending().await,
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

/// Connects, retrying with backoff while the server is not up yet. Says
/// what it connects to; while the peer cannot be reached it says so within
/// a second and again every few seconds, with the reason and a hint.
pub async fn connect(config: &ClientConfig) -> Result<(Channel, TokenInterceptor), ClientError> {
    let endpoints = config.endpoints()?;
    let header = config
        .token
        .as_ref()
        .map(|t| {
            format!("Bearer {}", t.trim()).parse().map_err(|_| {
                ClientError::Config("the token holds characters not allowed in a header".into())
            })
        })
        .transpose()?;
    let peer = config.peer;
    let address = config.endpoint.as_str();
    // A hint names the address as `--listen` takes it: host and port.
    let listen = address.split_once("://").map_or(address, |(_, rest)| rest);
    let announce = config.announce;
    tell!(
        announce,
        info,
        "connecting to the {} at {address}",
        peer.name()
    );
    let started = Instant::now();
    let deadline = config.connect_timeout.map(|t| started + t);
    let mut last_notice: Option<Instant> = None;
    let mut last_reason: Option<String> = None;
    let mut attempt = 1;
    loop {
        // The last wait ends at the deadline, for one attempt there.
        let mut wait = config.retry.delay(attempt);
        if let Some(at) = deadline {
            wait = wait.min(at.saturating_duration_since(Instant::now()));
        }
        tokio::time::sleep(wait).await;
        let connecting = reach(&endpoints);
        tokio::pin!(connecting);
        let give_up = async {
            match deadline {
                Some(at) => tokio::time::sleep_until(at.into()).await,
                None => std::future::pending().await,
            }
        };
        tokio::pin!(give_up);
        // Until the deadline, with a word after a second of silence.
        let result = loop {
            let silent_too_long = async {
                match last_notice {
                    None => tokio::time::sleep_until((started + FIRST_NOTICE).into()).await,
                    Some(_) => std::future::pending().await,
                }
            };
            tokio::select! {
                result = &mut connecting => break Some(result),
                () = &mut give_up => break None,
                () = silent_too_long => {
                    tell!(announce, warn,
                        "no answer yet from the {} at {address}; still trying",
                        peer.name()
                    );
                    last_notice = Some(Instant::now());
                }
            }
        };
        let reason = match result {
            Some(Ok(channel)) => {
                if last_notice.is_some() {
                    tell!(
                        announce,
                        info,
                        "reached the {} at {address} after {:.1} s",
                        peer.name(),
                        started.elapsed().as_secs_f64()
                    );
                }
                return Ok((channel, TokenInterceptor { header }));
            }
            Some(Err(error)) => innermost_cause(&error),
            // Cut short by the deadline: the last real failure says more.
            None => last_reason
                .take()
                .unwrap_or_else(|| "no answer".to_string()),
        };
        tracing::debug!(attempt, %reason, endpoint = %address, "not reachable yet");
        let out_of_time = deadline.is_some_and(|at| Instant::now() >= at);
        if out_of_time || !config.retry.allows(attempt + 1) {
            return Err(ClientError::Unreachable {
                peer,
                endpoint: address.to_string(),
                attempts: attempt,
                waited_s: started.elapsed().as_secs_f64(),
                last_error: reason,
            });
        }
        if last_notice.is_none_or(|at| at.elapsed() >= NOTICE_EVERY) {
            tell!(
                announce,
                warn,
                "cannot reach the {} at {address} ({reason}): is `{}` running there? \
                 start one with `{} --listen {listen}`; retrying",
                peer.name(),
                peer.command(),
                peer.command()
            );
            last_notice = Some(Instant::now());
        }
        last_reason = Some(reason);
        attempt += 1;
    }
}

/// Logs at `$loud` when announcing, else at debug.
macro_rules! tell {
    ($announce:expr, $loud:ident, $($arg:tt)*) => {
        if $announce {
            tracing::$loud!($($arg)*);
        } else {
            tracing::debug!($($arg)*);
        }
    };
}
use tell;

/// The most specific cause of an error: what the operating system or the
/// TLS layer said, without the wrappers that repeat it.
fn innermost_cause(error: &dyn std::error::Error) -> String {
    let mut innermost = error;
    while let Some(source) = innermost.source() {
        innermost = source;
    }
    innermost.to_string()
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
    fn a_one_shot_client_retries_calls_for_about_its_timeout() {
        let config = ClientConfig::new("h:1").one_shot(Duration::from_secs(5));
        let attempts = config.retry.max_attempts.expect("bounded");
        let waited: Duration = (1..=attempts).map(|a| config.retry.delay(a)).sum();
        assert!(
            waited >= Duration::from_secs(5) && waited < Duration::from_secs(8),
            "{attempts} attempts wait {waited:?}"
        );
    }

    #[test]
    fn plain_addresses_get_a_scheme() {
        let plain = ClientConfig::new("127.0.0.1:1");
        assert_eq!(plain.url("127.0.0.1:1"), "http://127.0.0.1:1");
        let tls = ClientConfig {
            tls_ca_pem: Some(Vec::new()),
            ..ClientConfig::new("h:1")
        };
        assert_eq!(tls.url("h:1"), "https://h:1");
        assert_eq!(plain.url("https://h:2"), "https://h:2");
    }

    #[test]
    fn several_addresses_are_separated_by_commas() {
        let config = ClientConfig::new("a:1, http://b:2,,");
        assert_eq!(config.addresses(), ["a:1", "http://b:2"]);
        assert_eq!(config.endpoints().unwrap().len(), 2);
        let error = ClientConfig::new(" , ").endpoints().unwrap_err();
        assert!(error.to_string().contains("no server address"), "{error}");
    }
}
