//! Every call refuses bad input with the right code and a message naming the
//! field, and a refused call changes nothing stored.

use crate::common::{TestServer, all_tiles, batch, create_map, dense_delta, send_batches};
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use tonic::Code;
use tonic::transport::Channel;

/// Asserts the call failed with `code` and a message that names `field`.
#[track_caller]
fn refused<T: std::fmt::Debug>(result: Result<T, tonic::Status>, code: Code, field: &str) {
    let status = result.expect_err("the call should be refused");
    assert_eq!(status.code(), code, "{status:?}");
    assert!(
        status.message().contains(field),
        "message {:?} should name {field:?}",
        status.message()
    );
}

/// What a map looks like from outside: its info and every tile.
async fn snapshot(
    client: &mut MapServiceClient<Channel>,
    map: &str,
) -> (pb::MapInfo, Vec<(pb::TileKey, u64, Vec<i16>)>) {
    let info = client
        .get_map_info(pb::MapRef { name: map.into() })
        .await
        .expect("map info")
        .into_inner();
    (info, all_tiles(client, map).await)
}

/// A server holding map "m" (tiles of 8 x 8) with one applied batch.
async fn server_with_map() -> (TestServer, MapServiceClient<Channel>) {
    let config = deog_server::ServerConfig {
        limits: deog_server::Limits {
            max_message_bytes: 64 << 10,
            ..Default::default()
        },
        ..Default::default()
    };
    let server = TestServer::start_with(config).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    let (acks, error) = send_batches(
        &mut client,
        vec![batch("m", "c", 1, vec![dense_delta(0, 0, &[100; 64])])],
    )
    .await;
    assert!(error.is_none() && acks.len() == 1);
    (server, client)
}

fn frame(robot: &str, sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: robot.into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pb::Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.5,
        }),
        true_pose: None,
        ranges: vec![1.0; 16],
        rig: String::new(),
        reference_pose: None,
    }
}

fn estimate(robot: &str, sequence: u64) -> pb::PoseEstimate {
    pb::PoseEstimate {
        robot: robot.into(),
        map: "m".into(),
        frame_sequence: sequence,
        time_s: 1.0,
        pose: Some(pb::Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.0,
        }),
        covariance: vec![0.0; 9],
        particle_count: 100,
        converged: true,
        lost_score: 0.1,
        particle_sample: Vec::new(),
    }
}

#[tokio::test]
async fn create_map_refuses_bad_names_and_settings() {
    let (_server, mut client) = server_with_map().await;
    let before = snapshot(&mut client, "m").await;
    let request = |f: &dyn Fn(&mut pb::CreateMapRequest)| {
        let mut r = pb::CreateMapRequest {
            name: "new".into(),
            ..Default::default()
        };
        f(&mut r);
        r
    };
    let cases: Vec<(pb::CreateMapRequest, Code, &str)> = vec![
        (request(&|r| r.name.clear()), Code::InvalidArgument, "name"),
        (
            request(&|r| r.name = "a/b".into()),
            Code::InvalidArgument,
            "name",
        ),
        (
            request(&|r| r.name = "x".repeat(129)),
            Code::InvalidArgument,
            "name",
        ),
        (
            request(&|r| r.resolution_m = f64::NAN),
            Code::InvalidArgument,
            "resolution_m",
        ),
        (
            request(&|r| r.resolution_m = f64::INFINITY),
            Code::InvalidArgument,
            "resolution_m",
        ),
        (
            request(&|r| r.resolution_m = -0.1),
            Code::InvalidArgument,
            "resolution_m",
        ),
        (
            request(&|r| r.tile_size = 12),
            Code::InvalidArgument,
            "tile_size",
        ),
        (
            request(&|r| r.tile_size = 1 << 20),
            Code::InvalidArgument,
            "tile_size",
        ),
        (
            request(&|r| r.clamp_min_probability = f64::NAN),
            Code::InvalidArgument,
            "clamp_min_probability",
        ),
        (
            request(&|r| r.clamp_max_probability = 1.5),
            Code::InvalidArgument,
            "clamp_max_probability",
        ),
        (
            request(&|r| {
                r.clamp_min_probability = 0.9;
                r.clamp_max_probability = 0.2;
            }),
            Code::InvalidArgument,
            "clamp",
        ),
        (
            request(&|r| r.name = "m".into()),
            Code::AlreadyExists,
            "\"m\"",
        ),
    ];
    for (request, code, field) in cases {
        refused(client.create_map(request).await, code, field);
    }
    let maps = client
        .list_maps(pb::ListMapsRequest {})
        .await
        .expect("list")
        .into_inner()
        .maps;
    assert_eq!(maps.len(), 1, "no map was created: {maps:?}");
    assert_eq!(snapshot(&mut client, "m").await, before);
}

