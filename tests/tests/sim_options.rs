//! `deog sim --max-message-bytes` (or `DEOG_SIM_MAX_MESSAGE_BYTES`) sets the
//! simulator process's request limit, and a limit too small is refused;
//! `--max-robots` and `--max-watchers` cap what clients can make it hold;
//! `--token-file`, `--tls-cert` and `--tls-key` guard it as they guard the
//! map server, and its clients pass them with `--sim-token-file`,
//! `--sim-tls-ca` and `--sim-tls-domain`.

use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_client::RobotServiceClient;
use deog_robot_client::{ClientConfig, SimClient};
use deog_tests::{ServerProcess, failure, run_deog, succeeded};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_request_limit_is_set_by_option_or_environment() {
    let sim = ServerProcess::start_sim("map2", &["--max-message-bytes", "2048"]).await;
    let mut client = RobotServiceClient::connect(sim.url())
        .await
        .expect("connect");
    // Past 2048 bytes, though far below the default limit of 64 KiB.
    let status = client
        .spawn(pb::SpawnRequest {
            name: "a".repeat(4096),
            pose: None,
        })
        .await
        .expect_err("oversized");
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("SpawnRequest"), "{status:?}");
    drop(sim);

    let listen = ["sim", "--listen", "127.0.0.1:0"];
    let by_option = failure(&run_deog(
        &[&listen[..], &["--max-message-bytes", "100"]].concat(),
        &[],
    ));
    let by_environment = failure(&run_deog(
        &listen,
        &[("DEOG_SIM_MAX_MESSAGE_BYTES", "100".to_string())],
    ));
    for stderr in [by_option, by_environment] {
        assert!(stderr.contains("max_message_bytes"), "{stderr}");
        assert!(stderr.contains("got 100"), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn robots_and_watchers_past_their_caps_are_resource_exhausted() {
    let sim = ServerProcess::start_sim(
        "map2",
        &["--robots", "2", "--max-robots", "2", "--max-watchers", "1"],
    )
    .await;
    let mut client = RobotServiceClient::connect(sim.url())
        .await
        .expect("connect");
    let status = client
        .spawn(pb::SpawnRequest {
            name: "third".into(),
            pose: None,
        })
        .await
        .expect_err("past --max-robots");
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("--max-robots"), "{status:?}");
    let mut first = client
        .watch_state(pb::RobotRef {
            name: "scout-1".into(),
        })
        .await
        .expect("first watch")
        .into_inner();
    first.message().await.expect("open").expect("a state");
    let status = match client
        .watch_state(pb::RobotRef {
            name: "scout-2".into(),
        })
        .await
    {
        Ok(stream) => stream.into_inner().message().await.expect_err("refused"),
        Err(status) => status,
    };
    assert_eq!(status.code(), tonic::Code::ResourceExhausted, "{status:?}");
    assert!(status.message().contains("--max-watchers"), "{status:?}");
    drop(sim);

    let listen = ["sim", "--listen", "127.0.0.1:0"];
    let too_many = failure(&run_deog(
        &[&listen[..], &["--robots", "3", "--max-robots", "2"]].concat(),
        &[],
    ));
    assert!(too_many.contains("--max-robots"), "{too_many}");
    let zero = failure(&run_deog(
        &listen,
        &[("DEOG_SIM_MAX_WATCHERS", "0".to_string())],
    ));
    assert!(zero.contains("max_watchers"), "{zero}");
}

/// `deog <args>` against the simulator at `sim`, with `env` besides.
fn against(sim: &ServerProcess, args: &[&str], env: &[(&str, String)]) -> std::process::Output {
    let mut env = env.to_vec();
    env.push(("DEOG_SIM", sim.addr.to_string()));
    run_deog(args, &env)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_token_file_the_simulator_serves_only_clients_that_send_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let token_file = dir.path().join("sim-token");
    std::fs::write(&token_file, "s3cret\n").expect("write token");
    let token_file = token_file.to_str().expect("utf-8 path").to_string();
    let sim =
        ServerProcess::start_sim("map2", &["--speed", "10", "--token-file", &token_file]).await;

    let mut raw = RobotServiceClient::connect(sim.url())
        .await
        .expect("connect");
    let status = raw
        .get_world(pb::GetWorldRequest {})
        .await
        .expect_err("no token");
    assert_eq!(status.code(), tonic::Code::Unauthenticated, "{status:?}");

    let wander = [
        "wander",
        "--robot",
        "w",
        "--spawn",
        "--duration",
        "1",
        "--no-publish",
    ];
    let refused = failure(&against(&sim, &wander, &[]));
    assert!(refused.contains("authorization"), "{refused}");
    let by_env = [("DEOG_SIM_TOKEN_FILE", token_file.clone())];
    succeeded(&against(&sim, &wander, &by_env));

    let robot = SimClient::connect(ClientConfig {
        token: Some("s3cret".into()),
        ..ClientConfig::new(sim.addr.to_string())
    })
    .await
    .expect("connect");
    let at = robot
        .state("w")
        .await
        .expect("state")
        .true_pose
        .expect("pose");
    let pose = format!("{},{},{}", at.x, at.y, at.theta);
    let teleport = ["teleport", "--robot", "w", "--pose", &pose];
    failure(&against(&sim, &teleport, &[]));
    let moved = succeeded(&against(
        &sim,
        &[&teleport[..], &["--sim-token-file", &token_file]].concat(),
        &[],
    ));
    assert!(moved.contains("w is now at"), "{moved}");
}

/// A certificate for "localhost" and its key, PEM.
fn localhost_certificate() -> (String, String) {
    let rcgen::CertifiedKey { cert, signing_key } =
        rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).expect("certificate");
    (cert.pem(), signing_key.serialize_pem())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_tls_the_simulator_serves_clients_that_trust_its_certificate() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (cert, key) = localhost_certificate();
    let cert_file = dir.path().join("sim.crt");
    let key_file = dir.path().join("sim.key");
    std::fs::write(&cert_file, &cert).expect("write");
    std::fs::write(&key_file, &key).expect("write");
    let (cert_file, key_file) = (
        cert_file.to_str().expect("utf-8").to_string(),
        key_file.to_str().expect("utf-8").to_string(),
    );
    let sim = ServerProcess::start_sim_tls(
        "map2",
        &[
            "--speed",
            "10",
            "--tls-cert",
            &cert_file,
            "--tls-key",
            &key_file,
        ],
        cert.as_bytes(),
    )
    .await;
    let wander = [
        "wander",
        "--robot",
        "t",
        "--spawn",
        "--duration",
        "1",
        "--no-publish",
    ];
    // A plain client gets nothing from the TLS port (a one-shot command:
    // a follower such as wander would keep trying).
    let plain = failure(&against(
        &sim,
        &[
            "teleport",
            "--robot",
            "t",
            "--pose",
            "1,1,0",
            "--connect-timeout",
            "2",
        ],
        &[],
    ));
    assert!(plain.contains("error: teleporting t:"), "{plain}");
    let trusting = [
        ("DEOG_SIM_TLS_CA", cert_file.clone()),
        ("DEOG_SIM_TLS_DOMAIN", "localhost".to_string()),
    ];
    succeeded(&against(&sim, &wander, &trusting));
}

#[test]
fn a_bad_tls_key_file_is_named_with_the_reason_by_both_servers() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (cert, _) = localhost_certificate();
    let cert_file = dir.path().join("good.crt");
    let bad_key = dir.path().join("bad.key");
    std::fs::write(&cert_file, &cert).expect("write");
    std::fs::write(&bad_key, "not a key\n").expect("write");
    let (cert_file, bad_key) = (
        cert_file.to_str().expect("utf-8"),
        bad_key.to_str().expect("utf-8"),
    );
    let data = dir.path().join("data");
    let data = data.to_str().expect("utf-8");
    let tls = ["--tls-cert", cert_file, "--tls-key", bad_key];
    let sim = failure(&run_deog(
        &[&["sim", "--listen", "127.0.0.1:0"][..], &tls].concat(),
        &[],
    ));
    let server = failure(&run_deog(
        &[
            &["server", "--listen", "127.0.0.1:0", "--data", data][..],
            &tls,
        ]
        .concat(),
        &[],
    ));
    for stderr in [sim, server] {
        assert!(stderr.contains(bad_key), "{stderr}");
        assert!(stderr.contains("no private key"), "{stderr}");
        assert!(!stderr.contains("transport error"), "{stderr}");
    }
}
