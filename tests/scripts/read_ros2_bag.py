#!/usr/bin/env python3
"""Reads a ROS 2 recording (MCAP) with mcap_ros2's own decoder, as ROS 2
tools would, and prints a JSON summary: per topic its schema, message
encoding and message count, and a few decoded fields of its first and
last messages.

Usage: read_ros2_bag.py FILE.mcap
"""

import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.reader import read_ros2_messages


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def fields(schema, m):
    """The fields a test checks, by type."""
    if schema == "sensor_msgs/msg/LaserScan":
        return {"frame_id": m.header.frame_id, "stamp": seconds(m.header.stamp),
                "angle_min": m.angle_min, "angle_max": m.angle_max,
                "angle_increment": m.angle_increment, "range_min": m.range_min,
                "range_max": m.range_max, "ranges": list(m.ranges)}
    if schema == "sensor_msgs/msg/Range":
        return {"frame_id": m.header.frame_id, "stamp": seconds(m.header.stamp),
                "radiation_type": m.radiation_type, "field_of_view": m.field_of_view,
                "min_range": m.min_range, "max_range": m.max_range, "range": m.range}
    if schema == "nav_msgs/msg/Odometry":
        p = m.pose.pose
        return {"frame_id": m.header.frame_id, "child_frame_id": m.child_frame_id,
                "stamp": seconds(m.header.stamp), "x": p.position.x, "y": p.position.y,
                "yaw": yaw(p.orientation)}
    if schema == "geometry_msgs/msg/PoseStamped":
        p = m.pose
        return {"frame_id": m.header.frame_id, "stamp": seconds(m.header.stamp),
                "x": p.position.x, "y": p.position.y, "yaw": yaw(p.orientation)}
    if schema == "geometry_msgs/msg/PoseWithCovarianceStamped":
        p = m.pose.pose
        return {"frame_id": m.header.frame_id, "stamp": seconds(m.header.stamp),
                "x": p.position.x, "y": p.position.y, "yaw": yaw(p.orientation),
                "covariance": list(m.pose.covariance)}
    if schema == "tf2_msgs/msg/TFMessage":
        return {"transforms": [
            {"parent": t.header.frame_id, "child": t.child_frame_id,
             "x": t.transform.translation.x, "y": t.transform.translation.y,
             "yaw": yaw(t.transform.rotation)} for t in m.transforms]}
    if schema == "nav_msgs/msg/OccupancyGrid":
        data = list(m.data)
        return {"frame_id": m.header.frame_id, "width": m.info.width,
                "height": m.info.height, "resolution": m.info.resolution,
                "origin_x": m.info.origin.position.x, "origin_y": m.info.origin.position.y,
                "cells": len(data), "unknown": sum(1 for v in data if v == -1),
                "occupied": sum(1 for v in data if v >= 65),
                "free": sum(1 for v in data if 0 <= v <= 20),
                "out_of_range": sum(1 for v in data if v < -1 or v > 100)}
    return {}


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    path = sys.argv[1]
    topics = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        profile = reader.get_header().profile
        summary = reader.get_summary()
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        topics[channel.topic] = {
            "schema": schema.name, "schema_encoding": schema.encoding,
            "message_encoding": channel.message_encoding, "count": 0,
            "frame_ids": [],
        }
    for message in read_ros2_messages(path):
        topic = topics[message.channel.topic]
        topic["count"] += 1
        decoded = fields(message.schema.name, message.ros_msg)
        if "first" not in topic:
            topic["first"] = decoded
        topic["last"] = decoded
        frame_id = decoded.get("frame_id")
        if frame_id is not None and frame_id not in topic["frame_ids"]:
            topic["frame_ids"].append(frame_id)
    json.dump({"profile": profile, "topics": topics}, sys.stdout, indent=1,
              allow_nan=True)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
