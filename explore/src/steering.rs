//! The steering's decisions, one robot state at a time: which plan to
//! follow, when to ask for the next, when a goal is reached or has
//! stalled, what to bar and for how long, when to turn on the spot and
//! look about, and when the map is explored. The caller drives the robot,
//! publishes the goals, runs the planner and logs what happened
//! ([`Decision`]); nothing here waits or talks to anything.
//!
//! A goal not neared for [`STALL_S`] (by the way left along its path) is
//! barred for [`BAR_S`], for [`ARRIVED_BAR_S`] the second time; the
//! frontier cells around a goal reached are barred for [`ARRIVED_BAR_S`]
//! (if still a frontier once reached, nothing more can be seen of it from
//! there). With frontiers left but none in reach, the robot keeps looking
//! for [`UNREACHABLE_PATIENCE_S`], and until its bars run out, before it
//! calls the map explored.

use deog_grid::Pose2;

use crate::follow::{Clearance, FollowCommand, PathFollower};
use crate::goal::{Blacklist, Goal, GoalParams};

/// Plans in a row that found nothing before the robot is done.
pub const EMPTY_PLANS_TO_STOP: u32 = 3;
/// Simulated seconds a robot keeps looking when frontiers remain but none
/// can be reached: the map changes under it (a wall thickened by a
/// sonar's cone thins as more frames come, other robots open the way).
pub const UNREACHABLE_PATIENCE_S: f64 = 30.0;
/// Simulated seconds a barred goal stays barred the first time; barred
/// again at the same place, it stays barred as long as a goal reached.
pub const BAR_S: f64 = 60.0;
/// Simulated seconds a goal reached stays barred: for the rest of any
/// run worth the name (a frontier still there once reached is one nothing
/// more can be seen from).
pub const ARRIVED_BAR_S: f64 = 3600.0;
/// A goal reached bars the cells of its frontier within this distance of
/// it, metres (a long frontier's far end may yet be seen from elsewhere)...
pub const ARRIVED_BAR_REACH_M: f64 = 2.5;
/// ...each within this radius, metres.
pub const ARRIVED_BAR_CELL_M: f64 = 0.15;
/// Blocked this near its goal, metres, the robot counts it reached.
pub const BLOCKED_REACHES_M: f64 = 1.0;
/// A place a frontier was looked at from is not used again within this
/// distance, metres.
pub const APPROACH_BAR_M: f64 = 0.5;
/// Simulated seconds without nearing its goal before it is barred.
pub const STALL_S: f64 = 12.0;
/// Simulated seconds turned in place to look about when the map has
/// nothing near the robot yet, or after being blocked.
pub const LOOK_ABOUT_S: f64 = 2.0;
/// Simulated seconds before the next plan after one that found nothing:
/// the cartographer catches up meanwhile.
pub const AFTER_NOTHING_S: f64 = 1.0;
/// Metres the way left must shrink by to count as nearing the goal.
const PROGRESS_M: f64 = 0.1;

/// What one plan found.
#[derive(Debug, Clone)]
pub enum Plan {
    /// A goal and the way there; `tight` when it was found only on the
    /// map's own cells, through gaps the merged cells close.
    Go {
        /// Where to.
        goal: Goal,
        /// The way there.
        follower: PathFollower,
        /// Found only through gaps the merged cells close.
        tight: bool,
    },
    /// Nothing known around the robot yet: look about first.
    LookAbout,
    /// No reachable frontier.
    Nothing {
        /// Frontiers out of reach.
        frontiers: usize,
    },
}

/// What a plan starts from.
#[derive(Debug, Clone)]
pub struct PlanRequest {
    /// The pose to plan from.
    pub pose: Pose2,
    /// When it was asked for, simulated seconds.
    pub now_s: f64,
    /// The goal being driven to, if any.
    pub current: Option<(f64, f64)>,
    /// The places barred when it was asked for.
    pub blacklist: Blacklist,
}

