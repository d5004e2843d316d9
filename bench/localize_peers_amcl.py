#!/usr/bin/env python3
"""amcl's side of `deog bench localize-peers`.

Runs nav2's amcl (the C core through the PyPI package `amcl`) over the
sonar frames deog recorded, on the occupancy grid deog exported from its
own sonar-built map, once per run of the run file, and prints one JSON
object on stdout: per run, the updates made, the CPU seconds of the
update calls alone and the estimate at every frame.

The frames file (little-endian): magic "DEOGAF01", u32 frame count, u32
beam count, f64 range_max, the beams' bearings (f64 each, radians, robot
frame), then per frame f64 time (s), f64 odometry x, y, theta and the
beams' ranges (f64 each, metres from the robot's centre; range_max where
the sonar heard nothing).

The grid file: magic "DEOGAG01", u32 width, u32 height, f64 resolution,
f64 origin x, f64 origin y (the lower-left corner of the lower-left
cell), then width * height i8 cells row by row from the bottom row up
(0 free, 100 occupied, -1 unknown), as a ROS OccupancyGrid holds them.

The run file: JSON, {"motion": {alpha1..alpha5}, "laser": {z_hit, z_short,
z_max, z_rand, sigma_hit, lambda_short, chi_outlier, max_beams},
"robot_model": "differential", "update_min_d": m, "update_min_a": rad,
"runs": [{"name", "min_particles", "max_particles", "alpha_slow",
"alpha_fast", "initial_pose": [x, y, theta], "initial_std": [sx, sy,
stheta]}]}.

Needs numpy and the `amcl` module (`pip install amcl numpy`). With --probe
it only imports them and prints their versions: exit 3 if either is
missing.
"""

import argparse
import json
import math
import platform
import struct
import sys
import time

MISSING_EXIT = 3


def versions():
    """The interpreter's, numpy's and the amcl package's versions."""
    import numpy

    try:
        from importlib.metadata import version

        amcl_version = version("amcl")
    except Exception:  # noqa: BLE001 - a missing distribution record only
        amcl_version = "unknown"
    return {
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "amcl": amcl_version,
    }


def read_frames(path):
    """(range_max, bearings, frames): each frame (time, (x, y, theta), ranges)."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"DEOGAF01":
        raise SystemExit(f"{path}: not a deog amcl frames file")
    count, beams, range_max = struct.unpack_from("<IId", data, 8)
    pos = 24
    bearings = np.frombuffer(data, dtype="<f8", count=beams, offset=pos)
    pos += 8 * beams
    frames = []
    for _ in range(count):
        t, x, y, theta = struct.unpack_from("<dddd", data, pos)
        pos += 32
        ranges = np.frombuffer(data, dtype="<f8", count=beams, offset=pos)
        pos += 8 * beams
        frames.append((t, (x, y, theta), ranges))
    if pos != len(data):
        raise SystemExit(f"{path}: {len(data) - pos} bytes past the last frame")
    return range_max, bearings, frames


def read_grid(path):
    """(width, height, resolution, origin x, origin y, rows bottom first)."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"DEOGAG01":
        raise SystemExit(f"{path}: not a deog occupancy grid file")
    width, height, res, ox, oy = struct.unpack_from("<IIddd", data, 8)
    pos = 40
    if len(data) - pos != width * height:
        raise SystemExit(f"{path}: {len(data) - pos} cells for {width} x {height}")
    cells = np.frombuffer(data, dtype="<i1", count=width * height, offset=pos)
    return width, height, res, ox, oy, cells.reshape(height, width)


def compose(a, b):
    """Pose a then pose b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    theta = a[2] + b[2]
    return (
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        math.atan2(math.sin(theta), math.cos(theta)),
    )


def between(a, b):
    """Pose b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    theta = b[2] - a[2]
    return (
        c * dx + s * dy,
        -s * dx + c * dy,
        math.atan2(math.sin(theta), math.cos(theta)),
    )


def run_one(amcl, spec, settings, grid, scans, frames):
    """One filter over every frame: its updates, their CPU and the poses."""
    motion = amcl.MotionParameters(**settings["motion"])
    laser = amcl.LaserParameters(**settings["laser"])
    localizer = amcl.AMCL(
        spec["min_particles"],
        spec["max_particles"],
        spec["alpha_slow"],
        spec["alpha_fast"],
        motion,
        laser,
        settings["robot_model"],
    )
    localizer.set_map(grid)
    # The beams start at the robot's centre (their ranges say so).
    localizer.set_laser_pose(amcl.Vector3D(0.0, 0.0, 0.0))
    sx, sy, st = spec["initial_std"]
    localizer.set_initial_pose(
        amcl.Vector3D(*spec["initial_pose"]),
        amcl.create_diagonal_covariance(sx * sx, sy * sy, st * st),
    )
    min_d, min_a = settings["update_min_d"], settings["update_min_a"]
    last_odom = None
    last_pose = None
    cpu = 0.0
    updates = 0
    poses = []
    for (t, odom, _ranges), scan in zip(frames, scans):
        # nav2's node updates the filter only once the robot has moved
        # update_min_d or turned update_min_a since the last update; the
        # package updates on every call, so the gate is kept here.
        due = last_odom is None
        if not due:
            d = between(last_odom, odom)
            due = math.hypot(d[0], d[1]) >= min_d or abs(d[2]) >= min_a
        if due:
            start = time.thread_time()
            localizer.update(scan, amcl.Vector3D(*odom))
            cpu += time.thread_time() - start
            mean = localizer.get_pose_mean()
            updates += 1
            last_odom = odom
            last_pose = (mean.x, mean.y, mean.theta)
        # Between updates the estimate moves with the odometry, as nav2's
        # map -> odom transform carries it.
        poses.append(compose(last_pose, between(last_odom, odom)))
    return {
        "name": spec["name"],
        "updates": updates,
        "update_cpu_s": cpu,
        "poses": poses,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", nargs="?", help="the frames file deog wrote")
    parser.add_argument("grid", nargs="?", help="the occupancy grid file deog wrote")
    parser.add_argument("runs", nargs="?", help="the run file deog wrote")
    parser.add_argument("--probe", action="store_true")
    args = parser.parse_args()

    try:
        import numpy  # noqa: F401
        import amcl
    except ImportError as e:
        print(e, file=sys.stderr)
        return MISSING_EXIT
    if args.probe:
        print(json.dumps(versions()))
        return 0
    if args.frames is None or args.grid is None or args.runs is None:
        parser.error("give the frames, grid and run files")

    range_max, bearings, frames = read_frames(args.frames)
    width, height, res, ox, oy, rows = read_grid(args.grid)
    with open(args.runs) as f:
        settings = json.load(f)
    # The package looks a point up as floor((x - ox) / res + 0.5): cell i
    # is centred on ox + i * res. deog's cell i spans [ox + i res, ox +
    # (i + 1) res), so the origin moves half a cell to line the two up.
    grid = amcl.create_occupancy_grid_from_list(
        rows.tolist(), res, ox + res / 2.0, oy + res / 2.0
    )
    bearing_list = bearings.tolist()
    scans = [
        amcl.create_laser_scan_from_list(
            [[r, b] for r, b in zip(ranges.tolist(), bearing_list)], range_max
        )
        for _, _, ranges in frames
    ]
    runs = [run_one(amcl, spec, settings, grid, scans, frames) for spec in settings["runs"]]
    print(json.dumps({**versions(), "frames": len(frames), "width": width, "height": height, "runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
