//! The planning half of `deog explore`: reads the map's changed tiles,
//! finds the frontiers, prices every cell from the robot at once and
//! picks a goal and the path to it. It runs as a task of its own, so the
//! robot keeps being steered, and stopped short of walls, meanwhile.
//!
//! A plan is tried on the map's cells merged to about 10 cm, then on its
//! own cells with a narrower margin, then with a margin of a few
//! centimetres (a sonar's cones narrow gaps on the map). Frontiers left
//! out of reach even so are looked at from the reachable cell nearest
//! them; with no frontier left, the bands the map has seen but not decided
//! are looked at again from near, for a minute.

use anyhow::{Context, Result, bail};
use deog_explore::{
    Blacklist, CostParams, Costmap, FollowParams, Frontier, Goal, GoalParams, OccupancyWindow,
    PathFollower, Plan, PlanRequest, TravelCosts, approach_goal, choose_goal_keeping,
    find_frontiers, find_undecided,
};
use deog_grid::{
    CellBox, CellIndex, Occupancy, OccupancyThresholds, OccupancyView, Pose2, Resolution, TileSize,
};
use deog_robot_client::{MapClient, TileCache};
use deog_simulator::deog_rig::Rig;

use super::{ExploreArgs, follow_params};

/// Cells of unknown margin kept around the robot and the map in a window.
const WINDOW_MARGIN_CELLS: i32 = 40;
/// Simulated seconds another explorer's goal counts without news of it.
const CLAIM_LIFETIME_S: f64 = 120.0;
/// Bands the map has seen but not decided shorter than this, metres, are
/// not worth a look.
const UNDECIDED_MIN_M: f64 = 0.3;
/// Simulated seconds a robot spends looking again at such bands, from the
/// first: where the map has many (along every wall of a large building)
/// more looks change little, and the robot must stop some time.
const UNDECIDED_BUDGET_S: f64 = 60.0;
/// A frontier no path reaches is looked at from the reachable cell nearest
/// it, if one lies within this distance, metres.
const APPROACH_REACH_M: f64 = 2.0;
/// The margin past the body's radius of the last attempt at a plan, metres.
const SQUEEZE_MARGIN_M: f64 = 0.05;
/// A tight plan's share of the cruise speed, and of the distances at
/// which the robot slows and stops short of an echo.
const TIGHT_SPEED_SHARE: f64 = 0.5;

/// The map as the explorer reads it: the cache's cells classified.
struct CachedMap<'a> {
    cache: &'a TileCache,
    thresholds: OccupancyThresholds,
}

impl OccupancyView for CachedMap<'_> {
    fn occupancy(&self, cell: CellIndex) -> Occupancy {
        self.thresholds.classify(self.cache.cell(cell))
    }
}

/// The planning half: reads the map and picks goals. It runs as a task of
/// its own, so that the robot keeps being steered, and stopped short of
/// walls, while a plan is worked out.
pub(super) struct Planner {
    robot: String,
    map: String,
    client: MapClient,
    cache: TileCache,
    resolution: Resolution,
    costs: CostParams,
    /// The costs on the map's own cells, where a narrower margin suffices.
    fine_costs: CostParams,
    /// The last resort on the map's own cells: a margin of a few
    /// centimetres, for gaps a sonar's cones have narrowed on the map
    /// (the follower's own ranges still stop the robot short of a wall).
    squeeze_costs: CostParams,
    pub(super) goals: GoalParams,
    pub(super) follow: FollowParams,
    min_frontier_m: f64,
    /// Map cells merged into a planning cell, per side.
    coarsening: u32,
    /// When the robot first went to look again at what the map has seen
    /// but not decided, simulated seconds.
    undecided_from_s: Option<f64>,
}

/// One attempt at a plan, on cells of one size.
struct Attempt {
    window: OccupancyWindow,
    costs: TravelCosts,
    chosen: Option<Goal>,
    frontiers: Vec<Frontier>,
    known_nearby: bool,
}

impl Planner {
    pub(super) async fn new(
        client: MapClient,
        map: &str,
        rig: &Rig,
        args: &ExploreArgs,
    ) -> Result<Self> {
        let info = client
            .map_info(map)
            .await
            .with_context(|| format!("map {map:?}: is its cartographer running?"))?;
        let resolution = Resolution::new(info.resolution_m)?;
        let tile_size = TileSize::new(info.tile_size)?;
        let costs = CostParams {
            // Paths are planned on 10 cm cells: the margin covers their
            // half-diagonal as well as the pursuit's cutting of corners.
            lethal_radius_m: rig.body_radius() + 0.15,
            inflation_m: rig.body_radius() + 0.6,
            ..CostParams::default()
        };
        // On the map's own (5 cm) cells the half-diagonal is smaller, so a
        // gap 5 cm narrower still lets the robot through.
        let fine_costs = CostParams {
            lethal_radius_m: rig.body_radius() + 0.15 - resolution.metres(),
            ..costs
        };
        Ok(Self {
            robot: args.robot.clone(),
            map: map.to_string(),
            client,
            cache: TileCache::new(map, tile_size),
            resolution,
            costs,
            fine_costs,
            squeeze_costs: CostParams {
                lethal_radius_m: rig.body_radius() + SQUEEZE_MARGIN_M,
                ..costs
            },
            goals: GoalParams::default(),
            follow: follow_params(args)?,
            min_frontier_m: args.min_frontier_m,
            coarsening: (args.plan_resolution_m / resolution.metres())
                .round()
                .max(1.0) as u32,
            undecided_from_s: None,
        })
    }

