//! The store the servers under test share: a sled data directory (one
//! server), a private PostgreSQL the bench starts, or a PostgreSQL
//! database named by a URL.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use deog_harness::{os, proc_stats};
use deog_pg_cluster::{ClusterOptions, LocalCluster};

/// The database the bench creates on its private PostgreSQL.
const PRIVATE_DATABASE: &str = "deog_bench";

/// `--store` as given.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StoreChoice {
    /// A fresh sled data directory (`sled`).
    Sled,
    /// A private PostgreSQL the bench starts, durable (`postgres`).
    PrivatePostgres,
    /// A PostgreSQL database the bench is given (`postgres://…`); it
    /// should be fresh: the bench creates nothing but its maps and the
    /// baseline's table.
    PostgresUrl(String),
}

impl StoreChoice {
    /// Reads `--store`; `None` if it is none of the three.
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "sled" => Some(Self::Sled),
            "postgres" => Some(Self::PrivatePostgres),
            url if deog_server::store::is_postgres_url(url) => {
                Some(Self::PostgresUrl(url.to_string()))
            }
            _ => None,
        }
    }

    /// Whether several servers may share it.
    pub fn is_shared(&self) -> bool {
        !matches!(self, Self::Sled)
    }

    /// How the figures name it: `sled`, `postgres` (private) or
    /// `postgres-url` (a URL is not written out: it may hold a password).
    pub fn label(&self) -> &'static str {
        match self {
            Self::Sled => "sled",
            Self::PrivatePostgres => "postgres",
            Self::PostgresUrl(_) => "postgres-url",
        }
    }
}

/// The store of one run, open for as long as it lives.
pub(super) enum StoreUnderTest {
    /// A sled data directory.
    Sled {
        /// The directory; its parent is a temporary folder of the run.
        data: PathBuf,
    },
    /// A PostgreSQL database.
    Postgres {
        /// The database's URL.
        url: String,
        /// The private server, when the bench started it; stopped on drop.
        cluster: Option<LocalCluster>,
    },
}

impl StoreUnderTest {
    /// Prepares `choice`: a data directory under `work`, or a started
    /// private PostgreSQL with a new database, or the given database.
    pub fn open(choice: &StoreChoice, work: &Path) -> Result<Self> {
        Ok(match choice {
            StoreChoice::Sled => Self::Sled {
                data: work.join("data"),
            },
            StoreChoice::PrivatePostgres => {
                // PostgreSQL's own defaults: fsync and synchronous_commit
                // on, so an acknowledged update is on disk.
                let cluster = LocalCluster::start_with(&ClusterOptions::default())
                    .context("starting a private PostgreSQL")?;
                let url = cluster
                    .create_database(PRIVATE_DATABASE)
                    .context("creating the bench's database")?;
                Self::Postgres {
                    url,
                    cluster: Some(cluster),
                }
            }
            StoreChoice::PostgresUrl(url) => Self::Postgres {
                url: url.clone(),
                cluster: None,
            },
        })
    }

    /// The arguments of `deog server` that name this store.
    pub fn server_args(&self, cache_mb: u64) -> Vec<OsString> {
        let mut args = match self {
            Self::Sled { data } => {
                let mut args = os(&["--data"]);
                args.push(data.clone().into_os_string());
                args
            }
            // The URL, which may hold a password, goes in the
            // environment ([`StoreUnderTest::server_env`]).
            Self::Postgres { .. } => Vec::new(),
        };
        args.extend(os(&["--cache-mb", &cache_mb.to_string()]));
        args
    }

    /// The environment of a server on this store: `DEOG_STORE` on
    /// PostgreSQL.
    pub fn server_env(&self) -> Vec<(&'static str, &str)> {
        self.postgres_url()
            .map(|url| ("DEOG_STORE", url))
            .into_iter()
            .collect()
    }

    /// The database's URL, on PostgreSQL.
    pub fn postgres_url(&self) -> Option<&str> {
        match self {
            Self::Sled { .. } => None,
            Self::Postgres { url, .. } => Some(url),
        }
    }

