//! Connections to PostgreSQL, pooled, with their prepared statements, and
//! the one place database errors become [`StoreError`]s.
//!
//! The connections' sockets are driven by a small runtime of the store's
//! own; a statement is sent from the calling thread, which parks until the
//! answer comes. That keeps the store synchronous, as its contract is, and
//! usable from any thread, inside an async handler or not.

use super::PostgresConfig;
use crate::error::StoreError;
use crate::store::change::{StoreChange, decode_changes};
use std::collections::HashMap;
use std::future::Future;
use std::sync::{Arc, Condvar, Mutex};
use std::task::{Context, Poll, Wake, Waker};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_postgres::AsyncMessage;
use tokio_postgres::error::SqlState;
use tokio_postgres::types::ToSql;
use tokio_postgres::{Client, NoTls, Row, Statement};

/// How long a connection attempt may take when the connection string does
/// not say (`connect_timeout`).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// Waits on this thread for `future`, parking between polls. The futures
/// it is given only talk to connection tasks over channels, so they need
/// no runtime of their own.
fn block_on<F: Future>(future: F) -> F::Output {
    struct Unpark(std::thread::Thread);
    impl Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
    }
    let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut context = Context::from_waker(&waker);
    let mut future = std::pin::pin!(future);
    loop {
        if let Poll::Ready(output) = future.as_mut().poll(&mut context) {
            return output;
        }
        std::thread::park();
    }
}

/// The store's connections.
pub(super) struct Pool {
    config: tokio_postgres::Config,
    /// Names this store's changes, so that its own notifications are
    /// told apart from other servers'.
    origin: String,
    runtime: Option<tokio::runtime::Runtime>,
    idle: Mutex<Vec<Conn>>,
    max_idle: usize,
    open: Arc<OpenCount>,
    /// Commits notify, and the listener listens; otherwise it polls.
    notify: bool,
}

impl Drop for Pool {
    fn drop(&mut self) {
        if let Some(runtime) = self.runtime.take() {
            // Dropping a runtime may not block inside another one.
            runtime.shutdown_background();
        }
    }
}

impl Pool {
    pub(super) fn new(config: &PostgresConfig) -> Result<Self, StoreError> {
        let mut parsed: tokio_postgres::Config = config.url.parse().map_err(|e| {
            StoreError::invalid(
                "store",
                format!("not a PostgreSQL connection string: {}", worded(&e)),
            )
        })?;
        if parsed.get_connect_timeout().is_none() {
            parsed.connect_timeout(CONNECT_TIMEOUT);
        }
        if parsed.get_application_name().is_none() {
            parsed.application_name("deog");
        }
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("deog-postgres")
            .enable_all()
            .build()
            .map_err(|e| StoreError::Backend(format!("cannot start the database runtime: {e}")))?;
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        Ok(Self {
            origin: format!("{}-{nanos:x}", std::process::id()),
            config: parsed,
            runtime: Some(runtime),
            idle: Mutex::new(Vec::new()),
            max_idle: config.pool_size.max(1),
            open: Arc::new(OpenCount {
                count: Mutex::new(0),
                freed: Condvar::new(),
                limit: config.max_connections.max(1),
            }),
            notify: true,
        })
    }

    /// What names this store's changes.
    pub(super) fn origin(&self) -> &str {
        &self.origin
    }

    /// Follows the changes other servers notify on `channel`: a task on
    /// the store's runtime listens on a connection of its own, connects
    /// again whenever it is lost, and sends [`StoreChange::Resync`] each
    /// time it starts listening (what came meanwhile was not heard). Ends
    /// when the receiver is dropped.
    pub(super) fn listen(&self, channel: &'static str) -> mpsc::Receiver<StoreChange> {
        let (sender, receiver) = mpsc::channel(FEED_BUFFER);
        if let Some(runtime) = &self.runtime {
            if self.notify {
                runtime.spawn(listen(
                    self.config.clone(),
                    channel,
                    self.origin.clone(),
                    sender,
                ));
            } else {
                runtime.spawn(poll(sender));
            }
        }
        receiver
    }

