//! `RobotService` over real TCP on 127.0.0.1: several robots driven at
//! once, watch streams, kidnapping, and bad or oversized input refused with
//! the right code and a message naming the field or message.

use std::time::Duration;

use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_client::RobotServiceClient;
use deog_simulator::serve::{SimServeConfig, serve_sim};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_world::{Point2, Polygon, World};
use tokio::sync::oneshot;
use tonic::Code;
use tonic::transport::Channel;

/// A 10 m x 8 m room with a 1 m box at (4..5, 4..5).
fn room() -> World {
    World::new(
        "room",
        Some(Polygon::rectangle(
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 8.0),
        )),
        vec![Polygon::rectangle(
            Point2::new(4.0, 4.0),
            Point2::new(5.0, 5.0),
        )],
    )
    .expect("world")
}

struct Sim {
    client: RobotServiceClient<Channel>,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), deog_simulator::SimError>>,
}

impl Sim {
    async fn start(speed: f64) -> Self {
        Self::start_with(SimServeConfig {
            speed,
            ..SimServeConfig::default()
        })
        .await
    }

    async fn start_with(config: SimServeConfig) -> Self {
        Self::start_sim(SimConfig::default(), config).await
    }

    async fn start_sim(sim_config: SimConfig, config: SimServeConfig) -> Self {
        let sim = Simulation::new(room(), sim_config, 7).expect("simulation");
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(serve_sim(sim, listener, config, async {
            let _ = stopped.await;
        }));
        let mut client = None;
        for _ in 0..100 {
            if let Ok(c) = RobotServiceClient::connect(format!("http://{addr}")).await {
                client = Some(c);
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Self {
            client: client.expect("simulator reachable"),
            stop: Some(stop),
            task,
        }
    }

    async fn stop(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        tokio::time::timeout(Duration::from_secs(10), &mut self.task)
            .await
            .expect("stops in time")
            .expect("task")
            .expect("serve result");
    }
}

fn pose(x: f64, y: f64, theta: f64) -> Option<pb::Pose2> {
    Some(pb::Pose2 { x, y, theta })
}

#[tokio::test]
async fn eight_robots_are_driven_at_once_and_each_moves_its_own_way() {
    let sim = Sim::start(20.0).await;
    let mut tasks = Vec::new();
    for i in 0..8 {
        let mut client = sim.client.clone();
        tasks.push(tokio::spawn(async move {
            let name = format!("scout-{i}");
            let y = 0.8 + 0.8 * i as f64;
            let start = client
                .spawn(pb::SpawnRequest {
                    name: name.clone(),
                    pose: pose(1.0, y, 0.0),
                })
                .await
                .expect("spawn")
                .into_inner();
            assert_eq!(start.ranges.len(), 16);
            assert_eq!(start.sequence, 1, "the sonars fire at spawn");
            // Forward at 0.3 m/s, turning a little one way or the other.
            let angular = if i % 2 == 0 { 0.05 } else { -0.05 };
            client
                .drive(pb::DriveRequest {
                    name: name.clone(),
                    command: Some(pb::Twist2 {
                        linear: 0.3,
                        angular,
                    }),
                })
                .await
                .expect("drive");
            // Bounded wait for one simulated second of driving, counted from
            // the drive (on a busy machine the robot may stand a while
            // between its spawn and its drive at 20x).
            let start = client
                .get_state(pb::RobotRef { name: name.clone() })
                .await
                .expect("state")
                .into_inner();
            let mut state = start.clone();
            for _ in 0..200 {
                tokio::time::sleep(Duration::from_millis(10)).await;
                state = client
                    .get_state(pb::RobotRef { name: name.clone() })
                    .await
                    .expect("state")
                    .into_inner();
                if state.time_s - start.time_s > 1.0 {
                    break;
                }
            }
            (i, start, state)
        }));
    }
    for task in tasks {
        let (i, start, end) = task.await.expect("robot task");
        let (a, b) = (start.true_pose.unwrap(), end.true_pose.unwrap());
        assert!(b.x > a.x + 0.15, "robot {i} moved forward: {a:?} -> {b:?}");
        let turned = b.theta - a.theta;
        assert_eq!(turned > 0.0, i % 2 == 0, "robot {i} turned its own way");
        assert!(end.sequence > start.sequence);
        assert!(!end.bumper);
    }
    let mut client = sim.client.clone();
    let robots = client
        .list_robots(pb::ListSimRobotsRequest {})
        .await
        .expect("list")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 8);
    sim.stop().await;
}

#[tokio::test]
async fn a_watcher_gets_every_firing_and_a_kidnap_leaves_odometry_alone() {
    let sim = Sim::start(10.0).await;
    let mut client = sim.client.clone();
    client
        .spawn(pb::SpawnRequest {
            name: "k".into(),
            pose: pose(2.0, 2.0, 0.0),
        })
        .await
        .expect("spawn");
    let mut watch = client
        .watch_state(pb::RobotRef { name: "k".into() })
        .await
        .expect("watch")
        .into_inner();
    let mut sequences = Vec::new();
    while sequences.len() < 20 {
        let state = tokio::time::timeout(Duration::from_secs(5), watch.message())
            .await
            .expect("a state in time")
            .expect("stream")
            .expect("open");
        sequences.push(state.sequence);
    }
    for pair in sequences.windows(2) {
        assert_eq!(pair[1], pair[0] + 1, "{sequences:?}");
    }
    let before = client
        .get_state(pb::RobotRef { name: "k".into() })
        .await
        .expect("state")
        .into_inner();
    let after = client
        .teleport(pb::TeleportRequest {
            name: "k".into(),
            pose: pose(8.0, 6.0, 1.0),
        })
        .await
        .expect("teleport")
        .into_inner();
    assert_eq!(after.true_pose, pose(8.0, 6.0, 1.0));
    assert_eq!(after.odometry, before.odometry, "odometry is not told");
    sim.stop().await;
}

#[tokio::test]
async fn bad_requests_are_refused_with_the_field_named() {
    let sim = Sim::start(1.0).await;
    let mut client = sim.client.clone();
    client
        .spawn(pb::SpawnRequest {
            name: "a".into(),
            pose: pose(1.0, 1.0, 0.0),
        })
        .await
        .expect("spawn");
    let spawn = |name: &str, p: Option<pb::Pose2>| pb::SpawnRequest {
        name: name.into(),
        pose: p,
    };
    let cases: Vec<(pb::SpawnRequest, Code, &str)> = vec![
        (spawn("", None), Code::InvalidArgument, "name"),
        (spawn("a b", None), Code::InvalidArgument, "name"),
        (
            spawn("b", pose(f64::NAN, 1.0, 0.0)),
            Code::InvalidArgument,
            "pose.x",
        ),
        (
            spawn("b", pose(1.0, f64::INFINITY, 0.0)),
            Code::InvalidArgument,
            "pose.y",
        ),
        (
            spawn("b", pose(1.0, 1.0, 1e300)),
            Code::InvalidArgument,
            "pose.theta",
        ),
        (
            spawn("b", pose(4.5, 4.5, 0.0)),
            Code::FailedPrecondition,
            "does not fit",
        ),
        (
            spawn("b", pose(20.0, 1.0, 0.0)),
            Code::FailedPrecondition,
            "does not fit",
        ),
        (
            spawn("b", pose(0.1, 1.0, 0.0)),
            Code::FailedPrecondition,
            "does not fit",
        ),
        (spawn("a", None), Code::AlreadyExists, "\"a\""),
    ];
    for (request, code, text) in cases {
        let status = client.spawn(request.clone()).await.expect_err("refused");
        assert_eq!(status.code(), code, "{request:?}: {status:?}");
        assert!(
            status.message().contains(text),
            "{status:?} should name {text}"
        );
    }
    let drive = |name: &str, command: Option<pb::Twist2>| pb::DriveRequest {
        name: name.into(),
        command,
    };
    let twist = |linear, angular| Some(pb::Twist2 { linear, angular });
    let cases: Vec<(pb::DriveRequest, Code, &str)> = vec![
        (drive("a", None), Code::InvalidArgument, "command"),
        (
            drive("a", twist(f64::NAN, 0.0)),
            Code::InvalidArgument,
            "command.linear",
        ),
        (
            drive("a", twist(0.0, f64::NEG_INFINITY)),
            Code::InvalidArgument,
            "command.angular",
        ),
        (drive("nobody", twist(0.1, 0.0)), Code::NotFound, "nobody"),
    ];
    for (request, code, text) in cases {
        let status = client.drive(request.clone()).await.expect_err("refused");
        assert_eq!(status.code(), code, "{request:?}: {status:?}");
        assert!(
            status.message().contains(text),
            "{status:?} should name {text}"
        );
    }
    let status = client
        .teleport(pb::TeleportRequest {
            name: "a".into(),
            pose: None,
        })
        .await
        .expect_err("no pose");
    assert_eq!(status.code(), Code::InvalidArgument);
    assert!(status.message().contains("pose"));
    let status = client
        .teleport(pb::TeleportRequest {
            name: "a".into(),
            pose: pose(4.5, 4.5, 0.0),
        })
        .await
        .expect_err("into the box");
    assert_eq!(status.code(), Code::FailedPrecondition);
    let status = client
        .get_state(pb::RobotRef { name: "zz".into() })
        .await
        .expect_err("unknown");
    assert_eq!(status.code(), Code::NotFound);
    let status = match client.watch_state(pb::RobotRef { name: "zz".into() }).await {
        Ok(stream) => stream.into_inner().message().await.expect_err("unknown"),
        Err(status) => status,
    };
    assert_eq!(status.code(), Code::NotFound);
    // Speed limits: the executed command is clamped.
    let state = client
        .drive(drive("a", twist(50.0, 0.0)))
        .await
        .expect("drive");
    drop(state);
    let mut fastest: f64 = 0.0;
    for _ in 0..100 {
        tokio::time::sleep(Duration::from_millis(20)).await;
        let s = client
            .get_state(pb::RobotRef { name: "a".into() })
            .await
            .expect("state")
            .into_inner();
        fastest = fastest.max(s.velocity.map_or(0.0, |v| v.linear));
    }
    assert!(fastest > 0.0 && fastest <= 1.0 + 1e-9, "{fastest}");
    // Nothing refused changed the world: one robot.
    let robots = client
        .list_robots(pb::ListSimRobotsRequest {})
        .await
        .expect("list")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 1);
    let world = client
        .get_world(pb::GetWorldRequest {})
        .await
        .expect("world")
        .into_inner();
    assert_eq!(world.name, "room");
    assert_eq!(world.sonar_count, 16);
    sim.stop().await;
}

