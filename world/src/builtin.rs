//! The worlds built into every program, and the one way a user names a
//! world: a built-in name, a world file (`.toml`) or a map_server map
//! (`.yaml`).
//!
//! The built-in worlds are the files of the top-level `worlds/` folder,
//! compiled in so that `--world map2` works from any directory.

use std::path::Path;

use crate::error::WorldError;
use crate::world::World;
use crate::world_file::{load_world_any, parse_world};

/// The built-in worlds: (name, the text of `worlds/NAME.toml`).
pub const BUILT_IN_WORLDS: [(&str, &str); 3] = [
    ("map1", include_str!("../../worlds/map1.toml")),
    ("map2", include_str!("../../worlds/map2.toml")),
    ("office", include_str!("../../worlds/office.toml")),
];

/// Loads the world `spec` names. An existing file wins over a built-in
/// name, so a world file called `map2` in the working directory is the one
/// loaded; otherwise `spec` must be one of [`BUILT_IN_WORLDS`]. Errors name
/// `spec` and, when nothing matches, the built-in names.
pub fn load_world_spec(spec: &str) -> Result<World, WorldError> {
    let path = Path::new(spec);
    if path.exists() {
        return load_world_any(path).map_err(|source| WorldError::LoadFile {
            file: path.display().to_string(),
            source: Box::new(source),
        });
    }
    if let Some((name, text)) = BUILT_IN_WORLDS.iter().find(|(name, _)| *name == spec) {
        return parse_world(text, &format!("worlds/{name}.toml")).map_err(|source| {
            WorldError::LoadBuiltIn {
                name: (*name).to_owned(),
                source: Box::new(source),
            }
        });
    }
    Err(WorldError::UnknownWorld {
        spec: spec.to_owned(),
        known: BUILT_IN_WORLDS
            .iter()
            .map(|(name, _)| (*name).to_owned())
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use std::error::Error as _;

    use super::*;

    #[test]
    fn every_built_in_world_loads_under_its_name() {
        for (name, _) in BUILT_IN_WORLDS {
            let world = load_world_spec(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(world.name(), name);
        }
    }

    #[test]
    fn an_unknown_name_names_itself_and_the_built_in_worlds() {
        let e = load_world_spec("no-such-world").expect_err("unknown");
        assert_eq!(
            e.to_string(),
            "no world \"no-such-world\": give a file (.toml world or .yaml map_server map) or one of map1, map2, office"
        );
    }

    #[test]
    fn a_bad_file_names_the_spec_then_the_fault() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("flat.toml");
        std::fs::write(
            &path,
            "name = \"flat\"\nboundary = [[0, 0], [1, 1], [2, 2]]\n",
        )
        .expect("write");
        let spec = path.display().to_string();
        let e = load_world_spec(&spec).expect_err("degenerate");
        assert_eq!(e.to_string(), format!("loading world {spec}"));
        let cause = e.source().map(ToString::to_string);
        assert_eq!(
            cause.as_deref(),
            Some(
                format!("{spec}:2: boundary: encloses no area (its points lie on one line)")
                    .as_str()
            )
        );
    }
}
