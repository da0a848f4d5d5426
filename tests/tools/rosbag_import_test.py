#!/usr/bin/env python3
"""`carvemap import rosbag` on bags written by ROS's own Python library (make_rosbag.py),
checked against the geometry the bags were made from, read back with h5py alone.

Every frame of the scan.h5: /path at its time is base_link's true pose; every ray is the
true ray of its beam or pixel (a no-return exactly where the true range exceeds range_max or
the pixel was NaN); the bz2 and lz4 bags give the same arrays as the uncompressed one. Bad input (a
bag cut short, a missing topic, a fixed frame /tf does not reach) fails naming the file and
leaves no scan.h5.

With --ros2 DIR, the same robot recorded as ROS 2 bags (tests/data/ros2/: MCAP written by
@mcap/core, plain, zstd and lz4; sqlite3 written by Python's sqlite3; a bag directory; CDR
messages by @foxglove/cdr) is imported and checked against the same truth.

  rosbag_import_test.py --carvemap BIN --work DIR [--ros2 DIR]
"""
import argparse
import importlib.util
import math
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np

from check_scan_floorplan import quat_to_matrix  # beside this file: the same h5py-only reading

HERE = os.path.dirname(os.path.abspath(__file__))
spec = importlib.util.spec_from_file_location("make_rosbag", os.path.join(HERE, "make_rosbag.py"))
bagmaker = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bagmaker)

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def run(args, expect_ok=True):
    p = subprocess.run(args, capture_output=True, text=True)
    if expect_ok and p.returncode != 0:
        print(p.stdout, p.stderr)
        raise SystemExit(f"failed: {' '.join(args)}")
    return p


def load(path, name=None):
    """The scan's one sensor, or sensor `name` of several, with the scan's /path."""
    with h5py.File(path, "r") as f:
        if name is None:
            (name,) = list(f["sensors"].keys())
        s = f["sensors"][name]
        kind = s.attrs["kind"]
        kind = kind.decode() if isinstance(kind, bytes) else str(kind)
        return {
            "path": f["path"][()],
            "kind": kind,
            "rows": int(s.attrs.get("rows", 0)),
            "cols": int(s.attrs.get("cols", 0)),
            "R": np.array(s.attrs["R_s2c"]).reshape(3, 3),
            "T": np.array(s.attrs["T_s2c"]),
            "frames": s["frames"][()],
            "points": s["points"][()],
        }


def truth_rays(kind, t):
    """The true end points in the sensor frame of a frame at bag time t (NaN: no return)."""
    if kind == "scan":
        origin, r = bagmaker.sensor_in_world(t, bagmaker.LASER_IN_BASE)
        out = []
        for k in range(181):
            a = -math.pi / 2 + k * (math.pi / 180)
            d = np.array([math.cos(a), math.sin(a), 0.0])
            rng = bagmaker.ray_to_room(origin, r @ d)
            out.append(d * rng if rng <= 5.0 else np.full(3, np.nan))
        return np.array(out)
    origin, r = bagmaker.sensor_in_world(t, bagmaker.CAMERA_IN_BASE, bagmaker.rot_y(bagmaker.CAMERA_PITCH))
    out = []
    for v in range(3):
        for u in range(5):
            if (v, u) == (1, 2):
                out.append(np.full(3, np.nan))
                continue
            d = np.array([1.0, 0.25 * (u - 2), 0.2 * (1 - v)])
            d /= np.linalg.norm(d)
            out.append(d * bagmaker.ray_to_room(origin, r @ d))
    return np.array(out)


