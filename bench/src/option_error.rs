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
