//! A first `initdb`'s data folder kept as a template, so later clusters of
//! the same server binaries copy it rather than run `initdb` again: a test
//! suite under cargo-nextest starts a server per test, and `initdb` takes
//! over a second where a copy takes a tenth of that.
//!
//! The template lives in the system's temporary folder (`/tmp` when the
//! server runs as `postgres`), one per server binaries and user, named
//! `deog-pg-template-...`. It is written whole under another name and
//! renamed into place, so a reader sees it complete or not at all; one that
//! lacks the files every data folder has is passed over. It is only a
//! shortcut: any failure to read or write it falls back to `initdb`.

use std::fs;
use std::path::{Path, PathBuf};

use crate::process::{self, Runner};

/// Raised whenever what `initdb` is run with changes, so that no template
/// made with other arguments is copied.
const VERSION: u32 = 1;

/// Where the template of the binaries in `bin_dir` is kept for the user
/// the servers run as.
pub(crate) fn dir(bin_dir: &Path, runner: &Runner) -> PathBuf {
    let binaries: String = bin_dir
        .to_string_lossy()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    let (base, user) = if runner.as_server_user {
        (PathBuf::from("/tmp"), "postgres".to_string())
    } else {
        let uid = process::effective_uid().map_or("unknown".into(), |uid| uid.to_string());
        (std::env::temp_dir(), format!("uid{uid}"))
    };
    base.join(format!(
        "deog-pg-template{}-{user}-v{VERSION}",
        binaries.trim_end_matches('-')
    ))
}

/// Whether `dir` holds what every initialised data folder has.
fn is_complete(dir: &Path) -> bool {
    dir.join("PG_VERSION").is_file() && dir.join("global").join("pg_control").is_file()
}

/// Copies the template `template` to `data_dir` (which must not exist yet)
/// as the servers' user; false, with nothing left behind, if there is no
/// complete template or the copy fails.
pub(crate) fn copy_into(template: &Path, data_dir: &Path, runner: &Runner) -> bool {
    if !is_complete(template) {
        return false;
    }
    match copy(template, data_dir, runner) {
        Ok(()) => true,
        Err(error) => {
            tracing::debug!(template = %template.display(), %error, "the cluster template could not be copied; running initdb");
            let _ = fs::remove_dir_all(data_dir);
            false
        }
    }
}

/// Keeps a copy of the freshly initialised `data_dir` as the template, if
/// none is there yet. Best effort: a failure only costs later clusters an
/// `initdb`.
pub(crate) fn keep(data_dir: &Path, template: &Path, runner: &Runner) {
    if is_complete(template) {
        return;
    }
    let mut partial = template.as_os_str().to_owned();
    partial.push(format!(".partial-{}", std::process::id()));
    let partial = PathBuf::from(partial);
    let _ = fs::remove_dir_all(&partial);
    let kept = copy(data_dir, &partial, runner).is_ok() && fs::rename(&partial, template).is_ok();
    if !kept {
        // Another process may have put its template in place first.
        let _ = fs::remove_dir_all(&partial);
    }
}

/// `cp -a from to` as the servers' user, keeping the modes PostgreSQL
/// checks (a data folder must be the server user's alone).
fn copy(from: &Path, to: &Path, runner: &Runner) -> Result<(), crate::ClusterError> {
    let mut command = runner.server(Path::new("cp"));
    command.arg("-a").arg(from).arg(to);
    process::run(&mut command).map(drop)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Copies as this process's user, whoever that is: the folders below
    /// are this test's own.
    fn plain() -> Runner {
        Runner {
            as_server_user: false,
        }
    }

    /// A folder with the files every initialised data folder has.
    fn data_folder(path: &Path) {
        fs::create_dir_all(path.join("global")).unwrap();
        fs::write(path.join("PG_VERSION"), "15\n").unwrap();
        fs::write(path.join("global").join("pg_control"), [7u8; 16]).unwrap();
    }

    #[test]
    fn a_template_is_kept_once_and_copied_whole() {
        let temp = tempfile::tempdir().unwrap();
        let (data, template) = (temp.path().join("data"), temp.path().join("template"));
        data_folder(&data);
        keep(&data, &template, &plain());
        assert!(is_complete(&template));

        // A second keep leaves the first template alone and nothing else.
        fs::write(data.join("PG_VERSION"), "16\n").unwrap();
        keep(&data, &template, &plain());
        assert_eq!(
            fs::read_to_string(template.join("PG_VERSION")).unwrap(),
            "15\n"
        );
        assert_eq!(fs::read_dir(temp.path()).unwrap().count(), 2);

        let copy = temp.path().join("copy");
        assert!(copy_into(&template, &copy, &plain()));
        assert_eq!(
            fs::read(copy.join("global").join("pg_control")).unwrap(),
            [7u8; 16]
        );
    }

    #[test]
    fn an_incomplete_template_is_passed_over() {
        let temp = tempfile::tempdir().unwrap();
        let template = temp.path().join("template");
        fs::create_dir_all(&template).unwrap();
        fs::write(template.join("PG_VERSION"), "15\n").unwrap();
        let data = temp.path().join("data");
        assert!(!copy_into(&template, &data, &plain()));
        assert!(!data.exists());
        assert!(!copy_into(&temp.path().join("none"), &data, &plain()));
    }

    #[test]
    fn templates_are_named_by_binaries_and_user() {
        let root = Runner {
            as_server_user: true,
        };
        let dir15 = dir(Path::new("/usr/lib/postgresql/15/bin"), &root);
        assert_eq!(
            dir15,
            PathBuf::from(format!(
                "/tmp/deog-pg-template-usr-lib-postgresql-15-bin-postgres-v{VERSION}"
            ))
        );
        assert_ne!(dir15, dir(Path::new("/usr/lib/postgresql/16/bin"), &root));
        assert_ne!(
            dir15,
            dir(Path::new("/usr/lib/postgresql/15/bin"), &plain())
        );
    }
}
