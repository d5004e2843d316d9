//! Frames and pose estimates: stored per robot, read by range, followed live.

use crate::common::{TestServer, create_map};
use deog_proto::v1 as pb;
use std::time::Duration;

fn frame(robot: &str, sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: robot.into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pb::Pose2 {
            x: sequence as f64,
            y: 0.5,
            theta: 0.1,
        }),
        true_pose: Some(pb::Pose2 {
            x: sequence as f64 + 0.01,
            y: 0.5,
            theta: 0.1,
        }),
        ranges: (0..16).map(|i| 1.0 + f64::from(i) * 0.1).collect(),
        rig: String::new(),
        reference_pose: None,
    }
}

fn pose(robot: &str, frame_sequence: u64) -> pb::PoseEstimate {
    pb::PoseEstimate {
        robot: robot.into(),
        map: "m".into(),
        frame_sequence,
        time_s: frame_sequence as f64 * 0.1,
        pose: Some(pb::Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.3,
        }),
        covariance: vec![0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.001],
        particle_count: 500,
        converged: frame_sequence > 2,
        lost_score: 0.1,
        particle_sample: Vec::new(),
    }
}

async fn collect<T>(mut stream: tonic::Streaming<T>) -> Vec<T> {
    let mut out = Vec::new();
    while let Some(item) = stream.message().await.unwrap() {
        out.push(item);
    }
    out
}

async fn next<T>(stream: &mut tonic::Streaming<T>) -> T {
    tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("in time")
        .expect("ok")
        .expect("open")
}

#[tokio::test]
async fn frames_are_stored_per_robot_deduplicated_and_read_by_range() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let frames: Vec<_> = (1..=10)
        .map(|s| frame("scout-1", s))
        .chain((1..=3).map(|s| frame("scout-2", s)))
        .collect();
    let reply = client
        .publish_frames(pb::PublishFramesRequest {
            frames: frames.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((reply.stored, reply.duplicates), (13, 0));
    // A resend, plus one new frame.
    let mut again = frames[8..10].to_vec();
    again.push(frame("scout-1", 11));
    let reply = client
        .publish_frames(pb::PublishFramesRequest { frames: again })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((reply.stored, reply.duplicates), (1, 2));

    let robots = client
        .list_robots(pb::ListRobotsRequest {})
        .await
        .unwrap()
        .into_inner()
        .robots;
    let summary: Vec<_> = robots
        .iter()
        .map(|r| {
            (
                r.robot.as_str(),
                r.first_sequence,
                r.last_sequence,
                r.frame_count,
            )
        })
        .collect();
    assert_eq!(summary, [("scout-1", 1, 11, 11), ("scout-2", 1, 3, 3)]);

    let reader = client.clone();
    let read = |from, to, limit| {
        let mut client = reader.clone();
        async move {
            let request = pb::ReadFramesRequest {
                robot: "scout-1".into(),
                from_sequence: from,
                to_sequence: to,
                limit,
            };
            collect(client.read_frames(request).await.unwrap().into_inner()).await
        }
    };
    let all = read(0, 0, 0).await;
    assert_eq!(all.len(), 11);
    assert_eq!(all[3], frames[3], "a frame reads back exactly as published");
    let seqs = |v: Vec<pb::SonarFrame>| v.iter().map(|f| f.sequence).collect::<Vec<_>>();
    assert_eq!(seqs(read(4, 6, 0).await), [4, 5, 6]);
    assert_eq!(seqs(read(9, 0, 0).await), [9, 10, 11]);
    assert_eq!(seqs(read(2, 0, 2).await), [2, 3]);
    // Robot names that merely share a prefix do not mix.
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: vec![frame("scout-10", 1)],
        })
        .await
        .unwrap();
    assert_eq!(read(0, 0, 0).await.len(), 11);
}

#[tokio::test]
async fn subscribers_replay_from_a_sequence_then_follow_live() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: (1..=5).map(|s| frame("r", s)).collect(),
        })
        .await
        .unwrap();

    let mut replay = client
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence: 3,
        })
        .await
        .unwrap()
        .into_inner();
    let mut live_only = client
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence: 0,
        })
        .await
        .unwrap()
        .into_inner();
    for expected in 3..=5 {
        assert_eq!(next(&mut replay).await.sequence, expected);
    }
    // Frames of another robot are not sent.
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: vec![frame("other", 1)],
        })
        .await
        .unwrap();
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: vec![frame("r", 6), frame("r", 7)],
        })
        .await
        .unwrap();
    assert_eq!(next(&mut replay).await.sequence, 6);
    assert_eq!(next(&mut replay).await.sequence, 7);
    assert_eq!(next(&mut live_only).await.sequence, 6);
    assert_eq!(next(&mut live_only).await.sequence, 7);
}

