#!/usr/bin/env python3
"""OctoMap's side of `deog bench laser-mapping`.

Reads the scans deog wrote (world-frame echoes and each scan's sensor
origin, on the plane z = 0), builds an `octomap.OcTree` with the given
resolution, hit and miss probabilities and clamping, inserts every scan
with `insertPointCloud(points, origin, maxrange)` once per pass, and times
only the insertions. Then it writes the final map's z = 0 layer as a list
of cells with their log-odds, and prints one JSON object on stdout.

The scans file (little-endian): magic "DEOGPC01", u32 scan count, then per
scan the origin (f64 x, f64 y), u32 point count and the points (f64 x,
f64 y each). The cells file: magic "DEOGOC01", u64 cell count, then per
cell i32 x, i32 y (floor(metres / resolution)) and f32 log-odds (nats).

A scan is one origin with its points, so rays from several origins (a
sonar ring's transducers) come as several scans, one reading each
(`deog bench sonar-mapping`). With --time-empty-calls it then times the
same insertPointCloud calls again with no points, at the same origins,
and reports that as `empty_call_seconds`: what the calls cost beyond
OctoMap's own work on the rays (Python's loop, the call, the conversion of
the arguments), to tell apart when a scan is a single ray.

Needs numpy and the `octomap` module (`pip install octomap-python numpy`).
With --probe it only imports them and prints their versions: exit 3 if
either is missing.
"""

import argparse
import json
import platform
import struct
import sys
import time

MISSING_EXIT = 3


def versions():
    """The interpreter's, numpy's and octomap-python's versions."""
    import numpy

    try:
        from importlib.metadata import version

        octomap_version = version("octomap-python")
    except Exception:  # noqa: BLE001 - a missing distribution record only
        octomap_version = "unknown"
    return {
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "octomap": octomap_version,
    }


def read_scans(path):
    """The scans as (origin, points) pairs of numpy arrays, z = 0 added."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"DEOGPC01":
        raise SystemExit(f"{path}: not a deog point-cloud file")
    (count,) = struct.unpack_from("<I", data, 8)
    pos = 12
    scans = []
    for _ in range(count):
        x, y, n = struct.unpack_from("<ddI", data, pos)
        pos += 20
        xy = np.frombuffer(data, dtype="<f8", count=2 * n, offset=pos).reshape(n, 2)
        pos += 16 * n
        points = np.zeros((n, 3), dtype=np.float64)
        points[:, :2] = xy
        scans.append((np.array([x, y, 0.0]), points))
    if pos != len(data):
        raise SystemExit(f"{path}: {len(data) - pos} bytes past the last scan")
    return scans


def export_cells(tree, resolution, path):
    """Writes the z = 0 layer's cells; returns how many."""
    import numpy as np

    xs, ys, values = [], [], []
    for leaf in tree.begin_leafs():
        size = leaf.getSize()
        cx, cy, cz = leaf.getCoordinate()
        half = size / 2.0
        # The plane's layer is the voxels from z = 0 to one resolution up
        # (OctoMap's keys floor the coordinate); the test is on its centre,
        # clear of the float32 coordinates' rounding.
        if not (cz - half < resolution / 2.0 < cz + half):
            continue
        # A leaf deeper than the finest is one cell; a coarser one (pruned
        # children all alike) covers a square of them.
        side = max(1, round(size / resolution))
        x0 = round((cx - half) / resolution)
        y0 = round((cy - half) / resolution)
        value = leaf.getValue()
        for i in range(side):
            for j in range(side):
                xs.append(x0 + i)
                ys.append(y0 + j)
                values.append(value)
    cells = np.zeros(len(xs), dtype=[("x", "<i4"), ("y", "<i4"), ("l", "<f4")])
    cells["x"] = xs
    cells["y"] = ys
    cells["l"] = values
    with open(path, "wb") as f:
        f.write(b"DEOGOC01")
        f.write(struct.pack("<Q", len(cells)))
        f.write(cells.tobytes())
    return len(cells)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scans", nargs="?", help="the scans file deog wrote")
    parser.add_argument("--cells-out", help="where to write the final map's cells")
    parser.add_argument("--resolution", type=float, default=0.05)
    parser.add_argument("--prob-hit", type=float, default=0.7)
    parser.add_argument("--prob-miss", type=float, default=0.4)
    parser.add_argument("--clamp-min", type=float, default=0.12)
    parser.add_argument("--clamp-max", type=float, default=0.97)
    parser.add_argument("--max-range", type=float, default=20.0)
    parser.add_argument("--passes", type=int, default=1)
    parser.add_argument("--time-empty-calls", action="store_true")
    parser.add_argument("--probe", action="store_true")
    args = parser.parse_args()

    try:
        import numpy
        import octomap
    except ImportError as e:
        print(e, file=sys.stderr)
        return MISSING_EXIT
    if args.probe:
        print(json.dumps(versions()))
        return 0
    if args.scans is None or args.cells_out is None:
        parser.error("give the scans file and --cells-out")

    scans = read_scans(args.scans)
    tree = octomap.OcTree(args.resolution)
    tree.setProbHit(args.prob_hit)
    tree.setProbMiss(args.prob_miss)
    tree.setClampingThresMin(args.clamp_min)
    tree.setClampingThresMax(args.clamp_max)
    # A scan without echoes has nothing to insert (deog maps nothing for it
    # either: beams without a return are skipped on both sides).
    work = [(origin, points) for origin, points in scans if len(points) > 0]

    pass_seconds = []
    for _ in range(args.passes):
        start = time.perf_counter()
        for origin, points in work:
            tree.insertPointCloud(points, origin, maxrange=args.max_range)
        pass_seconds.append(time.perf_counter() - start)

    empty_call_seconds = None
    if args.time_empty_calls:
        # The same calls with nothing to insert: the tree is not touched.
        empty = numpy.zeros((0, 3), dtype=numpy.float64)
        start = time.perf_counter()
        for _ in range(args.passes):
            for origin, _points in work:
                tree.insertPointCloud(empty, origin, maxrange=args.max_range)
        empty_call_seconds = time.perf_counter() - start

    exported = export_cells(tree, args.resolution, args.cells_out)
    seconds = sum(pass_seconds)
    scans_done = len(scans) * args.passes
    report = {
        **versions(),
        "scans": scans_done,
        "passes": args.passes,
        "seconds": seconds,
        "pass_seconds": pass_seconds,
        "scans_per_s": scans_done / seconds if seconds > 0 else 0.0,
        "leaf_cells": tree.getNumLeafNodes(),
        "tree_nodes": tree.size(),
        "exported_cells": exported,
        "memory_bytes": tree.memoryUsage(),
        "calls": len(work) * args.passes,
    }
    if empty_call_seconds is not None:
        report["empty_call_seconds"] = empty_call_seconds
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
