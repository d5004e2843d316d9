//! Scan matching of one pose against a distance field: the filter's
//! estimate, refined to the pose at which a frame's echoes lie nearest the
//! map's walls.
//!
//! The particle filter's estimate is the mean of a cluster of particles,
//! each moved with noise and scored with a tempered, clamped model: it
//! follows the robot well, but a few centimetres off where the frame
//! fits best. Starting from it, Gauss–Newton minimises
//!
//! `Σₖ dₖ(p)² / σ² + (p − p₀)ᵀ P (p − p₀)`
//!
//! over the pose `p`, where `dₖ(p)` is echo `k`'s distance to the nearest
//! occupied cell (the field bilinearly interpolated between cell centres,
//! so that it has a gradient), taken only for echoes within
//! [`RefineParams::inlier_distance`] of a wall (the others met something
//! the map does not hold) and weighted down the farther they are
//! (Cauchy weights), and `P` a weak prior that holds `p` near the
//! filter's `p₀` along directions the echoes say nothing about (a
//! corridor's length). The refined pose is kept only when enough echoes
//! agree with it, their fit improved, and it lies within
//! [`RefineParams::max_shift_m`] and [`RefineParams::max_turn_rad`] of
//! the filter's: the refinement polishes an estimate, it never relocates
//! one.
//!
//! The refinement touches only what is reported: the particles are left
//! as the filter made them.

use deog_grid::Pose2;

use crate::distance_field::{FIELD_UNKNOWN, FieldCodes, FieldSpec};
use crate::error::{LocalizerError, within};

/// How an estimate is refined.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineParams {
    /// Gauss–Newton iterations at most.
    pub iterations: usize,
    /// Echoes farther than this from a wall, metres, are left out.
    pub inlier_distance: f64,
    /// σ of an echo's distance to the wall it met, metres.
    pub sigma_m: f64,
    /// Scale of the Cauchy weights, metres: an echo this far from a wall
    /// counts half as much as one on it.
    pub robust_scale_m: f64,
    /// σ of the prior on the filter's position, metres.
    pub prior_std_m: f64,
    /// σ of the prior on the filter's heading, radians.
    pub prior_std_rad: f64,
    /// The refined pose is dropped if farther than this from the
    /// filter's, metres.
    pub max_shift_m: f64,
    /// ... or turned more than this from it, radians.
    pub max_turn_rad: f64,
    /// The least share of a frame's echoes that must be inliers.
    pub min_inlier_share: f64,
    /// The least number of inliers.
    pub min_inliers: usize,
}

impl Default for RefineParams {
    /// Ten iterations; echoes within 0.15 m of a wall, σ 0.05 m, Cauchy
    /// weights of scale 0.05 m; a prior
    /// of 0.1 m and 0.1 rad; kept within 0.25 m and 0.1 rad of the filter
    /// when at least 20 echoes and a quarter of the frame agree.
    fn default() -> Self {
        Self {
            iterations: 10,
            inlier_distance: 0.15,
            sigma_m: 0.05,
            robust_scale_m: 0.05,
            prior_std_m: 0.1,
            prior_std_rad: 0.1,
            max_shift_m: 0.25,
            max_turn_rad: 0.1,
            min_inlier_share: 0.25,
            min_inliers: 20,
        }
    }
}

impl RefineParams {
    /// The parameters if each is in range.
    pub fn validate(self) -> Result<Self, LocalizerError> {
        if !(1..=100).contains(&self.iterations) {
            return Err(LocalizerError::Invalid(format!(
                "iterations must be in [1, 100], got {}",
                self.iterations
            )));
        }
        within("inlier_distance", self.inlier_distance, 0.01, 20.0)?;
        within("sigma_m", self.sigma_m, 1e-3, 5.0)?;
        within("robust_scale_m", self.robust_scale_m, 1e-3, 20.0)?;
        within("prior_std_m", self.prior_std_m, 1e-3, 100.0)?;
        within("prior_std_rad", self.prior_std_rad, 1e-3, 10.0)?;
        within("max_shift_m", self.max_shift_m, 0.0, 100.0)?;
        within("max_turn_rad", self.max_turn_rad, 0.0, std::f64::consts::PI)?;
        within("min_inlier_share", self.min_inlier_share, 0.0, 1.0)?;
        Ok(self)
    }
}

/// A refined pose and how well the frame fits there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// The pose.
    pub pose: Pose2,
    /// Echoes within the inlier distance of a wall at the pose.
    pub inliers: usize,
    /// Their root-mean-square distance to the wall, metres.
    pub rms_distance_m: f64,
}

