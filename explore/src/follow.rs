//! Driving along a path: pure pursuit towards a point a look-ahead
//! distance along it, turning in place when that point is well off the
//! heading, slowing as the robot's own ranges see something ahead and
//! stopping short of it, whatever the map says (walls it has not got yet
//! included).

use deog_grid::{Pose2, normalize_angle};

use crate::error::ExploreError;

/// How the follower drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowParams {
    /// Forward speed in the open, m/s.
    pub cruise_speed: f64,
    /// Fastest turn, rad/s.
    pub max_turn_rate: f64,
    /// How far along the path the steering point lies, metres.
    pub lookahead_m: f64,
    /// The goal is reached within this distance, metres.
    pub goal_tolerance_m: f64,
    /// Past this heading error, radians, the robot turns in place.
    pub turn_in_place_rad: f64,
    /// Clearance ahead below which the robot stops, metres.
    pub stop_distance_m: f64,
    /// Clearance beside the path (between [`FRONT_DEG`] and
    /// [`BESIDE_DEG`] off the heading) below which it stops, metres.
    pub beside_stop_m: f64,
    /// Clearance ahead below which it slows, metres.
    pub slow_distance_m: f64,
}

impl Default for FollowParams {
    fn default() -> Self {
        Self {
            cruise_speed: 0.5,
            max_turn_rate: 1.0,
            lookahead_m: 0.6,
            goal_tolerance_m: 0.3,
            turn_in_place_rad: 1.0,
            stop_distance_m: 0.45,
            beside_stop_m: 0.15,
            slow_distance_m: 1.0,
        }
    }
}

impl FollowParams {
    /// Checks every figure.
    pub fn validate(&self) -> Result<(), ExploreError> {
        let positive = [
            ("cruise_speed", self.cruise_speed),
            ("max_turn_rate", self.max_turn_rate),
            ("lookahead_m", self.lookahead_m),
            ("goal_tolerance_m", self.goal_tolerance_m),
            ("turn_in_place_rad", self.turn_in_place_rad),
            ("stop_distance_m", self.stop_distance_m),
            ("beside_stop_m", self.beside_stop_m),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ExploreError::Invalid {
                    name,
                    reason: format!("must be positive, got {value}"),
                });
            }
        }
        if !(self.slow_distance_m.is_finite() && self.slow_distance_m > self.stop_distance_m) {
            return Err(ExploreError::Invalid {
                name: "slow_distance_m",
                reason: format!(
                    "must be past stop_distance_m ({}), got {}",
                    self.stop_distance_m, self.slow_distance_m
                ),
            });
        }
        Ok(())
    }
}

/// What the robot's own ranges see, metres from its body's edge: ahead
/// (within a narrow cone of its heading), beside the path, and to the
/// left and right.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearance {
    /// Ahead: within [`FRONT_DEG`] of the heading.
    pub ahead: f64,
    /// Beside the path: from [`FRONT_DEG`] to [`BESIDE_DEG`] off it.
    pub beside: f64,
    /// Left.
    pub left: f64,
    /// Right.
    pub right: f64,
}

/// Echoes within this bearing of the heading, degrees, are ahead...
pub const FRONT_DEG: f64 = 15.0;
/// ...and those from there to this bearing, degrees, beside the path...
pub const BESIDE_DEG: f64 = 60.0;
/// ...and count as this much farther when the robot slows for what lies
/// ahead, metres.
pub const BESIDE_ALLOWANCE_M: f64 = 0.3;

impl Clearance {
    /// The clearance ahead the robot slows for: ahead, or beside the path
    /// counted [`BESIDE_ALLOWANCE_M`] farther (a cone beside the heading
    /// may hear something off to the side: a door's jamb, a pillar passed
    /// between).
    pub fn front(&self) -> f64 {
        self.ahead.min(self.beside + BESIDE_ALLOWANCE_M)
    }

    /// What echoes at `points` (metres in the robot's frame, x ahead, y to
    /// the left) leave around a body of `body_radius_m`: ahead the nearest
    /// within [`FRONT_DEG`], beside the nearest from there to
    /// [`BESIDE_DEG`]; left and right the nearest between 35° and 120° off
    /// the heading.
    pub fn of_echoes(points: impl IntoIterator<Item = (f64, f64)>, body_radius_m: f64) -> Self {
        let mut clearance = Clearance {
            ahead: f64::INFINITY,
            beside: f64::INFINITY,
            left: f64::INFINITY,
            right: f64::INFINITY,
        };
        for (x, y) in points {
            let distance = (x.hypot(y) - body_radius_m).max(0.0);
            let bearing = normalize_angle(y.atan2(x)).to_degrees();
            if bearing.abs() <= FRONT_DEG {
                clearance.ahead = clearance.ahead.min(distance);
            } else if bearing.abs() <= BESIDE_DEG {
                clearance.beside = clearance.beside.min(distance);
            }
            let side = if (35.0..=120.0).contains(&bearing) {
                &mut clearance.left
            } else if (-120.0..=-35.0).contains(&bearing) {
                &mut clearance.right
            } else {
                continue;
            };
            *side = side.min(distance);
        }
        clearance
    }
}

