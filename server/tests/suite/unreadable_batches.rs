//! An update stream whose batch cannot be read ends with an error naming the
//! batch, never with OK: the batches before it stay acknowledged and applied,
//! none after it is.

use crate::common::{TestServer, all_tiles, batch, create_map, dense_delta, send_batches};
use deog_proto::v1 as pb;
use prost::Message;
use prost::bytes::BufMut;
use tonic::Code;
use tonic::codec::{Codec, DecodeBuf, Decoder, EncodeBuf, Encoder};
use tonic::codegen::http::uri::PathAndQuery;

fn small_limits() -> deog_server::ServerConfig {
    deog_server::ServerConfig {
        limits: deog_server::Limits {
            max_message_bytes: 64 << 10,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The keys of the stored tiles, as (x, y).
async fn stored_keys(
    client: &mut deog_proto::v1::map_service_client::MapServiceClient<tonic::transport::Channel>,
) -> Vec<(i32, i32)> {
    all_tiles(client, "m")
        .await
        .iter()
        .map(|(key, _, _)| (key.x, key.y))
        .collect()
}

#[tokio::test]
async fn a_batch_over_the_transport_limit_ends_the_stream_with_resource_exhausted() {
    let config = small_limits();
    let transport_limit = config.limits.transport_message_bytes();
    let server = TestServer::start_with(config).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;

    let mut oversize = batch("m", "c", 2, vec![dense_delta(1, 0, &[5; 64])]);
    oversize.tiles[0].cells = vec![1; transport_limit + 1];
    let (acks, error) = send_batches(
        &mut client,
        vec![
            batch("m", "c", 1, vec![dense_delta(0, 0, &[5; 64])]),
            oversize,
            batch("m", "c", 3, vec![dense_delta(2, 0, &[5; 64])]),
        ],
    )
    .await;

    let sequences: Vec<u64> = acks.iter().map(|a| a.sequence).collect();
    assert_eq!(sequences, [1], "exactly the first batch is acknowledged");
    let status = error.expect("the stream must not end with OK");
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
    assert!(
        status.message().contains("batch 2") && status.message().contains("too large"),
        "the message should name the batch and the reason: {:?}",
        status.message()
    );
    assert_eq!(stored_keys(&mut client).await, [(0, 0)]);
    let cursor = client
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "m".into(),
            client_id: "c".into(),
        })
        .await
        .expect("cursor")
        .into_inner();
    assert_eq!(cursor.last_sequence, 1);
}

/// Sends already encoded messages as they are, so a test can send bytes
/// that are no `UpdateBatch`.
#[derive(Debug, Clone, Copy, Default)]
struct RawBatches;

#[derive(Debug)]
struct RawEncoder;

#[derive(Debug)]
struct AckDecoder;

impl Encoder for RawEncoder {
    type Item = Vec<u8>;
    type Error = tonic::Status;
    fn encode(&mut self, item: Vec<u8>, dst: &mut EncodeBuf<'_>) -> Result<(), tonic::Status> {
        dst.put_slice(&item);
        Ok(())
    }
}

impl Decoder for AckDecoder {
    type Item = pb::UpdateAck;
    type Error = tonic::Status;
    fn decode(&mut self, src: &mut DecodeBuf<'_>) -> Result<Option<pb::UpdateAck>, tonic::Status> {
        pb::UpdateAck::decode(src)
            .map(Some)
            .map_err(|e| tonic::Status::internal(e.to_string()))
    }
}

impl Codec for RawBatches {
    type Encode = Vec<u8>;
    type Decode = pb::UpdateAck;
    type Encoder = RawEncoder;
    type Decoder = AckDecoder;
    fn encoder(&mut self) -> RawEncoder {
        RawEncoder
    }
    fn decoder(&mut self) -> AckDecoder {
        AckDecoder
    }
}

#[tokio::test]
async fn a_batch_that_is_not_a_protobuf_message_ends_the_stream_with_an_error() {
    let server = TestServer::start_with(small_limits()).await;
    let mut client = server.client().await;
    create_map(&mut client, "m", 8).await;

    // Field 1 (map, a string) sent as a varint: no UpdateBatch reads so.
    let not_a_batch = vec![0x08, 0x01];
    let messages = vec![
        batch("m", "c", 1, vec![dense_delta(0, 0, &[5; 64])]).encode_to_vec(),
        not_a_batch,
        batch("m", "c", 3, vec![dense_delta(2, 0, &[5; 64])]).encode_to_vec(),
    ];
    let channel = tonic::transport::Channel::from_shared(server.url())
        .expect("url")
        .connect()
        .await
        .expect("connect");
    let mut grpc = tonic::client::Grpc::new(channel);
    grpc.ready().await.expect("ready");
    let mut stream = grpc
        .streaming(
            tonic::Request::new(tokio_stream::iter(messages)),
            PathAndQuery::from_static("/deog.v1.MapService/ApplyUpdates"),
            RawBatches,
        )
        .await
        .expect("open the stream")
        .into_inner();
    let mut acks = Vec::new();
    let mut error = None;
    for _ in 0..10 {
        match stream.message().await {
            Ok(Some(ack)) => acks.push(ack.sequence),
            Ok(None) => break,
            Err(status) => {
                error = Some(status);
                break;
            }
        }
    }

    assert_eq!(acks, [1], "exactly the first batch is acknowledged");
    let status = error.expect("the stream must not end with OK");
    assert_eq!(status.code(), Code::Internal, "{status:?}");
    assert!(
        status.message().contains("batch 2") && status.message().contains("wire type"),
        "the message should name the batch and the reason: {:?}",
        status.message()
    );
    assert_eq!(stored_keys(&mut client).await, [(0, 0)]);
}
