//! `deog localize` as its own process: a server, the simulator, a wanderer
//! and a cartographer build map2's map; a second robot then wanders (its
//! cartographer adding its frames), and the localizer, knowing nothing of
//! where it started, follows its frames on the server's map. `deog eval
//! localize` judges the estimates it published against the simulator's
//! true poses.

use deog_tests::{ServerProcess, json_field as field, run_deog, succeeded};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_is_found_on_the_map_the_cartographer_built() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let sim = ServerProcess::start_sim("map2", &["--speed", "20", "--seed", "5"]).await;
    let env = [
        ("DEOG_SERVER", server.addr.to_string()),
        ("DEOG_SIM", sim.addr.to_string()),
    ];
    // Ten simulated minutes of mapping, as the map quality figures.
    succeeded(&run_deog(
        &[
            "wander",
            "--robot",
            "mapper",
            "--spawn",
            "--seed",
            "3",
            "--duration",
            "600",
        ],
        &env,
    ));
    succeeded(&run_deog(
        &["map", "--robot", "mapper", "--map", "m", "--idle-exit", "2"],
        &env,
    ));
    // Another robot drives for a simulated minute and a half; the localizer
    // then follows its frames from the first, starting from a uniform prior.
    succeeded(&run_deog(
        &[
            "wander",
            "--robot",
            "scout",
            "--spawn",
            "--seed",
            "7",
            "--duration",
            "90",
        ],
        &env,
    ));
    // Its cartographer maps its frames too, as every robot's does: the
    // wanderer's path depends on how the machine keeps pace with the
    // simulator, and the mapper may have left the scout's corners unmapped.
    succeeded(&run_deog(
        &["map", "--robot", "scout", "--map", "m", "--idle-exit", "2"],
        &env,
    ));
    let out = succeeded(&run_deog(
        &[
            "localize",
            "--robot",
            "scout",
            "--map",
            "m",
            "--from",
            "1",
            "--idle-exit",
            "2",
            "--cache-mb",
            "64",
        ],
        &env,
    ));
    assert!(out.contains("scout on m: 90"), "{out}");
    let report = dir.path().join("report.json");
    let plot = dir.path().join("path.png");
    let table = succeeded(&run_deog(
        &[
            "eval",
            "localize",
            "--robot",
            "scout",
            "--map",
            "m",
            "--json",
            report.to_str().expect("utf-8"),
            "--plot",
            plot.to_str().expect("utf-8"),
        ],
        &env,
    ));
    let json = std::fs::read_to_string(&report).expect("report written");
    assert_eq!(field(&json, "converged"), "true", "{table}\n{json}");
    let converge_s: f64 = field(&json, "converge_s").parse().expect("converge_s");
    assert!(
        converge_s < 60.0,
        "converged only after {converge_s} s\n{table}"
    );
    let x: f64 = field(&json, "x").parse().expect("x");
    let y: f64 = field(&json, "y").parse().expect("y");
    let degrees: f64 = field(&json, "mean_abs_error_deg").parse().expect("deg");
    assert!(x < 0.1 && y < 0.1, "mean errors {x} m, {y} m\n{table}");
    assert!(degrees < 3.0, "mean heading error {degrees}°\n{table}");
    assert!(std::fs::metadata(&plot).expect("plot written").len() > 1000);
}
