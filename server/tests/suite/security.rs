//! The server's outer shell over real TCP and a real sled directory: the
//! bearer token, TLS, health and reflection, and a graceful stop that keeps
//! every acknowledged batch.

use crate::common::{TestServer, all_tiles, batch, create_map, dense_delta};
use deog_proto::v1 as pb;
use deog_proto::v1::map_service_client::MapServiceClient;
use deog_robot_client::{ClientConfig, ClientError, MapClient, RetryPolicy};
use deog_server::{MAP_SERVICE_NAME, ServerConfig, TlsIdentity};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::Duration;
use tokio_stream::wrappers::ReceiverStream;
use tonic::Code;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint};
use tonic_health::pb::HealthCheckRequest;
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

const TOKEN: &str = "s3cret";

/// Upper bound for any single network step, so a hang fails instead of
/// stalling the suite.
const STEP: Duration = Duration::from_secs(10);

async fn bounded<F: std::future::Future>(what: &str, future: F) -> F::Output {
    tokio::time::timeout(STEP, future)
        .await
        .unwrap_or_else(|_| panic!("{what} took longer than {STEP:?}"))
}

/// A self-signed identity for "localhost"; the certificate doubles as the CA
/// clients trust.
fn localhost_identity() -> (TlsIdentity, Vec<u8>) {
    let rcgen::CertifiedKey { cert, signing_key } =
        rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).expect("certificate");
    let cert_pem = cert.pem().into_bytes();
    let identity = TlsIdentity {
        cert_pem: cert_pem.clone(),
        key_pem: signing_key.serialize_pem().into_bytes(),
    };
    (identity, cert_pem)
}

fn tls_endpoint(addr: SocketAddr, ca_pem: &[u8], domain: &str) -> Endpoint {
    Endpoint::from_shared(format!("https://{addr}"))
        .expect("url")
        .connect_timeout(Duration::from_secs(5))
        .tls_config(
            ClientTlsConfig::new()
                .ca_certificate(Certificate::from_pem(ca_pem))
                .domain_name(domain),
        )
        .expect("client TLS config")
}

/// Starts a TLS server and waits, over TLS, until it reports serving:
/// `TestServer` only waits by itself for plain servers.
async fn start_tls(config: ServerConfig, ca_pem: &[u8]) -> (TestServer, Channel) {
    assert!(config.tls.is_some());
    let server = TestServer::start_with(config).await;
    let endpoint = tls_endpoint(server.addr, ca_pem, "localhost");
    for _ in 0..100 {
        if let Ok(channel) = endpoint.connect().await {
            let serving = HealthClient::new(channel.clone())
                .check(HealthCheckRequest {
                    service: MAP_SERVICE_NAME.into(),
                })
                .await
                .is_ok_and(|r| r.into_inner().status == ServingStatus::Serving as i32);
            if serving {
                return (server, channel);
            }
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("TLS server at {} never became ready", server.addr);
}

/// `message` with `authorization: <value>`.
fn with_auth<T>(message: T, value: &str) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request
        .metadata_mut()
        .insert("authorization", value.parse().expect("header value"));
    request
}

fn bearer() -> String {
    format!("Bearer {TOKEN}")
}

async fn list_maps(
    client: &mut MapServiceClient<Channel>,
    authorization: Option<&str>,
) -> Result<Vec<String>, tonic::Status> {
    let request = match authorization {
        Some(value) => with_auth(pb::ListMapsRequest {}, value),
        None => tonic::Request::new(pb::ListMapsRequest {}),
    };
    let reply = bounded("list maps", client.list_maps(request)).await?;
    Ok(reply
        .into_inner()
        .maps
        .into_iter()
        .map(|m| m.name)
        .collect())
}

async fn health_status(channel: Channel, service: &str) -> Result<i32, tonic::Status> {
    let request = HealthCheckRequest {
        service: service.into(),
    };
    let reply = bounded("health check", HealthClient::new(channel).check(request)).await?;
    Ok(reply.into_inner().status)
}

async fn plain_channel(server: &TestServer) -> Channel {
    Channel::from_shared(server.url())
        .expect("url")
        .connect()
        .await
        .expect("connect")
}

/// A robot-client configuration that gives up quickly, for calls meant to
/// fail.
fn robot_config(addr: SocketAddr) -> ClientConfig {
    ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(10),
            max: Duration::from_millis(50),
            max_attempts: Some(3),
        },
        ..ClientConfig::new(addr.to_string())
    }
}