#[tokio::test]
async fn a_subscriber_that_falls_behind_misses_no_frame() {
    let config = deog_server::ServerConfig {
        event_buffer: 8,
        stream_buffer: 2,
        ..Default::default()
    };
    let server = TestServer::start_with(config).await;
    let mut client = server.client().await;
    let mut stream = client
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence: 1,
        })
        .await
        .unwrap()
        .into_inner();
    // 300 frames, one request each, while the subscriber reads nothing.
    for s in 1..=300 {
        client
            .publish_frames(pb::PublishFramesRequest {
                frames: vec![frame("r", s)],
            })
            .await
            .unwrap();
    }
    for expected in 1..=300 {
        assert_eq!(next(&mut stream).await.sequence, expected);
    }
}

#[tokio::test]
async fn poses_are_stored_read_by_range_and_watched() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 0).await;
    let mut all = client
        .watch_poses(pb::WatchPosesRequest {
            robot: String::new(),
        })
        .await
        .unwrap()
        .into_inner();
    let mut one = client
        .watch_poses(pb::WatchPosesRequest { robot: "b".into() })
        .await
        .unwrap()
        .into_inner();
    for s in 1..=4 {
        client.publish_pose(pose("a", s)).await.unwrap();
    }
    client.publish_pose(pose("b", 1)).await.unwrap();
    for s in 1..=4 {
        assert_eq!(next(&mut all).await, pose("a", s));
    }
    assert_eq!(next(&mut all).await, pose("b", 1));
    assert_eq!(next(&mut one).await, pose("b", 1));

    let read = collect(
        client
            .read_poses(pb::ReadPosesRequest {
                robot: "a".into(),
                from_sequence: 2,
                to_sequence: 3,
            })
            .await
            .unwrap()
            .into_inner(),
    )
    .await;
    assert_eq!(read, [pose("a", 2), pose("a", 3)]);
    // A new estimate for the same frame replaces the old one.
    let mut better = pose("a", 2);
    better.converged = true;
    client.publish_pose(better.clone()).await.unwrap();
    let read = collect(
        client
            .read_poses(pb::ReadPosesRequest {
                robot: "a".into(),
                from_sequence: 0,
                to_sequence: 0,
            })
            .await
            .unwrap()
            .into_inner(),
    )
    .await;
    assert_eq!(read.len(), 4);
    assert_eq!(read[1], better);
}

fn goal(robot: &str, map: &str, x: f64, active: bool) -> pb::ExplorationGoal {
    pb::ExplorationGoal {
        robot: robot.into(),
        map: map.into(),
        x,
        y: -1.5,
        time_s: 12.5,
        active,
    }
}

#[tokio::test]
async fn explorers_goals_are_kept_one_per_map_and_robot_listed_and_watched() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let mut watched = client
        .watch_goals(pb::ListGoalsRequest { map: "m".into() })
        .await
        .unwrap()
        .into_inner();
    client
        .publish_goal(goal("a", "m", 1.0, true))
        .await
        .unwrap();
    client
        .publish_goal(goal("b", "m", 2.0, true))
        .await
        .unwrap();
    client
        .publish_goal(goal("a", "other", 3.0, true))
        .await
        .unwrap();
    // A newer goal replaces the robot's earlier one on that map.
    client
        .publish_goal(goal("a", "m", 4.0, false))
        .await
        .unwrap();
    let list = |map: &str| pb::ListGoalsRequest { map: map.into() };
    let mut on_m = client
        .list_goals(list("m"))
        .await
        .unwrap()
        .into_inner()
        .goals;
    on_m.sort_by(|x, y| x.robot.cmp(&y.robot));
    assert_eq!(
        on_m,
        [goal("a", "m", 4.0, false), goal("b", "m", 2.0, true)]
    );
    let on_other = client
        .list_goals(list("other"))
        .await
        .unwrap()
        .into_inner()
        .goals;
    assert_eq!(on_other, [goal("a", "other", 3.0, true)]);
    assert!(
        client
            .list_goals(list("none"))
            .await
            .unwrap()
            .into_inner()
            .goals
            .is_empty()
    );
    // The watcher of m hears m's goals only, in order.
    assert_eq!(next(&mut watched).await, goal("a", "m", 1.0, true));
    assert_eq!(next(&mut watched).await, goal("b", "m", 2.0, true));
    assert_eq!(next(&mut watched).await, goal("a", "m", 4.0, false));
    // Bad goals are refused and change nothing.
    let mut bad = goal("a", "m", f64::NAN, true);
    let status = client.publish_goal(bad.clone()).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status}");
    bad.x = 0.0;
    bad.robot = "bad\0name".into();
    assert_eq!(
        client.publish_goal(bad).await.unwrap_err().code(),
        tonic::Code::InvalidArgument
    );
    let status = client.list_goals(list("")).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    let after = client
        .list_goals(list("m"))
        .await
        .unwrap()
        .into_inner()
        .goals;
    assert_eq!(after.len(), 2);
}

