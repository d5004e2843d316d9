//! `deog localize` refuses bad options and unknown maps with a clear
//! error, before following any frame. (Apart from `localize.rs`, whose
//! simulated run should not share the machine with these processes.)

use deog_tests::{ServerProcess, failure, run_deog};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_options_and_unknown_maps_are_clear_errors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let env = [("DEOG_SERVER", server.addr.to_string())];
    let localize = |extra: &[&str]| {
        let mut args = vec![
            "localize",
            "--robot",
            "scout",
            "--map",
            "m",
            "--idle-exit",
            "1",
        ];
        args.extend_from_slice(extra);
        failure(&run_deog(&args, &env))
    };
    let cases: [(&[&str], &str); 11] = [
        (&[], "does not exist"),
        (&["--firing-period", "20"], "--firing-period"),
        (&["--firing-period", "NaN"], "--firing-period"),
        (&["--cache-mb", "4"], "--cache-mb"),
        (&["--specular-angle", "120"], "--specular-angle"),
        (&["--surface-depth", "2"], "--surface-depth"),
        (&["--tempering", "0"], "tempering"),
        (
            &["--max-particles", "10", "--min-particles", "20"],
            "min_particles",
        ),
        (&["--initial-pose", "1,nan,0"], "--initial-pose"),
        (&["--initial-pose", "refrence"], "or `reference` or `true`"),
        (&["--preset", "laser"], "real-laser"),
    ];
    for (extra, expected) in cases {
        let stderr = localize(extra);
        assert!(stderr.contains(expected), "{extra:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{extra:?}: {stderr}");
    }
}
