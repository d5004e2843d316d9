//! The `deog demo` binary, run as a user would.

use std::process::Command;

use deog_tests::deog_binary;

#[test]
fn demo_maps_the_room_and_writes_a_pgm() {
    let out = tempfile::tempdir().unwrap();
    let output = Command::new(deog_binary())
        .args(["demo", "--frames", "200", "--out"])
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "demo failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );

    // "... cells observed; 83.0% of the 27113 classified cells match the room"
    let percent: f64 = stdout
        .split("observed; ")
        .nth(1)
        .and_then(|rest| rest.split('%').next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no score in: {stdout}"));
    assert!(
        percent > 75.0,
        "map matches the room in only {percent}% of cells"
    );

    let pgm = std::fs::read(out.path().join("map.pgm")).unwrap();
    let header = String::from_utf8_lossy(&pgm[..20]);
    let mut fields = header.split_whitespace();
    assert_eq!(fields.next(), Some("P5"));
    let width: usize = fields.next().unwrap().parse().unwrap();
    let height: usize = fields.next().unwrap().parse().unwrap();
    // The room is 10 m x 8 m: at 5 cm, at least 200 x 160 cells.
    assert!(width >= 200 && height >= 160, "{width} x {height}");
    let pixels = &pgm[pgm.len() - width * height..];
    for value in [0u8, 254, 205] {
        assert!(pixels.contains(&value), "no pixel of value {value}");
    }
}

#[test]
fn demo_rejects_zero_frames() {
    let output = Command::new(deog_binary())
        .args(["demo", "--frames", "0"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--frames"));
}
