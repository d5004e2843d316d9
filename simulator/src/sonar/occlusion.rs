//! Sonar echoes with specular loss on: a wall struck at a grazing angle
//! sends no echo back (or a late one) but still stands in the way, so it
//! hides the walls behind it from the part of the cone it fills.
//!
//! Each cone is a fan of rays, one every [`RAY_SPACING_DEG`] at most, both
//! edges included. Each ray's first wall is found by exact ray–segment
//! tests and judged at the hit: grazing when the angle between the ray and
//! the wall's normal is past the critical incidence. A sonar's echo is the
//! nearest of
//! - each ray's first hit: its distance when not grazing; when grazing,
//!   nothing ([`Specular::Lost`]) or the distance times the factor
//!   ([`Specular::Long`]);
//! - each wall's nearest point inside the cone (the echo the cone model
//!   gives without specular loss), judged the same way, when no other wall
//!   crosses the line from the sensor to it and it is no farther than the
//!   farthest first hit of the fan.
//!
//! With an index of a world's faces ([`SegmentIndex::one_sided`]), a
//! wall seen from its solid side sends no echo: a ray that reaches it
//! there met its obstacle's corner, where the face turned towards the
//! sensor is the one struck.
//!
//! The second keeps an unhidden wall's echo exact (the foot of the
//! perpendicular rarely lies on a ray) and lets a post thinner than the
//! rays' spacing answer; the rays tell what a grazed wall hides. Where a
//! wall is partly hidden, its visible part is known to the rays'
//! resolution.
//!
//! Speed: one walk outward over the walls near the robot, as without
//! specular loss, gathering per sonar the walls inside its wedge within
//! the farthest first hit of its fan; a sonar is settled once every wall
//! still unvisited is farther than that.

use std::ops::ControlFlow;

use deog_world::segment_index::{Visit, distance2};
use deog_world::{Point2, Segment, SegmentIndex};

use super::{MAX_SONARS, SonarRing, Specular, Wedge, nearest_in_wedge};
use crate::laser::ray_hits;

/// The largest angle between two neighbouring rays of a cone's fan,
/// degrees.
pub const RAY_SPACING_DEG: f64 = 2.0;

/// Two first hits this close (metres) are at the same place, a corner:
/// the wall that echoes is preferred over the grazed one.
const TIE_M: f64 = 1e-9;

/// The rays across a cone of half-angle `half_angle` (radians): (cos, sin)
/// of each ray's angle from the axis, evenly spaced from the right edge to
/// the left, at most [`RAY_SPACING_DEG`] apart.
pub(super) fn fan(half_angle: f64) -> Vec<(f64, f64)> {
    // At least the two edges.
    let gaps = (2.0 * half_angle / RAY_SPACING_DEG.to_radians())
        .ceil()
        .max(1.0) as usize;
    (0..=gaps)
        .map(|j| {
            let angle = half_angle * (2.0 * j as f64 / gaps as f64 - 1.0);
            let (sin, cos) = angle.sin_cos();
            (cos, sin)
        })
        .collect()
}

/// A ray's first wall.
#[derive(Debug, Clone, Copy)]
struct FirstHit {
    /// Distance from the sensor, metres; infinite for none.
    distance: f64,
    /// Struck past the critical incidence.
    grazing: bool,
}

const NO_HIT: FirstHit = FirstHit {
    distance: f64::INFINITY,
    grazing: false,
};