/// A distance to the nearest occupied cell, continuous in position.
pub trait DistanceLookup {
    /// The distance at `(x, y)`, metres, and its gradient; `None` where
    /// the map does not know.
    fn distance_at(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])>;
}

/// A field's codes, bilinearly interpolated between cell centres.
#[derive(Debug)]
pub struct InterpolatedField<'a, F> {
    codes: &'a F,
    spec: FieldSpec,
    cell_m: f64,
}

impl<'a, F: FieldCodes> InterpolatedField<'a, F> {
    /// The field of `codes` quantized by `spec`, on cells `cell_m` wide.
    pub fn new(codes: &'a F, spec: FieldSpec, cell_m: f64) -> Self {
        Self {
            codes,
            spec,
            cell_m,
        }
    }

    fn at_cell(&self, cx: f64, cy: f64) -> Option<f64> {
        let m = self.cell_m;
        let code = self.codes.code_at((cx + 0.5) * m, (cy + 0.5) * m);
        (code != FIELD_UNKNOWN).then(|| f64::from(code) * self.spec.step())
    }
}

impl<F: FieldCodes> DistanceLookup for InterpolatedField<'_, F> {
    fn distance_at(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        let u = x / self.cell_m - 0.5;
        let v = y / self.cell_m - 0.5;
        let (cx, cy) = (u.floor(), v.floor());
        let (fx, fy) = (u - cx, v - cy);
        let d00 = self.at_cell(cx, cy)?;
        let d10 = self.at_cell(cx + 1.0, cy)?;
        let d01 = self.at_cell(cx, cy + 1.0)?;
        let d11 = self.at_cell(cx + 1.0, cy + 1.0)?;
        let bottom = d00 + (d10 - d00) * fx;
        let top = d01 + (d11 - d01) * fx;
        let d = bottom + (top - bottom) * fy;
        let gx = ((d10 - d00) * (1.0 - fy) + (d11 - d01) * fy) / self.cell_m;
        let gy = (top - bottom) / self.cell_m;
        Some((d, [gx, gy]))
    }
}

/// `start` refined so that `endpoints` (echo endpoints in the robot's
/// frame, metres) lie nearest the walls of `field`; `None` when the
/// refinement is not to be trusted (see the module's documentation).
pub fn refine_pose(
    field: &impl DistanceLookup,
    endpoints: &[(f64, f64)],
    start: &Pose2,
    params: &RefineParams,
) -> Option<Refined> {
    let needed = params
        .min_inliers
        .max((params.min_inlier_share * endpoints.len() as f64).ceil() as usize)
        .max(1);
    let before = fit(field, endpoints, start, params)?;
    if before.inliers < needed {
        return None;
    }
    let inv_var = 1.0 / (params.sigma_m * params.sigma_m);
    let prior = [
        1.0 / (params.prior_std_m * params.prior_std_m),
        1.0 / (params.prior_std_m * params.prior_std_m),
        1.0 / (params.prior_std_rad * params.prior_std_rad),
    ];
    let mut pose = *start;
    for _ in 0..params.iterations {
        let (sin, cos) = pose.theta.sin_cos();
        let mut h = [[0.0f64; 3]; 3];
        let mut g = [0.0f64; 3];
        for &(ex, ey) in endpoints {
            let x = pose.x + cos * ex - sin * ey;
            let y = pose.y + sin * ex + cos * ey;
            let Some((d, [gx, gy])) = field.distance_at(x, y) else {
                continue;
            };
            if d > params.inlier_distance {
                continue;
            }
            // ∂(x, y)/∂θ of the endpoint.
            let (dxt, dyt) = (-sin * ex - cos * ey, cos * ex - sin * ey);
            let j = [gx, gy, gx * dxt + gy * dyt];
            // Cauchy weights: an echo far from the wall it is paired with
            // (a wrong pairing, a thing the map lacks) pulls less.
            let w = inv_var / (1.0 + (d / params.robust_scale_m).powi(2));
            for a in 0..3 {
                g[a] += j[a] * d * w;
                for b in 0..3 {
                    h[a][b] += j[a] * j[b] * w;
                }
            }
        }
        let offset = [
            pose.x - start.x,
            pose.y - start.y,
            wrap(pose.theta - start.theta),
        ];
        for a in 0..3 {
            h[a][a] += prior[a];
            g[a] += prior[a] * offset[a];
        }
        let step = solve3(&h, &g)?;
        pose = Pose2::new(
            pose.x - step[0],
            pose.y - step[1],
            wrap(pose.theta - step[2]),
        );
        if step[0].hypot(step[1]) < 1e-4 && step[2].abs() < 1e-4 {
            break;
        }
    }
    let after = fit(field, endpoints, &pose, params)?;
    let shift = (pose.x - start.x).hypot(pose.y - start.y);
    let turn = wrap(pose.theta - start.theta).abs();
    (after.inliers >= needed
        && after.cost <= before.cost
        && shift <= params.max_shift_m
        && turn <= params.max_turn_rad)
        .then_some(Refined {
            pose,
            inliers: after.inliers,
            rms_distance_m: after.rms_distance_m,
        })
}