#[tokio::test]
async fn oversized_requests_are_refused_as_resource_exhausted_naming_the_message() {
    let sim = Sim::start_with(SimServeConfig {
        max_message_bytes: 4096,
        ..SimServeConfig::default()
    })
    .await;
    let mut client = sim.client.clone();
    let start = client
        .spawn(pb::SpawnRequest {
            name: "a".into(),
            pose: pose(1.0, 1.0, 0.0),
        })
        .await
        .expect("spawn")
        .into_inner();
    // Past the limit of 4096 bytes, though well within what tonic decodes.
    let huge = "a".repeat(8 << 10);
    let results = [
        (
            "SpawnRequest",
            client
                .spawn(pb::SpawnRequest {
                    name: huge.clone(),
                    pose: pose(2.0, 2.0, 0.0),
                })
                .await
                .map(drop),
        ),
        (
            "DriveRequest",
            client
                .drive(pb::DriveRequest {
                    name: huge.clone(),
                    command: Some(pb::Twist2 {
                        linear: 0.3,
                        angular: 0.0,
                    }),
                })
                .await
                .map(drop),
        ),
        (
            "TeleportRequest",
            client
                .teleport(pb::TeleportRequest {
                    name: huge.clone(),
                    pose: pose(2.0, 2.0, 0.0),
                })
                .await
                .map(drop),
        ),
        (
            "RobotRef",
            client
                .get_state(pb::RobotRef { name: huge.clone() })
                .await
                .map(drop),
        ),
        (
            "RobotRef",
            match client
                .watch_state(pb::RobotRef { name: huge.clone() })
                .await
            {
                Ok(stream) => stream.into_inner().message().await.map(drop),
                Err(status) => Err(status),
            },
        ),
    ];
    for (message, result) in results {
        let status = result.expect_err("oversized");
        assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
        assert!(
            status.message().contains(message),
            "{status:?} should name {message}"
        );
    }
    let robots = client
        .list_robots(pb::ListSimRobotsRequest {})
        .await
        .expect("list")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 1, "nothing was spawned");
    assert_eq!(robots[0].true_pose, start.true_pose, "nothing moved");
    assert_eq!(robots[0].velocity, start.velocity, "nothing was driven");
    sim.stop().await;
}

