//! The ROS 2 `.msg` definitions of the recorded types, as rosbag2 writes
//! them into an MCAP schema: the type's own definition, then each type it
//! uses once, after a line of 80 `=` and a `MSG: pkg/Type` line.

/// The line between one definition and the next.
const SEPARATOR: &str =
    "================================================================================";

/// Each type's own definition (constants and fields, comments left out).
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    (
        "geometry_msgs/PoseStamped",
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
    ),
    (
        "geometry_msgs/PoseWithCovarianceStamped",
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
    ),
    (
        "sensor_msgs/LaserScan",
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n",
    ),
    (
        "sensor_msgs/Range",
        "uint8 ULTRASOUND=0\nuint8 INFRARED=1\nstd_msgs/Header header\nuint8 radiation_type\nfloat32 field_of_view\nfloat32 min_range\nfloat32 max_range\nfloat32 range\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "nav_msgs/MapMetaData",
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n",
    ),
    (
        "nav_msgs/OccupancyGrid",
        "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
];

/// The schema text of `type_name` (`sensor_msgs/msg/LaserScan` or
/// `sensor_msgs/LaserScan`): its definition with every type it uses
/// appended, depth first, each once; `None` for a type not recorded here.
pub fn schema_text(type_name: &str) -> Option<String> {
    let short = type_name.replacen("/msg/", "/", 1);
    let own = definition(&short)?;
    let mut text = own.to_owned();
    let mut seen = vec![short.clone()];
    append_dependencies(own, &mut seen, &mut text);
    Some(text)
}

fn definition(short_name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(name, _)| *name == short_name)
        .map(|(_, text)| *text)
}

/// The types a definition's fields use (`pkg/Type`, array marks dropped).
fn field_types(definition: &str) -> impl Iterator<Item = &str> {
    definition.lines().filter_map(|line| {
        let kind = line.split_whitespace().next()?;
        let kind = kind.split('[').next()?;
        kind.contains('/').then_some(kind)
    })
}

fn append_dependencies(definition_text: &str, seen: &mut Vec<String>, text: &mut String) {
    for kind in field_types(definition_text) {
        if seen.iter().any(|s| s == kind) {
            continue;
        }
        seen.push(kind.to_owned());
        // Every field type of the table's definitions is in the table.
        let Some(own) = definition(kind) else {
            continue;
        };
        text.push_str(SEPARATOR);
        text.push_str("\nMSG: ");
        text.push_str(kind);
        text.push('\n');
        text.push_str(own);
        append_dependencies(own, seen, text);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_type_has_a_definition() {
        for (name, text) in DEFINITIONS {
            for kind in field_types(text) {
                assert!(definition(kind).is_some(), "{name} uses {kind}");
            }
        }
    }

    #[test]
    fn a_schema_appends_each_dependency_once_after_a_separator() {
        let text = schema_text("nav_msgs/msg/Odometry").unwrap();
        assert!(text.starts_with("std_msgs/Header header\n"));
        for kind in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
        ] {
            let marker = format!("{SEPARATOR}\nMSG: {kind}\n");
            assert_eq!(text.matches(&marker).count(), 1, "{kind} in\n{text}");
        }
        assert_eq!(text.matches("MSG: ").count(), 9);
        assert!(schema_text("sensor_msgs/msg/Image").is_none());
    }
}