    /// Whether commits notify the other servers (the database has
    /// `NOTIFY`).
    pub(super) fn notifies(&self) -> bool {
        self.notify
    }

    /// Finds whether the database has `NOTIFY`, unless told to poll.
    pub(super) fn probe_notify(&mut self, conn: &mut Conn, poll: bool) -> Result<(), StoreError> {
        if poll {
            self.notify = false;
            return Ok(());
        }
        match block_on(
            conn.client
                .simple_query("SELECT pg_notify('deog_probe', '')"),
        ) {
            Ok(_) => self.notify = true,
            Err(error)
                if error.code().is_some_and(|code| {
                    *code == SqlState::UNDEFINED_FUNCTION
                        || *code == SqlState::FEATURE_NOT_SUPPORTED
                }) =>
            {
                tracing::warn!(
                    error = %worded(&error),
                    "the database has no NOTIFY: watchers hear other servers' changes by polling, once a second"
                );
                self.notify = false;
            }
            Err(error) => return Err(store_error(error)),
        }
        Ok(())
    }

    /// The database and hosts, without credentials.
    pub(super) fn describe(&self) -> String {
        let hosts: Vec<String> = self
            .config
            .get_hosts()
            .iter()
            .map(|host| match host {
                tokio_postgres::config::Host::Tcp(name) => name.clone(),
                tokio_postgres::config::Host::Unix(path) => path.display().to_string(),
            })
            .collect();
        format!(
            "{} on {}",
            self.config.get_dbname().unwrap_or("(default)"),
            hosts.join(",")
        )
    }

    /// An idle connection, or a new one while fewer than the limit are
    /// open; otherwise waits for one to come back, up to [`BUSY_WAIT`].
    pub(super) fn get(&self) -> Result<Conn, StoreError> {
        self.take(true)
    }

    /// A connection for the writer, which never waits behind readers: it
    /// may open one past the limit (one writer per server).
    pub(super) fn get_for_writer(&self) -> Result<Conn, StoreError> {
        self.take(false)
    }

    fn take(&self, within_limit: bool) -> Result<Conn, StoreError> {
        let deadline = std::time::Instant::now() + BUSY_WAIT;
        loop {
            let conn = self.idle.lock().ok().and_then(|mut idle| idle.pop());
            match conn {
                Some(conn) if conn.client.is_closed() => continue,
                Some(conn) => return Ok(conn),
                None => {}
            }
            let mut open = self.open.count.lock().unwrap_or_else(|p| p.into_inner());
            if !within_limit || *open < self.open.limit {
                *open += 1;
                drop(open);
                let permit = Permit(self.open.clone());
                return self.connect(permit);
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return Err(StoreError::Unavailable(format!(
                    "all {} connections to PostgreSQL stayed busy for {} s",
                    self.open.limit,
                    BUSY_WAIT.as_secs()
                )));
            }
            // Woken when a connection comes back or closes; the idle list
            // is looked at again either way.
            let wait = (deadline - now).min(Duration::from_millis(100));
            let _ = self
                .open
                .freed
                .wait_timeout(open, wait)
                .map_err(|p| p.into_inner());
        }
    }

    /// Returns a connection for reuse, unless it broke.
    pub(super) fn put(&self, conn: Conn) {
        if conn.client.is_closed() {
            return;
        }
        if let Ok(mut idle) = self.idle.lock()
            && idle.len() < self.max_idle
        {
            idle.push(conn);
        }
        self.open.freed.notify_one();
    }

    /// Drops every idle connection (after a failure that may have broken
    /// them all, such as a failover).
    pub(super) fn clear(&self) {
        if let Ok(mut idle) = self.idle.lock() {
            idle.clear();
        }
    }

