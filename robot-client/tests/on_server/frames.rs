//! `MapClient`'s frame calls against a real map server on 127.0.0.1 over a
//! sled directory in a temp dir: the robot listing, and a subscription that
//! replays stored frames and then follows new ones.

use deog_grid::Pose2;
use deog_proto::v1 as pb;
use deog_robot_client::ClientError;
use deog_robot_client::convert::{pose_from_wire, pose_to_wire};
use deog_server::ServerConfig;
use std::time::Duration;

use crate::common::Server;

const ROBOT: &str = "scout-1";

fn frame(sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: ROBOT.into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pose_to_wire(Pose2::new(sequence as f64, 0.0, 0.5))),
        true_pose: None,
        ranges: vec![1.0; 16],
        rig: String::new(),
        reference_pose: None,
    }
}

async fn next_frame(stream: &mut tonic::Streaming<pb::SonarFrame>) -> pb::SonarFrame {
    tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("a frame in time")
        .expect("stream")
        .expect("open")
}

#[tokio::test]
async fn robots_lists_each_robot_with_its_sequence_range() {
    let server = Server::start(ServerConfig::default()).await;
    assert!(server.client.robots().await.expect("robots").is_empty());
    server
        .client
        .publish_frames((1..=3).map(frame).collect())
        .await
        .expect("publish");
    let robots = server.client.robots().await.expect("robots");
    assert_eq!(robots.len(), 1, "{robots:?}");
    let robot = &robots[0];
    assert_eq!(robot.robot, ROBOT);
    assert_eq!((robot.first_sequence, robot.last_sequence), (1, 3));
    assert_eq!(robot.frame_count, 3);
}

#[tokio::test]
async fn a_subscription_replays_from_its_sequence_then_follows() {
    let server = Server::start(ServerConfig::default()).await;
    server
        .client
        .publish_frames((1..=3).map(frame).collect())
        .await
        .expect("publish");
    let mut frames = server
        .client
        .subscribe_frames(ROBOT, 2)
        .await
        .expect("subscribe");
    for sequence in [2, 3] {
        let got = next_frame(&mut frames).await;
        assert_eq!(got.sequence, sequence);
        assert_eq!(
            got.odometry.map(pose_from_wire),
            Some(Pose2::new(sequence as f64, 0.0, 0.5))
        );
    }
    server
        .client
        .publish_frames(vec![frame(4)])
        .await
        .expect("publish live");
    assert_eq!(next_frame(&mut frames).await.sequence, 4);
}

#[tokio::test]
async fn a_subscription_to_a_bad_robot_name_is_refused_naming_the_field() {
    let server = Server::start(ServerConfig::default()).await;
    match server.client.subscribe_frames("no robot", 1).await {
        Err(ClientError::Status(status)) => {
            assert_eq!(status.code(), tonic::Code::InvalidArgument);
            assert_eq!(
                status.message(),
                "robot: character ' ' is not allowed (use A-Z a-z 0-9 _ . -)"
            );
        }
        Err(other) => panic!("expected the server's refusal, got {other}"),
        Ok(_) => panic!("a name with a space was accepted"),
    }
}
