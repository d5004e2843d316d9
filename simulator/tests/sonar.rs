//! Sonar ranges against hand-computed geometry, specular loss, dropouts,
//! and the determinism of a whole robot run.
//!
//! Unless a test says otherwise the robot stands at the origin facing +x,
//! so sonar 0 sits at (0.2, 0) on the ring and looks along +x; hand
//! computations below are distances from that point.

use std::f64::consts::FRAC_PI_2;

use approx::assert_abs_diff_eq;
use deog_grid::{Pose2, SCOUT_RING_RADIUS_M, SensorRing};
use deog_simulator::{OdometryNoise, Robot, ScoutParams, SonarParams, SonarRing, Specular};
use deog_world::{Point2, Polygon, Segment, SegmentIndex, World};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SENSOR_X: f64 = SCOUT_RING_RADIUS_M;

fn seg(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
    Segment::new(Point2::new(ax, ay), Point2::new(bx, by))
}

/// A long straight wall through `through` whose normal points at `normal`
/// radians from +x.
fn wall_through(through: Point2, normal: f64) -> Segment {
    let (dx, dy) = (-normal.sin() * 30.0, normal.cos() * 30.0);
    seg(
        through.x - dx,
        through.y - dy,
        through.x + dx,
        through.y + dy,
    )
}

fn ranges(sonar: &SonarRing, walls: Vec<Segment>, pose: Pose2) -> Vec<f64> {
    let index = SegmentIndex::new(walls);
    let mut out = vec![0.0; sonar.len()];
    sonar
        .true_ranges(&index, &pose, &mut out)
        .expect("valid pose and output");
    out
}

fn exact() -> SonarRing {
    SonarRing::new(SensorRing::scout(), SonarParams::exact()).expect("valid params")
}

fn origin() -> Pose2 {
    Pose2::new(0.0, 0.0, 0.0)
}

#[test]
fn a_wall_straight_ahead_reads_its_distance_less_the_ring_radius() {
    let r = ranges(&exact(), vec![seg(3.0, -5.0, 3.0, 5.0)], origin());
    assert_abs_diff_eq!(r[0], 3.0 - SENSOR_X, epsilon = 1e-9);

    // The same wall seen by a robot facing up, 3 m below it.
    let r = ranges(
        &exact(),
        vec![seg(-5.0, 4.0, 5.0, 4.0)],
        Pose2::new(1.0, 1.0, FRAC_PI_2),
    );
    assert_abs_diff_eq!(r[0], 3.0 - SENSOR_X, epsilon = 1e-9);
}

#[test]
fn noise_stays_within_one_percent() {
    let sonar = SonarRing::scout();
    let index = SegmentIndex::new(vec![seg(3.0, -5.0, 3.0, 5.0)]);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut out = [0.0; 16];
    let truth = 3.0 - SENSOR_X;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for _ in 0..2000 {
        sonar
            .fire(&index, &origin(), &mut rng, &mut out)
            .expect("valid input");
        lo = lo.min(out[0]);
        hi = hi.max(out[0]);
    }
    assert!(lo >= truth * 0.99 - 1e-12 && hi <= truth * 1.01 + 1e-12);
    // And it is noise: it spreads over most of the band.
    assert!(lo < truth * 0.995 && hi > truth * 1.005, "{lo} .. {hi}");
}

#[test]
fn a_tilted_wall_reads_the_foot_when_it_is_inside_the_cone() {
    // Normal 10° off the axis, the wall through (3.2, 0): the foot of the
    // perpendicular from the sensor is 10° off axis, inside the ±15° cone,
    // at distance 3 cos 10°.
    let wall = wall_through(Point2::new(SENSOR_X + 3.0, 0.0), 10f64.to_radians());
    let r = ranges(&exact(), vec![wall], origin());
    assert_abs_diff_eq!(r[0], 3.0 * 10f64.to_radians().cos(), epsilon = 1e-9);
}