#[tokio::test]
async fn map_calls_refuse_unknown_maps_and_bad_names() {
    let (_server, mut client) = server_with_map().await;
    let before = snapshot(&mut client, "m").await;
    let unknown = || pb::MapRef {
        name: "nowhere".into(),
    };
    refused(
        client.get_map_info(unknown()).await,
        Code::NotFound,
        "nowhere",
    );
    refused(client.clear_map(unknown()).await, Code::NotFound, "nowhere");
    refused(
        client.delete_map(unknown()).await,
        Code::NotFound,
        "nowhere",
    );
    refused(
        client
            .get_map_info(pb::MapRef {
                name: "bad name".into(),
            })
            .await,
        Code::InvalidArgument,
        "name",
    );
    refused(
        client
            .get_update_cursor(pb::UpdateCursorRequest {
                map: "nowhere".into(),
                client_id: "c".into(),
            })
            .await,
        Code::NotFound,
        "nowhere",
    );
    refused(
        client
            .get_update_cursor(pb::UpdateCursorRequest {
                map: "m".into(),
                client_id: "".into(),
            })
            .await,
        Code::InvalidArgument,
        "client_id",
    );
    assert_eq!(snapshot(&mut client, "m").await, before);
}

#[tokio::test]
async fn apply_updates_refuses_bad_batches_and_applies_nothing_of_them() {
    let (_server, mut client) = server_with_map().await;
    let before = snapshot(&mut client, "m").await;
    let good = || dense_delta(1, 1, &[5; 64]);
    let cases: Vec<(pb::UpdateBatch, Code, &str)> = vec![
        (
            batch("nowhere", "c", 2, vec![good()]),
            Code::NotFound,
            "nowhere",
        ),
        (
            batch("", "c", 2, vec![good()]),
            Code::InvalidArgument,
            "map",
        ),
        (
            batch("m", "", 2, vec![good()]),
            Code::InvalidArgument,
            "client_id",
        ),
        (
            batch("m", "c", 0, vec![good()]),
            Code::InvalidArgument,
            "sequence",
        ),
        // A good tile first: the whole batch is refused, not its tail.
        (
            batch("m", "c", 2, vec![good(), dense_delta(2, 2, &[1; 63])]),
            Code::InvalidArgument,
            "tiles[1].cells",
        ),
        (
            batch("m", "c", 2, vec![dense_delta(2, 2, &[1; 65])]),
            Code::InvalidArgument,
            "tiles[0].cells",
        ),
        (
            batch("m", "c", 2, vec![dense_delta(2, 2, &[i16::MIN; 64])]),
            Code::InvalidArgument,
            "tiles[0].cells",
        ),
        (
            batch("m", "c", 2, vec![dense_delta(i32::MAX, 0, &[1; 64])]),
            Code::InvalidArgument,
            "tiles[0].key",
        ),
        (
            batch("m", "c", 2, vec![dense_delta(0, -(1 << 28), &[1; 64])]),
            Code::InvalidArgument,
            "tiles[0].key",
        ),
        (
            batch(
                "m",
                "c",
                2,
                vec![pb::TileDelta {
                    key: None,
                    ..good()
                }],
            ),
            Code::InvalidArgument,
            "tiles[0].key",
        ),
        (
            batch(
                "m",
                "c",
                2,
                vec![pb::TileDelta {
                    encoding: 0,
                    ..good()
                }],
            ),
            Code::InvalidArgument,
            "tiles[0].encoding",
        ),
        (
            batch(
                "m",
                "c",
                2,
                vec![pb::TileDelta {
                    encoding: pb::CellEncoding::SparseI16Le as i32,
                    // Index 64 is past an 8 x 8 tile.
                    cells: [64u16.to_le_bytes(), 1i16.to_le_bytes()].concat(),
                    ..good()
                }],
            ),
            Code::InvalidArgument,
            "tiles[0].cells",
        ),
        // 5000 tiles of 8 x 8 dense deltas: past the 64 KiB message limit.
        (
            batch(
                "m",
                "c",
                2,
                (0..5000).map(|i| dense_delta(i, 0, &[1; 64])).collect(),
            ),
            Code::ResourceExhausted,
            "UpdateBatch",
        ),
    ];
    for (bad, code, field) in cases {
        let (acks, error) = send_batches(&mut client, vec![bad]).await;
        assert!(acks.is_empty(), "{acks:?}");
        refused(
            Err::<(), _>(error.expect("the stream should end with an error")),
            code,
            field,
        );
    }
    assert_eq!(snapshot(&mut client, "m").await, before);
    let cursor = client
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "m".into(),
            client_id: "c".into(),
        })
        .await
        .expect("cursor")
        .into_inner();
    assert_eq!(cursor.last_sequence, 1, "no refused batch moved the cursor");
}

