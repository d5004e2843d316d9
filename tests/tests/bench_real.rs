//! `deog bench real` through the real binary, on a prefix of the ACES log
//! with two global starts on short windows: every process runs, the run
//! folder holds their logs, and the JSON carries its keys with sane
//! figures.

use deog_tests::{run_deog, succeeded};

#[test]
fn bench_real_runs_the_recipe_on_a_real_log_and_reports_its_figures() {
    let log = format!(
        "{}/../data/carmen/aces-corrected.log.gz",
        env!("CARGO_MANIFEST_DIR")
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let json_path = dir.path().join("real.json");
    let stdout = succeeded(&run_deog(
        &[
            "bench",
            "real",
            "--log",
            &log,
            "--to",
            "120",
            "--starts",
            "2",
            "--settle-scans",
            "15",
            "--hold-scans",
            "5",
            // Global localization's first scans are the slow ones.
            "--max-particles",
            "20000",
            "--out",
            out.to_str().unwrap(),
            "--json",
            json_path.to_str().unwrap(),
        ],
        &[],
    ));
    assert!(stdout.contains("tracking: RMS position error"), "{stdout}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(json["scans"], 120);
    assert_eq!(json["log_scans"], 440);
    assert_eq!(json["recipe"]["field_tempering"], 0.5);
    assert_eq!(json["recipe"]["field_beams"], 180);
    assert_eq!(json["recipe"]["motion_noise_scale"], 2.0);
    assert_eq!(json["recipe"]["min_particles"], 2000);
    assert_eq!(json["recipe"]["max_particles"], 20000);

    let map = &json["map"];
    let observed = map["observed_cells"].as_u64().unwrap();
    let occupied = map["occupied_cells"].as_u64().unwrap();
    assert!(occupied > 1000 && occupied < observed, "{map}");

    let t = &json["tracking"];
    assert_eq!(t["estimates"], 120, "{t}");
    let rms = t["rms_position_m"].as_f64().unwrap();
    assert!(rms > 0.0 && rms < 0.3, "{t}");
    let heading = t["mean_abs_error_deg"].as_f64().unwrap();
    assert!((0.0..10.0).contains(&heading), "{t}");
    let within = t["within_bounds_fraction"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&within), "{t}");
    assert!(t["max_position_error_m"].as_f64().unwrap() >= rms, "{t}");
    assert!(t["seconds_per_frame"].as_f64().unwrap() > 0.0, "{t}");

    let g = &json["global"];
    let starts = g["starts"].as_array().unwrap();
    assert_eq!(starts.len(), 2);
    for start in starts {
        let scan = start["scan"].as_u64().unwrap();
        assert!((1..=100).contains(&scan), "{start}");
        assert_eq!(start["to"].as_u64().unwrap(), scan + 20, "{start}");
        assert!(start["converged"].is_boolean(), "{start}");
        assert!(start["estimates"].as_u64().unwrap() > 0, "{start}");
    }
    let fraction = g["converged_fraction"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&fraction), "{g}");

    // Every process logged into the run folder.
    for name in [
        "server",
        "import",
        "map",
        "localize-tracking",
        "localize-global-1",
        "localize-global-2",
    ] {
        let log = out.join("logs").join(format!("{name}.log"));
        assert!(log.is_file(), "{} missing", log.display());
    }
}