fn map_request(name: &str) -> pb::CreateMapRequest {
    pb::CreateMapRequest {
        name: name.into(),
        tile_size: 8,
        ..Default::default()
    }
}

fn assert_unauthenticated(error: ClientError) {
    let text = error.to_string();
    match error {
        ClientError::Status(status) => assert_eq!(status.code(), Code::Unauthenticated, "{status}"),
        other => panic!("expected a refused call, got {other}"),
    }
    assert!(text.contains("authorization"), "{text}");
}

#[tokio::test]
async fn the_token_guards_every_map_call_but_not_health() {
    let server = TestServer::start_with(ServerConfig {
        token: Some(TOKEN.into()),
        ..ServerConfig::default()
    })
    .await;
    let mut client = server.client().await;

    let missing = list_maps(&mut client, None).await.unwrap_err();
    assert_eq!(missing.code(), Code::Unauthenticated, "{missing:?}");
    for wrong in [
        "Bearer wrong",
        "Bearer s3cre",
        "Bearer s3crett",
        TOKEN,
        "Basic s3cret",
    ] {
        let refused = list_maps(&mut client, Some(wrong)).await.unwrap_err();
        assert_eq!(refused.code(), Code::Unauthenticated, "{wrong:?}");
    }
    assert!(
        list_maps(&mut client, Some(&bearer()))
            .await
            .unwrap()
            .is_empty()
    );

    // Writes and streams go through the same check, and a refused write
    // leaves nothing behind.
    let create = client.create_map(tonic::Request::new(map_request("nope")));
    assert_eq!(
        bounded("create", create).await.unwrap_err().code(),
        Code::Unauthenticated
    );
    let updates = tokio_stream::iter(vec![batch("nope", "c", 1, Vec::new())]);
    let apply = client.apply_updates(tonic::Request::new(updates));
    assert_eq!(
        bounded("apply", apply).await.unwrap_err().code(),
        Code::Unauthenticated
    );
    let query = pb::TileQuery {
        map: "nope".into(),
        ..Default::default()
    };
    let tiles = client.get_tiles(tonic::Request::new(query));
    assert_eq!(
        bounded("tiles", tiles).await.unwrap_err().code(),
        Code::Unauthenticated
    );
    let created = client.create_map(with_auth(map_request("yes"), &bearer()));
    bounded("create", created).await.unwrap();
    assert_eq!(
        list_maps(&mut client, Some(&bearer())).await.unwrap(),
        ["yes"]
    );

    // Load balancers and orchestrators probe health without credentials.
    let channel = plain_channel(&server).await;
    let status = health_status(channel.clone(), MAP_SERVICE_NAME)
        .await
        .unwrap();
    assert_eq!(status, ServingStatus::Serving as i32);

    // The robot client sends the token on every call; a trailing newline,
    // as read from a token file, is trimmed on both sides.
    let robot = MapClient::connect(ClientConfig {
        token: Some(format!("{TOKEN}\n")),
        ..robot_config(server.addr)
    })
    .await
    .unwrap();
    robot.ensure_map(map_request("robot")).await.unwrap();
    assert_eq!(robot.map_info("robot").await.unwrap().tile_size, 8);
    assert_eq!(robot.map_info("yes").await.unwrap().version, 0);

    // Without a token the connection itself succeeds; the first call is
    // refused, and not retried as if transient.
    let anonymous = MapClient::connect(robot_config(server.addr)).await.unwrap();
    let error = anonymous.map_info("robot").await.unwrap_err();
    assert!(!error.is_transient());
    assert_unauthenticated(error);
    let wrong = MapClient::connect(ClientConfig {
        token: Some("wrong".into()),
        ..robot_config(server.addr)
    })
    .await
    .unwrap();
    let error = wrong.ensure_map(map_request("robot2")).await.unwrap_err();
    assert!(matches!(&error, ClientError::Status(s) if s.code() == Code::Unauthenticated));
    server.stop().await;
}

