#!/usr/bin/env python3
"""Writes a ROS 2 recording (MCAP, CDR) of a robot driving a circle in a
known room: sensor_msgs/LaserScan on /scan from a 360-degree laser, ranges
ray cast against the room's walls, nav_msgs/Odometry on /odom at twice the
scan rate and half a period apart (so a scan's odometry must be
interpolated), the laser's mount on /tf_static through base_link, the true
pose on /ground_truth and an unrelated /chatter topic.

The room: walls around [0, 8] x [0, 6] metres, a 1 m box with corners
(5.5, 3.5) and (6.5, 4.5). The robot: a circle of radius 1.5 m about
(3.5, 3.0), counter-clockwise at 0.5 m/s. Odometry is exact, in an odom
frame that is the room's.

Usage: write_ros2_bag.py OUT.mcap [--scans N] [--compression zstd|lz4|none]
"""

import argparse
import math
import sys

from mcap.writer import CompressionType
from mcap_ros2.writer import Writer

ROOM = [((0, 0), (8, 0)), ((8, 0), (8, 6)), ((8, 6), (0, 6)), ((0, 6), (0, 0))]
BOX = [((5.5, 3.5), (6.5, 3.5)), ((6.5, 3.5), (6.5, 4.5)),
       ((6.5, 4.5), (5.5, 4.5)), ((5.5, 4.5), (5.5, 3.5))]
WALLS = ROOM + BOX

CENTRE = (3.5, 3.0)
RADIUS = 1.5
SPEED = 0.5
SCAN_PERIOD = 0.1
START = 1_700_000_000.0
BEAMS = 360
ANGLE_MIN = -math.pi
INCREMENT = 2 * math.pi / BEAMS
RANGE_MIN = 0.05
RANGE_MAX = 12.0
# The laser on the robot: base_footprint -> base_link -> laser.
BASE_LINK_Z = 0.1
LASER_X, LASER_Z = 0.2, 0.15

TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
SEP = "=" * 80 + "\n"


def msgdef(own, *deps):
    text = own
    for name, body in deps:
        text += SEP + "MSG: " + name + "\n" + body
    return text


POINT = "float64 x\nfloat64 y\nfloat64 z\n"
QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
POSE = "Point position\nQuaternion orientation\n"
VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
TWIST = "Vector3 linear\nVector3 angular\n"