#[tokio::test]
async fn a_message_limit_below_the_minimum_is_refused() {
    let sim = Simulation::new(room(), SimConfig::default(), 7).expect("simulation");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let config = SimServeConfig {
        max_message_bytes: 100,
        ..SimServeConfig::default()
    };
    let error = tokio::time::timeout(
        Duration::from_secs(10),
        serve_sim(sim, listener, config, std::future::pending()),
    )
    .await
    .expect("refused at once")
    .expect_err("refused");
    assert!(error.to_string().contains("max_message_bytes"), "{error}");
}

#[tokio::test]
async fn a_teleport_to_a_non_finite_pose_is_refused_and_the_robot_stays() {
    let sim = Sim::start(1.0).await;
    let mut client = sim.client.clone();
    let start = client
        .spawn(pb::SpawnRequest {
            name: "t".into(),
            pose: pose(2.0, 2.0, 0.5),
        })
        .await
        .expect("spawn")
        .into_inner();
    let cases = [
        (pose(f64::NAN, 2.0, 0.0), "pose.x"),
        (pose(f64::INFINITY, 2.0, 0.0), "pose.x"),
        (pose(3.0, f64::NEG_INFINITY, 0.0), "pose.y"),
        (pose(3.0, f64::NAN, 0.0), "pose.y"),
        (pose(3.0, 3.0, f64::NAN), "pose.theta"),
        (pose(3.0, 3.0, f64::INFINITY), "pose.theta"),
    ];
    for (bad, field) in cases {
        let status = client
            .teleport(pb::TeleportRequest {
                name: "t".into(),
                pose: bad,
            })
            .await
            .expect_err("refused");
        assert_eq!(status.code(), Code::InvalidArgument, "{bad:?}: {status:?}");
        assert!(
            status.message().contains(field),
            "{status:?} should name {field}"
        );
        let now = client
            .get_state(pb::RobotRef { name: "t".into() })
            .await
            .expect("state")
            .into_inner();
        assert_eq!(now.true_pose, start.true_pose, "after {bad:?}");
        assert_eq!(now.odometry, start.odometry, "after {bad:?}");
    }
    assert_eq!(start.true_pose, pose(2.0, 2.0, 0.5));
    sim.stop().await;
}

