//! What an explorer's run did, for its last line: frames, goals, bumps,
//! distance and time, counted from the robot's states and the steering's
//! events.

use deog_explore::SteeringEvent;
use deog_grid::Pose2;
use deog_proto::v1 as pb;
use deog_robot_client::convert::pose_or_origin;

/// What the run did, for its last line; and where the robot was last.
#[derive(Debug, Default)]
pub(super) struct Summary {
    pub(super) frames: u64,
    pub(super) published: u64,
    pub(super) goals: u64,
    pub(super) barred: u64,
    pub(super) bumps: u64,
    pub(super) distance_m: f64,
    pub(super) sim_seconds: f64,
    pub(super) finished: bool,
    /// The simulation time of the first state seen and of the last.
    start_time_s: Option<f64>,
    pub(super) last_time_s: f64,
    pub(super) last_pose: Option<Pose2>,
    was_bumped: bool,
}

impl Summary {
    /// Counts `state`, the robot's next: the distance it drove since the
    /// last, a bump that began, the simulated time since the first.
    pub(super) fn observe(&mut self, state: &pb::RobotState) {
        let truth = pose_or_origin(state.true_pose);
        let start = *self.start_time_s.get_or_insert(state.time_s);
        if let Some(previous) = self.last_pose {
            self.distance_m += (truth.x - previous.x).hypot(truth.y - previous.y);
        }
        self.last_pose = Some(truth);
        if state.bumper && !self.was_bumped {
            self.bumps += 1;
            tracing::warn!(
                x = truth.x,
                y = truth.y,
                heading_deg = truth.theta.to_degrees(),
                "bumped into something"
            );
        }
        self.was_bumped = state.bumper;
        self.frames += 1;
        self.sim_seconds = state.time_s - start;
        self.last_time_s = state.time_s;
    }

    /// Logs and counts what the steering decided.
    pub(super) fn note(&mut self, events: &[SteeringEvent]) {
        for event in events {
            match event {
                SteeringEvent::NewGoal { goal, tight } => {
                    self.goals += 1;
                    tracing::info!(
                        x = goal.x,
                        y = goal.y,
                        frontier_m = goal.frontier_m,
                        travel_m = goal.travel_m,
                        tight,
                        approach = goal.approach,
                        "new goal"
                    );
                }
                SteeringEvent::Barred { x, y } => {
                    self.barred += 1;
                    tracing::info!(x, y, "goal not neared: barred for a while");
                }
                SteeringEvent::NoReachableFrontier {
                    frontiers,
                    empty_plans,
                } => tracing::info!(frontiers, empty_plans, "no reachable frontier"),
            }
        }
    }
}
