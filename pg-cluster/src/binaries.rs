//! Where the PostgreSQL server binaries are.

use std::env;
use std::fs;
use std::path::{Path, PathBuf};

use crate::ClusterError;

/// The environment variable that names the binaries' folder, overriding the
/// search.
pub const BIN_DIR_VAR: &str = "DEOG_PG_BIN";

/// Where Debian installs one folder per major version.
const DEBIAN_ROOT: &str = "/usr/lib/postgresql";

/// The folder holding `initdb` and `postgres`.
///
/// In order: the folder named by `$DEOG_PG_BIN` (an error if it lacks the
/// binaries); the highest version's `/usr/lib/postgresql/<version>/bin`
/// holding both; the real folder (symbolic links resolved) of the `initdb`
/// found on `PATH`, if `postgres` is beside it.
pub fn binaries() -> Result<PathBuf, ClusterError> {
    if let Some(dir) = env::var_os(BIN_DIR_VAR) {
        let dir = PathBuf::from(dir);
        return if has_server(&dir) {
            Ok(dir)
        } else {
            Err(ClusterError::NotInstalled {
                searched: format!("${BIN_DIR_VAR}={}", dir.display()),
            })
        };
    }
    if let Some(dir) = debian_bin_dir(Path::new(DEBIAN_ROOT)) {
        return Ok(dir);
    }
    if let Some(dir) = path_bin_dir() {
        return Ok(dir);
    }
    Err(ClusterError::NotInstalled {
        searched: format!("{DEBIAN_ROOT}/*/bin and PATH"),
    })
}

/// The path of the tool `name` from `bin_dir`, or the bare name (found on
/// `PATH` when run) if it is not there. Debian puts client tools such as
/// `psql` in the same folder as the server, but other layouts may not.
pub(crate) fn tool(bin_dir: &Path, name: &str) -> PathBuf {
    let beside = bin_dir.join(name);
    if beside.is_file() {
        beside
    } else {
        PathBuf::from(name)
    }
}

/// Whether `dir` holds both `initdb` and `postgres`.
fn has_server(dir: &Path) -> bool {
    dir.join("initdb").is_file() && dir.join("postgres").is_file()
}

/// The highest-versioned `<root>/<version>/bin` holding the server.
fn debian_bin_dir(root: &Path) -> Option<PathBuf> {
    let mut versions: Vec<(Vec<u32>, PathBuf)> = fs::read_dir(root)
        .ok()?
        .filter_map(|entry| {
            let entry = entry.ok()?;
            let name = entry.file_name().into_string().ok()?;
            let version = parse_version(&name)?;
            let bin = entry.path().join("bin");
            has_server(&bin).then_some((version, bin))
        })
        .collect();
    versions.sort();
    versions.pop().map(|(_, bin)| bin)
}

/// "15" -> [15], "9.6" -> [9, 6]; anything else is not a version folder.
fn parse_version(name: &str) -> Option<Vec<u32>> {
    name.split('.').map(|part| part.parse().ok()).collect()
}

/// The real folder of `initdb` on `PATH`. Links are resolved because some
/// images link only the server binaries into `/usr/local/bin`, leaving
/// `psql` and `pg_isready` behind in the real folder.
fn path_bin_dir() -> Option<PathBuf> {
    let path = env::var_os("PATH")?;
    env::split_paths(&path)
        .map(|dir| dir.join("initdb"))
        .find(|initdb| initdb.is_file())
        .and_then(|initdb| fs::canonicalize(initdb).ok())
        .and_then(|initdb| initdb.parent().map(Path::to_path_buf))
        .filter(|dir| has_server(dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_sort_numerically() {
        let mut versions = [
            parse_version("9.6"),
            parse_version("15"),
            parse_version("10"),
        ];
        versions.sort();
        assert_eq!(versions[2], Some(vec![15]));
        assert_eq!(parse_version("common"), None);
    }

    #[test]
    fn the_highest_version_with_a_server_wins() {
        let root = tempfile::tempdir().unwrap();
        for (version, complete) in [("13", true), ("16", false), ("15", true)] {
            let bin = root.path().join(version).join("bin");
            fs::create_dir_all(&bin).unwrap();
            fs::write(bin.join("initdb"), "").unwrap();
            if complete {
                fs::write(bin.join("postgres"), "").unwrap();
            }
        }
        assert_eq!(
            debian_bin_dir(root.path()),
            Some(root.path().join("15").join("bin"))
        );
    }

    #[test]
    fn not_installed_says_what_to_install() {
        let error = ClusterError::NotInstalled {
            searched: "nowhere".into(),
        };
        assert!(
            error
                .to_string()
                .contains("install the PostgreSQL server (Debian: apt-get install postgresql)")
        );
    }
}
