//! `deog eval localize` through the real binary and a real map server: a
//! robot's frames with true poses (one kidnap jump) and pose estimates
//! with known errors go in through the robot client; the JSON must hold
//! the hand-computed figures and the plot must decode at the framing's
//! size, with the paths and kidnap marks drawn.

use deog_proto::v1 as pb;
use deog_robot_client::{ClientConfig, MapClient};
use deog_tests::{ServerProcess, failure, run_deog, succeeded};
use std::path::Path;
use std::process::Output;

const ROBOT: &str = "r1";

fn deog(args: &[&str], server: &ServerProcess) -> Output {
    run_deog(args, &[("DEOG_SERVER", server.addr.to_string())])
}

fn pose(x: f64, y: f64, theta: f64) -> pb::Pose2 {
    pb::Pose2 { x, y, theta }
}

fn time(sequence: u64) -> f64 {
    0.1 * sequence as f64
}

/// The true pose of frame 1..=60: along y = 1 from x = 0.5, 0.1 m a frame
/// (1 m/s), to frame 30 at x = 3.4; then carried off to (1.0, 2.5) at
/// frame 31 and on at 0.05 m a frame.
fn truth(sequence: u64) -> pb::Pose2 {
    if sequence <= 30 {
        pose(0.5 + 0.1 * (sequence - 1) as f64, 1.0, 0.0)
    } else {
        pose(1.0 + 0.05 * (sequence - 31) as f64, 2.5, 0.0)
    }
}

/// Frame 1..=60's odometry: the true path's steps, but not the kidnap's
/// jump (the wheels do not notice a robot carried off).
fn odometry(sequence: u64) -> pb::Pose2 {
    if sequence <= 30 {
        truth(sequence)
    } else {
        pose(3.4 + 0.05 * (sequence - 30) as f64, 1.0, 0.0)
    }
}

/// The localizer's estimate of frame 1..=60 and its map: 1 m off at
/// first, then (+0.10, -0.05, +0.02 rad) off from frame 6; after the
/// kidnap it stays where the robot was for frames 31..=37, then is
/// (-0.04, +0.08, -0.01 rad) off from frame 38. The estimate for frame 20
/// was made on another map and is 2 m off.
fn estimate(sequence: u64) -> (pb::Pose2, &'static str) {
    let t = truth(sequence);
    let off = |dx: f64, dy: f64, dt: f64| pose(t.x + dx, t.y + dy, t.theta + dt);
    match sequence {
        1..=5 => (off(1.0, 0.0, 0.0), "m"),
        20 => (off(2.0, 0.0, 0.0), "other"),
        6..=30 => (off(0.10, -0.05, 0.02), "m"),
        31..=37 => (pose(3.5, 0.95, 0.02), "m"),
        _ => (off(-0.04, 0.08, -0.01), "m"),
    }
}

