//! The settings a server starts with.

/// Settings for [`crate::LocalCluster::start_with`].
///
/// The defaults are PostgreSQL's own durability defaults on a free port.
/// Benchmarks that do not care about crashes can turn `fsync` and
/// `synchronous_commit` off for speed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClusterOptions {
    /// The server's `synchronous_commit` setting (default on).
    pub synchronous_commit: bool,
    /// The server's `fsync` setting (default on). Turned off, a
    /// [`crate::LocalCluster::kill`] can still be survived (the page cache
    /// holds the writes), but a machine crash cannot.
    pub fsync: bool,
    /// Further `name = value` server settings, passed as `-c name=value`
    /// after the ones above, so they win.
    pub extra_settings: Vec<(String, String)>,
    /// A fixed TCP port on 127.0.0.1; `None` picks a free one.
    pub port: Option<u16>,
}

impl Default for ClusterOptions {
    fn default() -> Self {
        Self {
            synchronous_commit: true,
            fsync: true,
            extra_settings: Vec::new(),
            port: None,
        }
    }
}