/// What the steering goes by besides the plans.
#[derive(Debug, Clone, Copy)]
pub struct SteeringParams {
    /// The fastest turn on the spot, rad/s.
    pub max_turn_rate: f64,
    /// Simulated seconds between plans while following a path.
    pub replan_s: f64,
    /// The goals' radii: a plan's goal within `current_radius_m` of the
    /// last is the same goal; bars reach `blacklist_radius_m`.
    pub goals: GoalParams,
}

/// Something the caller may want to log or count.
#[derive(Debug, Clone, PartialEq)]
pub enum SteeringEvent {
    /// A plan's goal is a new one (not the last goal again).
    NewGoal {
        /// The goal.
        goal: Goal,
        /// Found only through gaps the merged cells close.
        tight: bool,
    },
    /// A goal not neared for [`STALL_S`] was barred.
    Barred {
        /// Where, metres.
        x: f64,
        /// See `x`.
        y: f64,
    },
    /// A plan found no reachable frontier.
    NoReachableFrontier {
        /// Frontiers out of reach.
        frontiers: usize,
        /// Plans in a row that found nothing.
        empty_plans: u32,
    },
}

/// What to do for one robot state.
#[derive(Debug, Clone, Default)]
pub struct Decision {
    /// The command to drive, forward m/s and turn rad/s; `None` leaves the
    /// last one in force.
    pub drive: Option<(f64, f64)>,
    /// A goal to tell the other robots this one is heading for.
    pub claim: Option<(f64, f64)>,
    /// A plan to ask the planner for.
    pub request: Option<PlanRequest>,
    /// The path follower's command, when a path was followed.
    pub followed: Option<FollowCommand>,
    /// What happened, to log or count.
    pub events: Vec<SteeringEvent>,
    /// No reachable frontier is left and nothing may yet open one: stop.
    pub finished: bool,
}

/// The goal being driven to, and how it is going.
#[derive(Debug, Clone)]
struct Pursuit {
    goal: Goal,
    follower: PathFollower,
    planned_at_s: f64,
    /// The shortest way left along the path so far, metres, and when.
    best_distance: f64,
    best_at_s: f64,
}

/// The steering's state between robot states.
#[derive(Debug, Clone)]
pub struct Steering {
    params: SteeringParams,
    blacklist: Blacklist,
    /// When the last bar for a while runs out, simulated seconds.
    bars_lapse_s: f64,
    pursuit: Option<Pursuit>,
    /// The last goal driven to: where, the shortest way left to it, when.
    last_goal: Option<(f64, f64, f64, f64)>,
    look_about_until: Option<f64>,
    /// Plans in a row that found nothing.
    empty_plans: u32,
    /// When the plans began to find frontiers but none in reach.
    out_of_reach_since: Option<f64>,
    next_plan_s: f64,
    /// Whether a plan has been asked for and not come back.
    planning: bool,
}

impl Steering {
    /// A robot with no goal yet, nothing barred, about to ask for a plan.
    pub fn new(params: SteeringParams) -> Self {
        Self {
            params,
            blacklist: Blacklist::default(),
            bars_lapse_s: f64::NEG_INFINITY,
            pursuit: None,
            last_goal: None,
            look_about_until: None,
            empty_plans: 0,
            out_of_reach_since: None,
            next_plan_s: f64::NEG_INFINITY,
            planning: false,
        }
    }

    /// The places barred now.
    pub fn blacklist(&self) -> &Blacklist {
        &self.blacklist
    }

    /// While the robot looks about, the turn to drive (towards the more
    /// open side); plans wait meanwhile. `None` once it is done looking.
    pub fn looking_about(&mut self, now_s: f64, clearance: Clearance) -> Option<(f64, f64)> {
        if self.look_about_until.is_some_and(|until| now_s < until) {
            let turn = if clearance.left >= clearance.right {
                1.0
            } else {
                -1.0
            };
            return Some((0.0, turn * self.params.max_turn_rate));
        }
        self.look_about_until = None;
        None
    }