def check_against_truth(scan, kind, label):
    path, frames, pts = scan["path"], scan["frames"], scan["points"]
    rows = {row["t"]: row for row in path}
    check(len(frames) > 0 and all(fr["t"] in rows for fr in frames),
          f"{label}: a /path row at every frame's time")
    worst_pose = worst_ray = 0.0
    wrong_no_return = 0
    for i, fr in enumerate(frames):
        t = fr["t"] - bagmaker.T0
        row = rows[fr["t"]]
        p, yaw = bagmaker.base_pose(t)
        rq = quat_to_matrix((row["qw"], row["qx"], row["qy"], row["qz"]))
        worst_pose = max(worst_pose, np.linalg.norm(np.array([row["x"], row["y"], row["z"]]) - p),
                         np.abs(rq - bagmaker.rot_z(yaw)).max())
        got = pts[fr["first"]:fr["first"] + fr["count"]]
        want = truth_rays(kind, t)
        if got.shape != want.shape:
            check(False, f"{label}: frame {i} has {got.shape} rays, truth {want.shape}")
            continue
        nan_got, nan_want = np.isnan(got).any(axis=1), np.isnan(want).any(axis=1)
        wrong_no_return += int((nan_got != nan_want).sum())
        both = ~nan_got & ~nan_want
        if both.any():
            worst_ray = max(worst_ray, np.abs(got[both] - want[both]).max())
    # Stamps are whole nanoseconds and points float32 (~5e-7 m at 5 m).
    check(worst_pose < 1e-6, f"{label}: /path within 1e-6 of base_link's true pose ({worst_pose:.2e})")
    check(worst_ray < 2e-5, f"{label}: rays within 2e-5 m of the truth ({worst_ray:.2e})")
    check(wrong_no_return == 0, f"{label}: no-returns exactly where the truth has none ({wrong_no_return} wrong)")
    print(f"{label}: {len(frames)} frames, pose error {worst_pose:.1e}, ray error {worst_ray:.1e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--carvemap", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--ros2", help="the ROS 2 bags of tests/data/ros2")
    a = ap.parse_args()
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    bags = {}
    for name, extra in (("plain", []), ("bz2", ["--compression", "bz2"]),
                        ("lz4", ["--compression", "lz4"]),
                        ("unorganized", ["--cloud-unorganized"])):
        bags[name] = os.path.join(a.work, name + ".bag")
        run([sys.executable, os.path.join(HERE, "make_rosbag.py"), bags[name]] + extra)
    reader = [sys.executable, os.path.join(HERE, "independent_reader.py"), "--scan"]

    def imported(bag, topic, out, *extra):
        out = os.path.join(a.work, out)
        run([a.carvemap, "import", "rosbag", bag, "--topic", topic, "-o", out, *extra])
        run(reader + [out])
        return load(out) if "," not in topic else out

    scan = imported(bags["plain"], "/scan", "scan.h5")
    check(scan["kind"] == "line", "LaserScan gives a line sensor")
    check(np.allclose(scan["T"], bagmaker.LASER_IN_BASE[0]) and np.allclose(scan["R"], np.eye(3)),
          "the laser's mounting is base_link ➜ laser of /tf_static")
    check_against_truth(scan, "scan", "/scan")
    scan_bz2 = imported(bags["bz2"], "/scan", "scan_bz2.h5")
    check(np.array_equal(scan["points"], scan_bz2["points"], equal_nan=True)
          and np.array_equal(scan["path"], scan_bz2["path"]), "the bz2 bag gives the same scan")
    scan_lz4 = imported(bags["lz4"], "/scan", "scan_lz4.h5")
    check(np.array_equal(scan["points"], scan_lz4["points"], equal_nan=True)
          and np.array_equal(scan["path"], scan_lz4["path"]), "the lz4 bag gives the same scan")

    cloud = imported(bags["plain"], "/cloud", "cloud.h5")
    check(cloud["kind"] == "grid" and (cloud["rows"], cloud["cols"]) == (3, 5),
          "an organized cloud gives a 3 × 5 grid sensor")
    check(np.allclose(cloud["R"], bagmaker.camera_rotation()) and
          np.allclose(cloud["T"], bagmaker.CAMERA_IN_BASE[0]), "the camera's mounting")
    check_against_truth(cloud, "cloud", "/cloud organized")
    # Both topics at once: two sensors on one /path, each as its topic alone gave it.
    both = imported(bags["plain"], "/scan,/cloud", "both.h5")
    for name, alone, kind in (("scan", scan, "scan"), ("cloud", cloud, "cloud")):
        got = load(both, name)
        check(np.array_equal(got["points"], alone["points"], equal_nan=True)
              and np.array_equal(got["frames"]["t"], alone["frames"]["t"]),
              f"--topic /scan,/cloud: sensor {name} as its topic alone gave it")
        check_against_truth(got, kind, f"/scan,/cloud: {name}")
    with h5py.File(both, "r") as f:
        merged = np.union1d(scan["path"]["t"], cloud["path"]["t"])
        check(np.array_equal(f["path"]["t"], merged),
              "--topic /scan,/cloud: /path at every frame time of both topics, once")
    points = imported(bags["unorganized"], "/cloud", "points.h5")
    check(points["kind"] == "points", "an unorganized cloud gives a points sensor")
    check_against_truth(points, "cloud", "/cloud unorganized")

    # A shorter max range: more no-returns, none farther than it.
    short = imported(bags["plain"], "/scan", "short.h5", "--max-range", "3")
    finite = short["points"][~np.isnan(short["points"]).any(axis=1)]
    check(len(finite) > 0 and np.linalg.norm(finite, axis=1).max() <= 3.0,
          "--max-range 3: no return beyond 3 m")

    if a.ros2:
        for name in ("robot.mcap", "robot_zstd.mcap", "robot_lz4.mcap", "robot.db3", "robot_db3"):
            bag = os.path.join(a.ros2, name)
            label = name.replace(".", "_")
            s2 = imported(bag, "/scan", f"ros2_{label}_scan.h5")
            check(s2["kind"] == "line", f"{name}: LaserScan gives a line sensor")
            check_against_truth(s2, "scan", f"{name} /scan")
            c2 = imported(bag, "/cloud", f"ros2_{label}_cloud.h5")
            check(c2["kind"] == "grid" and (c2["rows"], c2["cols"]) == (3, 5),
                  f"{name}: an organized cloud gives a 3 × 5 grid sensor")
            check(np.allclose(c2["R"], bagmaker.camera_rotation()) and
                  np.allclose(c2["T"], bagmaker.CAMERA_IN_BASE[0]), f"{name}: the camera's mounting")
            check_against_truth(c2, "cloud", f"{name} /cloud")
            check(np.array_equal(s2["path"]["t"], scan["path"]["t"]),
                  f"{name}: the frames at the ROS 1 bag's stamps")
        p2 = imported(os.path.join(a.ros2, "robot_unorganized.mcap"), "/cloud", "ros2_points.h5")
        check(p2["kind"] == "points", "robot_unorganized.mcap: an unorganized cloud gives points")
        check_against_truth(p2, "cloud", "robot_unorganized.mcap /cloud")
        with open(os.path.join(a.ros2, "robot.mcap"), "rb") as f:
            mcap = f.read()
        cut2 = os.path.join(a.work, "cut.mcap")
        with open(cut2, "wb") as f:
            f.write(mcap[: len(mcap) // 2])
        out = os.path.join(a.work, "bad_mcap", "scan.h5")
        p = run([a.carvemap, "import", "rosbag", cut2, "--topic", "/scan", "-o", out],
                expect_ok=False)
        check(p.returncode != 0 and cut2 in p.stderr and "cut short" in p.stderr,
              f"an MCAP file cut short fails naming it (stderr: {p.stderr.strip()})")
        check(not os.path.exists(out), "an MCAP file cut short: no scan.h5 left")

    # Bad input: an error naming the file, and no scan.h5 left behind.
    with open(bags["plain"], "rb") as f:
        data = f.read()
    cut = os.path.join(a.work, "cut.bag")
    with open(cut, "wb") as f:
        f.write(data[: len(data) * 3 // 5])
    cases = [
        ([cut, "--topic", "/scan"], [cut, "cut short"]),
        ([bags["plain"], "--topic", "/nope"], ["no messages on topic /nope",
                                                "/scan (sensor_msgs/LaserScan)"]),
        ([bags["plain"], "--topic", "/scan", "--fixed-frame", "world"],
         ["no /tf chain from frame", "\"world\""]),
        ([bags["plain"], "--topic", "/tf"], ["tf2_msgs/TFMessage; sensor_msgs/LaserScan or"]),
    ]
    for i, (args, needles) in enumerate(cases):
        out = os.path.join(a.work, f"bad{i}", "scan.h5")
        p = run([a.carvemap, "import", "rosbag", *args, "-o", out], expect_ok=False)
        check(p.returncode != 0, f"bad input {i} fails")
        for n in needles:
            check(n in p.stderr, f"bad input {i}: the error says {n!r} (stderr: {p.stderr.strip()})")
        check(not os.path.exists(out), f"bad input {i}: no scan.h5 left")

    if failures:
        print(f"0 passed, {len(failures)} failed")
        raise SystemExit(1)
    print("rosbag import: all checks passed")


if __name__ == "__main__":
    main()