#[tokio::test]
async fn tls_serves_calls_to_clients_that_trust_the_certificate() {
    let (identity, ca_pem) = localhost_identity();
    let (server, channel) = start_tls(
        ServerConfig {
            tls: Some(identity),
            ..ServerConfig::default()
        },
        &ca_pem,
    )
    .await;
    let mut client = MapServiceClient::new(channel);
    assert!(list_maps(&mut client, None).await.unwrap().is_empty());
    let info = create_map(&mut client, "secure", 8).await;
    assert_eq!((info.name.as_str(), info.version), ("secure", 0));
    assert_eq!(list_maps(&mut client, None).await.unwrap(), ["secure"]);

    // A plaintext HTTP/2 client gets nothing from a TLS port.
    let plain = bounded("plaintext call", async {
        let channel = Channel::from_shared(server.url())
            .expect("url")
            .connect()
            .await?;
        let mut client = MapServiceClient::new(channel);
        client
            .list_maps(pb::ListMapsRequest {})
            .await
            .map_err(|status| anyhow::anyhow!(status))?;
        anyhow::Ok(())
    })
    .await;
    assert!(plain.is_err(), "a plaintext call succeeded on the TLS port");

    // The client really verifies the server: a certificate it does not
    // trust, or one for another name, fails the handshake.
    let (_, other_ca) = localhost_identity();
    let untrusted = tls_endpoint(server.addr, &other_ca, "localhost");
    let misnamed = tls_endpoint(server.addr, &ca_pem, "map.example.org");
    for endpoint in [untrusted, misnamed] {
        let result = bounded("TLS call", async {
            let mut client = MapServiceClient::new(endpoint.connect().await?);
            client
                .list_maps(pb::ListMapsRequest {})
                .await
                .map_err(|status| anyhow::anyhow!(status))?;
            anyhow::Ok(())
        })
        .await;
        assert!(
            result.is_err(),
            "TLS with an unverifiable certificate succeeded"
        );
    }

    // The robot client turns TLS on with a CA; the name to check is given
    // because the address is an IP.
    let robot = MapClient::connect(ClientConfig {
        tls_ca_pem: Some(ca_pem.clone()),
        tls_domain: Some("localhost".into()),
        ..robot_config(server.addr)
    })
    .await
    .unwrap();
    let made = robot.ensure_map(map_request("robot")).await.unwrap();
    assert_eq!(made.name, "robot");
    assert_eq!(robot.map_info("secure").await.unwrap().tile_size, 8);
    // Ensuring an existing map returns it.
    assert_eq!(
        robot
            .ensure_map(map_request("robot"))
            .await
            .unwrap()
            .version,
        0
    );
    let untrusting = MapClient::connect(ClientConfig {
        tls_ca_pem: Some(other_ca),
        tls_domain: Some("localhost".into()),
        ..robot_config(server.addr)
    })
    .await;
    match untrusting {
        Err(_) => {}
        Ok(client) => assert!(client.map_info("secure").await.is_err()),
    }
    server.stop().await;
}