    /// Decides for one robot state at `pose`, with the plan that came back
    /// since the last (with the time it was asked for), if any. Call
    /// [`Self::looking_about`] first: while it turns, plans wait.
    pub fn step(
        &mut self,
        now_s: f64,
        pose: Pose2,
        clearance: Clearance,
        plan: Option<(f64, Plan)>,
    ) -> Decision {
        let mut decision = Decision::default();
        if let Some((planned_at_s, plan)) = plan {
            self.planning = false;
            if !self.take_plan(now_s, pose, planned_at_s, plan, &mut decision) {
                return decision;
            }
        }
        let replan = self
            .pursuit
            .as_ref()
            .is_none_or(|p| now_s - p.planned_at_s >= self.params.replan_s);
        if replan && !self.planning && now_s >= self.next_plan_s {
            self.blacklist.expire(now_s);
            decision.request = Some(PlanRequest {
                pose,
                now_s,
                current: self.pursuit.as_ref().map(|p| (p.goal.x, p.goal.y)),
                blacklist: self.blacklist.clone(),
            });
            self.planning = true;
        }
        decision.drive = Some(self.follow(now_s, pose, clearance, &mut decision));
        decision
    }

    /// Takes a plan that came back; false when the robot is to do nothing
    /// more for this state (look about, wait for the map, or stop).
    fn take_plan(
        &mut self,
        now_s: f64,
        pose: Pose2,
        planned_at_s: f64,
        plan: Plan,
        decision: &mut Decision,
    ) -> bool {
        let goals = self.params.goals;
        match plan {
            Plan::Go { ref goal, .. }
                if self
                    .blacklist
                    .bars(goal.x, goal.y, goals.blacklist_radius_m) =>
            {
                // Planned before its goal was barred: plan again with the
                // blacklist as it is now.
                self.pursuit = None;
            }
            Plan::Go {
                goal,
                follower,
                tight,
            } => {
                self.empty_plans = 0;
                self.out_of_reach_since = None;
                // The same goal as the last one, even if the pursuit was
                // dropped in between (blocked, looking about): its progress
                // carries over, so a goal the robot keeps being turned
                // back from is still barred.
                let same = self.last_goal.is_some_and(|(x, y, _, _)| {
                    (x - goal.x).hypot(y - goal.y) <= goals.current_radius_m
                });
                let distance = follower.remaining_length_m(pose);
                let (best_distance, best_at_s) = match self.last_goal {
                    Some((_, _, best, at)) if same => (best, at),
                    _ => {
                        decision.events.push(SteeringEvent::NewGoal {
                            goal: goal.clone(),
                            tight,
                        });
                        (distance, now_s)
                    }
                };
                // Each plan refreshes the claim, so that it stays fresh.
                decision.claim = Some((goal.x, goal.y));
                self.pursuit = Some(Pursuit {
                    goal,
                    follower,
                    planned_at_s,
                    best_distance,
                    best_at_s,
                });
            }
            Plan::LookAbout => {
                self.look_about_until = Some(now_s + LOOK_ABOUT_S);
                return false;
            }
            Plan::Nothing { frontiers } => {
                self.pursuit = None;
                self.empty_plans += 1;
                let since = *self.out_of_reach_since.get_or_insert(now_s);
                decision.events.push(SteeringEvent::NoReachableFrontier {
                    frontiers,
                    empty_plans: self.empty_plans,
                });
                // Frontiers left out of reach: not done while the map may
                // yet open a way or a bar run out.
                let hoping = frontiers > 0
                    && (now_s - since < UNREACHABLE_PATIENCE_S || now_s < self.bars_lapse_s);
                if self.empty_plans >= EMPTY_PLANS_TO_STOP && !hoping {
                    decision.finished = true;
                    return false;
                }
                // Let the cartographer catch up before looking again; turn
                // meanwhile, so that the sonars sweep what the map holds
                // around the robot.
                self.next_plan_s = now_s + AFTER_NOTHING_S;
                if frontiers > 0 {
                    self.look_about_until = Some(now_s + LOOK_ABOUT_S);
                }
                decision.drive = Some((0.0, 0.0));
                return false;
            }
        }
        true
    }

