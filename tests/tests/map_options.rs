//! `deog map` refuses bad sonar model options with a clear error naming
//! them, before it connects to anything: the server named here does not
//! exist, so reaching for it would fail differently (and only after its
//! retries).

use deog_tests::{failure, run_deog};

#[test]
fn bad_sonar_model_options_are_refused_before_connecting() {
    // Port 9 (discard) on loopback: nothing of ours listens there.
    let env = [("DEOG_SERVER", "127.0.0.1:9".to_string())];
    let cases: [(&[&str], &str); 5] = [
        (&["--min-empty", "0.3"], "min_empty"),
        (&["--min-empty", "0.99"], "min_empty"),
        (&["--min-occupied", "0.7"], "min_occupied"),
        (&["--max-mapped-range", "20"], "max_mapped_range"),
        (&["--max-occupied", "NaN"], "max_occupied"),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["map", "--robot", "scout", "--map", "m"];
        args.extend_from_slice(extra);
        let stderr = failure(&run_deog(&args, &env));
        assert!(stderr.contains(expected), "{extra:?}: {stderr}");
        assert!(stderr.contains("--max-mapped-range"), "{extra:?}: {stderr}");
        assert!(!stderr.contains("connecting"), "{extra:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{extra:?}: {stderr}");
    }
}

#[test]
fn a_bad_firing_period_is_refused_before_connecting() {
    let env = [("DEOG_SERVER", "127.0.0.1:9".to_string())];
    for period in ["NaN", "20", "inf"] {
        let args = [
            "map",
            "--robot",
            "scout",
            "--map",
            "m",
            "--firing-period",
            period,
        ];
        let stderr = failure(&run_deog(&args, &env));
        assert!(stderr.contains("--firing-period"), "{period}: {stderr}");
        assert!(!stderr.contains("connecting"), "{period}: {stderr}");
        assert!(!stderr.contains("panicked"), "{period}: {stderr}");
    }
}