    fn connect(&self, permit: Permit) -> Result<Conn, StoreError> {
        let runtime = self
            .runtime
            .as_ref()
            .ok_or_else(|| StoreError::Unavailable("the store is closing".into()))?;
        let config = self.config.clone();
        let (sender, receiver) = std::sync::mpsc::sync_channel(1);
        runtime.spawn(async move {
            match config.connect(NoTls).await {
                Ok((client, connection)) => {
                    let _ = sender.send(Ok(client));
                    if let Err(error) = connection.await {
                        tracing::debug!(error = %worded(&error), "database connection ended");
                    }
                }
                Err(error) => {
                    let _ = sender.send(Err(error));
                }
            }
        });
        let client = receiver
            .recv()
            .map_err(|_| StoreError::Unavailable("the database runtime stopped".into()))?
            .map_err(|error| {
                StoreError::Unavailable(format!(
                    "cannot connect to PostgreSQL ({}): {}",
                    self.describe(),
                    worded(&error)
                ))
            })?;
        Ok(Conn {
            client,
            statements: HashMap::new(),
            _permit: permit,
        })
    }
}

/// How long a call waits for a connection when all are busy.
const BUSY_WAIT: Duration = Duration::from_secs(30);

/// The connections open, against the limit.
struct OpenCount {
    count: Mutex<usize>,
    freed: Condvar,
    limit: usize,
}

/// One open connection's place in the count, given back when it closes.
struct Permit(Arc<OpenCount>);

impl Drop for Permit {
    fn drop(&mut self) {
        let mut count = self.0.count.lock().unwrap_or_else(|p| p.into_inner());
        *count = count.saturating_sub(1);
        drop(count);
        self.0.freed.notify_one();
    }
}

/// Changes waiting for the server to relay them.
const FEED_BUFFER: usize = 4096;
/// How long the listener waits before connecting again.
const LISTEN_RETRY: Duration = Duration::from_secs(1);

async fn listen(
    config: tokio_postgres::Config,
    channel: &'static str,
    origin: String,
    sender: mpsc::Sender<StoreChange>,
) {
    let mut attempts = 0u64;
    while !sender.is_closed() {
        attempts += 1;
        match config.connect(NoTls).await {
            Ok((client, mut connection)) => {
                let (payloads, mut received) = mpsc::unbounded_channel();
                let driver = tokio::spawn(async move {
                    while let Some(message) =
                        std::future::poll_fn(|cx| connection.poll_message(cx)).await
                    {
                        match message {
                            Ok(AsyncMessage::Notification(note)) => {
                                if payloads.send(note.payload().to_string()).is_err() {
                                    break;
                                }
                            }
                            Ok(_) => {}
                            Err(error) => {
                                tracing::warn!(error = %worded(&error), "lost the connection that hears other servers' changes");
                                break;
                            }
                        }
                    }
                });
                match client.batch_execute(&format!("LISTEN {channel}")).await {
                    Ok(()) => {
                        if attempts > 1 {
                            tracing::info!("hearing other servers' changes again");
                        }
                        attempts = 0;
                        if sender.send(StoreChange::Resync).await.is_err() {
                            return;
                        }
                        while let Some(payload) = received.recv().await {
                            let changes = match decode_changes(&payload) {
                                Ok((from, _)) if from == origin => continue,
                                Ok((_, changes)) => changes,
                                Err(line) => {
                                    tracing::warn!(%line, "a change notification could not be read; resyncing");
                                    vec![StoreChange::Resync]
                                }
                            };
                            for change in changes {
                                if sender.send(change).await.is_err() {
                                    return;
                                }
                            }
                        }
                    }
                    Err(error) => {
                        tracing::warn!(error = %worded(&error), "cannot listen for other servers' changes");
                    }
                }
                driver.abort();
                drop(client);
            }
            Err(error) => {
                if attempts == 1 || attempts % 60 == 0 {
                    tracing::warn!(error = %worded(&error), attempts, "cannot connect to hear other servers' changes; retrying every second");
                }
            }
        }
        tokio::time::sleep(LISTEN_RETRY).await;
    }
}