    /// The command along the path being followed, and what reaching or
    /// giving up its goal bars.
    fn follow(
        &mut self,
        now_s: f64,
        pose: Pose2,
        clearance: Clearance,
        decision: &mut Decision,
    ) -> (f64, f64) {
        let Some(p) = self.pursuit.as_mut() else {
            return (0.0, 0.0);
        };
        let distance = (p.goal.x - pose.x).hypot(p.goal.y - pose.y);
        // Progress is the way left along the path, which falls as the
        // robot goes round a pillar while the straight distance may not.
        let way_left = p.follower.remaining_length_m(pose);
        if way_left < p.best_distance - PROGRESS_M {
            p.best_distance = way_left;
            p.best_at_s = now_s;
        }
        self.last_goal = Some((p.goal.x, p.goal.y, p.best_distance, p.best_at_s));
        let stalled = now_s - p.best_at_s > STALL_S;
        let command = p.follower.command(pose, clearance);
        decision.followed = Some(command);
        // Stopped by something just short of the goal is as near as the
        // robot gets: as good as there.
        let reached = command == FollowCommand::Arrived
            || (command == FollowCommand::Blocked && distance <= BLOCKED_REACHES_M);
        if reached {
            let goal = &p.goal;
            if goal.approach {
                // A frontier looked at from near: not from here again;
                // turn, so that the sonars sweep it, then plan (the way
                // there may have opened).
                self.blacklist
                    .add_within(goal.x, goal.y, APPROACH_BAR_M, now_s + ARRIVED_BAR_S);
                self.look_about_until = Some(now_s + LOOK_ABOUT_S);
                self.pursuit = None;
                return (0.0, 0.0);
            }
            // A frontier the robot stands at and still sees as one (a gap
            // in a wall's line, the far side of furniture) cannot be seen
            // better from there: bar its cells around the goal, or the
            // robot would come back to it for ever.
            for &(x, y) in &goal.frontier_cells {
                if (x - goal.x).hypot(y - goal.y) <= ARRIVED_BAR_REACH_M {
                    self.blacklist
                        .add_within(x, y, ARRIVED_BAR_CELL_M, now_s + ARRIVED_BAR_S);
                }
            }
            if command == FollowCommand::Blocked {
                self.look_about_until = Some(now_s + LOOK_ABOUT_S);
            }
            self.pursuit = None;
            return (0.0, 0.0);
        }
        if let FollowCommand::Drive { linear, angular } = command
            && !stalled
        {
            return (linear, angular);
        }
        if stalled {
            let (x, y) = (p.goal.x, p.goal.y);
            self.bar_stalled(x, y, now_s);
            self.last_goal = None;
            decision.events.push(SteeringEvent::Barred { x, y });
        }
        self.pursuit = None;
        self.look_about_until = Some(now_s + LOOK_ABOUT_S);
        (0.0, 0.0)
    }

    /// Bars a goal not neared: for a while the first time, as long as a
    /// goal reached when the robot failed there before.
    fn bar_stalled(&mut self, x: f64, y: f64, now_s: f64) {
        let first = self.blacklist.bar_failure(
            (x, y),
            now_s,
            (BAR_S, ARRIVED_BAR_S),
            self.params.goals.blacklist_radius_m,
        );
        if first {
            self.bars_lapse_s = self.bars_lapse_s.max(now_s + BAR_S);
        }
    }
}

#[cfg(test)]
mod tests {
    use deog_grid::CellIndex;

    use super::*;
    use crate::follow::FollowParams;

    const OPEN: Clearance = Clearance {
        ahead: f64::INFINITY,
        beside: f64::INFINITY,
        left: f64::INFINITY,
        right: f64::INFINITY,
    };

    fn steering() -> Steering {
        Steering::new(SteeringParams {
            max_turn_rate: 1.0,
            replan_s: 3.0,
            goals: GoalParams::default(),
        })
    }