impl SonarRing {
    /// Each sonar's echo from its wedge with grazed walls hiding what lies
    /// behind them, unclamped, or `max_range` for none. Sensor `i` lies
    /// within `radius(i)` of `center`, and every sensor within `reach`.
    // Kept out of the frame without specular loss, which it would slow.
    #[inline(never)]
    pub(super) fn occluded_echoes(
        &self,
        index: &SegmentIndex,
        wedges: &[Wedge; MAX_SONARS],
        center: Point2,
        radius: impl Fn(usize) -> f64,
        reach: f64,
        out: &mut [f64],
    ) {
        let n = self.mounts.len();
        // Each sonar's axis, halfway between its wedge's edges.
        let mut axes = [(0.0, 0.0); MAX_SONARS];
        for (axis, w) in axes.iter_mut().zip(&wedges[..n]) {
            let scale = 0.5 / self.cos_half;
            *axis = ((w.rx + w.lx) * scale, (w.ry + w.ly) * scale);
        }
        let rays = self.fan.len();
        let max_range = self.params.max_range;
        let one_sided = index.one_sided();
        let mut hits = vec![NO_HIT; n * rays];
        // Per sonar: the walls met inside its wedge, and how far its fan's
        // farthest first hit is (max_range until every ray has one).
        let mut walls: Vec<Vec<&Segment>> = vec![Vec::new(); n];
        let mut far = [max_range; MAX_SONARS];
        // n <= MAX_SONARS = 64 (checked in `new`).
        let mut active: u64 = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };
        index.visit_outward(center, max_range + reach, |visit| match visit {
            Visit::Wall(wall) => {
                let dc2 = distance2(wall, center);
                let mut mask = active;
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let bound = far[i] + radius(i);
                    let s = &wedges[i];
                    if dc2 < bound * bound && nearest_in_wedge(s, wall).is_some() {
                        walls[i].push(wall);
                        let fan_hits = &mut hits[i * rays..(i + 1) * rays];
                        self.cast_fan(s, axes[i], wall, one_sided, fan_hits);
                    }
                }
                ControlFlow::Continue(())
            }
            Visit::Cleared(cleared) => {
                let mut mask = active;
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    far[i] = hits[i * rays..(i + 1) * rays]
                        .iter()
                        .fold(0.0, |m: f64, h| m.max(h.distance.min(max_range)));
                    // Every unvisited wall is farther than `cleared` from
                    // the centre, so farther than cleared - radius from
                    // the sensor: past every ray's first hit.
                    if far[i] + radius(i) <= cleared {
                        active &= !(1u64 << i);
                    }
                }
                if active == 0 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            }
        });
        for (i, echo) in out[..n].iter_mut().enumerate() {
            let fan_hits = &hits[i * rays..(i + 1) * rays];
            let far = fan_hits
                .iter()
                .fold(0.0, |m: f64, h| m.max(h.distance.min(max_range)));
            *echo = self.nearest_echo(&wedges[i], fan_hits, &walls[i], one_sided, far);
        }
    }

    /// Lowers each ray's first hit in `hits` to where it meets `wall`, if
    /// nearer, for the sonar of wedge `s` whose axis is the unit vector
    /// `(ux, uy)`. A `one_sided` wall seen from its solid side stands in
    /// the way but sends no echo, as if grazed.
    fn cast_fan(
        &self,
        s: &Wedge,
        (ux, uy): (f64, f64),
        wall: &Segment,
        one_sided: bool,
        hits: &mut [FirstHit],
    ) {
        let p = (wall.a.x - s.x, wall.a.y - s.y);
        let (ex, ey) = (wall.b.x - wall.a.x, wall.b.y - wall.a.y);
        let ee = ex * ex + ey * ey;
        let from_behind = one_sided && !faces_sensor(s, wall);
        for (&(cos, sin), hit) in self.fan.iter().zip(hits.iter_mut()) {
            let (dx, dy) = (ux * cos - uy * sin, uy * cos + ux * sin);
            let Some(distance) = ray_hits(dx, dy, p, ex, ey) else {
                continue;
            };
            // cos(incidence) = |d × e| / |e| for the unit ray d.
            let cross = dx * ey - dy * ex;
            let grazing = from_behind || cross * cross < self.cos2_incidence * ee;
            let nearer = distance < hit.distance - TIE_M
                || (distance <= hit.distance + TIE_M && hit.grazing && !grazing);
            if nearer {
                *hit = FirstHit { distance, grazing };
            }
        }
    }

    /// A grazed wall's echo at `distance`: late, or none.
    fn grazed(&self, distance: f64) -> f64 {
        match self.params.specular {
            Specular::Long { factor, .. } => distance * factor,
            Specular::Off | Specular::Lost { .. } => f64::INFINITY,
        }
    }

    /// The sonar's echo from its fan's first hits and the nearest points
    /// of `walls` (every wall inside its wedge within `far`; when
    /// `one_sided`, only those facing the sensor), or `max_range` for
    /// none.
    fn nearest_echo(
        &self,
        s: &Wedge,
        hits: &[FirstHit],
        walls: &[&Segment],
        one_sided: bool,
        far: f64,
    ) -> f64 {
        let mut best = self.params.max_range;
        for hit in hits.iter().filter(|h| h.distance.is_finite()) {
            let echo = if hit.grazing {
                self.grazed(hit.distance)
            } else {
                hit.distance
            };
            best = best.min(echo);
        }
        for (k, wall) in walls.iter().enumerate() {
            if one_sided && !faces_sensor(s, wall) {
                continue;
            }
            let Some(near) = nearest_in_wedge(s, wall) else {
                continue;
            };
            let distance = near.d2.sqrt();
            let echo = if near.grazing(self.cos2_incidence) {
                self.grazed(distance)
            } else {
                distance
            };
            if echo < best && distance <= far && !hidden(s.x, s.y, near.qx, near.qy, walls, k) {
                best = echo;
            }
        }
        best
    }
}