/// How often a store without `NOTIFY` asks for a look at what moved.
const POLL_INTERVAL: Duration = Duration::from_secs(1);

async fn poll(sender: mpsc::Sender<StoreChange>) {
    // The first poll at once: it is the look later ones compare with.
    loop {
        if sender.send(StoreChange::Poll).await.is_err() {
            return;
        }
        tokio::time::sleep(POLL_INTERVAL).await;
    }
}

/// One connection and the statements prepared on it.
pub(super) struct Conn {
    client: Client,
    statements: HashMap<&'static str, Statement>,
    _permit: Permit,
}

impl Conn {
    fn statement(&mut self, sql: &'static str) -> Result<Statement, StoreError> {
        if let Some(statement) = self.statements.get(sql) {
            return Ok(statement.clone());
        }
        let statement = block_on(self.client.prepare(sql)).map_err(store_error)?;
        self.statements.insert(sql, statement.clone());
        Ok(statement)
    }

    /// Runs a query and returns all its rows.
    pub(super) fn query(
        &mut self,
        sql: &'static str,
        params: &[&(dyn ToSql + Sync)],
    ) -> Result<Vec<Row>, StoreError> {
        let statement = self.statement(sql)?;
        block_on(self.client.query(&statement, params)).map_err(store_error)
    }

    /// Runs a statement and returns how many rows it changed.
    pub(super) fn execute(
        &mut self,
        sql: &'static str,
        params: &[&(dyn ToSql + Sync)],
    ) -> Result<u64, StoreError> {
        let statement = self.statement(sql)?;
        block_on(self.client.execute(&statement, params)).map_err(store_error)
    }

    /// Runs statements without parameters (BEGIN, COMMIT, the schema).
    pub(super) fn batch(&mut self, sql: &str) -> Result<(), StoreError> {
        block_on(self.client.batch_execute(sql)).map_err(store_error)
    }
}

/// A database error in words: the server's message where there is one.
pub(super) fn worded(error: &tokio_postgres::Error) -> String {
    match error.as_db_error() {
        Some(db) => match db.detail() {
            Some(detail) => format!("{} ({detail})", db.message()),
            None => db.message().to_string(),
        },
        None => {
            let mut text = error.to_string();
            let mut source = std::error::Error::source(error);
            while let Some(cause) = source {
                text.push_str(": ");
                text.push_str(&cause.to_string());
                source = cause.source();
            }
            text
        }
    }
}

/// The one mapping of database errors: a lost connection or a server that
/// cannot take writes now is unavailable (the writer recovers); a deadlock
/// or serialization failure is a conflict (the group is applied again); a
/// full disk is out of space; anything else is the backend's failure.
pub(super) fn store_error(error: tokio_postgres::Error) -> StoreError {
    let text = worded(&error);
    let Some(code) = error.code() else {
        // No SQLSTATE: the connection itself failed.
        return StoreError::Unavailable(format!("PostgreSQL connection lost: {text}"));
    };
    if *code == SqlState::T_R_DEADLOCK_DETECTED || *code == SqlState::T_R_SERIALIZATION_FAILURE {
        StoreError::Conflict(text)
    } else if *code == SqlState::DISK_FULL {
        StoreError::OutOfSpace(text)
    } else if code.code().starts_with("08")
        || code.code().starts_with("57P")
        || *code == SqlState::READ_ONLY_SQL_TRANSACTION
        || *code == SqlState::TOO_MANY_CONNECTIONS
    {
        // Connection exceptions, a server shutting down, or a standby not
        // yet promoted.
        StoreError::Unavailable(text)
    } else {
        StoreError::Backend(format!("PostgreSQL: {text}"))
    }
}
