//! Property tests: every message type decodes to what was encoded, and no
//! byte string makes a decoder or the recording reader panic.

use deog_recording::messages::{
    Header, LaserScan, MapMetaData, OccupancyGrid, Odometry, Point, Pose, PoseWithCovariance,
    PoseWithCovarianceStamped, Quaternion, Range, TfMessage, Time, Transform, TransformStamped,
    Twist, TwistWithCovariance, Vector3, decode, encode,
};
use deog_recording::{ImportOptions, read_recording};
use proptest::prelude::*;

fn time() -> impl Strategy<Value = Time> {
    (any::<i32>(), 0u32..1_000_000_000).prop_map(|(sec, nanosec)| Time { sec, nanosec })
}

fn header() -> impl Strategy<Value = Header> {
    (time(), "[a-z_/]{0,20}").prop_map(|(stamp, frame_id)| Header { stamp, frame_id })
}

fn vector() -> impl Strategy<Value = Vector3> {
    (any::<f64>(), any::<f64>(), any::<f64>()).prop_map(|(x, y, z)| Vector3 { x, y, z })
}

fn quaternion() -> impl Strategy<Value = Quaternion> {
    (any::<f64>(), any::<f64>(), any::<f64>(), any::<f64>()).prop_map(|(x, y, z, w)| Quaternion {
        x,
        y,
        z,
        w,
    })
}

fn pose() -> impl Strategy<Value = Pose> {
    (vector(), quaternion()).prop_map(|(v, orientation)| Pose {
        position: Point {
            x: v.x,
            y: v.y,
            z: v.z,
        },
        orientation,
    })
}

fn covariance() -> impl Strategy<Value = [f64; 36]> {
    prop::array::uniform32(any::<f64>()).prop_flat_map(|head| {
        prop::array::uniform4(any::<f64>()).prop_map(move |tail| {
            let mut out = [0.0; 36];
            out[..32].copy_from_slice(&head);
            out[32..].copy_from_slice(&tail);
            out
        })
    })
}

/// Equal bit for bit (NaN payloads included), through the encoding.
fn same_bytes<M: deog_recording::messages::RosMessage>(a: &M, b: &M) -> bool {
    encode(a) == encode(b)
}

proptest! {
    #[test]
    fn laser_scans_round_trip(
        header in header(),
        figures in prop::array::uniform7(any::<f32>()),
        ranges in prop::collection::vec(any::<f32>(), 0..400),
        intensities in prop::collection::vec(any::<f32>(), 0..10),
    ) {
        let scan = LaserScan {
            header,
            angle_min: figures[0],
            angle_max: figures[1],
            angle_increment: figures[2],
            time_increment: figures[3],
            scan_time: figures[4],
            range_min: figures[5],
            range_max: figures[6],
            ranges,
            intensities,
        };
        let back: LaserScan = decode(&encode(&scan)).unwrap();
        prop_assert!(same_bytes(&back, &scan));
        prop_assert_eq!(back.ranges.len(), scan.ranges.len());
        prop_assert_eq!(back.header, scan.header);
    }

    #[test]
    fn ranges_round_trip(header in header(), kind in any::<u8>(), figures in prop::array::uniform4(-1e6f32..1e6)) {
        let range = Range {
            header,
            radiation_type: kind,
            field_of_view: figures[0],
            min_range: figures[1],
            max_range: figures[2],
            range: figures[3],
        };
        prop_assert_eq!(decode::<Range>(&encode(&range)).unwrap(), range);
    }

    #[test]
    fn odometry_round_trips(
        header in header(),
        child in "[a-z_]{0,12}",
        pose in pose(),
        pose_covariance in covariance(),
        linear in vector(),
        angular in vector(),
        twist_covariance in covariance(),
    ) {
        let odometry = Odometry {
            header,
            child_frame_id: child,
            pose: PoseWithCovariance { pose, covariance: pose_covariance },
            twist: TwistWithCovariance {
                twist: Twist { linear, angular },
                covariance: twist_covariance,
            },
        };
        let back: Odometry = decode(&encode(&odometry)).unwrap();
        prop_assert!(same_bytes(&back, &odometry));
        prop_assert_eq!(back.child_frame_id, odometry.child_frame_id);
    }

    #[test]
    fn estimates_round_trip(header in header(), pose in pose(), covariance in covariance()) {
        let estimate = PoseWithCovarianceStamped {
            header,
            pose: PoseWithCovariance { pose, covariance },
        };
        let back: PoseWithCovarianceStamped = decode(&encode(&estimate)).unwrap();
        prop_assert!(same_bytes(&back, &estimate));
    }

    #[test]
    fn transforms_round_trip(
        transforms in prop::collection::vec((header(), "[a-z_]{0,12}", vector(), quaternion()), 0..8),
    ) {
        let message = TfMessage {
            transforms: transforms
                .into_iter()
                .map(|(header, child_frame_id, translation, rotation)| TransformStamped {
                    header,
                    child_frame_id,
                    transform: Transform { translation, rotation },
                })
                .collect(),
        };
        let back: TfMessage = decode(&encode(&message)).unwrap();
        prop_assert!(same_bytes(&back, &message));
        prop_assert_eq!(back.transforms.len(), message.transforms.len());
    }

    #[test]
    fn occupancy_grids_round_trip(
        header in header(),
        resolution in any::<f32>(),
        width in 0u32..50,
        origin in pose(),
        data in prop::collection::vec(any::<i8>(), 0..500),
    ) {
        let grid = OccupancyGrid {
            header: header.clone(),
            info: MapMetaData {
                map_load_time: header.stamp,
                resolution,
                width,
                height: 7,
                origin,
            },
            data,
        };
        let back: OccupancyGrid = decode(&encode(&grid)).unwrap();
        prop_assert!(same_bytes(&back, &grid));
        prop_assert_eq!(back.data, grid.data);
    }

    #[test]
    fn any_bytes_decode_to_a_message_or_an_error(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = decode::<LaserScan>(&bytes);
        let _ = decode::<Odometry>(&bytes);
        let _ = decode::<TfMessage>(&bytes);
        let _ = decode::<OccupancyGrid>(&bytes);
        let _ = decode::<Range>(&bytes);
    }

    #[test]
    fn any_bytes_read_as_a_recording_or_an_error(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let mut with_magic = mcap::MAGIC.to_vec();
        with_magic.extend_from_slice(&bytes);
        prop_assert!(read_recording(&with_magic, &ImportOptions::default()).is_err());
        prop_assert!(read_recording(&bytes, &ImportOptions::default()).is_err());
    }
}
