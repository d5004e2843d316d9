//! The crate's one error type.

use thiserror::Error;

/// What can go wrong reading or writing a map_server map. Every variant
/// names the file it is about (as the caller spelled its path) and, for the
/// YAML, the line (1-based) and the key.
#[derive(Debug, Error)]
pub enum MapFileError {
    /// A file could not be read or written (missing, unreadable, not UTF-8).
    #[error("{file}: {source}")]
    Io {
        /// The path, as given.
        file: String,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A YAML line is not of the flat `key: value` form.
    #[error("{file}:{line}: {reason}")]
    YamlSyntax {
        /// The YAML file.
        file: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        reason: String,
    },
    /// A YAML value is malformed or out of range.
    #[error("{file}:{line}: {field}: {reason}")]
    Yaml {
        /// The YAML file.
        file: String,
        /// 1-based line number of the key.
        line: usize,
        /// The key, e.g. `occupied_thresh`.
        field: String,
        /// What is wrong with its value, quoting it.
        reason: String,
    },
    /// A required YAML key is absent.
    #[error("{file}: missing key `{key}`")]
    MissingKey {
        /// The YAML file.
        file: String,
        /// The absent key.
        key: String,
    },
    /// The image does not start with the magic number of a grayscale PGM.
    #[error("{file}: not a grayscale PGM: magic {found:?}, expected \"P5\" or \"P2\"")]
    WrongMagic {
        /// The image file.
        file: String,
        /// The file's first two bytes, lossily as text.
        found: String,
    },
    /// The image ends before its header or its pixels are complete.
    #[error("{file}: truncated: {reason}")]
    Truncated {
        /// The image file.
        file: String,
        /// What was missing.
        reason: String,
    },
    /// A malformed image header or pixel value (not a number, zero size,
    /// maxval out of 1..=255, a pixel above maxval).
    #[error("{file}: {reason}")]
    BadImage {
        /// The image file.
        file: String,
        /// What is wrong.
        reason: String,
    },
    /// The pixel count disagrees with width x height: extra data in an
    /// image file, or a [`crate::MapImage`] whose `pixels` has the wrong
    /// length when written.
    #[error("{file}: size mismatch: {reason}")]
    SizeMismatch {
        /// The file read or about to be written.
        file: String,
        /// The two counts.
        reason: String,
    },
    /// An in-memory [`crate::MapImage`] field cannot be used for what was
    /// asked (written to a file, or turned into world coordinates).
    #[error("{field}: {reason}")]
    InvalidMap {
        /// The field, e.g. `origin`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl MapFileError {
    /// An [`MapFileError::Io`] for `file`.
    pub(crate) fn io(file: &str, source: std::io::Error) -> Self {
        Self::Io {
            file: file.to_owned(),
            source,
        }
    }

    /// An [`MapFileError::InvalidMap`].
    pub(crate) fn invalid_map(field: &str, reason: impl Into<String>) -> Self {
        Self::InvalidMap {
            field: field.to_owned(),
            reason: reason.into(),
        }
    }
}
