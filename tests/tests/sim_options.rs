//! `deog sim --max-message-bytes` (or `DEOG_SIM_MAX_MESSAGE_BYTES`) sets the
//! simulator process's request limit, and a limit too small is refused.

use deog_proto::v1 as pb;
use deog_proto::v1::robot_service_client::RobotServiceClient;
use deog_tests::{ServerProcess, failure, run_deog};

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
