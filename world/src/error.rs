//! The world crate's one error type.

use thiserror::Error;

/// What can go wrong building, reading or indexing a world.
#[derive(Debug, Error)]
pub enum WorldError {
    /// A world with neither a boundary nor an obstacle has no extent.
    #[error("world {0:?} has neither a boundary nor obstacles")]
    EmptyWorld(String),
    /// A world file (TOML) is malformed: bad syntax, an unknown key, or a
    /// value out of range.
    #[error("{file}:{line}: {field}: {reason}")]
    WorldFile {
        /// The file, as named to the parser.
        file: String,
        /// 1-based line number.
        line: usize,
        /// The key, with its place: `name`, `boundary`, `obstacle[1].points`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A world file could not be read.
    #[error("{file}: {source}")]
    ReadWorld {
        /// The file, as named.
        file: String,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A ROS map_server map (YAML + PGM) could not be read; the error names
    /// the file, and for the YAML the line and key.
    #[error(transparent)]
    MapFile(#[from] deog_mapfile::MapFileError),
    /// A world was asked for by a name that is neither an existing file
    /// nor a built-in world.
    #[error(
        "no world {spec:?}: give a file (.toml world or .yaml map_server map) or one of {}",
        .known.join(", ")
    )]
    UnknownWorld {
        /// What the user gave.
        spec: String,
        /// The built-in worlds' names.
        known: Vec<String>,
    },
    /// The world file a user named could not be loaded; the source says why.
    #[error("loading world {file}")]
    LoadFile {
        /// The file, as the user named it.
        file: String,
        /// What went wrong reading or parsing it.
        #[source]
        source: Box<WorldError>,
    },
    /// A built-in world could not be parsed; the source says why.
    #[error("loading built-in world {name}")]
    LoadBuiltIn {
        /// The built-in world's name.
        name: String,
        /// What is wrong with its text.
        #[source]
        source: Box<WorldError>,
    },
    /// A generated city too small for a single block.
    #[error("a city {side_px} cells a side has no room for a block")]
    CityTooSmall {
        /// The city's side, cells.
        side_px: u32,
    },
    /// A value given to the world crate is out of range or malformed.
    #[error("{field}: {reason}")]
    Invalid {
        /// The offending field, as the caller named it.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl WorldError {
    /// An [`WorldError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}