    /// Reads what changed on the map, then plans from the request's pose.
    async fn plan(&mut self, request: &PlanRequest) -> Result<Plan> {
        let began = std::time::Instant::now();
        let PlanRequest { pose, now_s, .. } = *request;
        let info = self.client.map_info(&self.map).await?;
        let robot = self.resolution.cell_of(pose.x, pose.y)?;
        let around = CellBox::new(
            CellIndex::new(robot.x - WINDOW_MARGIN_CELLS, robot.y - WINDOW_MARGIN_CELLS),
            CellIndex::new(robot.x + WINDOW_MARGIN_CELLS, robot.y + WINDOW_MARGIN_CELLS),
        )
        .context("a window around the robot")?;
        let region = match info.bounds_cells {
            Some(b) => CellBox::new(
                CellIndex::new(b.min_x - WINDOW_MARGIN_CELLS, b.min_y - WINDOW_MARGIN_CELLS),
                CellIndex::new(b.max_x + WINDOW_MARGIN_CELLS, b.max_y + WINDOW_MARGIN_CELLS),
            )
            .map_or(around, |map| map.union(&around)),
            None => around,
        };
        self.cache.refresh(&self.client, region).await?;
        let claims = self.claims(now_s).await?;
        // Planning is seconds of CPU on a large map at fine cells: off the
        // runtime's workers, or the steering task waiting behind it on the
        // same worker drives blind on its last command meanwhile.
        let look_again = self
            .undecided_from_s
            .is_none_or(|from| request.now_s - from < UNDECIDED_BUDGET_S);
        let (plan, looked_again) = tokio::task::block_in_place(|| {
            self.plan_on_cells(began, region, &claims, request, look_again)
        })?;
        if looked_again && self.undecided_from_s.is_none() {
            tracing::info!("no frontier left: looking again at what the map has not decided");
            self.undecided_from_s = Some(request.now_s);
        }
        Ok(plan)
    }

    /// [`Self::plan`]'s work once the map and the claims are read: the
    /// windows, the costs, the goal and the path to it.
    fn plan_on_cells(
        &self,
        began: std::time::Instant,
        region: CellBox,
        claims: &[(f64, f64)],
        &PlanRequest {
            pose,
            current,
            ref blacklist,
            ..
        }: &PlanRequest,
        look_again: bool,
    ) -> Result<(Plan, bool)> {
        let view = CachedMap {
            cache: &self.cache,
            thresholds: OccupancyThresholds::default(),
        };
        let fine = OccupancyWindow::from_view(&view, region, self.resolution)?;
        let request = (pose, current, blacklist);
        let mut attempt = self.attempt(
            fine.coarsened(self.coarsening)?,
            self.costs,
            claims,
            request,
        )?;
        // Nothing reachable on merged cells may be a gap they close: look
        // again on the map's own cells before giving up.
        let mut tight = false;
        if attempt.chosen.is_none() && self.coarsening > 1 {
            attempt = self.attempt(fine.clone(), self.fine_costs, claims, request)?;
            tight = true;
        }
        // Still nothing, with frontiers left: squeeze through.
        if attempt.chosen.is_none() && !attempt.frontiers.is_empty() {
            attempt = self.attempt(fine, self.squeeze_costs, claims, request)?;
            tight = true;
        }
        // No frontier at all: look again, from near, at what the map has
        // seen but not decided, for a while.
        let mut looked_again = false;
        if attempt.chosen.is_none() && attempt.frontiers.is_empty() && look_again {
            attempt.chosen = self.undecided_goal(&attempt, claims, request);
            looked_again = attempt.chosen.is_some();
            tight = true;
        }
        // Frontiers left, none in reach even so: go and look at one from
        // as near as the robot can get.
        if attempt.chosen.is_none() && !attempt.frontiers.is_empty() {
            attempt.chosen = approach_goal(
                &attempt.window,
                &attempt.frontiers,
                &attempt.costs,
                blacklist,
                APPROACH_REACH_M,
                &self.goals,
            );
        }
        tracing::debug!(
            cells = attempt.window.len(),
            frontiers = attempt.frontiers.len(),
            ms = began.elapsed().as_secs_f64() * 1e3,
            "planned"
        );
        let Attempt {
            window,
            costs,
            chosen,
            frontiers,
            known_nearby,
        } = attempt;
        let Some(goal) = chosen else {
            if !known_nearby {
                return Ok((Plan::LookAbout, false));
            }
            return Ok((
                Plan::Nothing {
                    frontiers: frontiers.len(),
                },
                false,
            ));
        };
        let goal_index = window
            .index_of(goal.cell)
            .context("the goal lies in the window")?;
        let path = costs
            .path_to(&window, goal_index)
            .context("a reachable goal has a path")?
            .into_iter()
            .map(|cell| window.centre_of(cell))
            .collect();
        // Through a tight gap the robot goes slower, and so may come
        // nearer an echo before it stops: between pillars it could not
        // pass otherwise.
        let follow = if tight {
            FollowParams {
                cruise_speed: self.follow.cruise_speed * TIGHT_SPEED_SHARE,
                stop_distance_m: self.follow.stop_distance_m * TIGHT_SPEED_SHARE,
                slow_distance_m: self.follow.slow_distance_m * TIGHT_SPEED_SHARE,
                ..self.follow
            }
        } else {
            self.follow
        };
        Ok((
            Plan::Go {
                goal,
                follower: PathFollower::new(path, follow)?,
                tight,
            },
            looked_again,
        ))
    }