LASER_SCAN = msgdef(
    "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n"
    "float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n"
    "float32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n",
    ("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME))
ODOMETRY = msgdef(
    "std_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME),
    ("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"),
    ("geometry_msgs/Pose", POSE), ("geometry_msgs/Point", POINT),
    ("geometry_msgs/Quaternion", QUATERNION),
    ("geometry_msgs/TwistWithCovariance", "Twist twist\nfloat64[36] covariance\n"),
    ("geometry_msgs/Twist", TWIST), ("geometry_msgs/Vector3", VECTOR3))
TF_MESSAGE = msgdef(
    "geometry_msgs/TransformStamped[] transforms\n",
    ("geometry_msgs/TransformStamped",
     "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"),
    ("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME),
    ("geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"),
    ("geometry_msgs/Vector3", VECTOR3), ("geometry_msgs/Quaternion", QUATERNION))
POSE_STAMPED = msgdef(
    "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
    ("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME),
    ("geometry_msgs/Pose", POSE), ("geometry_msgs/Point", POINT),
    ("geometry_msgs/Quaternion", QUATERNION))


def pose_at(t):
    """The robot's true pose t seconds after the start: (x, y, heading)."""
    phi = SPEED * t / RADIUS
    return (CENTRE[0] + RADIUS * math.cos(phi), CENTRE[1] + RADIUS * math.sin(phi),
            phi + math.pi / 2)


def ray_cast(ox, oy, angle):
    """Distance from (ox, oy) along angle to the nearest wall, or inf."""
    dx, dy = math.cos(angle), math.sin(angle)
    best = math.inf
    for (ax, ay), (bx, by) in WALLS:
        ex, ey = bx - ax, by - ay
        denom = dx * ey - dy * ex
        if abs(denom) < 1e-12:
            continue
        t = ((ax - ox) * ey - (ay - oy) * ex) / denom
        u = ((ax - ox) * dy - (ay - oy) * dx) / denom
        if t > 0 and 0 <= u <= 1:
            best = min(best, t)
    return best


def stamp(seconds):
    nanos = round(seconds * 1e9)
    return {"sec": nanos // 1_000_000_000, "nanosec": nanos % 1_000_000_000}


def quaternion(yaw):
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def pose(x, y, yaw):
    return {"position": {"x": x, "y": y, "z": 0.0}, "orientation": quaternion(yaw)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--scans", type=int, default=200)
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    args = parser.parse_args()
    compression = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                   "none": CompressionType.NONE}[args.compression]
    with open(args.out, "wb") as f:
        writer = Writer(f, compression=compression, chunk_size=64 * 1024)
        scan_schema = writer.register_msgdef("sensor_msgs/msg/LaserScan", LASER_SCAN)
        odom_schema = writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY)
        tf_schema = writer.register_msgdef("tf2_msgs/msg/TFMessage", TF_MESSAGE)
        pose_schema = writer.register_msgdef("geometry_msgs/msg/PoseStamped", POSE_STAMPED)
        chatter_schema = writer.register_msgdef("std_msgs/msg/String", "string data\n")

        def write(topic, schema, message, seconds):
            nanos = round(seconds * 1e9)
            writer.write_message(topic, schema, message, log_time=nanos, publish_time=nanos)

        def transform(parent, child, x, z, seconds):
            return {"header": {"stamp": stamp(seconds), "frame_id": parent},
                    "child_frame_id": child,
                    "transform": {"translation": {"x": x, "y": 0.0, "z": z},
                                  "rotation": quaternion(0.0)}}

        write("/tf_static", tf_schema, {"transforms": [
            transform("base_footprint", "base_link", 0.0, BASE_LINK_Z, START),
            transform("base_link", "laser", LASER_X, LASER_Z, START)]}, START)
        write("/chatter", chatter_schema, {"data": "hello"}, START)

        duration = args.scans * SCAN_PERIOD
        # Odometry every half scan period, from before the first scan to
        # after the last, half an odometry period off the scans' stamps.
        odom_period = SCAN_PERIOD / 2
        steps = int(duration / odom_period) + 3
        events = []
        for k in range(steps):
            events.append((k * odom_period - odom_period / 2, "odom"))
        for i in range(args.scans):
            events.append((i * SCAN_PERIOD, "scan"))
        events.sort()
        scan_index = 0
        for t, kind in events:
            x, y, heading = pose_at(t)
            seconds = START + 1.0 + t
            if kind == "odom":
                write("/odom", odom_schema, {
                    "header": {"stamp": stamp(seconds), "frame_id": "odom"},
                    "child_frame_id": "base_footprint",
                    "pose": {"pose": pose(x, y, heading), "covariance": [0.0] * 36},
                    "twist": {"twist": {"linear": {"x": SPEED, "y": 0.0, "z": 0.0},
                                        "angular": {"x": 0.0, "y": 0.0, "z": SPEED / RADIUS}},
                              "covariance": [0.0] * 36},
                }, seconds)
                continue
            lx, ly = x + LASER_X * math.cos(heading), y + LASER_X * math.sin(heading)
            ranges = []
            for b in range(BEAMS):
                r = ray_cast(lx, ly, heading + ANGLE_MIN + b * INCREMENT)
                if r > RANGE_MAX:
                    r = math.inf
                # Some drivers' invalid readings, which an import must take.
                if scan_index % 5 == 0 and b % 37 == 0:
                    r = math.nan
                ranges.append(r)
            write("/scan", scan_schema, {
                "header": {"stamp": stamp(seconds), "frame_id": "laser"},
                "angle_min": ANGLE_MIN, "angle_max": ANGLE_MIN + (BEAMS - 1) * INCREMENT,
                "angle_increment": INCREMENT, "time_increment": 0.0,
                "scan_time": SCAN_PERIOD, "range_min": RANGE_MIN, "range_max": RANGE_MAX,
                "ranges": ranges, "intensities": [],
            }, seconds)
            write("/ground_truth", pose_schema, {
                "header": {"stamp": stamp(seconds), "frame_id": "map"},
                "pose": pose(x, y, heading)}, seconds)
            scan_index += 1
        writer.finish()
    print(f"wrote {args.out}: {args.scans} scans")
    return 0


if __name__ == "__main__":
    sys.exit(main())