#[tokio::test]
async fn tile_reads_and_watches_refuse_bad_queries() {
    let (_server, mut client) = server_with_map().await;
    let region = |min_x, max_x| pb::CellBox {
        min_x,
        min_y: 0,
        max_x,
        max_y: 10,
    };
    let query = |map: &str, selection| pb::TileQuery {
        map: map.into(),
        selection,
        newer_than_version: 0,
    };
    use pb::tile_query::Selection;
    let cases: Vec<(pb::TileQuery, Code, &str)> = vec![
        (
            query("nowhere", Some(Selection::Region(region(0, 1)))),
            Code::NotFound,
            "nowhere",
        ),
        (query("m", None), Code::InvalidArgument, "selection"),
        (
            query("m", Some(Selection::Region(region(5, 1)))),
            Code::InvalidArgument,
            "region",
        ),
        (
            query(
                "m",
                Some(Selection::Keys(pb::TileKeys {
                    keys: vec![
                        pb::TileKey { x: 0, y: 0 },
                        pb::TileKey { x: i32::MIN, y: 0 },
                    ],
                })),
            ),
            Code::InvalidArgument,
            "keys.keys[1]",
        ),
        (
            query(
                "m",
                Some(Selection::Keys(pb::TileKeys {
                    keys: (0..20_000).map(|x| pb::TileKey { x, y: x }).collect(),
                })),
            ),
            Code::ResourceExhausted,
            "TileQuery",
        ),
    ];
    for (bad, code, field) in cases {
        let result = match client.get_tiles(bad).await {
            Ok(stream) => stream.into_inner().message().await.map(|_| ()),
            Err(status) => Err(status),
        };
        refused(result, code, field);
    }
    let watch = |map: &str, region| pb::WatchTilesRequest {
        map: map.into(),
        region,
        include_cells: false,
    };
    let cases: Vec<(pb::WatchTilesRequest, Code, &str)> = vec![
        (
            watch("nowhere", Some(region(0, 1))),
            Code::NotFound,
            "nowhere",
        ),
        (watch("m", None), Code::InvalidArgument, "region"),
        (
            watch("m", Some(region(3, 2))),
            Code::InvalidArgument,
            "region",
        ),
        (watch("", Some(region(0, 1))), Code::InvalidArgument, "map"),
    ];
    for (bad, code, field) in cases {
        let result = match client.watch_tiles(bad).await {
            Ok(stream) => stream.into_inner().message().await.map(|_| ()),
            Err(status) => Err(status),
        };
        refused(result, code, field);
    }
}