#[tokio::test]
async fn tls_and_token_together_need_both() {
    let (identity, ca_pem) = localhost_identity();
    let (server, channel) = start_tls(
        ServerConfig {
            tls: Some(identity),
            token: Some(TOKEN.into()),
            ..ServerConfig::default()
        },
        &ca_pem,
    )
    .await;
    let mut client = MapServiceClient::new(channel.clone());
    let missing = list_maps(&mut client, None).await.unwrap_err();
    assert_eq!(missing.code(), Code::Unauthenticated);
    let wrong = list_maps(&mut client, Some("Bearer wrong"))
        .await
        .unwrap_err();
    assert_eq!(wrong.code(), Code::Unauthenticated);
    assert!(
        list_maps(&mut client, Some(&bearer()))
            .await
            .unwrap()
            .is_empty()
    );
    let status = health_status(channel, MAP_SERVICE_NAME).await.unwrap();
    assert_eq!(status, ServingStatus::Serving as i32);

    let tls_only = ClientConfig {
        tls_ca_pem: Some(ca_pem),
        tls_domain: Some("localhost".into()),
        ..robot_config(server.addr)
    };
    let anonymous = MapClient::connect(tls_only.clone()).await.unwrap();
    assert_unauthenticated(anonymous.ensure_map(map_request("m")).await.unwrap_err());
    let robot = MapClient::connect(ClientConfig {
        token: Some(TOKEN.into()),
        ..tls_only
    })
    .await
    .unwrap();
    robot.ensure_map(map_request("m")).await.unwrap();
    assert_eq!(robot.map_info("m").await.unwrap().name, "m");
    server.stop().await;
}

/// Every service name that reflection version `$version` (a module of
/// `tonic_reflection::pb`) lists on `$channel`, sorted.
macro_rules! reflected_services {
    ($version:ident, $channel:expr) => {{
        use tonic_reflection::pb::$version::ServerReflectionRequest;
        use tonic_reflection::pb::$version::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$version::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$version::server_reflection_response::MessageResponse;
        let mut client = ServerReflectionClient::new($channel);
        let request = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::ListServices(String::new())),
        };
        let mut replies = bounded(
            "reflection",
            client.server_reflection_info(tokio_stream::iter(vec![request])),
        )
        .await
        .unwrap()
        .into_inner();
        let reply = bounded("reflection reply", replies.message())
            .await
            .unwrap()
            .expect("a reflection reply");
        match reply.message_response {
            Some(MessageResponse::ListServicesResponse(list)) => {
                let mut names: Vec<String> = list.service.into_iter().map(|s| s.name).collect();
                names.sort();
                names
            }
            other => panic!("unexpected reflection reply {other:?}"),
        }
    }};
}

#[tokio::test]
async fn health_and_reflection_describe_the_server_without_a_token() {
    // With a token set, both must stay open: they carry no map data.
    let server = TestServer::start_with(ServerConfig {
        token: Some(TOKEN.into()),
        ..ServerConfig::default()
    })
    .await;
    let channel = plain_channel(&server).await;
    let serving = ServingStatus::Serving as i32;
    assert_eq!(
        health_status(channel.clone(), MAP_SERVICE_NAME)
            .await
            .unwrap(),
        serving
    );
    // "" is the server as a whole.
    assert_eq!(health_status(channel.clone(), "").await.unwrap(), serving);
    let unknown = health_status(channel.clone(), "deog.v1.NoSuchService")
        .await
        .unwrap_err();
    assert_eq!(unknown.code(), Code::NotFound);

    let services = reflected_services!(v1, channel);
    for name in [MAP_SERVICE_NAME, "grpc.reflection.v1.ServerReflection"] {
        assert!(
            services.iter().any(|s| s == name),
            "{name} missing from {services:?}"
        );
    }
    server.stop().await;
}

#[tokio::test]
async fn reflection_lists_exactly_the_served_services_in_both_versions() {
    let server = TestServer::start().await;
    let served = [
        MAP_SERVICE_NAME,
        "grpc.health.v1.Health",
        "grpc.reflection.v1.ServerReflection",
        "grpc.reflection.v1alpha.ServerReflection",
    ];
    let services = reflected_services!(v1, plain_channel(&server).await);
    assert_eq!(services, served);
    let services = reflected_services!(v1alpha, plain_channel(&server).await);
    assert_eq!(services, served);
    server.stop().await;
}