    /// Inflates `window` with `params` and chooses a goal on it.
    fn attempt(
        &self,
        window: OccupancyWindow,
        params: CostParams,
        claims: &[(f64, f64)],
        (pose, current, blacklist): (Pose2, Option<(f64, f64)>, &Blacklist),
    ) -> Result<Attempt> {
        let robot = window.resolution().cell_of(pose.x, pose.y)?;
        let costmap = Costmap::inflate(&window, params);
        let Some(costs) = TravelCosts::from(&window, &costmap, robot) else {
            bail!("the robot's cell lies outside its own window");
        };
        let known_nearby = window
            .neighbours(window.index_of(robot).unwrap_or(0))
            .any(|(i, _)| window.at(i) == Occupancy::Free);
        let frontiers = find_frontiers(&window, self.min_frontier_m);
        let chosen = choose_goal_keeping(
            &window,
            &frontiers,
            &costs,
            claims,
            blacklist,
            current,
            &self.goals,
        );
        Ok(Attempt {
            frontiers,
            window,
            costs,
            chosen,
            known_nearby,
        })
    }

    /// The best of the bands the map has observed but not decided, beside
    /// free cells, on `attempt`'s window and costs (at the map's own
    /// cells); `None` if none is reachable or worth a look.
    fn undecided_goal(
        &self,
        attempt: &Attempt,
        claims: &[(f64, f64)],
        (_, current, blacklist): (Pose2, Option<(f64, f64)>, &Blacklist),
    ) -> Option<Goal> {
        let window = &attempt.window;
        if window.resolution() != self.resolution {
            return None;
        }
        let thresholds = OccupancyThresholds::default();
        let undecided: Vec<bool> = (0..window.len())
            .map(|index| {
                let belief = self.cache.cell(window.cell_at(index));
                belief.is_some() && thresholds.classify(belief) == Occupancy::Unknown
            })
            .collect();
        let bands = find_undecided(window, &undecided, UNDECIDED_MIN_M);
        let goal = choose_goal_keeping(
            window,
            &bands,
            &attempt.costs,
            claims,
            blacklist,
            current,
            &self.goals,
        );
        tracing::debug!(
            bands = bands.len(),
            chosen = goal.is_some(),
            "undecided bands"
        );
        goal
    }

    /// The goals other explorers hold on the map: active, and set within
    /// the last two minutes (an explorer that died says nothing more).
    async fn claims(&self, now_s: f64) -> Result<Vec<(f64, f64)>> {
        Ok(self
            .client
            .goals(&self.map)
            .await
            .context("reading the other explorers' goals")?
            .into_iter()
            .filter(|g| {
                g.active && g.robot != self.robot && (now_s - g.time_s).abs() < CLAIM_LIFETIME_S
            })
            .map(|g| (g.x, g.y))
            .collect())
    }
}

/// Plans one request at a time, as the steering loop asks, until it stops
/// asking.
pub(super) fn spawn_planner(
    mut planner: Planner,
) -> (
    tokio::sync::mpsc::Sender<PlanRequest>,
    tokio::sync::mpsc::Receiver<Result<(PlanRequest, Plan)>>,
) {
    let (requests, mut asked) = tokio::sync::mpsc::channel::<PlanRequest>(1);
    let (answers, plans) = tokio::sync::mpsc::channel(1);
    tokio::spawn(async move {
        while let Some(request) = asked.recv().await {
            let plan = planner.plan(&request).await.map(|plan| (request, plan));
            if answers.send(plan).await.is_err() {
                break;
            }
        }
    });
    (requests, plans)
}
