//! Argument types several subcommands share: a pose on the command line,
//! and which of a frame's two poses to use.

use clap::ValueEnum;
use deog_grid::Pose2;
use deog_mapping::PoseChoice;

/// Which pose of a frame: the simulator's or the robot's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PoseSource {
    /// The simulator's true pose (the thesis's mapper used it).
    True,
    /// The robot's odometry.
    Odometry,
}

impl From<PoseSource> for PoseChoice {
    fn from(source: PoseSource) -> Self {
        match source {
            PoseSource::True => PoseChoice::True,
            PoseSource::Odometry => PoseChoice::Odometry,
        }
    }
}

/// Which pose `deog map` builds the map from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MapPoseSource {
    /// The simulator's true pose (the thesis's mapper used it).
    True,
    /// The robot's odometry.
    Odometry,
    /// A recording's reference pose (a corrected log's pose).
    Reference,
    /// The pose a localizer estimates for the robot on the map being
    /// built, converged estimates only, matched by frame sequence: a robot
    /// that localizes on a map keeps it current (lifelong mapping).
    Estimate,
}

impl From<MapPoseSource> for PoseChoice {
    fn from(source: MapPoseSource) -> Self {
        match source {
            MapPoseSource::True => PoseChoice::True,
            MapPoseSource::Odometry => PoseChoice::Odometry,
            MapPoseSource::Reference => PoseChoice::Reference,
            MapPoseSource::Estimate => PoseChoice::Estimate,
        }
    }
}

/// Where `deog localize --initial-pose` starts tracking from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InitialPose {
    /// A pose given as `x,y,theta`.
    Given(Pose2),
    /// The first frame's reference pose (a recording's corrected pose).
    Reference,
    /// The first frame's true pose (the simulator's).
    True,
}

/// `x,y,theta` in metres and radians, or `reference` or `true` for the
/// first frame's pose of that kind.
pub fn parse_initial_pose(text: &str) -> Result<InitialPose, String> {
    match text.trim() {
        "reference" => Ok(InitialPose::Reference),
        "true" => Ok(InitialPose::True),
        _ => parse_pose(text)
            .map(InitialPose::Given)
            .map_err(|e| format!("{e} (or `reference` or `true` for the first frame's pose)")),
    }
}

/// `x,y,theta` in metres and radians.
pub fn parse_pose(text: &str) -> Result<Pose2, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, theta] = parts.as_slice() else {
        return Err(format!("expected x,y,theta, got {text:?}"));
    };
    let number = |name: &str, s: &str| -> Result<f64, String> {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{name}: not a finite number: {s:?}"))
    };
    Ok(Pose2::new(
        number("x", x)?,
        number("y", y)?,
        number("theta", theta)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_initial_pose_is_three_numbers_or_a_frames_own() {
        assert_eq!(
            parse_initial_pose("1, -2.5, 0.5"),
            Ok(InitialPose::Given(Pose2::new(1.0, -2.5, 0.5)))
        );
        assert_eq!(parse_initial_pose("reference"), Ok(InitialPose::Reference));
        assert_eq!(parse_initial_pose("true"), Ok(InitialPose::True));
        let error = parse_initial_pose("1,2").expect_err("two numbers");
        assert!(
            error.contains("x,y,theta") && error.contains("`reference`"),
            "{error}"
        );
        assert!(parse_initial_pose("1,inf,0").is_err());
    }
}