#[test]
fn a_tilted_wall_reads_where_the_cone_edge_meets_it() {
    // Normal 30° off the axis: the foot (at 30°) is outside the cone, so
    // the nearest echo is where the +15° edge meets the wall. The wall is
    // n·q = 3 cos 30° and the edge is q = r (cos 15°, sin 15°), so
    // r = 3 cos 30° / cos(30° − 15°).
    let wall = wall_through(Point2::new(SENSOR_X + 3.0, 0.0), 30f64.to_radians());
    let r = ranges(&exact(), vec![wall], origin());
    let expected = 3.0 * 30f64.to_radians().cos() / 15f64.to_radians().cos();
    assert_abs_diff_eq!(r[0], expected, epsilon = 1e-9);
    // Longer than the foot, shorter than along the axis.
    assert!(r[0] > 3.0 * 30f64.to_radians().cos() && r[0] < 3.0);
}

#[test]
fn an_obstacle_just_inside_the_cone_edge_is_seen_and_just_outside_is_not() {
    // A short radial wall from 2 m to 2.5 m from the sensor, at a bearing.
    let radial = |deg: f64| {
        let (s, c) = deg.to_radians().sin_cos();
        seg(SENSOR_X + 2.0 * c, 2.0 * s, SENSOR_X + 2.5 * c, 2.5 * s)
    };
    let sonar = exact();
    for deg in [14.5, -14.5] {
        let r = ranges(&sonar, vec![radial(deg)], origin());
        assert_abs_diff_eq!(r[0], 2.0, epsilon = 1e-9);
    }
    for deg in [15.5, -15.5] {
        let r = ranges(&sonar, vec![radial(deg)], origin());
        assert_eq!(r[0], sonar.params().max_range, "seen at {deg}°");
    }
}

#[test]
fn beyond_max_range_reads_max_range_and_too_near_reads_min_range() {
    let sonar = exact();
    let p = *sonar.params();
    let r = ranges(
        &sonar,
        vec![seg(SENSOR_X + 11.0, -5.0, SENSOR_X + 11.0, 5.0)],
        origin(),
    );
    assert_eq!(r[0], p.max_range);
    // 5 cm from the sensor: under the 6 in minimum.
    let r = ranges(
        &sonar,
        vec![seg(SENSOR_X + 0.05, -1.0, SENSOR_X + 0.05, 1.0)],
        origin(),
    );
    assert_eq!(r[0], p.min_range);
    // No walls at all: every sonar reads max range.
    let r = ranges(&sonar, vec![], origin());
    assert!(r.iter().all(|&x| x == p.max_range));
}

/// A wall whose nearest point inside the cone is struck at 15° incidence
/// (the 30° wall above) and one struck at 35° (normal 50° off the axis,
/// met by the +15° edge), with a square wall 6 m behind both.
fn specular_scene(normal_deg: f64) -> Vec<Segment> {
    vec![
        wall_through(Point2::new(SENSOR_X + 3.0, 0.0), normal_deg.to_radians()),
        seg(SENSOR_X + 6.0, -20.0, SENSOR_X + 6.0, 20.0),
    ]
}

fn with_specular(specular: Specular) -> SonarRing {
    let params = SonarParams {
        specular,
        ..SonarParams::exact()
    };
    SonarRing::new(SensorRing::scout(), params).expect("valid params")
}

#[test]
fn specular_loss_cuts_off_past_the_incidence_angle_and_the_grazed_wall_hides_the_wall_behind() {
    let lost = with_specular(Specular::Lost {
        max_incidence: 20f64.to_radians(),
    });
    // 15° < 20°: the tilted wall answers.
    let r = ranges(&lost, specular_scene(30.0), origin());
    let at_edge = |normal_deg: f64| {
        3.0 * normal_deg.to_radians().cos() / (normal_deg - 15.0).to_radians().cos()
    };
    assert_abs_diff_eq!(r[0], at_edge(30.0), epsilon = 1e-9);
    // 35° > 20°: its echo is lost, and as it fills the cone it hides
    // the wall behind: nothing comes back.
    let r = ranges(&lost, specular_scene(50.0), origin());
    assert_eq!(r[0], lost.params().max_range);
    // Without the wall behind: nothing comes back.
    let r = ranges(&lost, specular_scene(50.0)[..1].to_vec(), origin());
    assert_eq!(r[0], lost.params().max_range);
    // A wall struck square on never loses its echo.
    let r = ranges(&lost, specular_scene(0.0), origin());
    assert_abs_diff_eq!(r[0], 3.0, epsilon = 1e-9);
}

