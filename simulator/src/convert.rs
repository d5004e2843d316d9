//! Wire messages of `RobotService` to checked values and back. Every
//! refusal names the field.

use deog_grid::Pose2;
use deog_proto::names;
use deog_proto::v1 as pb;
use tonic::{Code, Status};

use crate::error::SimError;
use crate::simulation::RobotSnapshot;

/// Poses farther than this from the origin are refused, metres.
const MAX_ABS_COORDINATE: f64 = 1e6;

impl From<SimError> for Status {
    fn from(error: SimError) -> Self {
        let code = match &error {
            SimError::Invalid { .. } => Code::InvalidArgument,
            SimError::TooLarge { .. } | SimError::Limit(_) => Code::ResourceExhausted,
            SimError::UnknownRobot(_) => Code::NotFound,
            SimError::RobotExists(_) => Code::AlreadyExists,
            SimError::Blocked(_) => Code::FailedPrecondition,
            _ => Code::Internal,
        };
        Status::new(code, error.to_string())
    }
}

/// Refuses a request whose encoding exceeds `limit` bytes, naming the
/// message.
pub fn check_size(what: &str, message: &impl prost::Message, limit: usize) -> Result<(), SimError> {
    let len = message.encoded_len();
    if len > limit {
        return Err(SimError::TooLarge {
            field: what.to_string(),
            reason: format!(
                "message of {len} bytes exceeds the simulator's limit of {limit} bytes"
            ),
        });
    }
    Ok(())
}

/// A robot name: 1 to 128 characters of `[A-Za-z0-9_.-]`, the rule the
/// map server applies too ([`names::check_robot_name`]).
pub fn robot_name(field: &str, value: &str) -> Result<String, SimError> {
    names::check_robot_name(value).map_err(|e| SimError::invalid(field, e.to_string()))?;
    Ok(value.to_string())
}

fn finite(field: &str, value: f64, limit: f64) -> Result<f64, SimError> {
    if !value.is_finite() {
        return Err(SimError::invalid(
            field,
            format!("must be a finite number, got {value}"),
        ));
    }
    if value.abs() > limit {
        return Err(SimError::invalid(
            field,
            format!("must be within ±{limit}, got {value}"),
        ));
    }
    Ok(value)
}

/// A required pose.
pub fn pose(field: &str, value: Option<&pb::Pose2>) -> Result<Pose2, SimError> {
    let p = value.ok_or_else(|| SimError::invalid(field, "is required"))?;
    Ok(Pose2::new(
        finite(&format!("{field}.x"), p.x, MAX_ABS_COORDINATE)?,
        finite(&format!("{field}.y"), p.y, MAX_ABS_COORDINATE)?,
        finite(&format!("{field}.theta"), p.theta, MAX_ABS_COORDINATE)?,
    ))
}

/// A required velocity command: (linear m/s, angular rad/s). Any finite
/// speed passes: the API promises to clamp it to the robot's limits, which
/// the robot does; NaN and infinities are refused.
pub fn twist(field: &str, value: Option<&pb::Twist2>) -> Result<(f64, f64), SimError> {
    let t = value.ok_or_else(|| SimError::invalid(field, "is required"))?;
    Ok((
        finite(&format!("{field}.linear"), t.linear, f64::MAX)?,
        finite(&format!("{field}.angular"), t.angular, f64::MAX)?,
    ))
}

fn pose_to_wire(p: &Pose2) -> pb::Pose2 {
    pb::Pose2 {
        x: p.x,
        y: p.y,
        theta: p.theta,
    }
}

/// A robot's state on the wire.
pub fn robot_state(s: &RobotSnapshot) -> pb::RobotState {
    pb::RobotState {
        name: s.name.clone(),
        time_s: s.time_s,
        true_pose: Some(pose_to_wire(&s.true_pose)),
        odometry: Some(pose_to_wire(&s.odometry)),
        ranges: s.ranges.clone(),
        sequence: s.sequence,
        velocity: Some(pb::Twist2 {
            linear: s.velocity.0,
            angular: s.velocity.1,
        }),
        bumper: s.bumper,
        rig: s.rig.to_string(),
        bumps: s.bumps,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_robot_name_is_an_invalid_argument_naming_the_field() {
        let status = Status::from(robot_name("name", "").unwrap_err());
        assert_eq!(status.code(), Code::InvalidArgument);
        assert_eq!(status.message(), "name: must be 1 to 128 characters, got 0");
        let status = Status::from(robot_name("name", "scout:1").unwrap_err());
        assert_eq!(
            status.message(),
            "name: character ':' is not allowed (use A-Z a-z 0-9 _ . -)"
        );
        assert_eq!(robot_name("name", "scout-1").unwrap(), "scout-1");
    }
}