    /// A goal at (x, 0) with a frontier of cells along y, and the straight
    /// path there from the origin.
    fn go(x: f64, approach: bool) -> Plan {
        let goal = Goal {
            cell: CellIndex::new(0, 0),
            x,
            y: 0.0,
            frontier_m: 1.0,
            travel_m: x,
            score: 0.0,
            frontier_cells: (-40..=40).map(|k| (x, 0.1 * f64::from(k))).collect(),
            approach,
        };
        let path = (0..=(x * 10.0) as i32)
            .map(|k| (0.1 * f64::from(k), 0.0))
            .collect();
        Plan::Go {
            goal,
            follower: PathFollower::new(path, FollowParams::default()).expect("a path"),
            tight: false,
        }
    }

    fn at(x: f64) -> Pose2 {
        Pose2::new(x, 0.0, 0.0)
    }

    #[test]
    fn it_asks_for_a_plan_at_once_and_not_again_while_one_is_due() {
        let mut s = steering();
        let first = s.step(0.0, at(0.0), OPEN, None);
        let request = first.request.expect("a plan asked for");
        assert_eq!((request.now_s, request.current), (0.0, None));
        assert_eq!(first.drive, Some((0.0, 0.0)), "nothing to follow yet");
        assert!(s.step(5.0, at(0.0), OPEN, None).request.is_none());
    }

    #[test]
    fn a_goal_is_claimed_followed_and_planned_again_after_the_replan_time() {
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        let d = s.step(0.5, at(0.0), OPEN, Some((0.0, go(5.0, false))));
        assert_eq!(d.claim, Some((5.0, 0.0)));
        assert!(matches!(d.events[..], [SteeringEvent::NewGoal { .. }]));
        let (linear, _) = d.drive.expect("driving");
        assert!(linear > 0.0, "{linear}");
        assert!(d.request.is_none(), "planned 0.5 s ago");
        let later = s.step(3.0, at(1.0), OPEN, None);
        let request = later.request.expect("replanned after 3 s");
        assert_eq!(request.current, Some((5.0, 0.0)));
        // The same goal again is no new goal, and is claimed afresh.
        let again = s.step(3.5, at(1.2), OPEN, Some((3.0, go(5.0, false))));
        assert!(again.events.is_empty(), "{:?}", again.events);
        assert_eq!(again.claim, Some((5.0, 0.0)));
    }

    #[test]
    fn a_goal_not_neared_is_barred_and_the_robot_looks_about() {
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        s.step(0.0, at(0.0), OPEN, Some((0.0, go(5.0, false))));
        // Replans of the same goal while the robot stays put.
        for k in 1..=4 {
            let now = 3.0 * f64::from(k);
            let d = s.step(now, at(0.0), OPEN, Some((now, go(5.0, false))));
            assert!(d.events.is_empty(), "{now}: {:?}", d.events);
        }
        let d = s.step(12.5, at(0.0), OPEN, None);
        assert_eq!(d.events, vec![SteeringEvent::Barred { x: 5.0, y: 0.0 }]);
        assert_eq!(d.drive, Some((0.0, 0.0)));
        assert!(s.blacklist().bars(5.0, 0.0, 0.6));
        let turn = s.looking_about(13.0, OPEN).expect("looking about");
        assert_eq!(turn, (0.0, 1.0), "towards the left, as open as the right");
        let right_open = Clearance { left: 0.5, ..OPEN };
        assert_eq!(s.looking_about(13.0, right_open), Some((0.0, -1.0)));
        assert_eq!(s.looking_about(12.5 + LOOK_ABOUT_S, OPEN), None);
        // A plan for the barred goal, made before the bar, is dropped.
        let d = s.step(15.0, at(0.0), OPEN, Some((11.0, go(5.0, false))));
        assert!(d.claim.is_none());
        assert!(d.request.is_some(), "planned again at once");
    }

