//! The simulator's limits and guards over real TCP on 127.0.0.1: watch
//! calls that leave nothing behind, caps on robots and watch streams, the
//! drive command clamped as the API says, the bearer token and TLS.

use std::net::SocketAddr;
use std::time::Duration;

use deog_proto::tls::TlsIdentity;
use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_client::RobotServiceClient;
use deog_robot_client::{ClientConfig, ClientError, RetryPolicy, SimClient};
use deog_simulator::serve::{SimServeConfig, serve_sim, serve_sim_server};
use deog_simulator::service::SimServer;
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_world::{Point2, Polygon, World};
use tokio::sync::oneshot;
use tokio_util::sync::CancellationToken;
use tonic::Code;
use tonic::transport::Channel;

const TOKEN: &str = "s3cret";

/// An 10 m x 8 m empty room.
fn room() -> World {
    World::new(
        "room",
        Some(Polygon::rectangle(
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 8.0),
        )),
        Vec::new(),
    )
    .expect("world")
}

/// A simulator served in this process, with a handle on its server.
struct Sim {
    addr: SocketAddr,
    server: SimServer,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), deog_simulator::SimError>>,
}

impl Sim {
    /// Starts a plain simulator; `start_with` for TLS ones.
    async fn start(config: SimServeConfig) -> Self {
        let sim = Self::start_with(config).await;
        // Ready once a plain connection is taken (the token, if any, is
        // checked per call, not per connection).
        for _ in 0..100 {
            if Channel::from_shared(sim.url())
                .expect("url")
                .connect()
                .await
                .is_ok()
            {
                return sim;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        panic!("simulator at {} never became reachable", sim.addr);
    }

    async fn start_with(config: SimServeConfig) -> Self {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind");
        let addr = listener.local_addr().expect("addr");
        let sim = Simulation::new(room(), SimConfig::default(), 7).expect("simulation");
        let token = CancellationToken::new();
        let server = SimServer::new(sim, config, token.clone()).expect("valid config");
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(serve_sim_server(server.clone(), token, listener, async {
            let _ = stopped.await;
        }));
        Self {
            addr,
            server,
            stop: Some(stop),
            task,
        }
    }

    fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    async fn client(&self) -> RobotServiceClient<Channel> {
        RobotServiceClient::connect(self.url())
            .await
            .expect("connect")
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

fn spawn_at(name: &str, x: f64, y: f64) -> pb::SpawnRequest {
    pb::SpawnRequest {
        name: name.into(),
        pose: Some(pb::Pose2 { x, y, theta: 0.0 }),
    }
}

/// The status of a watch call: refused at once or as the stream's first
/// item.
async fn watch_status(
    client: &mut RobotServiceClient<Channel>,
    name: &str,
) -> Result<tonic::Streaming<pb::RobotState>, tonic::Status> {
    let mut stream = client
        .watch_state(pb::RobotRef { name: name.into() })
        .await?
        .into_inner();
    // A stream that is really open starts with the current state.
    match tokio::time::timeout(Duration::from_secs(10), stream.message())
        .await
        .expect("an answer in time")
    {
        Ok(Some(_)) => Ok(stream),
        Ok(None) => Err(tonic::Status::unknown("ended at once")),
        Err(status) => Err(status),
    }
}

/// Waits (bounded) until `check` holds.
async fn eventually(what: &str, mut check: impl FnMut() -> bool) {
    for _ in 0..250 {
        if check() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("{what} did not happen within 5 s");
}

#[tokio::test]
async fn watching_unknown_robots_leaves_no_channel_behind() {
    // Each watch of an unknown robot used to leave a broadcast channel in
    // the server for ever: 20,000 of them grew it by 160 MiB.
    let sim = Sim::start(SimServeConfig::default()).await;
    let mut client = sim.client().await;
    for i in 0..2000 {
        let status = watch_status(&mut client, &format!("ghost-{i}"))
            .await
            .expect_err("no such robot");
        assert_eq!(status.code(), Code::NotFound, "{status:?}");
    }
    assert_eq!(sim.server.watch_channel_count(), 0);
    assert_eq!(sim.server.watcher_count(), 0);

    // A real robot's channel lives while it is watched and goes after.
    client
        .spawn(spawn_at("real", 2.0, 2.0))
        .await
        .expect("spawn");
    let stream = watch_status(&mut client, "real").await.expect("watch");
    assert_eq!(sim.server.watch_channel_count(), 1);
    assert_eq!(sim.server.watcher_count(), 1);
    drop(stream);
    let server = sim.server.clone();
    eventually("the channel going", || {
        server.watch_channel_count() == 0 && server.watcher_count() == 0
    })
    .await;
    sim.stop().await;
}

#[tokio::test]
async fn spawning_past_max_robots_is_resource_exhausted() {
    let sim = Sim::start(SimServeConfig {
        max_robots: 3,
        ..SimServeConfig::default()
    })
    .await;
    let mut client = sim.client().await;
    for i in 0..3 {
        client
            .spawn(spawn_at(&format!("r{i}"), 1.0 + 2.0 * f64::from(i), 2.0))
            .await
            .expect("spawn within the cap");
    }
    let status = client
        .spawn(spawn_at("r3", 8.0, 6.0))
        .await
        .expect_err("past the cap");
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("3 robots"), "{status:?}");
    assert!(status.message().contains("--max-robots"), "{status:?}");
    let robots = client
        .list_robots(pb::ListSimRobotsRequest {})
        .await
        .expect("list")
        .into_inner()
        .robots;
    assert_eq!(robots.len(), 3);
    sim.stop().await;
}

#[test]
fn robot_and_watcher_caps_out_of_range_are_refused() {
    for (config, field) in [
        (
            SimServeConfig {
                max_robots: 0,
                ..SimServeConfig::default()
            },
            "max_robots",
        ),
        (
            SimServeConfig {
                max_robots: 1_000_000,
                ..SimServeConfig::default()
            },
            "max_robots",
        ),
        (
            SimServeConfig {
                max_watchers: 0,
                ..SimServeConfig::default()
            },
            "max_watchers",
        ),
    ] {
        let error = config.validate().expect_err("out of range");
        assert!(error.to_string().contains(field), "{error}");
    }
}

#[tokio::test]
async fn watch_streams_past_max_watchers_are_resource_exhausted() {
    let sim = Sim::start(SimServeConfig {
        max_watchers: 2,
        ..SimServeConfig::default()
    })
    .await;
    let mut client = sim.client().await;
    client.spawn(spawn_at("w", 2.0, 2.0)).await.expect("spawn");
    let first = watch_status(&mut client, "w").await.expect("first");
    let _second = watch_status(&mut client, "w").await.expect("second");
    let status = watch_status(&mut client, "w")
        .await
        .expect_err("past the cap");
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("--max-watchers"), "{status:?}");
    assert_eq!(sim.server.watcher_count(), 2);
    // Closing one frees its place.
    drop(first);
    let server = sim.server.clone();
    eventually("a place freed", || server.watcher_count() == 1).await;
    watch_status(&mut client, "w").await.expect("a place again");
    sim.stop().await;
}

#[tokio::test]
async fn drive_commands_past_1000_m_per_s_are_clamped_not_refused() {
    // The API says commands are clamped to the robot's limits; speeds
    // above 1,000 m/s used to be refused instead.
    let sim = Sim::start(SimServeConfig {
        speed: 10.0,
        ..SimServeConfig::default()
    })
    .await;
    let mut client = sim.client().await;
    client
        .spawn(spawn_at("fast", 2.0, 4.0))
        .await
        .expect("spawn");
    let limits = deog_simulator::ScoutParams::default();
    for (linear, angular) in [(5000.0, 0.0), (-1e300, 1e6), (f64::MAX, -f64::MAX)] {
        client
            .drive(pb::DriveRequest {
                name: "fast".into(),
                command: Some(pb::Twist2 { linear, angular }),
            })
            .await
            .unwrap_or_else(|status| panic!("({linear}, {angular}) refused: {status:?}"));
    }
    client
        .drive(pb::DriveRequest {
            name: "fast".into(),
            command: Some(pb::Twist2 {
                linear: 5000.0,
                angular: 1e4,
            }),
        })
        .await
        .expect("clamped");
    let mut fastest = (0.0f64, 0.0f64);
    for _ in 0..50 {
        tokio::time::sleep(Duration::from_millis(20)).await;
        let state = client
            .get_state(pb::RobotRef {
                name: "fast".into(),
            })
            .await
            .expect("state")
            .into_inner();
        let v = state.velocity.expect("velocity");
        fastest = (
            fastest.0.max(v.linear.abs()),
            fastest.1.max(v.angular.abs()),
        );
    }
    assert!(
        fastest.0 > 0.0 && fastest.0 <= limits.max_linear + 1e-9,
        "{fastest:?}"
    );
    assert!(
        fastest.1 > 0.0 && fastest.1 <= limits.max_angular + 1e-9,
        "{fastest:?}"
    );

    for (linear, angular, field) in [
        (f64::NAN, 0.0, "command.linear"),
        (f64::INFINITY, 0.0, "command.linear"),
        (0.0, f64::NEG_INFINITY, "command.angular"),
        (0.0, f64::NAN, "command.angular"),
    ] {
        let status = client
            .drive(pb::DriveRequest {
                name: "fast".into(),
                command: Some(pb::Twist2 { linear, angular }),
            })
            .await
            .expect_err("not finite");
        assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
        assert!(status.message().contains(field), "{status:?}");
    }
    sim.stop().await;
}

/// A robot client that gives up quickly, for calls meant to fail.
fn client_config(addr: SocketAddr) -> ClientConfig {
    ClientConfig {
        retry: RetryPolicy {
            initial: Duration::from_millis(10),
            max: Duration::from_millis(50),
            max_attempts: Some(3),
        },
        ..ClientConfig::new(addr.to_string())
    }
}

fn unauthenticated(error: ClientError) -> bool {
    matches!(error, ClientError::Status(s) if s.code() == Code::Unauthenticated)
}

#[tokio::test]
async fn with_a_token_every_robot_call_needs_it() {
    let sim = Sim::start(SimServeConfig {
        token: Some(TOKEN.into()),
        ..SimServeConfig::default()
    })
    .await;
    let mut raw = sim.client().await;
    let status = raw
        .spawn(spawn_at("a", 2.0, 2.0))
        .await
        .expect_err("no token");
    assert_eq!(status.code(), Code::Unauthenticated, "{status:?}");
    for wrong in ["Bearer wrong", "Bearer s3cre", "Bearer s3crets3cret", TOKEN] {
        let mut request = tonic::Request::new(pb::GetWorldRequest {});
        request
            .metadata_mut()
            .insert("authorization", wrong.parse().expect("header"));
        let status = raw.get_world(request).await.expect_err("wrong token");
        assert_eq!(status.code(), Code::Unauthenticated, "{wrong:?}");
    }
    let status = watch_status(&mut raw, "a").await.expect_err("no token");
    assert_eq!(status.code(), Code::Unauthenticated, "{status:?}");

    // Health stays open for probes.
    let mut health = tonic_health::pb::health_client::HealthClient::new(
        Channel::from_shared(sim.url())
            .expect("url")
            .connect()
            .await
            .expect("connect"),
    );
    let serving = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: deog_simulator::serve::ROBOT_SERVICE_NAME.into(),
        })
        .await
        .expect("health without a token")
        .into_inner();
    assert_eq!(
        serving.status,
        tonic_health::pb::health_check_response::ServingStatus::Serving as i32
    );

    let anonymous = SimClient::connect(client_config(sim.addr))
        .await
        .expect("connect");
    assert!(unauthenticated(
        anonymous.world().await.expect_err("no token")
    ));
    let robot = SimClient::connect(ClientConfig {
        token: Some(format!("{TOKEN}\n")),
        ..client_config(sim.addr)
    })
    .await
    .expect("connect");
    robot.spawn("a", None).await.expect("spawn with the token");
    robot.drive("a", 0.2, 0.0).await.expect("drive");
    let mut watch = robot.watch("a").await.expect("watch");
    let first = tokio::time::timeout(Duration::from_secs(10), watch.message())
        .await
        .expect("in time")
        .expect("open")
        .expect("a state");
    assert_eq!(first.name, "a");
    assert_eq!(robot.robots().await.expect("list").len(), 1);
    sim.stop().await;
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

#[tokio::test]
async fn tls_and_token_together_serve_clients_that_have_both() {
    let (identity, ca_pem) = localhost_identity();
    let sim = Sim::start_with(SimServeConfig {
        tls: Some(identity),
        token: Some(TOKEN.into()),
        ..SimServeConfig::default()
    })
    .await;
    let tls = ClientConfig {
        tls_ca_pem: Some(ca_pem.clone()),
        tls_domain: Some("localhost".into()),
        retry: RetryPolicy::default(),
        ..client_config(sim.addr)
    };
    let robot = SimClient::connect(ClientConfig {
        token: Some(TOKEN.into()),
        ..tls.clone()
    })
    .await
    .expect("connect over TLS");
    let world = robot.world().await.expect("world over TLS");
    assert_eq!(world.name, "room");
    robot.spawn("secure", None).await.expect("spawn over TLS");

    let anonymous = SimClient::connect(tls).await.expect("connect");
    assert!(unauthenticated(
        anonymous.world().await.expect_err("no token")
    ));

    // A plaintext client gets nothing from the TLS port.
    let plain = async {
        let mut client = RobotServiceClient::connect(sim.url()).await?;
        client
            .get_world(pb::GetWorldRequest {})
            .await
            .map_err(|status| anyhow::anyhow!(status))?;
        anyhow::Ok(())
    };
    let plain = tokio::time::timeout(Duration::from_secs(10), plain)
        .await
        .expect("in time");
    assert!(plain.is_err(), "a plaintext call succeeded on the TLS port");
    // Nor does a client trusting another certificate.
    let (_, other_ca) = localhost_identity();
    let untrusting = SimClient::connect(ClientConfig {
        tls_ca_pem: Some(other_ca),
        tls_domain: Some("localhost".into()),
        token: Some(TOKEN.into()),
        ..client_config(sim.addr)
    })
    .await;
    if let Ok(client) = untrusting {
        assert!(client.world().await.is_err());
    }
    sim.stop().await;
}

#[tokio::test]
async fn a_bad_tls_key_is_refused_with_the_reason() {
    // It used to be reported as just "transport error".
    let (mut identity, _) = localhost_identity();
    identity.key_pem = b"-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n".to_vec();
    let sim = Simulation::new(room(), SimConfig::default(), 7).expect("simulation");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let config = SimServeConfig {
        tls: Some(identity),
        ..SimServeConfig::default()
    };
    let error = tokio::time::timeout(
        Duration::from_secs(10),
        serve_sim(sim, listener, config, std::future::pending()),
    )
    .await
    .expect("refused at once")
    .expect_err("refused");
    let text = error.to_string();
    assert!(text.contains("TLS key"), "{text}");
    assert!(text.contains("no private key"), "{text}");
    assert!(!text.starts_with("transport error"), "{text}");
}
