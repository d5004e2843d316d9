//! A world: polygon obstacles inside an optional boundary, in metres.

use crate::error::WorldError;
use crate::geometry::{Point2, Polygon, Segment};

/// The ground truth robots move and sense in. Free space is inside the
/// boundary (when there is one) and outside every obstacle.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    name: String,
    boundary: Option<Polygon>,
    obstacles: Vec<Polygon>,
    bounds: (Point2, Point2),
}

impl World {
    /// A world from its parts. Without a boundary the world's extent is the
    /// obstacles' bounding box. Errors when there is nothing to bound it.
    pub fn new(
        name: impl Into<String>,
        boundary: Option<Polygon>,
        obstacles: Vec<Polygon>,
    ) -> Result<Self, WorldError> {
        let name = name.into();
        let mut boxes = boundary.iter().chain(obstacles.iter()).map(Polygon::bounds);
        let Some(first) = boxes.next() else {
            return Err(WorldError::EmptyWorld(name));
        };
        let bounds = boxes.fold(first, |(min, max), (a, b)| {
            (
                Point2::new(min.x.min(a.x), min.y.min(a.y)),
                Point2::new(max.x.max(b.x), max.y.max(b.y)),
            )
        });
        Ok(Self {
            name,
            boundary,
            obstacles,
            bounds,
        })
    }

    /// The world's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The outer wall, if any: robots live inside it.
    pub fn boundary(&self) -> Option<&Polygon> {
        self.boundary.as_ref()
    }

    /// The obstacles.
    pub fn obstacles(&self) -> &[Polygon] {
        &self.obstacles
    }

    /// Axis-aligned extent, (min, max), metres.
    pub fn bounds(&self) -> (Point2, Point2) {
        self.bounds
    }

    /// Every wall: the edges of the boundary and of each obstacle.
    pub fn walls(&self) -> Vec<Segment> {
        self.boundary
            .iter()
            .chain(self.obstacles.iter())
            .flat_map(Polygon::edges)
            .collect()
    }

    /// Every wall as a face: oriented so that free space lies on its left
    /// (from `a` to `b`), the boundary's edges counter-clockwise and each
    /// obstacle's clockwise. A surface echoes only towards its free side;
    /// a sensor on a face's right sees it from inside solid matter.
    pub fn faces(&self) -> Vec<Segment> {
        self.boundary
            .iter()
            .flat_map(|b| b.oriented_edges(true))
            .chain(self.obstacles.iter().flat_map(|o| o.oriented_edges(false)))
            .collect()
    }

    /// Whether `p` lies in free space (inside the boundary, inside the
    /// bounds, outside every obstacle). Ignores the robot's size.
    pub fn is_free(&self, p: Point2) -> bool {
        let (min, max) = self.bounds;
        let within = p.x >= min.x && p.x <= max.x && p.y >= min.y && p.y <= max.y;
        within
            && self.boundary.as_ref().is_none_or(|b| b.contains(p))
            && !self.obstacles.iter().any(|o| o.contains(p))
    }
}