/// Whether the sensor of wedge `s` lies on the free side of the face
/// `wall`, its left from `a` to `b` ([`deog_world::World::faces`]).
fn faces_sensor(s: &Wedge, wall: &Segment) -> bool {
    let (ex, ey) = (wall.b.x - wall.a.x, wall.b.y - wall.a.y);
    ex * (s.y - wall.a.y) - ey * (s.x - wall.a.x) > 0.0
}

/// Whether a wall other than `walls[own]` crosses the line from the sensor
/// at (sx, sy) to the point (qx, qy) (relative to the sensor) before
/// reaching it. A wall through the point itself (a corner) does not count.
fn hidden(sx: f64, sy: f64, qx: f64, qy: f64, walls: &[&Segment], own: usize) -> bool {
    walls.iter().enumerate().any(|(k, w)| {
        if k == own {
            return false;
        }
        let (ax, ay) = (w.a.x - sx, w.a.y - sy);
        let (ex, ey) = (w.b.x - w.a.x, w.b.y - w.a.y);
        let denom = qx * ey - qy * ex;
        if denom == 0.0 {
            // Parallel: it cannot stand across the line.
            return false;
        }
        // sensor + s q = a + u e, for s in [0, 1) and u in [0, 1].
        let s = (ax * ey - ay * ex) / denom;
        let u = (ax * qy - ay * qx) / denom;
        (0.0..1.0 - 1e-9).contains(&s) && (0.0..=1.0).contains(&u)
    })
}

#[cfg(test)]
impl SonarRing {
    /// One sonar's echo with every wall inside its wedge gathered, no
    /// index, no early stop.
    pub(super) fn brute_force_occluded(&self, s: &Wedge, walls: &[Segment]) -> f64 {
        let mut hits = vec![NO_HIT; self.fan.len()];
        let inside: Vec<&Segment> = walls
            .iter()
            .filter(|w| nearest_in_wedge(s, w).is_some())
            .collect();
        let scale = 0.5 / self.cos_half;
        let axis = ((s.rx + s.lx) * scale, (s.ry + s.ly) * scale);
        for wall in &inside {
            self.cast_fan(s, axis, wall, false, &mut hits);
        }
        let max_range = self.params.max_range;
        let far = hits
            .iter()
            .fold(0.0, |m: f64, h| m.max(h.distance.min(max_range)));
        self.nearest_echo(s, &hits, &inside, false, far)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SonarParams;
    use approx::assert_abs_diff_eq;
    use deog_grid::{Pose2, SensorRing};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
        Segment::new(Point2::new(ax, ay), Point2::new(bx, by))
    }

