//! The one error of the benchmarks' option checks.

/// An option out of its range, or options that do not go together: the
/// message names the flag, as the person typed it, and what it takes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct OptionError {
    /// The flag at fault ("--cache-mb").
    pub flag: &'static str,
    /// The whole message, for the person at the terminal.
    pub message: String,
}

/// `Ok` when `ok`, else an [`OptionError`] blaming `flag` with the message
/// `message` makes (only made when needed).
pub(crate) fn require(
    ok: bool,
    flag: &'static str,
    message: impl FnOnce() -> String,
) -> Result<(), OptionError> {
    if ok {
        Ok(())
    } else {
        Err(OptionError {
            flag,
            message: message(),
        })
    }
}

/// `Ok` unless `file`, given with `flag`, names a folder that does not
/// exist: a figures file that cannot be written fails before the run, not
/// after it.
pub(crate) fn require_folder_of(
    file: Option<&std::path::Path>,
    flag: &'static str,
) -> Result<(), OptionError> {
    match file.and_then(|f| f.parent().map(|parent| (f, parent))) {
        Some((file, parent)) if !parent.as_os_str().is_empty() => {
            require(parent.is_dir(), flag, || {
                format!(
                    "{flag} {}: folder {} does not exist",
                    file.display(),
                    parent.display()
                )
            })
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn a_file_in_a_missing_folder_is_refused_naming_the_flag() {
        assert!(require_folder_of(None, "--json").is_ok());
        assert!(require_folder_of(Some(Path::new("figures.json")), "--json").is_ok());
        let here = std::env::temp_dir().join("figures.json");
        assert!(require_folder_of(Some(&here), "--json").is_ok());
        let error = require_folder_of(Some(Path::new("/no/such/folder/f.json")), "--out-json")
            .expect_err("no such folder");
        assert_eq!(error.flag, "--out-json");
        assert_eq!(
            error.message,
            "--out-json /no/such/folder/f.json: folder /no/such/folder does not exist"
        );
    }
}