    #[test]
    fn a_goal_reached_bars_its_frontier_nearby_and_a_look_out_point_its_place() {
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        s.step(0.0, at(0.0), OPEN, Some((0.0, go(3.0, false))));
        let d = s.step(2.0, at(2.9), OPEN, None);
        assert_eq!(d.followed, Some(FollowCommand::Arrived));
        assert_eq!(d.drive, Some((0.0, 0.0)));
        let barred = s.blacklist();
        assert!(barred.bars(3.0, 2.4, 0.0), "frontier within 2.5 m");
        assert!(
            !barred.bars(3.0, 3.5, 0.0),
            "its far end may be seen from elsewhere"
        );
        assert_eq!(s.looking_about(2.5, OPEN), None, "arrived: no look about");

        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        s.step(0.0, at(0.0), OPEN, Some((0.0, go(3.0, true))));
        s.step(2.0, at(2.9), OPEN, None);
        assert!(
            s.blacklist().bars(3.3, 0.0, 0.0),
            "within 0.5 m of the place"
        );
        assert!(s.looking_about(2.5, OPEN).is_some());
    }

    #[test]
    fn blocked_near_the_goal_counts_as_reached_and_far_from_it_does_not() {
        let blocked = Clearance { ahead: 0.2, ..OPEN };
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        s.step(0.0, at(0.0), OPEN, Some((0.0, go(3.0, false))));
        // Along the path, so that the follower passes its points.
        for x in [0.5, 1.0, 1.5, 2.0] {
            s.step(x / 2.0, at(x), OPEN, None);
        }
        let d = s.step(1.1, at(2.2), blocked, None);
        assert_eq!(d.followed, Some(FollowCommand::Blocked));
        assert!(
            s.blacklist().bars(3.0, 1.0, 0.0),
            "reached: its frontier barred"
        );
        assert!(s.looking_about(1.5, OPEN).is_some());

        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        s.step(0.0, at(0.0), OPEN, Some((0.0, go(5.0, false))));
        let d = s.step(1.0, at(1.0), blocked, None);
        assert!(d.events.is_empty());
        assert!(s.blacklist().is_empty(), "blocked far off bars nothing");
        assert!(s.looking_about(1.5, OPEN).is_some());
    }

    #[test]
    fn with_nothing_in_reach_it_stops_after_three_plans_or_its_patience() {
        // No frontier at all: done at the third empty plan.
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        for k in 1..=3 {
            let now = 2.0 * f64::from(k);
            let d = s.step(
                now,
                at(0.0),
                OPEN,
                Some((now - 1.0, Plan::Nothing { frontiers: 0 })),
            );
            assert_eq!(d.finished, k == 3, "plan {k}");
            if k < 3 {
                assert_eq!(d.drive, Some((0.0, 0.0)));
                assert!(d.request.is_none(), "the map catches up first");
                assert!(s.step(now + 0.5, at(0.0), OPEN, None).request.is_none());
                assert!(s.step(now + 1.0, at(0.0), OPEN, None).request.is_some());
            }
        }

        // Frontiers out of reach: it keeps looking for half a minute.
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        let nothing = || Plan::Nothing { frontiers: 2 };
        for now in [2.0, 4.0, 6.0, 20.0] {
            let d = s.step(now, at(0.0), OPEN, Some((now, nothing())));
            assert!(!d.finished, "{now}");
            assert!(
                s.looking_about(now + 1.0, OPEN).is_some(),
                "turns meanwhile"
            );
        }
        assert!(
            s.step(32.5, at(0.0), OPEN, Some((32.0, nothing())))
                .finished
        );
    }

    #[test]
    fn a_look_about_plan_turns_before_anything_else() {
        let mut s = steering();
        s.step(0.0, at(0.0), OPEN, None);
        let d = s.step(1.0, at(0.0), OPEN, Some((0.0, Plan::LookAbout)));
        assert_eq!(d.drive, None, "the last command stays for this state");
        assert!(d.request.is_none());
        assert!(s.looking_about(2.0, OPEN).is_some());
        assert!(s.looking_about(3.0, OPEN).is_none());
        assert!(s.step(3.0, at(0.0), OPEN, None).request.is_some());
    }
}