    /// A long wall through (x, 0) whose normal points `normal_deg` from +x.
    fn tilted(x: f64, normal_deg: f64) -> Segment {
        let n = normal_deg.to_radians();
        let (dx, dy) = (-n.sin() * 30.0, n.cos() * 30.0);
        seg(x - dx, -dy, x + dx, dy)
    }

    /// One sonar at the origin facing +x, exact, with `specular`.
    fn single(specular: Specular) -> SonarRing {
        let ring = SensorRing::from_mounts(vec![Pose2::new(0.0, 0.0, 0.0)]).expect("one mount");
        let params = SonarParams {
            specular,
            ..SonarParams::exact()
        };
        SonarRing::new(ring, params).expect("valid params")
    }

    fn read(sonar: &SonarRing, walls: Vec<Segment>) -> f64 {
        let mut out = [0.0];
        sonar
            .true_ranges(&SegmentIndex::new(walls), &Pose2::default(), &mut out)
            .expect("valid input");
        out[0]
    }

    const LOST: Specular = Specular::Lost {
        max_incidence: 0.349_065_850_398_865_9, // 20°
    };

    #[test]
    fn the_fan_spans_the_cone_edges_included_at_most_two_degrees_apart() {
        let rays = fan(15f64.to_radians());
        assert_eq!(rays.len(), 16);
        assert_abs_diff_eq!(rays[0].1, -(15f64.to_radians().sin()), epsilon = 1e-15);
        assert_abs_diff_eq!(rays[15].1, 15f64.to_radians().sin(), epsilon = 1e-15);
        let narrow = fan(1e-3);
        assert_eq!(narrow.len(), 2, "the two edges at least");
    }

    #[test]
    fn a_grazed_wall_filling_the_cone_hides_the_wall_behind() {
        // Struck 35° to 65° from its normal everywhere in the cone: past
        // 20°. Without occlusion the wall at 6 m would answer.
        let walls = vec![tilted(3.0, 50.0), seg(6.0, -20.0, 6.0, 20.0)];
        let lost = single(LOST);
        assert_eq!(read(&lost, walls.clone()), lost.params().max_range);
        let long = single(Specular::Long {
            max_incidence: 20f64.to_radians(),
            factor: 2.0,
        });
        // The late echo of the nearest grazed point, on the cone's edge.
        let edge = 3.0 * 50f64.to_radians().cos() / 35f64.to_radians().cos();
        assert_abs_diff_eq!(read(&long, walls), 2.0 * edge, epsilon = 1e-9);
    }

    #[test]
    fn a_grazed_wall_over_half_the_cone_lets_the_wall_behind_answer_through_the_rest() {
        // From -8.5° to -24° seen from the sensor, its normal 53° off the
        // axis: it fills the right part of the cone, grazed.
        let grazed = seg(2.0, -0.3, 4.0, -1.8);
        let walls = vec![grazed, seg(5.0, -20.0, 5.0, 20.0)];
        let lost = single(LOST);
        assert_abs_diff_eq!(read(&lost, walls), 5.0, epsilon = 1e-9);
        // A short square wall at 4 m behind the grazed one stays hidden;
        // the 5 m wall is heard through the left of the cone.
        let hidden = seg(4.0, -1.0, 4.0, -0.9);
        let walls = vec![grazed, hidden, seg(5.0, -20.0, 5.0, 20.0)];
        assert_abs_diff_eq!(read(&lost, walls.clone()), 5.0, epsilon = 1e-9);
        // Without specular loss the grazed wall answers first.
        let off = single(Specular::Off);
        assert!(read(&off, walls) < 2.1);
    }

    #[test]
    fn head_on_walls_and_thin_posts_still_echo() {
        let lost = single(LOST);
        assert_abs_diff_eq!(
            read(&lost, vec![seg(3.0, -5.0, 3.0, 5.0)]),
            3.0,
            epsilon = 1e-12
        );
        // Within 20° of square on: the nearest point in the cone answers.
        assert_abs_diff_eq!(
            read(&lost, vec![tilted(3.0, 10.0)]),
            3.0 * 10f64.to_radians().cos(),
            epsilon = 1e-9
        );
        // A post on the axis, between the rays at ±1°: still heard.
        assert_abs_diff_eq!(
            read(&lost, vec![seg(3.0, 0.0, 3.0, 0.0)]),
            3.0,
            epsilon = 1e-12
        );
        // And it hides the wall behind it only where it stands.
        let walls = vec![seg(3.0, 0.0, 3.0, 0.0), seg(4.0, -5.0, 4.0, 5.0)];
        assert_abs_diff_eq!(read(&lost, walls), 3.0, epsilon = 1e-12);
    }