#[test]
fn specular_long_comes_back_late_unless_a_direct_echo_is_nearer() {
    let long = with_specular(Specular::Long {
        max_incidence: 20f64.to_radians(),
        factor: 2.0,
    });
    let edge = 3.0 * 50f64.to_radians().cos() / 35f64.to_radians().cos();
    // 2 × 2.35 m = 4.71 m arrives before the 6 m wall's echo.
    let r = ranges(&long, specular_scene(50.0), origin());
    assert_abs_diff_eq!(r[0], 2.0 * edge, epsilon = 1e-9);
    // With the back wall at 4 m, the grazed wall hides it from most of
    // the cone but not from the right edge (below -11.9°, where the
    // grazed wall lies farther than 4 m): its direct echo from there,
    // known to the fan's 2° resolution, wins over the late one.
    let walls = vec![
        specular_scene(50.0)[0],
        seg(SENSOR_X + 4.0, -20.0, SENSOR_X + 4.0, 20.0),
    ];
    let r = ranges(&long, walls, origin());
    let through_the_gap = 4.0 / 11.85f64.to_radians().cos();
    assert!(
        r[0] >= through_the_gap - 1e-3 && r[0] <= 4.0 / 15f64.to_radians().cos(),
        "{}",
        r[0]
    );
}

/// A closed 6 x 4 m room with the robot inside: every sonar has an echo.
fn closed_room() -> (World, SegmentIndex) {
    let world = World::new(
        "room",
        Some(Polygon::rectangle(
            Point2::new(-3.0, -2.0),
            Point2::new(3.0, 2.0),
        )),
        vec![Polygon::rectangle(
            Point2::new(1.0, 0.5),
            Point2::new(1.6, 1.2),
        )],
    )
    .expect("a world");
    let index = SegmentIndex::new(world.walls());
    (world, index)
}

#[test]
fn dropouts_happen_at_their_rate() {
    let (_, index) = closed_room();
    let params = SonarParams {
        dropout_probability: 0.2,
        ..SonarParams::default()
    };
    let sonar = SonarRing::new(SensorRing::scout(), params).expect("valid params");
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut out = [0.0; 16];
    let (mut dropped, mut total) = (0usize, 0usize);
    for _ in 0..2000 {
        let pose = Pose2::new(
            rng.random_range(-2.0..0.5),
            rng.random_range(-1.5..1.5),
            rng.random_range(-3.0..3.0),
        );
        sonar
            .fire(&index, &pose, &mut rng, &mut out)
            .expect("valid input");
        dropped += out.iter().filter(|&&r| r == params.max_range).count();
        total += out.len();
    }
    let rate = dropped as f64 / total as f64;
    // 32 000 readings: the standard error is 0.0022.
    assert!((rate - 0.2).abs() < 0.01, "dropout rate {rate}");
}

/// 1000 steps of a robot driven at random in the room, firing every step:
/// every pose and every range.
fn run(seed: u64) -> (Vec<Pose2>, Vec<f64>) {
    let (world, index) = closed_room();
    let sonar = SonarRing::new(
        SensorRing::scout(),
        SonarParams {
            dropout_probability: 0.05,
            ..SonarParams::default()
        },
    )
    .expect("valid params");
    let mut robot = Robot::new(
        Pose2::new(-1.0, 0.0, 0.3),
        ScoutParams::default(),
        OdometryNoise::default(),
    )
    .expect("a robot");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut poses, mut all_ranges) = (Vec::new(), Vec::new());
    let mut out = [0.0; 16];
    for i in 0..1000 {
        if i % 50 == 0 {
            let v = rng.random_range(-0.3..1.0);
            let w = rng.random_range(-1.5..1.5);
            robot.set_command(v, w).expect("finite");
        }
        robot
            .step(0.05, &index, &world, &mut rng)
            .expect("valid dt");
        sonar
            .fire(&index, &robot.true_pose(), &mut rng, &mut out)
            .expect("valid input");
        poses.push(robot.true_pose());
        poses.push(robot.odometry());
        all_ranges.extend_from_slice(&out);
    }
    (poses, all_ranges)
}

