//! Sequence numbers of batches and frames: the highest one cannot lock a
//! client out of a map or make frame subscribers replay a robot's history.

use crate::common;
use crate::common::{
    SuiteBackend, TestBackend, TestServer, batch, create_map, dense_delta, send_batches,
};
use deog_proto::v1 as pb;
use deog_server::Store;
use deog_server::store::{FrameWrite, RobotSummary};
use std::time::Duration;
use tonic::Code;

fn frame(robot: &str, sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: robot.into(),
        sequence,
        time_s: 1.0,
        odometry: Some(pb::Pose2 {
            x: 1.0,
            y: 0.5,
            theta: 0.1,
        }),
        true_pose: None,
        ranges: vec![1.0; 16],
        rig: String::new(),
        reference_pose: None,
    }
}

async fn next<T>(stream: &mut tonic::Streaming<T>) -> T {
    tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("in time")
        .expect("ok")
        .expect("open")
}

async fn publish(
    client: &mut pb::map_service_client::MapServiceClient<tonic::transport::Channel>,
    frames: Vec<pb::SonarFrame>,
) -> Result<pb::PublishFramesResponse, tonic::Status> {
    client
        .publish_frames(pb::PublishFramesRequest { frames })
        .await
        .map(tonic::Response::into_inner)
}

async fn subscribe(
    client: &mut pb::map_service_client::MapServiceClient<tonic::transport::Channel>,
    from_sequence: u64,
) -> tonic::Streaming<pb::SonarFrame> {
    client
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence,
        })
        .await
        .expect("subscribe")
        .into_inner()
}

#[tokio::test]
async fn a_batch_numbered_u64_max_is_refused_and_its_client_keeps_the_map() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;

    let (acks, error) = send_batches(
        &mut client,
        vec![batch("m", "c", u64::MAX, vec![dense_delta(0, 0, &[5; 64])])],
    )
    .await;
    assert!(acks.is_empty(), "{acks:?}");
    let status = error.expect("u64::MAX must be refused");
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().contains("sequence") && status.message().contains("u64::MAX"),
        "{:?}",
        status.message()
    );

    let (acks, error) = send_batches(
        &mut client,
        vec![batch("m", "c", 2, vec![dense_delta(0, 0, &[5; 64])])],
    )
    .await;
    assert!(error.is_none(), "{error:?}");
    assert!(acks[0].applied, "the client's next batch is applied");
}

#[tokio::test]
async fn a_frame_numbered_u64_max_is_refused_and_subscribers_replay_nothing() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    publish(&mut client, (1..=3).map(|s| frame("r", s)).collect())
        .await
        .expect("frames 1 to 3");
    let mut new_only = subscribe(&mut client, 0).await;

    let status = publish(&mut client, vec![frame("r", u64::MAX)])
        .await
        .expect_err("u64::MAX must be refused");
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().contains("frames[0].sequence"),
        "{:?}",
        status.message()
    );

    publish(&mut client, vec![frame("r", 4)])
        .await
        .expect("frame 4");
    publish(&mut client, vec![frame("r", 5)])
        .await
        .expect("frame 5");
    assert_eq!(next(&mut new_only).await.sequence, 4);
    assert_eq!(next(&mut new_only).await.sequence, 5, "no replay");
}

#[tokio::test]
async fn a_stored_frame_numbered_u64_max_ends_the_replay_without_wrapping() {
    // Written before PublishFrames refused u64::MAX.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("store");
    {
        let store = SuiteBackend::open(&path);
        let sequences = [1, 2, u64::MAX];
        let summary = sequences
            .iter()
            .fold(RobotSummary::default(), |s, &q| s.with(q));
        let frames = sequences
            .iter()
            .map(|&q| (q, prost::Message::encode_to_vec(&frame("r", q))))
            .collect();
        store
            .write_frames(vec![FrameWrite {
                robot: "r".into(),
                summary,
                frames,
            }])
            .expect("write frames");
        store.flush().expect("flush");
    }
    let server = TestServer::start_at(path, deog_server::ServerConfig::default()).await;
    let mut client = server.client().await;
    let mut replay = subscribe(&mut client, 1).await;
    for expected in [1, 2, u64::MAX] {
        assert_eq!(next(&mut replay).await.sequence, expected);
    }
    publish(&mut client, vec![frame("r", 3)])
        .await
        .expect("frame 3");
    let mut also_three = subscribe(&mut client, 3).await;
    assert_eq!(next(&mut also_three).await.sequence, 3, "frame 3 is stored");
    // Past u64::MAX the first subscriber has seen everything there is.
    let more = tokio::time::timeout(Duration::from_millis(300), replay.message()).await;
    assert!(more.is_err(), "no replay after u64::MAX: {more:?}");
}