async fn publish(client: &MapClient) {
    // Frames 61..=65 carry odometry only: skipped.
    let frames: Vec<pb::SonarFrame> = (1..=65)
        .map(|s| pb::SonarFrame {
            robot: ROBOT.into(),
            sequence: s,
            time_s: time(s),
            odometry: Some(odometry(s.min(60))),
            true_pose: (s <= 60).then(|| truth(s)),
            ranges: vec![2.0; 16],
            rig: String::new(),
            reference_pose: None,
        })
        .collect();
    let (stored, _) = client.publish_frames(frames).await.expect("frames");
    assert_eq!(stored, 65);
    // Estimates name maps that exist.
    client
        .ensure_map(pb::CreateMapRequest {
            name: "other".into(),
            resolution_m: 0.05,
            tile_size: 64,
            ..Default::default()
        })
        .await
        .expect("map other");
    for s in 1..=60 {
        let (pose, map) = estimate(s);
        client
            .publish_pose(pb::PoseEstimate {
                robot: ROBOT.into(),
                map: map.into(),
                frame_sequence: s,
                time_s: time(s),
                pose: Some(pose),
                covariance: vec![0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.001],
                particle_count: 500,
                converged: s >= 6,
                lost_score: 0.0,
                particle_sample: Vec::new(),
            })
            .await
            .expect("pose");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eval_localize_reports_the_known_errors_and_plots_the_paths() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = ServerProcess::start(&dir.path().join("data"), &[]).await;
    let client = MapClient::connect(ClientConfig::new(server.addr.to_string()))
        .await
        .expect("map client");
    let arena = format!(
        "{}/../mapfile/tests/data/lse_arena.yaml",
        env!("CARGO_MANIFEST_DIR")
    );
    succeeded(&deog(&["import", "--map", "m", &arena], &server));
    publish(&client).await;
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();

    // On map m: the estimate for frame 20 does not count, so the filter
    // converges at frame 6.
    let (json_file, png_file) = (path("m.json"), path("m.png"));
    let args = [
        "eval", "localize", "--robot", ROBOT, "--map", "m", "--json", &json_file, "--plot",
        &png_file,
    ];
    let table = succeeded(&deog(&args, &server));
    assert!(
        table.contains("robot r1 on map m: 60 frames with a true pose"),
        "{table}"
    );
    assert!(
        table.contains("converged after 0.500 s and 0.500 m driven (frame 6)"),
        "{table}"
    );
    assert!(
        table.contains("kidnapped once, recovered, in 0.700 s"),
        "{table}"
    );

    let json = read_json(&json_file);
    let robots = json.get("robots").array();
    assert_eq!(robots.len(), 1);
    let r = &robots[0];
    assert_eq!(r.get("name").string(), ROBOT);
    assert_eq!(r.get("map").string(), "m");
    assert!(r.get("converged").boolean());
    close(r.get("converge_s").number(), 0.5);
    close(r.get("converge_distance_m").number(), 0.5);
    assert_eq!(r.get("converge_sequence").number(), 6.0);
    // Frames 6..=30 minus 20 (24) and 38..=60 (23) count: 47.
    let used = 47.0;
    assert_eq!(r.get("estimates_used").number(), used);
    assert_eq!(r.get("estimates").number(), 59.0);
    let mean_x = (24.0 * 0.10 + 23.0 * 0.04) / used;
    let mean_y = (24.0 * 0.05 + 23.0 * 0.08) / used;
    close(r.get("mean_abs_error_m").get("x").number(), mean_x);
    assert!(table.contains(&format!("| x | {mean_x:.4} m |")), "{table}");
    close(r.get("mean_abs_error_m").get("y").number(), mean_y);
    close(
        r.get("mean_abs_error_in").get("x").number(),
        mean_x / 0.0254,
    );
    let mean_theta = (24.0 * 0.02 + 23.0 * 0.01) / used;
    close(
        r.get("mean_abs_error_deg").number(),
        mean_theta.to_degrees(),
    );
    // Signed x errors: 24 of +0.10 and 23 of -0.04.
    let bias_x = (24.0 * 0.10 - 23.0 * 0.04) / used;
    let spread_x =
        ((24.0 * (0.10 - bias_x).powi(2) + 23.0 * (-0.04 - bias_x).powi(2)) / used).sqrt();
    close(r.get("std_error_m").get("x").number(), spread_x);
    close(r.get("mean_error_m").get("x").number(), bias_x);
    let rms = ((24.0 * (0.01 + 0.0025) + 23.0 * (0.0016 + 0.0064)) / used).sqrt();
    close(r.get("rms_position_m").number(), rms);
    assert!(r.get("kidnapped").boolean());
    assert!(r.get("recovered").boolean());
    close(r.get("recover_s").number(), 0.7);
    let kidnaps = r.get("kidnaps").array();
    assert_eq!(kidnaps.len(), 1);
    let k = &kidnaps[0];
    assert_eq!(k.get("sequence_before").number(), 30.0);
    assert_eq!(k.get("sequence").number(), 31.0);
    close(k.get("time_s").number(), 3.1);
    close(k.get("jump_m").number(), 2.4f64.hypot(1.5));
    close(k.get("recover_distance_m").number(), 0.35);
    assert_eq!(k.get("recover_sequence").number(), 38.0);
    // The filter said converged from frame 6: 54 estimates, of which
    // 31..=37 (7) were wrong.
    assert_eq!(r.get("filter_converged").number(), 54.0);
    assert_eq!(r.get("filter_converged_within_bounds").number(), 47.0);
    // Those 7 were metres off: false convergence.
    assert_eq!(r.get("false_converged").number(), 7.0);

    // The plot over the map: the longer side is 1000 px, and the map's
    // walls, both paths and the kidnap marks are all there.
    let (width, height, rgb) = read_png(&png_file);
    assert_eq!(width.max(height), 1000, "{width} x {height}");
    for (what, colour) in [
        ("wall", [0, 0, 0]),
        ("free", [255, 255, 255]),
        ("unknown", [205, 205, 205]),
        ("true path", [220, 0, 0]),
        ("estimated path", [0, 170, 0]),
        ("kidnap", [0, 0, 255]),
    ] {
        let count = rgb.chunks(3).filter(|p| *p == colour).count();
        assert!(count > 0, "no {what} pixel");
    }

    // Without --map the estimate for frame 20 counts: 2 m off, so the
    // filter only settles at frame 21 (2.0 s after frame 1).
    let (json_file, png_file) = (path("any.json"), path("any.png"));
    let args = [
        "eval", "localize", "--robot", ROBOT, "--json", &json_file, "--plot", &png_file,
    ];
    succeeded(&deog(&args, &server));
    let json = read_json(&json_file);
    let r = &json.get("robots").array()[0];
    assert!(matches!(r.get("map"), Json::Null));
    close(r.get("converge_s").number(), 2.0);
    assert_eq!(r.get("estimates_used").number(), 10.0 + 23.0);
    close(r.get("recover_s").number(), 0.7);
    // On white: the box of every true and estimated position (x from 0.5
    // to 4.4, the estimate 2 m off at frame 20; y from 0.95 to 2.58) plus
    // 0.5 m each side: 4.9 m by 2.63 m at 1000 px along x.
    let (mut min_x, mut max_x, mut min_y, mut max_y) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in 1..=60 {
        for p in [truth(s), estimate(s).0] {
            (min_x, max_x) = (min_x.min(p.x), max_x.max(p.x));
            (min_y, max_y) = (min_y.min(p.y), max_y.max(p.y));
        }
    }
    let (w, h) = (max_x - min_x + 1.0, max_y - min_y + 1.0);
    close(w, 4.9);
    close(h, 2.63);
    let (width, height, rgb) = read_png(&png_file);
    assert_eq!((width, height), (1000, (1000.0 * h / w).round() as u32));
    assert!(
        rgb.chunks(3).all(|p| p != [0, 0, 0]),
        "no map was asked for"
    );

    // A window of frames after the kidnap: no kidnap left in it, and the
    // estimate settles at frame 38.
    let json_file = path("window.json");
    let args = [
        "eval", "localize", "--robot", ROBOT, "--map", "m", "--from", "31", "--to", "60", "--json",
        &json_file,
    ];
    succeeded(&deog(&args, &server));
    let json = read_json(&json_file);
    let r = &json.get("robots").array()[0];
    close(r.get("converge_s").number(), 0.7);
    assert!(!r.get("kidnapped").boolean());
    assert!(matches!(r.get("recovered"), Json::Null));
    assert!(matches!(r.get("recover_s"), Json::Null));

    // Bad input: clear errors, no panic.
    let said = failure(&deog(&["eval", "localize", "--robot", "nobody"], &server));
    assert!(
        said.contains("robot nobody") && said.contains("no frame with a true pose"),
        "{said}"
    );
    let said = failure(&deog(
        &["eval", "localize", "--robot", ROBOT, "--map", "elsewhere"],
        &server,
    ));
    assert!(said.contains("no pose estimate on map elsewhere"), "{said}");
    let said = failure(&deog(
        &["eval", "localize", "--robot", ROBOT, "--converge-m", "0"],
        &server,
    ));
    assert!(said.contains("converge_m"), "{said}");
    assert!(!said.contains("panicked"), "{said}");
}

fn close(got: f64, want: f64) {
    assert!(
        (got - want).abs() <= 1e-9 * want.abs().max(1.0),
        "got {got}, want {want}"
    );
}

/// Width, height and RGB bytes of an 8-bit RGB PNG.
fn read_png(file: &str) -> (u32, u32, Vec<u8>) {
    let bytes = std::fs::read(file).expect("plot written");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut rgb = vec![0; reader.output_buffer_size().expect("size")];
    let frame = reader.next_frame(&mut rgb).expect("decodes");
    assert_eq!(frame.color_type, png::ColorType::Rgb);
    assert_eq!(frame.bit_depth, png::BitDepth::Eight);
    rgb.truncate(frame.buffer_size());
    (frame.width, frame.height, rgb)
}

fn read_json(file: &str) -> Json {
    let text = std::fs::read_to_string(Path::new(file)).expect("json written");
    let mut parser = Parser {
        text: text.as_bytes(),
        at: 0,
    };
    let value = parser.value();
    parser.space();
    assert_eq!(parser.at, text.len(), "trailing text in {text}");
    value
}

/// Just enough JSON to read the report: the file must parse whole.
#[derive(Debug, Clone)]
enum Json {
    Null,
    Bool(bool),
    Number(f64),
    String(String),
    Array(Vec<Json>),
    Object(Vec<(String, Json)>),
}

impl Json {
    fn get(&self, key: &str) -> &Json {
        match self {
            Json::Object(fields) => fields
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v)
                .unwrap_or_else(|| panic!("no {key} in {self:?}")),
            _ => panic!("{key} of a non-object {self:?}"),
        }
    }

    fn number(&self) -> f64 {
        match self {
            Json::Number(n) => *n,
            _ => panic!("not a number: {self:?}"),
        }
    }

    fn boolean(&self) -> bool {
        match self {
            Json::Bool(b) => *b,
            _ => panic!("not a boolean: {self:?}"),
        }
    }

    fn string(&self) -> &str {
        match self {
            Json::String(s) => s,
            _ => panic!("not a string: {self:?}"),
        }
    }

    fn array(&self) -> &[Json] {
        match self {
            Json::Array(items) => items,
            _ => panic!("not an array: {self:?}"),
        }
    }
}