#[tokio::test]
async fn frames_with_bad_numbers_are_refused_and_none_of_the_request_is_stored() {
    let (_server, mut client) = server_with_map().await;
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: vec![frame("r", 1)],
        })
        .await
        .expect("a good frame");
    let with = |f: &dyn Fn(&mut pb::SonarFrame)| {
        let mut bad = frame("r", 3);
        f(&mut bad);
        bad
    };
    let cases: Vec<(pb::SonarFrame, Code, &str)> = vec![
        (
            with(&|f| f.robot.clear()),
            Code::InvalidArgument,
            "frames[1].robot",
        ),
        (
            with(&|f| f.sequence = 0),
            Code::InvalidArgument,
            "frames[1].sequence",
        ),
        (
            with(&|f| f.time_s = f64::NAN),
            Code::InvalidArgument,
            "frames[1].time_s",
        ),
        (
            with(&|f| f.odometry = None),
            Code::InvalidArgument,
            "frames[1].odometry",
        ),
        (
            with(&|f| f.odometry.as_mut().expect("pose").theta = f64::INFINITY),
            Code::InvalidArgument,
            "frames[1].odometry.theta",
        ),
        (
            with(&|f| {
                f.true_pose = Some(pb::Pose2 {
                    x: f64::NEG_INFINITY,
                    y: 0.0,
                    theta: 0.0,
                })
            }),
            Code::InvalidArgument,
            "frames[1].true_pose.x",
        ),
        (
            with(&|f| f.ranges.clear()),
            Code::InvalidArgument,
            "frames[1].ranges",
        ),
        (
            with(&|f| f.ranges = vec![1.0; 5000]),
            Code::InvalidArgument,
            "frames[1].ranges",
        ),
        (
            with(&|f| f.ranges.push(1.0)),
            Code::InvalidArgument,
            "frames[1].ranges: rig scout reads 16 ranges per frame, the frame has 17",
        ),
        (
            with(&|f| f.rig = "laser180".into()),
            Code::InvalidArgument,
            "frames[1].ranges: rig laser180 reads 180 ranges per frame, the frame has 16",
        ),
        (
            with(&|f| f.rig = "no-such-rig".into()),
            Code::FailedPrecondition,
            "frames[1].rig: rig \"no-such-rig\" is not known",
        ),
        (
            with(&|f| {
                f.reference_pose = Some(pb::Pose2 {
                    x: 0.0,
                    y: f64::NAN,
                    theta: 0.0,
                })
            }),
            Code::InvalidArgument,
            "frames[1].reference_pose.y",
        ),
        (
            with(&|f| f.ranges[7] = f64::NAN),
            Code::InvalidArgument,
            "frames[1].ranges[7]",
        ),
        (
            with(&|f| f.ranges[2] = -1.0),
            Code::InvalidArgument,
            "frames[1].ranges[2]",
        ),
        // Finite but beyond what any consumer can use: refused at the door
        // rather than stored to stop a cartographer later.
        (
            with(&|f| f.true_pose.get_or_insert_with(Default::default).x = 1e300),
            Code::InvalidArgument,
            "frames[1].true_pose.x: must be within [-1000000, 1000000] m",
        ),
        (
            with(&|f| f.odometry.as_mut().expect("pose").y = -2e6),
            Code::InvalidArgument,
            "frames[1].odometry.y",
        ),
        (
            with(&|f| f.ranges[3] = 1e30),
            Code::InvalidArgument,
            "frames[1].ranges[3]: must be at most 10000 m",
        ),
        (
            with(&|f| f.time_s = 1e300),
            Code::InvalidArgument,
            "frames[1].time_s",
        ),
        (
            with(&|f| f.time_s = -5.0),
            Code::InvalidArgument,
            "frames[1].time_s: must be within [0, 10000000000] s",
        ),
    ];
    for (bad, code, field) in cases {
        // A good frame first: the request is refused whole.
        let request = pb::PublishFramesRequest {
            frames: vec![frame("r", 2), bad],
        };
        refused(client.publish_frames(request).await, code, field);
    }
    let oversized = pb::PublishFramesRequest {
        frames: (1..=600).map(|s| frame("big", s)).collect(),
    };
    refused(
        client.publish_frames(oversized).await,
        Code::ResourceExhausted,
        "PublishFramesRequest",
    );
    let robots = client
        .list_robots(pb::ListRobotsRequest {})
        .await
        .expect("robots")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 1, "{robots:?}");
    assert_eq!(
        (robots[0].frame_count, robots[0].last_sequence),
        (1, 1),
        "{robots:?}"
    );

    let read = |robot: &str, from, to| pb::ReadFramesRequest {
        robot: robot.into(),
        from_sequence: from,
        to_sequence: to,
        limit: 0,
    };
    for (bad, field) in [
        (read("r", 5, 2), "to_sequence"),
        (read("", 0, 0), "robot"),
        (read("r s", 0, 0), "robot"),
    ] {
        let result = match client.read_frames(bad).await {
            Ok(stream) => stream.into_inner().message().await.map(|_| ()),
            Err(status) => Err(status),
        };
        refused(result, Code::InvalidArgument, field);
    }
    let result = match client
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r?".into(),
            from_sequence: 1,
        })
        .await
    {
        Ok(stream) => stream.into_inner().message().await.map(|_| ()),
        Err(status) => Err(status),
    };
    refused(result, Code::InvalidArgument, "robot");
}