/// Sends one single-tile batch (tile (x, 0)) on its own stream.
async fn send_one(
    client: &mut pb::map_service_client::MapServiceClient<tonic::transport::Channel>,
    sequence: u64,
    x: i32,
) -> Result<pb::UpdateAck, tonic::Status> {
    let (acks, error) = send_batches(
        client,
        vec![batch("m", "c", sequence, vec![dense_delta(x, 0, &[5; 64])])],
    )
    .await;
    match error {
        Some(status) => Err(status),
        None => Ok(acks.into_iter().next().expect("one ack")),
    }
}

async fn cursor(
    client: &mut pb::map_service_client::MapServiceClient<tonic::transport::Channel>,
) -> u64 {
    client
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "m".into(),
            client_id: "c".into(),
        })
        .await
        .expect("cursor")
        .into_inner()
        .last_sequence
}

#[tokio::test]
async fn a_batch_out_of_order_is_refused_not_taken_for_a_resend() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    // Gaps are allowed: a client may number batches by its own inputs.
    for (sequence, x) in [(1, 1), (5, 5), (9, 9)] {
        let ack = send_one(&mut client, sequence, x).await.expect("applied");
        assert!(ack.applied, "{ack:?}");
    }
    let before = common::all_tiles(&mut client, "m").await;

    let resend = send_one(&mut client, 5, 5).await.expect("a resend");
    assert!(!resend.applied, "{resend:?}");

    let status = send_one(&mut client, 7, 7)
        .await
        .expect_err("7 was never applied and is below 9");
    assert_eq!(status.code(), Code::FailedPrecondition, "{status:?}");
    assert!(
        status.message().contains(
            "batch sequence 7 of client \"c\" on map \"m\" is below the last applied (9)"
        ) && status.message().contains("never applied"),
        "{:?}",
        status.message()
    );
    assert_eq!(common::all_tiles(&mut client, "m").await, before);
    assert_eq!(cursor(&mut client).await, 9);

    let ack = send_one(&mut client, 10, 10).await.expect("applied");
    assert!(ack.applied, "the client goes on after a refusal");
}

#[tokio::test]
async fn applied_sequences_are_kept_across_a_restart() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    for sequence in [1, 3] {
        assert!(
            send_one(&mut client, sequence, 0)
                .await
                .expect("ack")
                .applied
        );
    }
    let dir = server.stop().await.expect("temp dir");

    let server = TestServer::start_at(
        dir.path().join("store"),
        deog_server::ServerConfig::default(),
    )
    .await;
    let mut client = server.client().await;
    let resend = send_one(&mut client, 3, 0).await.expect("a resend");
    assert!(!resend.applied);
    let status = send_one(&mut client, 2, 0)
        .await
        .expect_err("2 was never applied");
    assert_eq!(status.code(), Code::FailedPrecondition, "{status:?}");
    assert_eq!(cursor(&mut client).await, 3);
}

#[tokio::test]
async fn a_pose_for_frame_u64_max_is_refused() {
    let server = TestServer::start().await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;
    let estimate = |frame_sequence| pb::PoseEstimate {
        robot: "r".into(),
        map: "m".into(),
        frame_sequence,
        time_s: 1.0,
        pose: Some(pb::Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.3,
        }),
        covariance: Vec::new(),
        particle_count: 10,
        converged: false,
        lost_score: 0.0,
        particle_sample: Vec::new(),
    };
    let status = client
        .publish_pose(estimate(u64::MAX))
        .await
        .expect_err("no frame carries u64::MAX");
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(status.message().contains("frame_sequence"), "{status:?}");
    client
        .publish_pose(estimate(u64::MAX - 1))
        .await
        .expect("the highest frame sequence");
}
