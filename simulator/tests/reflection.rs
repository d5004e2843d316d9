//! The simulator's reflection, over real TCP on 127.0.0.1: both versions
//! (v1, and v1alpha that many tools still ask) list exactly what it serves.

use std::time::Duration;

use deog_simulator::serve::{SimServeConfig, serve_sim};
use deog_simulator::simulation::{SimConfig, Simulation};
use deog_world::{Point2, Polygon, World};
use tonic::transport::Channel;

const SERVED: [&str; 4] = [
    "deog.v1.RobotService",
    "grpc.health.v1.Health",
    "grpc.reflection.v1.ServerReflection",
    "grpc.reflection.v1alpha.ServerReflection",
];

/// Bounds one network step, so a hang fails the test.
async fn bounded<T>(what: &str, step: impl std::future::Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(10), step)
        .await
        .unwrap_or_else(|_| panic!("{what} took over 10 s"))
}

/// Every service name that reflection version `$version` (a module of
/// `tonic_reflection::pb`) lists on `channel`, sorted.
macro_rules! listed {
    ($version:ident, $channel:expr) => {{
        use tonic_reflection::pb::$version::ServerReflectionRequest;
        use tonic_reflection::pb::$version::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$version::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$version::server_reflection_response::MessageResponse;
        let request = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::ListServices(String::new())),
        };
        let mut replies = bounded(
            "reflection",
            ServerReflectionClient::new($channel)
                .server_reflection_info(tokio_stream::iter([request])),
        )
        .await
        .expect("reflection answers")
        .into_inner();
        let reply = bounded("reflection reply", replies.message())
            .await
            .expect("a reply")
            .expect("a message");
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
async fn both_reflection_versions_list_exactly_the_served_services() {
    let world = World::new(
        "room",
        Some(Polygon::rectangle(
            Point2::new(0.0, 0.0),
            Point2::new(4.0, 4.0),
        )),
        Vec::new(),
    )
    .expect("world");
    let sim = Simulation::new(world, SimConfig::default(), 1).expect("simulation");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(serve_sim(sim, listener, SimServeConfig::default(), async {
        let _ = stopped.await;
    }));
    let mut channel = None;
    for _ in 0..100 {
        if let Ok(c) = Channel::from_shared(format!("http://{addr}"))
            .expect("uri")
            .connect()
            .await
        {
            channel = Some(c);
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let channel = channel.expect("simulator reachable");
    assert_eq!(listed!(v1, channel.clone()), SERVED);
    assert_eq!(listed!(v1alpha, channel), SERVED);
    let _ = stop.send(());
    bounded("the simulator's stop", task)
        .await
        .expect("task")
        .expect("serve result");
}