/// The follower's word for the next moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FollowCommand {
    /// Drive: forward m/s, turn rad/s.
    Drive {
        /// m/s.
        linear: f64,
        /// rad/s, counter-clockwise.
        angular: f64,
    },
    /// The goal is reached.
    Arrived,
    /// Something is in the way ahead: the path must be planned again.
    Blocked,
}

/// Follows one path.
#[derive(Debug, Clone)]
pub struct PathFollower {
    path: Vec<(f64, f64)>,
    progress: usize,
    params: FollowParams,
}

impl PathFollower {
    /// A follower of `path` (world points, the goal last).
    pub fn new(path: Vec<(f64, f64)>, params: FollowParams) -> Result<Self, ExploreError> {
        params.validate()?;
        if path.is_empty() {
            return Err(ExploreError::Invalid {
                name: "path",
                reason: "has no point".into(),
            });
        }
        Ok(Self {
            path,
            progress: 0,
            params,
        })
    }

    /// The path's last point.
    pub fn goal(&self) -> (f64, f64) {
        *self.path.last().expect("a path has a point")
    }

    /// The points not yet passed.
    pub fn remaining(&self) -> &[(f64, f64)] {
        &self.path[self.progress..]
    }

    /// The length of the way left from `pose`, metres: to the nearest
    /// point not yet passed, then along the path from it. Unlike the
    /// straight distance to the goal, it falls as a robot goes round an
    /// obstacle.
    pub fn remaining_length_m(&self, pose: Pose2) -> f64 {
        let remaining = self.remaining();
        let distance = |&(x, y): &(f64, f64)| (x - pose.x).hypot(y - pose.y);
        let nearest = (0..remaining.len())
            .min_by(|&a, &b| distance(&remaining[a]).total_cmp(&distance(&remaining[b])))
            .unwrap_or(0);
        let along: f64 = remaining[nearest..]
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
            .sum();
        distance(&remaining[nearest]) + along
    }

