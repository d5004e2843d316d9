//! Recordings written by `write_recording` and read back by
//! `read_recording`, and recordings made by hand that it must refuse.

use std::collections::BTreeMap;
use std::io::Cursor;

use approx::assert_abs_diff_eq;
use deog_grid::{ClampLimits, LogOdds, Pose2, Resolution, Tile, TileKey, TileMap, TileSize};
use deog_recording::messages::{
    Header, LaserScan, OccupancyGrid, Odometry, PoseWithCovariance, PoseWithCovarianceStamped,
    Range, RosMessage, Time, decode, encode,
};
use deog_recording::{
    Estimate, Frame, ImportOptions, MountSource, Recording, read_recording, schema_text,
    write_recording,
};
use deog_rig::{NoEcho, RangeSensor, Rig, SensorKind};

fn laser_rig() -> Rig {
    let laser = RangeSensor {
        mount: Pose2::new(0.15, -0.05, 0.1),
        kind: SensorKind::Laser {
            first_angle: -1.5,
            angle_step: 0.05,
            beam_count: 61,
        },
        min_range: 0.05,
        max_range: 12.0,
        no_echo: NoEcho {
            at_or_beyond: 12.0,
            zero: true,
        },
    };
    Rig::new("test-laser", 0.2, vec![laser]).unwrap()
}

fn frames(rig: &Rig, count: u64) -> Vec<Frame> {
    (0..count)
        .map(|i| Frame {
            sequence: i + 1,
            time_s: 10.0 + i as f64 * 0.2,
            odometry: Pose2::new(0.1 * i as f64, 0.02 * i as f64, 0.05 * i as f64),
            true_pose: Some(Pose2::new(1.0 + 0.1 * i as f64, 2.0, 0.3)),
            reference_pose: None,
            ranges: (0..rig.readings())
                .map(|b| {
                    if b % 7 == 0 {
                        12.0
                    } else {
                        1.0 + 0.01 * (b as f64 + i as f64)
                    }
                })
                .collect(),
        })
        .collect()
}

fn record(rig: &Rig, frames: &[Frame], estimates: &[Estimate], map: Option<&TileMap>) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    write_recording(
        &mut out,
        &Recording {
            rig,
            frames,
            estimates,
            map,
        },
    )
    .unwrap();
    out.into_inner()
}

fn options() -> ImportOptions {
    ImportOptions {
        first_sequence: 1,
        ..ImportOptions::default()
    }
}

#[test]
fn a_laser_recording_reads_back_as_the_same_frames_and_rig() {
    let rig = laser_rig();
    let frames = frames(&rig, 20);
    let bytes = record(&rig, &frames, &[], None);
    let back = read_recording(
        &bytes,
        &ImportOptions {
            reference_topic: Some("/true_pose".into()),
            ..options()
        },
    )
    .unwrap();
    assert_eq!(back.scan_topic, "/scan");
    assert_eq!(back.odom_topic, "/odom");
    assert_eq!(
        back.mounts,
        MountSource::StaticTransforms("base_link".into())
    );
    assert_eq!(back.frames.len(), 20);
    let sensor = back.rig.sensors()[0];
    let original = rig.sensors()[0];
    assert_abs_diff_eq!(sensor.mount.x, original.mount.x, epsilon = 1e-9);
    assert_abs_diff_eq!(sensor.mount.y, original.mount.y, epsilon = 1e-9);
    assert_abs_diff_eq!(sensor.mount.theta, original.mount.theta, epsilon = 1e-9);
    assert_abs_diff_eq!(sensor.max_range, 12.0, epsilon = 1e-6);
    let SensorKind::Laser {
        first_angle,
        angle_step,
        beam_count,
    } = sensor.kind
    else {
        panic!("a laser rig");
    };
    assert_eq!(beam_count, 61);
    assert_abs_diff_eq!(first_angle, -1.5, epsilon = 1e-6);
    assert_abs_diff_eq!(angle_step, 0.05, epsilon = 1e-6);
    for (a, b) in frames.iter().zip(&back.frames) {
        assert_eq!(a.sequence, b.sequence);
        assert_abs_diff_eq!(a.time_s, b.time_s, epsilon = 1e-9);
        assert_abs_diff_eq!(a.odometry.x, b.odometry.x, epsilon = 1e-9);
        assert_abs_diff_eq!(a.odometry.theta, b.odometry.theta, epsilon = 1e-9);
        let reference = b.reference_pose.unwrap();
        assert_abs_diff_eq!(reference.x, a.true_pose.unwrap().x, epsilon = 1e-9);
        for (&x, &y) in a.ranges.iter().zip(&b.ranges) {
            assert_abs_diff_eq!(x, y, epsilon = 1e-5);
        }
    }
}