#[test]
fn the_same_seed_gives_the_same_run_and_another_seed_another() {
    let a = run(9);
    let b = run(9);
    assert_eq!(a, b);
    let c = run(10);
    assert_ne!(a.0, c.0);
    assert_ne!(a.1, c.1);
}

#[test]
fn a_robot_driving_into_the_room_wall_stays_clear_of_it() {
    // And the sonar facing it reads its minimum.
    let (world, index) = closed_room();
    let mut robot = Robot::new(
        Pose2::new(-1.0, -1.0, 0.0),
        ScoutParams::default(),
        OdometryNoise::none(),
    )
    .expect("a robot");
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    robot.set_command(1.0, 0.0).expect("finite");
    robot.step(8.0, &index, &world, &mut rng).expect("valid dt");
    let p = robot.true_pose();
    let radius = robot.params().radius;
    assert!(robot.bumper());
    assert!(p.x > 3.0 - radius - 0.03 && p.x <= 3.0 - radius, "{p:?}");
    let mut out = [0.0; 16];
    exact()
        .true_ranges(&index, &p, &mut out)
        .expect("valid input");
    // Sonar 0 is within 5 cm of the wall: under the minimum range.
    assert_eq!(out[0], SonarParams::exact().min_range);
}

fn random_wall() -> impl Strategy<Value = Segment> {
    (
        -10.0..10.0f64,
        -10.0..10.0f64,
        -10.0..10.0f64,
        -10.0..10.0f64,
    )
        .prop_map(|(ax, ay, bx, by)| seg(ax, ay, bx, by))
}

/// Where the ray from `origin` along `dir` (unit) first meets `wall`.
fn ray_hit(origin: Point2, dir: (f64, f64), wall: &Segment) -> Option<f64> {
    let (ex, ey) = (wall.b.x - wall.a.x, wall.b.y - wall.a.y);
    let denom = dir.0 * ey - dir.1 * ex;
    if denom.abs() < 1e-12 {
        return None;
    }
    let (wx, wy) = (wall.a.x - origin.x, wall.a.y - origin.y);
    let t = (wx * ey - wy * ex) / denom;
    let u = (wx * dir.1 - wy * dir.0) / denom;
    (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// A reading is never shorter than the nearest wall (in any direction)
    /// and never longer than the range along the sonar's axis.
    #[test]
    fn readings_lie_between_the_nearest_wall_and_the_axis_range(
        walls in proptest::collection::vec(random_wall(), 1..8),
        x in -8.0..8.0f64,
        y in -8.0..8.0f64,
        theta in -4.0..4.0f64,
    ) {
        let sonar = exact();
        let p = *sonar.params();
        let pose = Pose2::new(x, y, theta);
        let out = ranges(&sonar, walls.clone(), pose);
        for (i, sensor) in SensorRing::scout().sensor_poses(&pose).enumerate() {
            let at = Point2::new(sensor.x, sensor.y);
            let nearest = walls.iter().map(|w| w.distance_to(at)).fold(f64::INFINITY, f64::min);
            prop_assert!(out[i] >= nearest.min(p.max_range) - 1e-9,
                "sonar {i}: {} < nearest {nearest}", out[i]);
            let dir = (sensor.theta.cos(), sensor.theta.sin());
            let axis = walls.iter().filter_map(|w| ray_hit(at, dir, w)).fold(f64::INFINITY, f64::min);
            if axis < p.max_range {
                prop_assert!(out[i] <= axis.max(p.min_range) + 1e-9,
                    "sonar {i}: {} > axis {axis}", out[i]);
            }
        }
    }
}