    /// map2's table, 1.5 to 3.0 m by 1.5 to 2.3 m, alone in a world.
    fn table() -> deog_world::World {
        let rect = deog_world::Polygon::rectangle(Point2::new(1.5, 1.5), Point2::new(3.0, 2.3));
        deog_world::World::new("table", None, vec![rect]).expect("world")
    }

    fn read_at(sonar: &SonarRing, index: &SegmentIndex, pose: Pose2) -> f64 {
        let mut out = [0.0];
        sonar
            .true_ranges(index, &pose, &mut out)
            .expect("valid input");
        out[0]
    }

    #[test]
    fn a_box_corner_is_not_heard_through_the_box() {
        let sonar = single(Specular::Lost {
            max_incidence: 30f64.to_radians(),
        });
        let world = table();
        // Above and left of the table, looking down past its near corner:
        // both faces there are struck past 30°; the far corner (1.5, 1.5)
        // lies square to the bottom face, which faces away.
        let pose = Pose2::new(1.2, 2.76, (-78f64).to_radians());
        let two_sided = read_at(&sonar, &SegmentIndex::new(world.walls()), pose);
        assert_abs_diff_eq!(two_sided, 0.3f64.hypot(1.26), epsilon = 1e-9);
        let faces = SegmentIndex::of_world(&world);
        assert!(faces.one_sided());
        assert_eq!(read_at(&sonar, &faces, pose), sonar.params().max_range);
        // Square on to its left face, the table still answers.
        let facing = Pose2::new(0.5, 1.9, 0.0);
        assert_abs_diff_eq!(read_at(&sonar, &faces, facing), 1.0, epsilon = 1e-9);
    }

    #[test]
    fn a_corner_met_square_on_by_one_wall_echoes() {
        // A room corner ahead: the wall at x = 3 is square on, the side
        // wall at y = 0.5 grazed; the corner they share answers.
        let walls = vec![seg(3.0, 0.5, 3.0, -5.0), seg(0.0, 0.5, 3.0, 0.5)];
        let lost = single(LOST);
        assert_abs_diff_eq!(read(&lost, walls), 3.0, epsilon = 1e-9);
    }

    #[test]
    fn the_indexed_frame_equals_gathering_every_wall() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let walls: Vec<Segment> = (0..300)
            .map(|_| {
                let (x, y) = (rng.random_range(0.0..30.0), rng.random_range(0.0..20.0));
                let len = rng.random_range(0.0..4.0);
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                seg(x, y, x + len * a.cos(), y + len * a.sin())
            })
            .collect();
        let index = SegmentIndex::new(walls.clone());
        let sonar = SonarRing::new(
            SensorRing::scout(),
            SonarParams {
                specular: Specular::Long {
                    max_incidence: 0.6,
                    factor: 1.5,
                },
                ..SonarParams::exact()
            },
        )
        .expect("valid params");
        let mut out = [0.0; 16];
        for _ in 0..200 {
            let pose = Pose2::new(
                rng.random_range(0.0..30.0),
                rng.random_range(0.0..20.0),
                rng.random_range(-4.0..4.0),
            );
            sonar.true_ranges(&index, &pose, &mut out).expect("valid");
            let wedges = sonar.wedges(&pose);
            for (i, &r) in out.iter().enumerate() {
                let expected = sonar
                    .brute_force_occluded(&wedges[i], &walls)
                    .clamp(sonar.params().min_range, sonar.params().max_range);
                assert_eq!(r, expected, "sonar {i} at {pose:?}");
            }
        }
    }
}