#[test]
fn the_scouts_sonars_read_back_as_rounds_of_ranges() {
    let rig = deog_rig::scout();
    let frames = frames(&rig, 5);
    let bytes = record(&rig, &frames, &[], None);
    let back = read_recording(&bytes, &options()).unwrap();
    assert_eq!(back.scan_topic, "/sonar");
    assert_eq!(back.scan_messages, 5 * 16);
    assert_eq!(back.incomplete, 0);
    assert_eq!(back.frames.len(), 5);
    assert!(back.rig.all_sonar());
    for (a, b) in rig.beams().iter().zip(back.rig.beams()) {
        assert_abs_diff_eq!(a.mount.x, b.mount.x, epsilon = 1e-9);
        let turn = deog_grid::normalize_angle(a.mount.theta - b.mount.theta);
        assert_abs_diff_eq!(turn, 0.0, epsilon = 1e-9);
    }
    for (&x, &y) in frames[3].ranges.iter().zip(&back.frames[3].ranges) {
        assert_abs_diff_eq!(x, y, epsilon = 1e-5);
    }
}

#[test]
fn estimates_and_the_map_are_recorded_with_their_schemas() {
    let rig = laser_rig();
    let frames = frames(&rig, 4);
    let estimates = vec![Estimate {
        frame_sequence: 2,
        time_s: frames[1].time_s,
        pose: Pose2::new(3.0, 4.0, 0.5),
        covariance: [0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.3],
    }];
    let size = TileSize::new(16).unwrap();
    let mut map = TileMap::new(Resolution::new(0.1).unwrap(), size, ClampLimits::NONE);
    let mut cells = vec![LogOdds::UNKNOWN_RAW; 256];
    cells[17] = LogOdds::from_probability(0.95).unwrap().raw();
    let bytes: Vec<u8> = cells.iter().flat_map(|c| c.to_le_bytes()).collect();
    map.insert(
        TileKey::new(0, 0),
        Tile::from_dense_bytes(size, &bytes).unwrap(),
    )
    .unwrap();
    let bytes = record(&rig, &frames, &estimates, Some(&map));

    let mut by_topic: BTreeMap<String, TopicSeen> = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().unwrap();
        let entry = by_topic.entry(message.channel.topic.clone()).or_insert((
            schema.name.clone(),
            schema.encoding.clone(),
            String::from_utf8(schema.data.to_vec()).unwrap(),
            Vec::new(),
        ));
        assert_eq!(message.channel.message_encoding, "cdr");
        entry.3.push(message.data.to_vec());
    }
    let names: Vec<(&str, &str, usize)> = by_topic
        .iter()
        .map(|(t, (s, _, _, m))| (t.as_str(), s.as_str(), m.len()))
        .collect();
    assert_eq!(
        names,
        vec![
            (
                "/estimate",
                "geometry_msgs/msg/PoseWithCovarianceStamped",
                1
            ),
            ("/map", "nav_msgs/msg/OccupancyGrid", 1),
            ("/odom", "nav_msgs/msg/Odometry", 4),
            ("/scan", "sensor_msgs/msg/LaserScan", 4),
            ("/tf", "tf2_msgs/msg/TFMessage", 4),
            ("/tf_static", "tf2_msgs/msg/TFMessage", 1),
            ("/true_pose", "geometry_msgs/msg/PoseStamped", 4),
        ]
    );
    for (name, encoding, text, _) in by_topic.values() {
        assert_eq!(encoding, "ros2msg");
        assert_eq!(Some(text.clone()), schema_text(name));
    }
    let estimate: PoseWithCovarianceStamped = decode(&by_topic["/estimate"].3[0]).unwrap();
    assert_eq!(estimate.header.frame_id, "map");
    assert_abs_diff_eq!(estimate.pose.pose.position.y, 4.0);
    assert_eq!(estimate.pose.covariance[35], 0.3);
    let grid: OccupancyGrid = decode(&by_topic["/map"].3[0]).unwrap();
    assert_eq!((grid.info.width, grid.info.height), (1, 1));
    assert_eq!(grid.data, vec![95]);
    assert_abs_diff_eq!(grid.info.origin.position.x, 0.1, epsilon = 1e-12);
    let odometry: Odometry = decode(&by_topic["/odom"].3[3]).unwrap();
    assert_eq!(odometry.child_frame_id, "base_link");
    assert!(odometry.twist.twist.linear.x > 0.0);
}