#[tokio::test]
async fn pose_estimates_with_bad_numbers_are_refused_and_not_stored() {
    let (_server, mut client) = server_with_map().await;
    let with = |f: &dyn Fn(&mut pb::PoseEstimate)| {
        let mut bad = estimate("r", 1);
        f(&mut bad);
        bad
    };
    let cases: Vec<(pb::PoseEstimate, Code, &str)> = vec![
        (with(&|e| e.robot.clear()), Code::InvalidArgument, "robot"),
        (
            with(&|e| e.map = "a b".into()),
            Code::InvalidArgument,
            "map",
        ),
        // Like every call, an estimate on a map that does not exist.
        (
            with(&|e| e.map = "ghost".into()),
            Code::NotFound,
            "map \"ghost\"",
        ),
        (
            with(&|e| e.frame_sequence = 0),
            Code::InvalidArgument,
            "frame_sequence",
        ),
        (
            with(&|e| e.time_s = f64::NAN),
            Code::InvalidArgument,
            "time_s",
        ),
        (with(&|e| e.pose = None), Code::InvalidArgument, "pose"),
        (
            with(&|e| e.pose.as_mut().expect("pose").y = f64::NAN),
            Code::InvalidArgument,
            "pose.y",
        ),
        (
            with(&|e| e.covariance = vec![0.0; 5]),
            Code::InvalidArgument,
            "covariance",
        ),
        (
            with(&|e| e.covariance[4] = f64::INFINITY),
            Code::InvalidArgument,
            "covariance[4]",
        ),
        (
            with(&|e| e.lost_score = 1.5),
            Code::InvalidArgument,
            "lost_score",
        ),
        (
            with(&|e| e.lost_score = f64::NAN),
            Code::InvalidArgument,
            "lost_score",
        ),
        (
            with(&|e| e.particle_sample = vec![1.0; 7]),
            Code::InvalidArgument,
            "particle_sample",
        ),
        (
            with(&|e| e.particle_sample = vec![0.5; 3 * 5_001]),
            Code::InvalidArgument,
            "particle_sample",
        ),
        (
            with(&|e| e.particle_sample = vec![0.0, 1.0, f32::NAN]),
            Code::InvalidArgument,
            "particle_sample[2]",
        ),
        (
            with(&|e| e.covariance = vec![0.0; 20_000]),
            Code::ResourceExhausted,
            "PoseEstimate",
        ),
    ];
    for (bad, code, field) in cases {
        refused(client.publish_pose(bad).await, code, field);
    }
    let mut poses = client
        .read_poses(pb::ReadPosesRequest {
            robot: "r".into(),
            from_sequence: 0,
            to_sequence: 0,
        })
        .await
        .expect("read poses")
        .into_inner();
    assert_eq!(poses.message().await.expect("end"), None, "nothing stored");
    let result = match client
        .read_poses(pb::ReadPosesRequest {
            robot: "r".into(),
            from_sequence: 9,
            to_sequence: 3,
        })
        .await
    {
        Ok(stream) => stream.into_inner().message().await.map(|_| ()),
        Err(status) => Err(status),
    };
    refused(result, Code::InvalidArgument, "to_sequence");
    let result = match client
        .watch_poses(pb::WatchPosesRequest {
            robot: "no such robot".into(),
        })
        .await
    {
        Ok(stream) => stream.into_inner().message().await.map(|_| ()),
        Err(status) => Err(status),
    };
    refused(result, Code::InvalidArgument, "robot");
}