/// How well a frame fits at a pose.
#[derive(Debug, Clone, Copy)]
struct Fit {
    inliers: usize,
    rms_distance_m: f64,
    /// `Σ min(d, inlier distance)²` over the endpoints the map knows: the
    /// truncated cost the refinement lowers.
    cost: f64,
}

/// How the frame fits at `pose`; `None` if no endpoint falls where the
/// map knows.
fn fit(
    field: &impl DistanceLookup,
    endpoints: &[(f64, f64)],
    pose: &Pose2,
    params: &RefineParams,
) -> Option<Fit> {
    let (sin, cos) = pose.theta.sin_cos();
    let (mut inliers, mut sum_sq, mut known) = (0usize, 0.0, 0usize);
    let mut cost = 0.0;
    for &(ex, ey) in endpoints {
        let x = pose.x + cos * ex - sin * ey;
        let y = pose.y + sin * ex + cos * ey;
        let Some((d, _)) = field.distance_at(x, y) else {
            continue;
        };
        known += 1;
        cost += d.min(params.inlier_distance).powi(2);
        if d <= params.inlier_distance {
            inliers += 1;
            sum_sq += d * d;
        }
    }
    (known > 0).then(|| Fit {
        inliers,
        cost,
        rms_distance_m: if inliers > 0 {
            (sum_sq / inliers as f64).sqrt()
        } else {
            f64::INFINITY
        },
    })
}

/// `x` solving `h x = g` (Cramer's rule); `None` when `h` is singular or
/// not positive definite (no pose fits better nearby).
fn solve3(h: &[[f64; 3]; 3], g: &[f64; 3]) -> Option<[f64; 3]> {
    let det3 = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let det = det3(h);
    let minor = h[0][0] * h[1][1] - h[0][1] * h[1][0];
    if !(det.is_finite() && det > 0.0 && minor > 0.0 && h[0][0] > 0.0) {
        return None;
    }
    let mut x = [0.0; 3];
    for (col, out) in x.iter_mut().enumerate() {
        let mut m = *h;
        for (row, line) in m.iter_mut().enumerate() {
            line[col] = g[row];
        }
        *out = det3(&m) / det;
    }
    Some(x)
}