/// A topic's schema name, schema encoding, schema text and messages.
type TopicSeen = (String, String, String, Vec<Vec<u8>>);

/// A recording of the given topics, each message `(log ns, CDR bytes)`.
fn handmade(topics: &[(&str, &str, Vec<Vec<u8>>)]) -> Vec<u8> {
    let mut writer = mcap::Writer::new(Cursor::new(Vec::new())).unwrap();
    for (topic, type_name, messages) in topics {
        let text = schema_text(type_name).unwrap_or_default();
        let schema = writer
            .add_schema(type_name, "ros2msg", text.as_bytes())
            .unwrap();
        let channel = writer
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .unwrap();
        for (i, data) in messages.iter().enumerate() {
            writer
                .write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: channel,
                        sequence: i as u32,
                        log_time: i as u64 * 100_000_000,
                        publish_time: 0,
                    },
                    data,
                )
                .unwrap();
        }
    }
    writer.finish().unwrap();
    writer.into_inner().into_inner()
}

fn scan_at(seconds: f64) -> Vec<u8> {
    encode(&LaserScan {
        header: Header::new(Time::from_seconds(seconds).unwrap(), "laser"),
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0, f32::NAN, f32::INFINITY, -0.5, f32::NEG_INFINITY],
        ..LaserScan::default()
    })
}

fn odom_at(seconds: f64, x: f64) -> Vec<u8> {
    encode(&Odometry {
        header: Header::new(Time::from_seconds(seconds).unwrap(), "odom"),
        child_frame_id: "base_footprint".into(),
        pose: PoseWithCovariance::from_planar(Pose2::new(x, 0.0, 0.0), &[0.0; 9]),
        ..Odometry::default()
    })
}

#[test]
fn odometry_is_interpolated_at_each_scans_stamp_and_scans_outside_it_are_left_out() {
    let bytes = handmade(&[
        (
            "/base_scan",
            LaserScan::TYPE_NAME,
            vec![scan_at(0.5), scan_at(1.25), scan_at(1.75), scan_at(3.0)],
        ),
        (
            "/wheel_odom",
            Odometry::TYPE_NAME,
            vec![odom_at(1.0, 0.0), odom_at(2.0, 1.0)],
        ),
    ]);
    let back = read_recording(&bytes, &options()).unwrap();
    assert_eq!(back.scan_topic, "/base_scan");
    assert_eq!(back.odom_topic, "/wheel_odom");
    assert_eq!(back.mounts, MountSource::Identity);
    assert_eq!(back.outside_odometry, 2);
    assert_eq!(back.frames.len(), 2);
    assert_abs_diff_eq!(back.frames[0].odometry.x, 0.25, epsilon = 1e-9);
    assert_abs_diff_eq!(back.frames[1].odometry.x, 0.75, epsilon = 1e-9);
    assert_eq!(back.frames[1].sequence, 2);
    // NaN, +inf and negative: no echo (the range limit); -inf: too near.
    assert_eq!(
        back.frames[0].ranges,
        vec![1.0, 10.0, 10.0, 10.0, 0.1f32 as f64]
    );
}