    /// The command at `pose` with `clearance` around it.
    pub fn command(&mut self, pose: Pose2, clearance: Clearance) -> FollowCommand {
        let p = self.params;
        let (gx, gy) = self.goal();
        if (gx - pose.x).hypot(gy - pose.y) <= p.goal_tolerance_m {
            return FollowCommand::Arrived;
        }
        // Pass the points already within reach; never go back along the path.
        while self.progress + 1 < self.path.len() {
            let (x, y) = self.path[self.progress];
            if (x - pose.x).hypot(y - pose.y) < p.lookahead_m {
                self.progress += 1;
            } else {
                break;
            }
        }
        let (tx, ty) = self.path[self.progress];
        let heading_error = normalize_angle((ty - pose.y).atan2(tx - pose.x) - pose.theta);
        let turn = (2.0 * heading_error).clamp(-p.max_turn_rate, p.max_turn_rate);
        if heading_error.abs() > p.turn_in_place_rad {
            return FollowCommand::Drive {
                linear: 0.0,
                angular: turn,
            };
        }
        if clearance.ahead < p.stop_distance_m || clearance.beside < p.beside_stop_m {
            return FollowCommand::Blocked;
        }
        let room = ((clearance.front() - p.stop_distance_m)
            / (p.slow_distance_m - p.stop_distance_m))
            .clamp(0.25, 1.0);
        let linear = p.cruise_speed * room * heading_error.cos().max(0.0);
        // Pure pursuit: the arc through the steering point.
        let distance = (tx - pose.x).hypot(ty - pose.y).max(1e-6);
        let curvature = 2.0 * heading_error.sin() / distance;
        let angular = (linear * curvature).clamp(-p.max_turn_rate, p.max_turn_rate);
        FollowCommand::Drive { linear, angular }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn echoes_beside_the_heading_count_farther_than_those_ahead() {
        let body = 0.2;
        // 0.5 m from the body straight ahead; 0.3 m at 40° to the left.
        let ahead = (0.7, 0.0);
        let beside = (
            0.5 * 40f64.to_radians().cos(),
            0.5 * 40f64.to_radians().sin(),
        );
        let c = Clearance::of_echoes([ahead, beside], body);
        assert!((c.front() - 0.5).abs() < 1e-9, "{c:?}");
        assert!((c.ahead - 0.5).abs() < 1e-9 && (c.beside - 0.3).abs() < 1e-9);
        assert!((c.left - 0.3).abs() < 1e-9, "{c:?}");
        assert!(c.right.is_infinite());
        // Beside alone: 0.3 m counts as 0.6 m ahead.
        let c = Clearance::of_echoes([beside], body);
        assert!((c.front() - 0.3 - BESIDE_ALLOWANCE_M).abs() < 1e-9, "{c:?}");
        // Behind: nothing ahead, nothing to the sides.
        let c = Clearance::of_echoes([(-0.6, 0.0)], body);
        assert!(c.front().is_infinite() && c.left.is_infinite() && c.right.is_infinite());
    }

    const OPEN: Clearance = Clearance {
        ahead: 10.0,
        beside: 10.0,
        left: 10.0,
        right: 10.0,
    };

    fn drive(
        follower: &mut PathFollower,
        mut pose: Pose2,
        clearance: Clearance,
        steps: usize,
    ) -> (Pose2, FollowCommand) {
        let dt = 0.05;
        let mut last = FollowCommand::Blocked;
        for _ in 0..steps {
            last = follower.command(pose, clearance);
            match last {
                FollowCommand::Drive { linear, angular } => {
                    pose.theta += angular * dt;
                    pose.x += linear * pose.theta.cos() * dt;
                    pose.y += linear * pose.theta.sin() * dt;
                }
                _ => return (pose, last),
            }
        }
        (pose, last)
    }

    #[test]
    fn a_robot_follows_an_l_shaped_path_to_its_goal() {
        let path = (0..=20)
            .map(|i| (f64::from(i) * 0.1, 0.0))
            .chain((1..=20).map(|i| (2.0, f64::from(i) * 0.1)))
            .collect();
        let mut follower = PathFollower::new(path, FollowParams::default()).unwrap();
        let (pose, last) = drive(
            &mut follower,
            Pose2 {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            OPEN,
            2_000,
        );
        assert_eq!(last, FollowCommand::Arrived, "{pose:?}");
        assert!((pose.x - 2.0).hypot(pose.y - 2.0) <= 0.3);
    }

    #[test]
    fn the_way_left_falls_round_a_corner_where_the_straight_distance_does_not() {
        // Round a U: out 1 m, across 1 m, back 1 m; the goal lies 1 m from
        // the start.
        let path: Vec<(f64, f64)> = (0..=10)
            .map(|i| (f64::from(i) * 0.1, 0.0))
            .chain((1..=10).map(|i| (1.0, f64::from(i) * 0.1)))
            .chain((1..=10).map(|i| (1.0 - f64::from(i) * 0.1, 1.0)))
            .collect();
        let follower = PathFollower::new(path, FollowParams::default()).unwrap();
        let start = Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        assert!((follower.remaining_length_m(start) - 3.0).abs() < 1e-9);
        // At the far corner the goal is no nearer in a straight line...
        let corner = Pose2 {
            x: 1.0,
            y: 0.0,
            theta: std::f64::consts::FRAC_PI_2,
        };
        let (gx, gy) = follower.goal();
        assert!((gx - corner.x).hypot(gy - corner.y) > 1.4);
        // ...but a third of the way has gone.
        let left = follower.remaining_length_m(corner);
        assert!((left - 2.0).abs() < 1e-9, "{left}");
    }

    #[test]
    fn a_goal_behind_is_turned_to_in_place() {
        let mut follower = PathFollower::new(vec![(-3.0, 0.0)], FollowParams::default()).unwrap();
        match follower.command(
            Pose2 {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
            OPEN,
        ) {
            FollowCommand::Drive { linear, angular } => {
                assert_eq!(linear, 0.0);
                assert!(angular.abs() > 0.5);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn something_close_ahead_stops_the_robot_and_nearer_slows_it() {
        let mut follower = PathFollower::new(vec![(5.0, 0.0)], FollowParams::default()).unwrap();
        let at = Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        let blocked = Clearance { ahead: 0.3, ..OPEN };
        assert_eq!(follower.command(at, blocked), FollowCommand::Blocked);
        // Beside the path, only nearer stops it.
        let beside = Clearance {
            beside: 0.3,
            ..OPEN
        };
        assert!(matches!(
            follower.command(at, beside),
            FollowCommand::Drive { .. }
        ));
        let brushing = Clearance {
            beside: 0.1,
            ..OPEN
        };
        assert_eq!(follower.command(at, brushing), FollowCommand::Blocked);
        // A robot that stops nearer ahead (squeezing between pillars) is
        // still stopped by what brushes its side.
        let mut squeezing = PathFollower::new(
            vec![(5.0, 0.0)],
            FollowParams {
                stop_distance_m: 0.2,
                slow_distance_m: 0.5,
                ..FollowParams::default()
            },
        )
        .unwrap();
        assert!(matches!(
            squeezing.command(at, blocked),
            FollowCommand::Drive { .. }
        ));
        assert_eq!(squeezing.command(at, brushing), FollowCommand::Blocked);
        let speed = |c: Clearance, f: &mut PathFollower| match f.command(at, c) {
            FollowCommand::Drive { linear, .. } => linear,
            other => panic!("{other:?}"),
        };
        let near = speed(Clearance { ahead: 0.6, ..OPEN }, &mut follower);
        let far = speed(OPEN, &mut follower);
        assert!(near < far && near > 0.0, "{near} {far}");
    }

    #[test]
    fn bad_parameters_and_empty_paths_are_refused() {
        assert!(PathFollower::new(Vec::new(), FollowParams::default()).is_err());
        let params = FollowParams {
            slow_distance_m: 0.1,
            ..FollowParams::default()
        };
        assert!(PathFollower::new(vec![(1.0, 1.0)], params).is_err());
    }
}