struct Parser<'a> {
    text: &'a [u8],
    at: usize,
}

impl Parser<'_> {
    fn space(&mut self) {
        while self.at < self.text.len() && self.text[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
    }

    fn expect(&mut self, byte: u8) {
        self.space();
        assert_eq!(
            self.text.get(self.at),
            Some(&byte),
            "expected {:?} at {}",
            byte as char,
            self.at
        );
        self.at += 1;
    }

    fn literal(&mut self, word: &str, value: Json) -> Json {
        assert!(
            self.text[self.at..].starts_with(word.as_bytes()),
            "bad literal at {}",
            self.at
        );
        self.at += word.len();
        value
    }

    fn value(&mut self) -> Json {
        self.space();
        match self.text.get(self.at).copied() {
            Some(b'{') => {
                self.at += 1;
                let mut fields = Vec::new();
                self.space();
                if self.text[self.at] == b'}' {
                    self.at += 1;
                    return Json::Object(fields);
                }
                loop {
                    self.space();
                    let key = self.string();
                    self.expect(b':');
                    fields.push((key, self.value()));
                    self.space();
                    self.at += 1;
                    match self.text[self.at - 1] {
                        b',' => continue,
                        b'}' => return Json::Object(fields),
                        other => panic!("unexpected {:?} at {}", other as char, self.at),
                    }
                }
            }
            Some(b'[') => {
                self.at += 1;
                let mut items = Vec::new();
                self.space();
                if self.text[self.at] == b']' {
                    self.at += 1;
                    return Json::Array(items);
                }
                loop {
                    items.push(self.value());
                    self.space();
                    self.at += 1;
                    match self.text[self.at - 1] {
                        b',' => continue,
                        b']' => return Json::Array(items),
                        other => panic!("unexpected {:?} at {}", other as char, self.at),
                    }
                }
            }
            Some(b'"') => Json::String(self.string()),
            Some(b'n') => self.literal("null", Json::Null),
            Some(b't') => self.literal("true", Json::Bool(true)),
            Some(b'f') => self.literal("false", Json::Bool(false)),
            _ => {
                let start = self.at;
                while self.at < self.text.len()
                    && matches!(
                        self.text[self.at],
                        b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9'
                    )
                {
                    self.at += 1;
                }
                let number = std::str::from_utf8(&self.text[start..self.at]).expect("ascii");
                Json::Number(
                    number
                        .parse()
                        .unwrap_or_else(|_| panic!("bad number {number:?} at {start}")),
                )
            }
        }
    }

    fn string(&mut self) -> String {
        self.expect(b'"');
        let mut out = Vec::new();
        loop {
            let byte = self.text[self.at];
            self.at += 1;
            match byte {
                b'"' => break,
                b'\\' => {
                    let escaped = self.text[self.at];
                    self.at += 1;
                    out.push(match escaped {
                        b'n' => b'\n',
                        b't' => b'\t',
                        b'r' => b'\r',
                        other => other,
                    });
                }
                other => out.push(other),
            }
        }
        String::from_utf8(out).expect("utf-8")
    }
}