/// The answers reflection version `$version` gives on `$channel` to a
/// stream of requests for `$symbols` (files containing each), in order:
/// for each, the files' names, or the error code answered in the stream.
macro_rules! reflected_symbols {
    ($version:ident, $channel:expr, $symbols:expr) => {{
        use tonic_reflection::pb::$version::ServerReflectionRequest;
        use tonic_reflection::pb::$version::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$version::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$version::server_reflection_response::MessageResponse;
        let mut client = ServerReflectionClient::new($channel);
        let requests: Vec<ServerReflectionRequest> = $symbols
            .iter()
            .map(|symbol: &&str| ServerReflectionRequest {
                host: String::new(),
                message_request: Some(MessageRequest::FileContainingSymbol((*symbol).to_owned())),
            })
            .collect();
        let count = requests.len();
        let mut replies = bounded(
            "reflection",
            client.server_reflection_info(tokio_stream::iter(requests)),
        )
        .await
        .unwrap()
        .into_inner();
        let mut answers: Vec<Result<Vec<String>, i32>> = Vec::new();
        for _ in 0..count {
            let reply = bounded("reflection reply", replies.message())
                .await
                .unwrap()
                .expect("a reflection reply for each request");
            answers.push(match reply.message_response {
                Some(MessageResponse::FileDescriptorResponse(files)) => Ok(files
                    .file_descriptor_proto
                    .iter()
                    .map(|f| {
                        <prost_types::FileDescriptorProto as prost::Message>::decode(f.as_slice())
                            .unwrap()
                            .name()
                            .to_owned()
                    })
                    .collect()),
                Some(MessageResponse::ErrorResponse(e)) => Err(e.error_code),
                other => panic!("unexpected reflection reply {other:?}"),
            });
        }
        // The client's side ended: so does the server's, with OK.
        assert!(
            bounded("reflection end", replies.message())
                .await
                .unwrap()
                .is_none()
        );
        answers
    }};
}

#[tokio::test]
async fn reflection_describes_every_served_service_in_both_versions_and_answers_errors_in_the_stream()
 {
    let server = TestServer::start().await;
    let symbols = [
        "grpc.reflection.v1alpha.ServerReflection",
        "no.such.Service",
        "grpc.reflection.v1.ServerReflection",
        "grpc.health.v1.Health",
        "deog.v1.MapService.ApplyUpdates",
    ];
    let v1 = reflected_symbols!(v1, plain_channel(&server).await, symbols);
    let v1alpha = reflected_symbols!(v1alpha, plain_channel(&server).await, symbols);
    for answers in [v1, v1alpha] {
        assert_eq!(answers.len(), symbols.len());
        assert_eq!(answers[1], Err(Code::NotFound as i32), "{answers:?}");
        for (symbol, answer) in symbols.iter().zip(&answers) {
            if *symbol != "no.such.Service" {
                let files = answer.as_ref().expect("files");
                assert!(!files.is_empty(), "{symbol}: no file");
            }
        }
        // The map service's file comes with the files it imports.
        let map_files = answers[4].as_ref().unwrap();
        assert!(map_files[0].starts_with("deog/v1/"), "{map_files:?}");
    }
    server.stop().await;
}

