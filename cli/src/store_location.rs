//! Where a store lives: a data directory (sled, the default) or a
//! PostgreSQL database named by a URL. Shared by `deog server` and
//! `deog copy`.

use anyhow::{Result, anyhow};
use deog_harness::redact::url_without_password as without_password;
use deog_server::store::is_postgres_url;
use deog_server::{PostgresConfig, PostgresStore, SledConfig, SledStore};
use std::path::PathBuf;

/// A store's place, as a user names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StoreLocation {
    /// A sled data directory.
    Directory(PathBuf),
    /// A PostgreSQL connection string (`postgres://…` or `postgresql://…`).
    Postgres(String),
}

impl StoreLocation {
    /// Reads `text`: a `postgres://` or `postgresql://` URL names a
    /// database, anything else a directory.
    pub fn parse(text: &str) -> Result<Self> {
        if is_postgres_url(text) {
            return Ok(Self::Postgres(text.to_string()));
        }
        if let Some((scheme, _)) = text.split_once("://") {
            return Err(anyhow!(
                "{text}: stores are data directories or postgres:// URLs, not {scheme}://"
            ));
        }
        Ok(Self::Directory(PathBuf::from(text)))
    }

    /// How it may be shown in logs: a URL without its password.
    pub fn describe(&self) -> String {
        match self {
            Self::Directory(path) => path.display().to_string(),
            Self::Postgres(url) => without_password(url),
        }
    }

    /// Opens a PostgreSQL store, creating or migrating its schema.
    pub fn open_postgres(url: &str, flag: &str) -> Result<PostgresStore> {
        PostgresStore::open(&PostgresConfig::new(url))
            .map_err(|error| anyhow!("{flag} {}: {error}", without_password(url)))
    }

    /// Opens a sled store in `path`.
    pub fn open_sled(path: &std::path::Path, cache_mb: u64, flag: &str) -> Result<SledStore> {
        SledStore::open(&SledConfig {
            path: path.to_path_buf(),
            cache_bytes: cache_mb << 20,
        })
        .map_err(|error| {
            let text = error.to_string();
            if text.contains("could not acquire lock") {
                anyhow!(
                    "{flag} {}: the store is in use (is a deog server running on it? stop it first)",
                    path.display()
                )
            } else {
                anyhow!("{flag} {}: {text}", path.display())
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_name_databases_and_anything_else_a_directory() {
        assert_eq!(
            StoreLocation::parse("postgres://deog@db/maps").unwrap(),
            StoreLocation::Postgres("postgres://deog@db/maps".into())
        );
        assert_eq!(
            StoreLocation::parse("deog-data").unwrap(),
            StoreLocation::Directory("deog-data".into())
        );
        let error = StoreLocation::parse("mysql://db/maps").unwrap_err();
        assert!(error.to_string().contains("not mysql://"), "{error}");
    }

    #[test]
    fn a_password_never_reaches_the_log() {
        let location = StoreLocation::parse("postgres://deog:s3cret@a,b:5433/maps?x=1").unwrap();
        assert_eq!(location.describe(), "postgres://deog:***@a,b:5433/maps?x=1");
        let location = StoreLocation::parse("postgresql://deog@db/maps").unwrap();
        assert_eq!(location.describe(), "postgresql://deog@db/maps");
    }
}
