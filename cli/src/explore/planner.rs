//! The planning half of `deog explore`: reads the map's changed tiles and
//! the other explorers' goals, and plans on them with
//! `deog_explore::plan_on`. It runs as a task of its own, so the robot
//! keeps being steered, and stopped short of walls, meanwhile.

use anyhow::{Context, Result};
use deog_explore::{Plan, PlanRequest, PlanSettings, plan_on};
use deog_grid::{
    CellBox, CellIndex, Occupancy, OccupancyThresholds, OccupancyView, Resolution, TileSize,
};
use deog_robot_client::{MapClient, TileCache};
use deog_simulator::deog_rig::Rig;

use super::{ExploreArgs, follow_params};

/// Cells of unknown margin kept around the robot and the map in a window.
const WINDOW_MARGIN_CELLS: i32 = 40;
/// Simulated seconds another explorer's goal counts without news of it.
const CLAIM_LIFETIME_S: f64 = 120.0;
/// Simulated seconds a robot spends looking again at the bands the map
/// has seen but not decided, from the first: where the map has many
/// (along every wall of a large building) more looks change little, and
/// the robot must stop some time.
const UNDECIDED_BUDGET_S: f64 = 60.0;

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
    pub(super) settings: PlanSettings,
    /// When the robot first went to look again at what the map has seen
    /// but not decided, simulated seconds.
    undecided_from_s: Option<f64>,
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
        let settings = PlanSettings::for_robot(
            rig.body_radius(),
            resolution,
            args.plan_resolution_m,
            args.min_frontier_m,
            follow_params(args)?,
        );
        Ok(Self {
            robot: args.robot.clone(),
            map: map.to_string(),
            client,
            cache: TileCache::new(map, tile_size),
            settings,
            undecided_from_s: None,
        })
    }

    /// Reads what changed on the map, then plans from the request's pose.
    async fn plan(&mut self, request: &PlanRequest) -> Result<Plan> {
        let began = std::time::Instant::now();
        let PlanRequest { pose, now_s, .. } = *request;
        let info = self.client.map_info(&self.map).await?;
        let robot = self.settings.resolution.cell_of(pose.x, pose.y)?;
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
        let look_again = self
            .undecided_from_s
            .is_none_or(|from| request.now_s - from < UNDECIDED_BUDGET_S);
        let view = CachedMap {
            cache: &self.cache,
            thresholds: OccupancyThresholds::default(),
        };
        let thresholds = OccupancyThresholds::default();
        let undecided = |cell| {
            let belief = self.cache.cell(cell);
            belief.is_some() && thresholds.classify(belief) == Occupancy::Unknown
        };
        // Planning is seconds of CPU on a large map at fine cells: off the
        // runtime's workers, or the steering task waiting behind it on the
        // same worker drives blind on its last command meanwhile.
        let outcome = tokio::task::block_in_place(|| {
            plan_on(
                &view,
                undecided,
                region,
                &claims,
                request,
                look_again,
                &self.settings,
            )
        })?;
        tracing::debug!(
            cells = outcome.cells,
            frontiers = outcome.frontiers,
            ms = began.elapsed().as_secs_f64() * 1e3,
            "planned"
        );
        if outcome.looked_again && self.undecided_from_s.is_none() {
            tracing::info!("no frontier left: looking again at what the map has not decided");
            self.undecided_from_s = Some(request.now_s);
        }
        Ok(outcome.plan)
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
