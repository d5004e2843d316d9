//! The rigs built into every program, and the one way a user names a rig:
//! a built-in name or a rig file.
//!
//! The built-in rigs are the files of the top-level `rigs/` folder,
//! compiled in so that `--rig pioneer3dx` works from any directory.

use std::path::Path;

use crate::error::RigError;
use crate::file::{load_rig_file, parse_rig};
use crate::rig::Rig;

/// The rig every process uses unless told otherwise.
pub const DEFAULT_RIG: &str = "scout";

/// The built-in rigs: (name, the text of `rigs/NAME.toml`).
pub const BUILT_IN_RIGS: [(&str, &str); 3] = [
    ("scout", include_str!("../../rigs/scout.toml")),
    ("pioneer3dx", include_str!("../../rigs/pioneer3dx.toml")),
    ("laser180", include_str!("../../rigs/laser180.toml")),
];

/// The built-in rig `name`, if there is one.
pub fn built_in_rig(name: &str) -> Option<Rig> {
    BUILT_IN_RIGS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(n, text)| {
            parse_rig(text, &format!("rigs/{n}.toml")).expect("the built-in rigs are valid")
        })
}

/// The Scout's rig, the default.
pub fn scout() -> Rig {
    built_in_rig(DEFAULT_RIG).expect("scout is built in")
}

/// Loads the rig `spec` names: a built-in name, else a rig file. A name
/// that is built in wins over a file of that name in the working
/// directory (a rig name is what frames carry, so it must mean one thing).
pub fn load_rig_spec(spec: &str) -> Result<Rig, RigError> {
    if let Some(rig) = built_in_rig(spec) {
        return Ok(rig);
    }
    let path = Path::new(spec);
    if path.exists() {
        return load_rig_file(path);
    }
    Err(RigError::Unknown {
        spec: spec.to_owned(),
        known: BUILT_IN_RIGS.iter().map(|(n, _)| (*n).to_owned()).collect(),
    })
}

/// Whether `name` is a built-in rig's: such names cannot be given to
/// another rig.
pub fn is_built_in(name: &str) -> bool {
    BUILT_IN_RIGS.iter().any(|(n, _)| *n == name)
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use approx::assert_abs_diff_eq;
    use deog_grid::SensorRing;

    use super::*;
    use crate::rig::BeamShape;

    #[test]
    fn every_built_in_rig_loads_under_its_name() {
        for (name, _) in BUILT_IN_RIGS {
            let rig = load_rig_spec(name).unwrap();
            assert_eq!(rig.name(), name);
        }
    }

    #[test]
    fn scout_is_the_ring_the_grid_knows() {
        let rig = scout();
        assert_eq!(rig.readings(), 16);
        assert!(rig.all_sonar());
        assert_eq!(rig.ring(), SensorRing::scout());
        for beam in rig.beams() {
            assert_eq!(
                beam.shape,
                BeamShape::Cone {
                    half_angle: 15f64.to_radians()
                }
            );
            assert_eq!(beam.max_range, 10.668);
            assert_eq!(beam.min_range, 0.1524);
        }
    }

    #[test]
    fn pioneer_has_two_arrays_of_eight() {
        let rig = load_rig_spec("pioneer3dx").unwrap();
        assert_eq!(rig.readings(), 16);
        let b = rig.beams();
        assert_abs_diff_eq!(b[0].mount.theta, PI / 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(b[3].mount.x, 0.166, epsilon = 1e-12);
        assert_abs_diff_eq!(b[11].mount.theta, -170f64.to_radians(), epsilon = 1e-12);
        assert_abs_diff_eq!(rig.body_radius(), 0.25);
    }

    #[test]
    fn laser180_is_a_one_degree_half_turn() {
        let rig = load_rig_spec("laser180").unwrap();
        assert_eq!(rig.readings(), 180);
        assert!(rig.all_laser());
        let b = rig.beams();
        assert_abs_diff_eq!(b[0].mount.theta, -PI / 2.0, epsilon = 1e-12);
        assert_abs_diff_eq!(
            b[1].mount.theta - b[0].mount.theta,
            PI / 180.0,
            epsilon = 1e-12
        );
        assert_eq!((b[0].min_range, b[0].max_range), (0.02, 50.0));
    }

    #[test]
    fn unknown_rigs_list_the_built_in_names() {
        let err = load_rig_spec("no-such-rig").unwrap_err().to_string();
        assert!(err.contains("scout, pioneer3dx, laser180"), "{err}");
    }

    #[test]
    fn a_file_is_read_when_no_built_in_has_the_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mine.toml");
        std::fs::write(
            &path,
            "name = \"mine\"\n[[sensor]]\nkind = \"laser\"\nfirst_angle_deg = -45\nangle_step_deg = 0.5\nbeam_count = 181\nmin_range_m = 0.1\nmax_range_m = 8\n",
        )
        .unwrap();
        let rig = load_rig_spec(path.to_str().unwrap()).unwrap();
        assert_eq!((rig.name(), rig.readings()), ("mine", 181));
    }
}