#[test]
fn missing_or_ambiguous_topics_are_named_in_the_error() {
    let two_odoms = handmade(&[
        ("/scan", LaserScan::TYPE_NAME, vec![scan_at(1.0)]),
        ("/odom", Odometry::TYPE_NAME, vec![odom_at(1.0, 0.0)]),
        (
            "/odom_filtered",
            Odometry::TYPE_NAME,
            vec![odom_at(1.0, 0.0)],
        ),
    ]);
    let err = read_recording(&two_odoms, &options())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("several odometry topics (/odom, /odom_filtered)"),
        "{err}"
    );
    assert!(err.contains("--odom-topic"), "{err}");
    let chosen = read_recording(
        &two_odoms,
        &ImportOptions {
            odom_topic: Some("/odom_filtered".into()),
            ..options()
        },
    )
    .unwrap();
    assert_eq!(chosen.odom_topic, "/odom_filtered");
    let err = read_recording(
        &two_odoms,
        &ImportOptions {
            scan_topic: Some("/odom".into()),
            ..options()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("/odom holds nav_msgs/msg/Odometry messages"),
        "{err}"
    );
    let err = read_recording(
        &two_odoms,
        &ImportOptions {
            scan_topic: Some("/nope".into()),
            ..options()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("no topic /nope"), "{err}");

    let no_odom = handmade(&[("/scan", LaserScan::TYPE_NAME, vec![scan_at(1.0)])]);
    let err = read_recording(&no_odom, &options())
        .unwrap_err()
        .to_string();
    assert!(err.contains("no odometry topic"), "{err}");
    assert!(err.contains("/scan (sensor_msgs/msg/LaserScan)"), "{err}");
}

#[test]
fn a_corrupt_message_is_named_by_topic_and_place() {
    let mut short = scan_at(1.5);
    short.truncate(40);
    let bytes = handmade(&[
        ("/scan", LaserScan::TYPE_NAME, vec![scan_at(1.0), short]),
        (
            "/odom",
            Odometry::TYPE_NAME,
            vec![odom_at(1.0, 0.0), odom_at(2.0, 0.0)],
        ),
    ]);
    let err = read_recording(&bytes, &options()).unwrap_err().to_string();
    assert!(
        err.contains("message 2 on /scan (sensor_msgs/msg/LaserScan)"),
        "{err}"
    );
    let err = read_recording(b"not an mcap file at all", &options())
        .unwrap_err()
        .to_string();
    assert!(err.contains("MCAP"), "{err}");
}

#[test]
fn scans_of_another_geometry_are_refused() {
    let mut other = LaserScan {
        header: Header::new(Time::from_seconds(1.5).unwrap(), "laser"),
        angle_min: -1.0,
        angle_increment: 0.5,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0; 4],
        ..LaserScan::default()
    };
    other.angle_max = 0.5;
    let bytes = handmade(&[
        (
            "/scan",
            LaserScan::TYPE_NAME,
            vec![scan_at(1.0), encode(&other)],
        ),
        (
            "/odom",
            Odometry::TYPE_NAME,
            vec![odom_at(1.0, 0.0), odom_at(2.0, 0.0)],
        ),
    ]);
    let err = read_recording(&bytes, &options()).unwrap_err().to_string();
    assert!(err.contains("scan 2 on /scan has 4 beams"), "{err}");
}