#[tokio::test]
async fn world_info_and_robot_states_carry_the_rig() {
    for name in ["scout", "pioneer3dx", "laser180"] {
        let rig = deog_rig::load_rig_spec(name).expect("built in");
        let config = SimConfig {
            rig: rig.clone(),
            ..SimConfig::default()
        };
        let sim = Sim::start_sim(
            config,
            SimServeConfig {
                speed: 20.0,
                ..SimServeConfig::default()
            },
        )
        .await;
        let mut client = sim.client.clone();
        let world = client
            .get_world(pb::GetWorldRequest {})
            .await
            .expect("world")
            .into_inner();
        let wire = world.rig.clone().expect("the rig is described");
        assert_eq!(wire, deog_proto::rig::rig_to_wire(&rig), "{name}");
        assert_eq!(
            deog_proto::rig::rig_from_wire(&wire).expect("valid"),
            rig,
            "{name}"
        );
        assert_eq!(world.robot_radius_m, rig.body_radius(), "{name}");
        let (count, max_range) = match name {
            "scout" => (16, 10.668),
            "pioneer3dx" => (16, 5.0),
            _ => (0, 0.0),
        };
        assert_eq!(world.sonar_count, count, "{name}");
        assert_eq!(world.sonar_max_range_m, max_range, "{name}");
        if name == "scout" {
            assert_eq!(world.sonar_ring_radius_m, 0.2);
            assert_eq!(world.sonar_cone_rad, 30f64.to_radians());
        }

        let spawned = client
            .spawn(pb::SpawnRequest {
                name: "r".into(),
                pose: pose(2.0, 2.0, 0.0),
            })
            .await
            .expect("spawn")
            .into_inner();
        assert_eq!(spawned.rig, name);
        assert_eq!(spawned.ranges.len(), rig.readings(), "{name}");
        rig.check_frame(&spawned.ranges)
            .expect("readings fit the rig");
        let mut watch = client
            .watch_state(pb::RobotRef { name: "r".into() })
            .await
            .expect("watch")
            .into_inner();
        for _ in 0..3 {
            let state = tokio::time::timeout(Duration::from_secs(10), watch.message())
                .await
                .expect("a state in time")
                .expect("stream")
                .expect("a state");
            assert_eq!(state.rig, name);
            assert_eq!(state.ranges.len(), rig.readings());
        }
        let listed = client
            .list_robots(pb::ListSimRobotsRequest {})
            .await
            .expect("list")
            .into_inner()
            .robots;
        assert_eq!(listed[0].rig, name);
        sim.stop().await;
    }
}