fn laser_rig(name: &str, beams: u32) -> pb::Rig {
    pb::Rig {
        name: name.into(),
        body_radius_m: 0.25,
        sensors: vec![pb::RangeSensor {
            mount: Some(pb::Pose2 {
                x: 0.1,
                y: 0.0,
                theta: 0.0,
            }),
            kind: Some(pb::range_sensor::Kind::Laser(pb::PlanarLaser {
                first_angle_rad: -1.0,
                angle_step_rad: 0.01,
                beam_count: beams,
            })),
            min_range_m: 0.05,
            max_range_m: 8.0,
            no_echo_m: 8.0,
            no_echo_zero: true,
        }],
    }
}

#[tokio::test]
async fn rigs_are_built_in_or_stored_once_under_their_name_and_survive_a_restart() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    let names = |rigs: Vec<pb::Rig>| rigs.into_iter().map(|r| r.name).collect::<Vec<_>>();
    let listed = client
        .list_rigs(pb::ListRigsRequest {})
        .await
        .unwrap()
        .into_inner()
        .rigs;
    assert_eq!(names(listed), ["scout", "pioneer3dx", "laser180"]);

    let mine = laser_rig("mine", 201);
    let stored = client.put_rig(mine.clone()).await.unwrap().into_inner();
    assert_eq!(stored, mine);
    // The same rig again is harmless; a different one under the name is not.
    client.put_rig(mine.clone()).await.unwrap();
    let status = client.put_rig(laser_rig("mine", 200)).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::AlreadyExists, "{status:?}");
    let status = client.put_rig(laser_rig("scout", 16)).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::AlreadyExists, "{status:?}");
    let mut bad = laser_rig("bad", 10);
    bad.sensors[0].max_range_m = -1.0;
    let status = client.put_rig(bad).await.unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("max_range_m"), "{status:?}");
    let status = client
        .get_rig(pb::RigRef {
            name: "nothing".into(),
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::NotFound, "{status:?}");

    // A frame of the stored rig is taken, with its reference pose.
    let mut laser_frame = frame("lidar-bot", 1);
    laser_frame.rig = "mine".into();
    laser_frame.ranges = vec![2.5; 201];
    laser_frame.true_pose = None;
    laser_frame.reference_pose = Some(pb::Pose2 {
        x: 3.0,
        y: -1.0,
        theta: 0.25,
    });
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: vec![laser_frame.clone()],
        })
        .await
        .unwrap();

    let path = server.path.clone();
    let dir = server.stop().await;
    let server = TestServer::start_at(path, Default::default()).await;
    let mut client = server.client().await;
    let listed = client
        .list_rigs(pb::ListRigsRequest {})
        .await
        .unwrap()
        .into_inner()
        .rigs;
    assert_eq!(names(listed), ["scout", "pioneer3dx", "laser180", "mine"]);
    let got = client
        .get_rig(pb::RigRef {
            name: "mine".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(got, mine);
    let read = collect(
        client
            .read_frames(pb::ReadFramesRequest {
                robot: "lidar-bot".into(),
                from_sequence: 0,
                to_sequence: 0,
                limit: 0,
            })
            .await
            .unwrap()
            .into_inner(),
    )
    .await;
    assert_eq!(read, vec![laser_frame]);
    drop(server);
    drop(dir);
}