/// An angle in (−π, π].
fn wrap(a: f64) -> f64 {
    let t = a.rem_euclid(std::f64::consts::TAU);
    if t > std::f64::consts::PI {
        t - std::f64::consts::TAU
    } else {
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Walls along the lines x = 0, x = 4, y = 0 and y = 3: the exact
    /// distance to the nearest, everywhere inside.
    struct Room;

    impl DistanceLookup for Room {
        fn distance_at(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
            if !(-1.0..5.0).contains(&x) || !(-1.0..4.0).contains(&y) {
                return None;
            }
            let walls = [
                (x.abs(), [x.signum(), 0.0]),
                ((4.0 - x).abs(), [-(4.0 - x).signum(), 0.0]),
                (y.abs(), [0.0, y.signum()]),
                ((3.0 - y).abs(), [0.0, -(3.0 - y).signum()]),
            ];
            walls.into_iter().min_by(|a, b| a.0.total_cmp(&b.0))
        }
    }

    /// A 360-beam scan of the room from `pose`, in the robot's frame.
    fn scan(pose: &Pose2) -> Vec<(f64, f64)> {
        (0..360)
            .map(|i| {
                let a = pose.theta + f64::from(i).to_radians();
                let (s, c) = a.sin_cos();
                let tx = if c > 1e-9 {
                    (4.0 - pose.x) / c
                } else if c < -1e-9 {
                    -pose.x / c
                } else {
                    f64::INFINITY
                };
                let ty = if s > 1e-9 {
                    (3.0 - pose.y) / s
                } else if s < -1e-9 {
                    -pose.y / s
                } else {
                    f64::INFINITY
                };
                let r = tx.min(ty);
                let local = f64::from(i).to_radians();
                (r * local.cos(), r * local.sin())
            })
            .collect()
    }

    #[test]
    fn a_pose_a_few_centimetres_off_is_brought_back() {
        let truth = Pose2::new(1.7, 1.2, 0.3);
        let endpoints = scan(&truth);
        let start = Pose2::new(1.75, 1.16, 0.32);
        let refined = refine_pose(&Room, &endpoints, &start, &RefineParams::default())
            .expect("the room pins the pose down");
        assert!((refined.pose.x - truth.x).abs() < 2e-3, "{refined:?}");
        assert!((refined.pose.y - truth.y).abs() < 2e-3, "{refined:?}");
        assert!(
            (refined.pose.theta - truth.theta).abs() < 1e-3,
            "{refined:?}"
        );
        assert!(refined.rms_distance_m < 2e-3);
    }

    #[test]
    fn a_pose_too_far_to_mend_is_left_alone() {
        let truth = Pose2::new(1.7, 1.2, 0.3);
        let endpoints = scan(&truth);
        let params = RefineParams {
            max_shift_m: 0.02,
            ..RefineParams::default()
        };
        let start = Pose2::new(1.8, 1.2, 0.3);
        assert_eq!(refine_pose(&Room, &endpoints, &start, &params), None);
    }

    #[test]
    fn too_few_echoes_near_a_wall_are_not_trusted() {
        let truth = Pose2::new(1.7, 1.2, 0.3);
        let mut endpoints = scan(&truth);
        // Most of the frame met things the map does not hold.
        for e in endpoints.iter_mut().skip(40) {
            *e = (e.0 * 0.5, e.1 * 0.5);
        }
        let params = RefineParams {
            min_inlier_share: 0.5,
            ..RefineParams::default()
        };
        assert_eq!(refine_pose(&Room, &endpoints, &truth, &params), None);
    }

    #[test]
    fn along_a_corridor_the_prior_holds_the_estimate() {
        /// Two walls, y = 0 and y = 2, endless in x.
        struct Corridor;
        impl DistanceLookup for Corridor {
            fn distance_at(&self, _x: f64, y: f64) -> Option<(f64, [f64; 2])> {
                Some(if y < 1.0 {
                    (y.abs(), [0.0, y.signum()])
                } else {
                    ((2.0 - y).abs(), [0.0, -(2.0 - y).signum()])
                })
            }
        }
        // Side-looking beams only: nothing along the corridor.
        let endpoints: Vec<(f64, f64)> = (0..60)
            .map(|i| {
                let x = f64::from(i) * 0.05 - 1.5;
                if i % 2 == 0 { (x, 1.0) } else { (x, -1.0) }
            })
            .collect();
        let start = Pose2::new(3.0, 1.04, 0.0);
        let refined = refine_pose(&Corridor, &endpoints, &start, &RefineParams::default())
            .expect("the walls fix y");
        assert!((refined.pose.y - 1.0).abs() < 1e-3, "{refined:?}");
        assert!((refined.pose.x - 3.0).abs() < 1e-3, "{refined:?}");
    }

    #[test]
    fn bad_parameters_are_refused() {
        let bad = RefineParams {
            sigma_m: 0.0,
            ..RefineParams::default()
        };
        assert!(bad.validate().is_err());
        let bad = RefineParams {
            iterations: 0,
            ..RefineParams::default()
        };
        assert!(bad.validate().is_err());
        assert!(RefineParams::default().validate().is_ok());
    }

    proptest! {
        #[test]
        fn refining_never_fits_worse(
            dx in -0.08f64..0.08, dy in -0.08f64..0.08, dt in -0.05f64..0.05,
        ) {
            let truth = Pose2::new(2.1, 1.4, -0.7);
            let endpoints = scan(&truth);
            let start = Pose2::new(truth.x + dx, truth.y + dy, truth.theta + dt);
            let params = RefineParams::default();
            let before = fit(&Room, &endpoints, &start, &params).unwrap();
            if let Some(r) = refine_pose(&Room, &endpoints, &start, &params) {
                let after = fit(&Room, &endpoints, &r.pose, &params).unwrap();
                prop_assert!(after.cost <= before.cost);
                let error = (r.pose.x - truth.x).hypot(r.pose.y - truth.y);
                prop_assert!(error <= dx.hypot(dy) + 1e-9, "{error} from {dx}, {dy}");
            }
        }
    }
}