    /// The folder whose files hold the data, when the bench knows it: the
    /// sled directory, or the private PostgreSQL's data folder (WAL
    /// included).
    pub fn data_dir(&self) -> Option<&Path> {
        match self {
            Self::Sled { data } => Some(data),
            Self::Postgres { cluster, .. } => cluster.as_ref().map(LocalCluster::data_dir),
        }
    }

    /// CPU seconds the private PostgreSQL's processes (the postmaster and
    /// its children: backends, WAL writer, checkpointer) have used; `None`
    /// when there is no private PostgreSQL. Processes that ended are not
    /// counted: the servers' connections live for the whole run.
    pub fn database_cpu_seconds(&self) -> Option<f64> {
        let Self::Postgres {
            cluster: Some(cluster),
            ..
        } = self
        else {
            return None;
        };
        let pid_file = std::fs::read_to_string(cluster.data_dir().join("postmaster.pid")).ok()?;
        let postmaster: u32 = pid_file.lines().next()?.trim().parse().ok()?;
        let mut total = proc_stats::cpu_seconds(postmaster).ok()?;
        for entry in std::fs::read_dir("/proc").ok()?.flatten() {
            let Some(pid) = entry
                .file_name()
                .to_str()
                .and_then(|n| n.parse::<u32>().ok())
            else {
                continue;
            };
            if parent_pid(pid) == Some(postmaster) {
                total += proc_stats::cpu_seconds(pid).unwrap_or(0.0);
            }
        }
        Some(total)
    }

    /// Fails unless the PostgreSQL database holds no maps: the bench's
    /// figures assume its maps start empty.
    pub async fn check_fresh(&self) -> Result<()> {
        let Some(url) = self.postgres_url() else {
            return Ok(());
        };
        let client = connect(url).await?;
        let has_maps: bool = client
            .query_one("SELECT to_regclass('maps') IS NOT NULL", &[])
            .await
            .context("checking that the database is fresh")?
            .get(0);
        let maps: i64 = if has_maps {
            client
                .query_one("SELECT count(*) FROM maps", &[])
                .await
                .context("counting the database's maps")?
                .get(0)
        } else {
            0
        };
        if maps > 0 {
            bail!("--store: the database already holds {maps} map(s); give the bench a fresh one");
        }
        Ok(())
    }

    /// `pg_database_size` of the PostgreSQL database, bytes.
    pub async fn database_bytes(&self) -> Result<Option<u64>> {
        let Some(url) = self.postgres_url() else {
            return Ok(None);
        };
        let client = connect(url).await?;
        let bytes: i64 = client
            .query_one("SELECT pg_database_size(current_database())", &[])
            .await
            .context("reading the database's size")?
            .get(0);
        Ok(Some(u64::try_from(bytes).unwrap_or(0)))
    }
}

/// A connection to `url` for the bench's own queries, driven on the
/// current runtime.
pub(super) async fn connect(url: &str) -> Result<tokio_postgres::Client> {
    let (client, connection) = tokio_postgres::connect(url, tokio_postgres::NoTls)
        .await
        .context("connecting to PostgreSQL")?;
    tokio::spawn(async move {
        if let Err(error) = connection.await {
            deog_harness::eprintln_above_bars!("bench's PostgreSQL connection: {error}");
        }
    });
    Ok(client)
}

/// Field 4 of `/proc/<pid>/stat`.
fn parent_pid(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let (_, rest) = stat.rsplit_once(')')?;
    rest.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn store_names_parse() {
        assert_eq!(StoreChoice::parse("sled"), Some(StoreChoice::Sled));
        assert_eq!(
            StoreChoice::parse("postgres"),
            Some(StoreChoice::PrivatePostgres)
        );
        assert_eq!(
            StoreChoice::parse("postgresql://deog@db/maps"),
            Some(StoreChoice::PostgresUrl("postgresql://deog@db/maps".into()))
        );
        assert_eq!(StoreChoice::parse("mysql://db/maps"), None);
        assert!(!StoreChoice::Sled.is_shared());
        assert!(StoreChoice::PrivatePostgres.is_shared());
    }
}
