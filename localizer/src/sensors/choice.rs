//! Which sensor model a rig's frames are scored with.

use std::fmt;
use std::str::FromStr;

use deog_rig::{BeamShape, Rig};

use crate::beam_model::BeamModelParams;
use crate::error::LocalizerError;
use crate::range_table::ConeGeometry;
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
    /// The model a rig's frames get unless the user picks one: the beam
    /// model for a rig of sonars only, the likelihood field otherwise.
    pub fn for_rig(rig: &Rig) -> Self {
        if rig.all_sonar() {
            Self::Beam
        } else {
            Self::LikelihoodField
        }
    }

    /// The cone the map's range tables are built for: the rig's sonars'
    /// (which must share one) for the beam model; `base`'s for the
    /// likelihood field, which builds no range table. Other figures come
    /// from `base`.
    pub fn cone_geometry(
        self,
        rig: &Rig,
        base: ConeGeometry,
    ) -> Result<ConeGeometry, LocalizerError> {
        if self != Self::Beam {
            return Ok(base);
        }
        let mut cones = rig.beams().iter().filter_map(|b| match b.shape {
            BeamShape::Cone { half_angle } => Some((half_angle, b.max_range)),
            BeamShape::Ray => None,
        });
        let Some((half_angle, max_range)) = cones.next() else {
            return Ok(base);
        };
        if !cones.all(|c| c == (half_angle, max_range)) {
            return Err(LocalizerError::Invalid(format!(
                "the beam model needs every sonar of rig {} to share one cone and range: \
                 use the likelihood field",
                rig.name()
            )));
        }
        Ok(ConeGeometry {
            half_angle,
            max_range,
            ..base
        })
    }

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
    fn a_rig_picks_its_model_and_the_beam_model_its_cone() {
        let scout = deog_rig::scout();
        let pioneer = deog_rig::built_in_rig("pioneer3dx").unwrap();
        let laser = deog_rig::built_in_rig("laser180").unwrap();
        assert_eq!(SensorChoice::for_rig(&scout), SensorChoice::Beam);
        assert_eq!(SensorChoice::for_rig(&laser), SensorChoice::LikelihoodField);
        let base = ConeGeometry {
            surface_depth: 0.02,
            ..ConeGeometry::default()
        };
        // The Scout's cone is the default one.
        let cone = SensorChoice::Beam.cone_geometry(&scout, base).unwrap();
        assert_eq!(cone, base);
        let cone = SensorChoice::Beam.cone_geometry(&pioneer, base).unwrap();
        assert_eq!((cone.max_range, cone.surface_depth), (5.0, 0.02));
        let cone = SensorChoice::LikelihoodField
            .cone_geometry(&pioneer, base)
            .unwrap();
        assert_eq!(cone, base);
        // Sonars of two cones cannot share one set of range tables.
        let text = "name = \"two\"\n[defaults]\nkind = \"sonar\"\nmin_range_m = 0.1\n\
                    [[sensor]]\nhalf_angle_deg = 10\nmax_range_m = 4\n\
                    [[sensor]]\nhalf_angle_deg = 15\nmax_range_m = 4\n";
        let mixed = deog_rig::parse_rig(text, "t").unwrap();
        let err = SensorChoice::Beam.cone_geometry(&mixed, base).unwrap_err();
        assert!(err.to_string().contains("share one cone"), "{err}");
    }

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
