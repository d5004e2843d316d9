//! Named sets of sonar figures, as the command line picks them
//! (`--sonar default|realistic|specular60`).

use std::fmt;
use std::str::FromStr;

use crate::error::SimError;
use crate::sonar::{SonarParams, Specular};

/// A named set of sonar figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SonarPreset {
    /// [`SonarParams::default`]: every wall echoes, ±1 % noise, all
    /// sonars fire together.
    #[default]
    Default,
    /// [`SonarParams::realistic`]: echoes lost past 30° of incidence,
    /// 2 % dropouts, 1 % crosstalk, sequential firing.
    Realistic,
    /// Echoes lost past 60° of incidence and 2 % dropouts, firing
    /// together: `deog bench localize --specular` of old.
    Specular60,
}

impl SonarPreset {
    /// Every preset, in the order help texts list them.
    pub const ALL: [SonarPreset; 3] = [Self::Default, Self::Realistic, Self::Specular60];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Default => "default",
            Self::Realistic => "realistic",
            Self::Specular60 => "specular60",
        }
    }

    /// The incidence past which its echoes are lost, degrees from a
    /// wall's normal; `None` when every wall echoes. What a localizer is
    /// told (`deog localize --specular-angle`).
    pub fn specular_angle_deg(self) -> Option<f64> {
        match self {
            Self::Default => None,
            Self::Realistic => Some(30.0),
            Self::Specular60 => Some(60.0),
        }
    }

    /// Its sonar figures.
    pub fn params(self) -> SonarParams {
        match self {
            Self::Default => SonarParams::default(),
            Self::Realistic => SonarParams::realistic(),
            Self::Specular60 => SonarParams {
                specular: Specular::Lost {
                    max_incidence: 60f64.to_radians(),
                },
                dropout_probability: 0.02,
                ..SonarParams::default()
            },
        }
    }
}

impl fmt::Display for SonarPreset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SonarPreset {
    type Err = SimError;

    fn from_str(name: &str) -> Result<Self, SimError> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|p| p.name()).collect();
                SimError::invalid(
                    "sonar preset",
                    format!("unknown preset {name:?} (one of {})", names.join(", ")),
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sonar_firing::SonarFiring;

    #[test]
    fn every_preset_parses_from_its_name_and_is_valid() {
        for preset in SonarPreset::ALL {
            assert_eq!(preset.name().parse::<SonarPreset>().ok(), Some(preset));
            preset.params().validate().expect("valid figures");
        }
        assert_eq!(SonarPreset::Default.params(), SonarParams::default());
        let realistic = SonarPreset::Realistic.params();
        assert_eq!(realistic.firing, SonarFiring::Sequential);
        assert_eq!(realistic.crosstalk_probability, 0.01);
        assert_eq!(realistic.dropout_probability, 0.02);
        assert!(
            matches!(realistic.specular, Specular::Lost { max_incidence }
            if (max_incidence.to_degrees() - 30.0).abs() < 1e-9)
        );
        for preset in SonarPreset::ALL {
            let angle = match preset.params().specular {
                Specular::Off => None,
                Specular::Lost { max_incidence } | Specular::Long { max_incidence, .. } => {
                    Some(max_incidence.to_degrees())
                }
            };
            assert_eq!(
                angle.map(f64::round),
                preset.specular_angle_deg(),
                "{preset}"
            );
        }
        let err = "loud".parse::<SonarPreset>().expect_err("unknown");
        assert!(
            err.to_string().contains("default, realistic, specular60"),
            "{err}"
        );
    }
}
