//! Which sensor model a rig's frames are scored with.

use std::fmt;
use std::str::FromStr;

use deog_rig::Rig;

use crate::beam_model::BeamModelParams;
use crate::error::LocalizerError;
use crate::sensors::{LikelihoodField, LikelihoodFieldParams, SensorModel, SonarCone};

/// A sensor model, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SensorChoice {
    /// The beam model over expected-range tables ([`SonarCone`]): each
    /// reading against the range the map predicts for its cone. Sonar
    /// rigs only, for now.
    #[default]
    Beam,
    /// The likelihood field ([`LikelihoodField`]): each echo's endpoint
    /// against its distance to the nearest occupied cell. Any rig.
    LikelihoodField,
}

impl SensorChoice {
    /// Every choice, in the order of its name in [`Self::NAMES`].
    pub const ALL: [SensorChoice; 2] = [SensorChoice::Beam, SensorChoice::LikelihoodField];

    /// The names [`FromStr`] takes.
    pub const NAMES: [&'static str; 2] = ["beam", "likelihood-field"];

    /// The model of `rig`'s frames this choice names: the beam model with
    /// `beam`, or the likelihood field with `field`.
    ///
    /// The beam model's range tables are for sonar cones: a rig with a
    /// laser is refused (use the likelihood field). For a sonar rig the
    /// cones of the map's [`crate::range_table::ConeGeometry`] are the ones
    /// scored, so they should be the rig's.
    pub fn build(
        self,
        rig: &Rig,
        beam: BeamModelParams,
        field: LikelihoodFieldParams,
    ) -> Result<Box<dyn SensorModel>, LocalizerError> {
        match self {
            Self::Beam if rig.all_sonar() => Ok(Box::new(SonarCone::new(rig.ring(), beam)?)),
            Self::Beam => Err(LocalizerError::Invalid(format!(
                "the beam model is not supported yet for rig {}, which has a laser \
                 (its range tables are for sonar cones): use the likelihood field",
                rig.name()
            ))),
            Self::LikelihoodField => Ok(Box::new(LikelihoodField::new(rig.clone(), field)?)),
        }
    }

    /// The choice's name, as [`FromStr`] takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Beam => Self::NAMES[0],
            Self::LikelihoodField => Self::NAMES[1],
        }
    }
}

impl fmt::Display for SensorChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SensorChoice {
    type Err = LocalizerError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| {
                LocalizerError::Invalid(format!(
                    "no sensor model called {s:?} (known: {})",
                    Self::NAMES.join(", ")
                ))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_choice_builds_for_the_rigs_it_fits() {
        let (beam, field) = (BeamModelParams::default(), LikelihoodFieldParams::default());
        let scout = deog_rig::scout();
        let laser = deog_rig::built_in_rig("laser180").unwrap();
        let sonar = SensorChoice::Beam.build(&scout, beam, field).unwrap();
        assert_eq!(sonar.readings(), 16);
        let err = SensorChoice::Beam.build(&laser, beam, field).unwrap_err();
        assert!(
            err.to_string().contains("use the likelihood field"),
            "{err}"
        );
        for rig in [&scout, &laser] {
            let model = SensorChoice::LikelihoodField
                .build(rig, beam, field)
                .unwrap();
            assert_eq!(model.readings(), rig.readings());
        }
        let bad = LikelihoodFieldParams {
            sigma_hit: 0.0,
            ..field
        };
        let err = SensorChoice::LikelihoodField
            .build(&laser, beam, bad)
            .unwrap_err();
        assert!(err.to_string().contains("sigma_hit"), "{err}");
    }

    #[test]
    fn choices_parse_from_their_names() {
        for choice in SensorChoice::ALL {
            assert_eq!(choice.to_string().parse::<SensorChoice>().unwrap(), choice);
        }
        let err = "laser".parse::<SensorChoice>().unwrap_err().to_string();
        assert!(err.contains("beam, likelihood-field"), "{err}");
    }
}