/// An MCAP record: opcode, length, body.
fn mcap_record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut out = vec![opcode];
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
    out
}

fn mcap_string(text: &str) -> Vec<u8> {
    let mut out = (text.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(text.as_bytes());
    out
}

#[test]
fn a_compressed_record_claiming_an_enormous_length_is_an_error_not_an_abort() {
    // Inside the chunk, a message record that claims 2^57 bytes: the
    // reader must not try to make room for them.
    let mut inner = vec![0x05];
    inner.extend_from_slice(&(1u64 << 57).to_le_bytes());
    inner.extend_from_slice(&[0; 32]);
    let compressed = zstd::bulk::compress(&inner, 3).unwrap();
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message start time
    chunk.extend_from_slice(&0u64.to_le_bytes()); // message end time
    chunk.extend_from_slice(&(inner.len() as u64).to_le_bytes());
    chunk.extend_from_slice(&0u32.to_le_bytes()); // no CRC
    chunk.extend_from_slice(&mcap_string("zstd"));
    chunk.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
    chunk.extend_from_slice(&compressed);
    let mut file = mcap::MAGIC.to_vec();
    let mut header = mcap_string("ros2");
    header.extend_from_slice(&mcap_string("hand"));
    file.extend(mcap_record(0x01, &header));
    file.extend(mcap_record(0x06, &chunk));
    file.extend(mcap_record(0x0f, &0u32.to_le_bytes()));
    file.extend(mcap_record(0x02, &[0; 20]));
    file.extend_from_slice(mcap::MAGIC);
    let err = read_recording(&file, &options()).unwrap_err();
    let cause = std::error::Error::source(&err).map(ToString::to_string);
    assert!(
        cause
            .as_deref()
            .is_some_and(|c| c.contains("length exceeds limit")),
        "{err}: {cause:?}"
    );
}

fn range_at(seconds: f64, frame_id: &str, range: f32) -> Vec<u8> {
    encode(&Range {
        header: Header::new(Time::from_seconds(seconds).unwrap(), frame_id),
        radiation_type: Range::ULTRASOUND,
        field_of_view: 0.5,
        min_range: 0.1,
        max_range: 5.0,
        range,
    })
}

#[test]
fn sonars_make_a_frame_once_each_has_reported_and_a_broken_round_is_left_out() {
    let bytes = handmade(&[
        (
            "/sonar",
            Range::TYPE_NAME,
            vec![
                range_at(1.0, "front", 1.0),
                range_at(1.01, "back", 2.0),
                // The back sonar misses this round.
                range_at(1.2, "front", 1.1),
                range_at(1.4, "front", 1.2),
                range_at(1.41, "back", f32::INFINITY),
            ],
        ),
        (
            "/odom",
            Odometry::TYPE_NAME,
            vec![odom_at(0.5, 0.0), odom_at(2.5, 2.0)],
        ),
    ]);
    let back = read_recording(&bytes, &options()).unwrap();
    assert_eq!(back.scan_topic, "/sonar");
    assert_eq!(back.scan_messages, 5);
    assert_eq!(back.incomplete, 1);
    assert_eq!(back.frames.len(), 2);
    assert!(back.rig.all_sonar());
    assert_eq!(back.rig.readings(), 2);
    assert_eq!(back.frames[0].ranges, vec![1.0, 2.0]);
    // A round's time is its last reading's; +inf is no echo.
    assert_abs_diff_eq!(back.frames[1].time_s, 1.41, epsilon = 1e-9);
    assert_eq!(back.frames[1].ranges, vec![1.2f32 as f64, 5.0]);
    assert_abs_diff_eq!(back.frames[1].odometry.x, 0.91, epsilon = 1e-9);
    let SensorKind::Sonar { half_angle } = back.rig.sensors()[0].kind else {
        panic!("a sonar");
    };
    assert_abs_diff_eq!(half_angle, 0.25, epsilon = 1e-7);
}
