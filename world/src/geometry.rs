//! Planar geometry of worlds: points, segments and polygons, in metres.

/// A point in the world frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point2 {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
}

impl Point2 {
    /// A point from its coordinates.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Euclidean distance to `other`.
    #[inline]
    pub fn distance(self, other: Point2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }
}

/// A wall: the straight segment from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: Point2,
    /// The other end.
    pub b: Point2,
}

impl Segment {
    /// A segment between two points.
    pub const fn new(a: Point2, b: Point2) -> Self {
        Self { a, b }
    }

    /// Length, metres.
    #[inline]
    pub fn length(&self) -> f64 {
        self.a.distance(self.b)
    }

    /// The point of the segment nearest to `p`.
    #[inline]
    pub fn closest_point(&self, p: Point2) -> Point2 {
        let (dx, dy) = (self.b.x - self.a.x, self.b.y - self.a.y);
        let len2 = dx * dx + dy * dy;
        if len2 == 0.0 {
            return self.a;
        }
        let t = (((p.x - self.a.x) * dx + (p.y - self.a.y) * dy) / len2).clamp(0.0, 1.0);
        Point2::new(self.a.x + t * dx, self.a.y + t * dy)
    }

    /// Distance from `p` to the segment.
    #[inline]
    pub fn distance_to(&self, p: Point2) -> f64 {
        self.closest_point(p).distance(p)
    }
}

/// A simple polygon (an obstacle), its vertices in order; the last joins the
/// first. At least three vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    vertices: Vec<Point2>,
}

impl Polygon {
    /// A polygon from at least three finite vertices; `None` otherwise.
    pub fn new(vertices: Vec<Point2>) -> Option<Self> {
        let finite = vertices.iter().all(|p| p.x.is_finite() && p.y.is_finite());
        (vertices.len() >= 3 && finite).then_some(Self { vertices })
    }

    /// An axis-aligned rectangle.
    pub fn rectangle(min: Point2, max: Point2) -> Self {
        Self {
            vertices: vec![
                min,
                Point2::new(max.x, min.y),
                max,
                Point2::new(min.x, max.y),
            ],
        }
    }

    /// The vertices, in order.
    pub fn vertices(&self) -> &[Point2] {
        &self.vertices
    }

    /// The edges, each vertex to the next, the last back to the first.
    pub fn edges(&self) -> impl Iterator<Item = Segment> + '_ {
        let n = self.vertices.len();
        (0..n).map(move |i| Segment::new(self.vertices[i], self.vertices[(i + 1) % n]))
    }

    /// Twice the signed area (shoelace): positive when the vertices run
    /// counter-clockwise, negative when clockwise.
    pub fn signed_area2(&self) -> f64 {
        self.edges().map(|e| e.a.x * e.b.y - e.b.x * e.a.y).sum()
    }

    /// The edges, each oriented with the polygon's inside on its left
    /// (`inside_left`) or on its right: counter-clockwise or clockwise
    /// whatever order the vertices were given in.
    pub fn oriented_edges(&self, inside_left: bool) -> impl Iterator<Item = Segment> + '_ {
        let flip = (self.signed_area2() > 0.0) != inside_left;
        self.edges()
            .map(move |e| if flip { Segment::new(e.b, e.a) } else { e })
    }

    /// Whether `p` is inside (even-odd rule; points on an edge may go
    /// either way).
    pub fn contains(&self, p: Point2) -> bool {
        let mut inside = false;
        for edge in self.edges() {
            let (a, b) = (edge.a, edge.b);
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// The axis-aligned bounding box, (min, max).
    pub fn bounds(&self) -> (Point2, Point2) {
        let mut min = Point2::new(f64::INFINITY, f64::INFINITY);
        let mut max = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
        for p in &self.vertices {
            min = Point2::new(min.x.min(p.x), min.y.min(p.y));
            max = Point2::new(max.x.max(p.x), max.y.max(p.y));
        }
        (min, max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_clamps_to_the_ends() {
        let s = Segment::new(Point2::new(0.0, 0.0), Point2::new(2.0, 0.0));
        assert_eq!(
            s.closest_point(Point2::new(1.0, 3.0)),
            Point2::new(1.0, 0.0)
        );
        assert_eq!(
            s.closest_point(Point2::new(-1.0, 1.0)),
            Point2::new(0.0, 0.0)
        );
        assert!((s.distance_to(Point2::new(3.0, 0.0)) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn oriented_edges_run_the_asked_way_whatever_the_vertices_order() {
        let square = |points: &[(f64, f64)]| {
            Polygon::new(points.iter().map(|&(x, y)| Point2::new(x, y)).collect()).expect("square")
        };
        let ccw = square(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        let cw = square(&[(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)]);
        assert!(ccw.signed_area2() > 0.0 && cw.signed_area2() < 0.0);
        for polygon in [&ccw, &cw] {
            for inside_left in [true, false] {
                for e in polygon.oriented_edges(inside_left) {
                    // The centre (0.5, 0.5) is left of a→b when the cross
                    // product of b − a and centre − a is positive.
                    let cross = (e.b.x - e.a.x) * (0.5 - e.a.y) - (e.b.y - e.a.y) * (0.5 - e.a.x);
                    assert_eq!(cross > 0.0, inside_left, "{e:?}");
                }
            }
        }
    }

    #[test]
    fn an_l_shape_contains_its_corner_but_not_its_notch() {
        let l = Polygon::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(2.0, 1.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 2.0),
            Point2::new(0.0, 2.0),
        ])
        .expect("polygon");
        assert!(l.contains(Point2::new(0.5, 0.5)));
        assert!(l.contains(Point2::new(0.5, 1.5)));
        assert!(!l.contains(Point2::new(1.5, 1.5)));
        assert_eq!(l.edges().count(), 6);
        assert!(Polygon::new(vec![Point2::new(0.0, 0.0), Point2::new(1.0, 0.0)]).is_none());
    }
}
