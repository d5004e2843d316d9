//! Read streams whose clients never read, over real TCP on 127.0.0.1: at
//! most `max_streams` run at once (one more is RESOURCE_EXHAUSTED, never a
//! hang), a stalled one ends after the stall timeout and frees its place,
//! and meanwhile the server's other reads (a SubscribeFrames catch-up) go on.

use crate::common::{TestServer, batch, create_map, dense_delta, send_batches};
use deog_proto::v1 as pb;
use deog_server::{ReadStreamLimits, ServerConfig};
use std::time::{Duration, Instant};
use tonic::Code;

const TILES: i32 = 400;

fn whole_map() -> pb::TileQuery {
    pb::TileQuery {
        map: "m".into(),
        selection: Some(pb::tile_query::Selection::Region(pb::CellBox {
            min_x: i32::MIN,
            min_y: i32::MIN,
            max_x: i32::MAX,
            max_y: i32::MAX,
        })),
        newer_than_version: 0,
    }
}

fn frame(sequence: u64) -> pb::SonarFrame {
    pb::SonarFrame {
        robot: "r".into(),
        sequence,
        time_s: sequence as f64 * 0.1,
        odometry: Some(pb::Pose2 {
            x: 1.0,
            y: 1.0,
            theta: 0.0,
        }),
        true_pose: None,
        ranges: vec![1.0; 16],
        rig: String::new(),
        reference_pose: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stalled_readers_take_at_most_their_share_and_give_it_back() {
    let server = TestServer::start_with(ServerConfig {
        reads: ReadStreamLimits {
            max_streams: 4,
            stalled_timeout: Duration::from_secs(1),
        },
        stream_buffer: 2,
        ..ServerConfig::default()
    })
    .await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 64).await;
    // 400 dense tiles of 8 KiB: 3.2 MB a whole-map read, more than the
    // transport buffers for a client that does not read.
    let cells: Vec<i16> = (0..64 * 64).map(|i| (i % 2000) as i16 - 1000).collect();
    let tiles: Vec<pb::TileDelta> = (0..TILES).map(|x| dense_delta(x, 0, &cells)).collect();
    let (acks, error) = send_batches(&mut client, vec![batch("m", "w", 1, tiles)]).await;
    assert!(error.is_none() && acks.len() == 1, "{error:?}");
    client
        .publish_frames(pb::PublishFramesRequest {
            frames: (1..=3).map(frame).collect(),
        })
        .await
        .expect("frames");

    // Four readers that never read, each on its own connection.
    let mut stalled = Vec::new();
    for _ in 0..4 {
        let mut reader = server.client().await;
        stalled.push(
            reader
                .get_tiles(whole_map())
                .await
                .expect("a place")
                .into_inner(),
        );
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let refused = server
        .client()
        .await
        .get_tiles(whole_map())
        .await
        .expect_err("a fifth read stream");
    assert_eq!(refused.code(), Code::ResourceExhausted, "{refused:?}");
    assert!(
        refused.message().contains("--max-read-streams"),
        "{}",
        refused.message()
    );

    // The catch-up of a frame subscription still runs.
    let mut follower = server.client().await;
    let mut frames = follower
        .subscribe_frames(pb::SubscribeFramesRequest {
            robot: "r".into(),
            from_sequence: 1,
        })
        .await
        .expect("subscribe")
        .into_inner();
    for sequence in 1..=3 {
        let frame = tokio::time::timeout(Duration::from_secs(5), frames.message())
            .await
            .expect("the catch-up in time")
            .expect("ok")
            .expect("a frame");
        assert_eq!(frame.sequence, sequence);
    }

    // The stalled streams end after their timeout and free their places:
    // a reader that reads gets the whole map.
    let started = Instant::now();
    let mut served = None;
    while started.elapsed() < Duration::from_secs(15) && served.is_none() {
        if let Ok(reply) = server.client().await.get_tiles(whole_map()).await {
            let mut stream = reply.into_inner();
            let mut count = 0;
            while let Some(_tile) = stream.message().await.expect("tile") {
                count += 1;
            }
            served = Some(count);
        } else {
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
    assert_eq!(served, Some(TILES as usize));
    drop(stalled);
    server.stop().await;
}