#[tokio::test]
async fn a_graceful_stop_keeps_every_acknowledged_batch() {
    const BATCHES: u64 = 24;
    const CLIENT: &str = "robot-7";
    let config = ServerConfig::default();
    let server = TestServer::start_with(config.clone()).await;
    let path = server.path.clone();
    let mut client = server.client().await;
    let info = create_map(&mut client, "kept", 8).await;
    let area = (info.tile_size * info.tile_size) as usize;

    // Small mixed-sign deltas over three tiles: sums stay far inside the
    // clamp limits, so the stored cells must equal them exactly.
    let mut sums: HashMap<(i32, i32), Vec<Option<i32>>> = HashMap::new();
    let mut planned = Vec::new();
    for sequence in 1..=BATCHES {
        let s = sequence as i32;
        let mut tiles = Vec::new();
        for key in [(0, 0), (s % 2 - 1, 3), (-5, s % 3)] {
            let cells: Vec<i16> = (0..area as i32)
                .map(|c| ((c * 7 + s * 13) % 11 - 5) as i16)
                .collect();
            let sum = sums.entry(key).or_insert_with(|| vec![None; area]);
            for (cell, &v) in sum.iter_mut().zip(&cells) {
                if v != 0 {
                    *cell = Some(cell.unwrap_or(0) + i32::from(v));
                }
            }
            tiles.push(dense_delta(key.0, key.1, &cells));
        }
        planned.push(batch("kept", CLIENT, sequence, tiles));
    }

    // Health is watched on its own connection, to see the stop announced.
    let mut health = HealthClient::new(plain_channel(&server).await);
    let mut watch = bounded(
        "health watch",
        health.watch(HealthCheckRequest {
            service: MAP_SERVICE_NAME.into(),
        }),
    )
    .await
    .unwrap()
    .into_inner();
    let first = bounded("health", watch.message()).await.unwrap().unwrap();
    assert_eq!(first.status, ServingStatus::Serving as i32);

    // One stream, kept open: each batch is sent after the previous ack.
    let (sender, outgoing) = tokio::sync::mpsc::channel(4);
    let mut planned = planned.into_iter();
    sender.send(planned.next().unwrap()).await.unwrap();
    let mut acks = bounded(
        "open updates",
        client.apply_updates(ReceiverStream::new(outgoing)),
    )
    .await
    .unwrap()
    .into_inner();
    let mut acked = 0;
    loop {
        let ack = bounded("ack", acks.message())
            .await
            .unwrap()
            .expect("an ack");
        acked += 1;
        assert_eq!(
            (ack.sequence, ack.applied, ack.map_version),
            (acked, true, acked)
        );
        match planned.next() {
            Some(next) => sender.send(next).await.unwrap(),
            None => break,
        }
    }
    assert_eq!(acked, BATCHES);

    let stopping = tokio::spawn(server.stop());
    // The open update stream is ended by the server with a status a client
    // treats as "reconnect and resend", not left hanging.
    let end = bounded("update stream end", acks.message()).await;
    assert!(
        matches!(&end, Err(status) if status.code() == Code::Unavailable),
        "{end:?}"
    );
    // The status flips before the transport stops; a watcher sees it.
    let last = bounded("health", watch.message()).await.unwrap().unwrap();
    assert_eq!(last.status, ServingStatus::NotServing as i32);
    // Health streams are not ended by the server; let go of ours so the
    // stop is not held for the whole grace period.
    drop((watch, health, acks, sender, client));
    let dir = bounded("graceful stop", stopping).await.expect("stop task");

    let server = TestServer::start_at(path, config).await;
    let mut client = server.client().await;
    let info = client
        .get_map_info(pb::MapRef {
            name: "kept".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.version, BATCHES);
    assert_eq!(info.tile_count, sums.len() as u64);
    let observed = sums.values().flatten().filter(|c| c.is_some()).count();
    assert_eq!(info.cell_count, observed as u64);
    let cursor = client
        .get_update_cursor(pb::UpdateCursorRequest {
            map: "kept".into(),
            client_id: CLIENT.into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(cursor.last_sequence, BATCHES);
    let tiles = all_tiles(&mut client, "kept").await;
    assert_eq!(tiles.len(), sums.len());
    for (key, _, cells) in tiles {
        let want = &sums[&(key.x, key.y)];
        for (i, (&got, want)) in cells.iter().zip(want).enumerate() {
            let want = want.map_or(i16::MIN, |v| v as i16);
            assert_eq!(got, want, "tile ({}, {}) cell {i}", key.x, key.y);
        }
    }
    server.stop().await;
    drop(dir);
}

#[tokio::test]
async fn a_stop_past_the_grace_period_closes_what_is_left() {
    let config = ServerConfig {
        shutdown_grace: Duration::from_millis(200),
        ..ServerConfig::default()
    };
    let server = TestServer::start_with(config.clone()).await;
    let path = server.path.clone();
    // A health watch is a stream the server never ends by itself, so it
    // outlives the grace period.
    let mut health = HealthClient::new(plain_channel(&server).await);
    let request = HealthCheckRequest {
        service: MAP_SERVICE_NAME.into(),
    };
    let mut watch = bounded("health watch", health.watch(request))
        .await
        .unwrap()
        .into_inner();
    bounded("health", watch.message()).await.unwrap().unwrap();
    let dir = bounded("stop", server.stop()).await;

    // serve() has returned: the store must be closed, so it opens again
    // while the watcher still holds its end.
    let restarted = tokio::spawn(TestServer::start_at(path, config)).await;
    assert!(
        restarted.is_ok(),
        "the store is still open after serve() returned"
    );
    // ... and the leftover stream must have been ended.
    let ended = tokio::time::timeout(Duration::from_secs(2), async {
        while let Ok(Some(_)) = watch.message().await {}
    })
    .await;
    assert!(
        ended.is_ok(),
        "a stream is still served after serve() returned"
    );
    restarted.unwrap().stop().await;
    drop(dir);
}

#[tokio::test]
async fn a_bad_tls_key_is_refused_with_the_reason() {
    // It used to be reported as "TLS setup failed: transport error".
    let (mut identity, _) = localhost_identity();
    identity.key_pem = b"-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n".to_vec();
    let dir = tempfile::tempdir().expect("temp dir");
    let store = deog_server::SledStore::open(&deog_server::SledConfig::new(dir.path().join("s")))
        .expect("store");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let config = ServerConfig {
        tls: Some(identity),
        ..ServerConfig::default()
    };
    let error = bounded(
        "refusal",
        deog_server::serve(
            std::sync::Arc::new(store),
            listener,
            config,
            std::future::pending(),
        ),
    )
    .await
    .expect_err("refused");
    let text = error.to_string();
    assert!(text.contains("TLS key"), "{text}");
    assert!(text.contains("no private key"), "{text}");
    assert!(!text.contains("transport error"), "{text}");

    // A key that parses but is not the certificate's is refused with the
    // transport's reason, not its bare "transport error".
    let (mut mismatched, _) = localhost_identity();
    mismatched.key_pem = localhost_identity().0.key_pem;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let store = deog_server::SledStore::open(&deog_server::SledConfig::new(dir.path().join("t")))
        .expect("store");
    let result = tokio::time::timeout(
        Duration::from_secs(2),
        deog_server::serve(
            std::sync::Arc::new(store),
            listener,
            ServerConfig {
                tls: Some(mismatched),
                ..ServerConfig::default()
            },
            std::future::pending(),
        ),
    )
    .await;
    let text = match result {
        Ok(Err(error)) => error.to_string(),
        other => panic!("a mismatched key was not refused: {other:?}"),
    };
    assert!(text.contains("TLS setup failed"), "{text}");
    assert!(text.contains("KeyMismatch"), "{text}");
}

#[tokio::test]
async fn health_watch_on_an_unknown_service_streams_service_unknown_and_stays_open() {
    let server = TestServer::start().await;
    let mut health = HealthClient::new(plain_channel(&server).await);
    // Check answers NOT_FOUND, as the protocol says.
    let checked = health_status(plain_channel(&server).await, "no.such.Service").await;
    assert_eq!(checked.expect_err("unknown").code(), Code::NotFound);
    // Watch streams SERVICE_UNKNOWN and does not end.
    let mut watch = bounded(
        "health watch",
        health.watch(HealthCheckRequest {
            service: "no.such.Service".into(),
        }),
    )
    .await
    .expect("a watch, not an error")
    .into_inner();
    let first = bounded("first status", watch.message())
        .await
        .expect("ok")
        .expect("a status");
    assert_eq!(first.status, ServingStatus::ServiceUnknown as i32);
    let next = tokio::time::timeout(Duration::from_millis(500), watch.message()).await;
    assert!(next.is_err(), "the watch stays open: {next:?}");
    drop(watch);
    // The map service, watched, is SERVING.
    let mut watch = bounded(
        "health watch",
        health.watch(HealthCheckRequest {
            service: MAP_SERVICE_NAME.into(),
        }),
    )
    .await
    .expect("watch")
    .into_inner();
    let first = bounded("status", watch.message()).await.unwrap().unwrap();
    assert_eq!(first.status, ServingStatus::Serving as i32);
    // A watch never ends by itself; the stop would wait out its grace.
    drop(watch);
    server.stop().await;
}
