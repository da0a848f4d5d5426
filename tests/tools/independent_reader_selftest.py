#!/usr/bin/env python3
"""Checks that independent_reader.py accepts a good file and rejects each kind of bad one.

Files are written here with h5py, as a foreign writer would, from docs/DESIGN.md §3/§4."""
import json
import os
import struct
import subprocess
import sys
import tempfile

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
READER = os.path.join(HERE, "independent_reader.py")


def write_scan(fname, mutate=None):
    path_dt = np.dtype([(n, "<f8") for n in ("t", "x", "y", "z", "qw", "qx", "qy", "qz")])
    path = np.zeros(3, dtype=path_dt)
    path["t"] = [0.0, 1.0, 2.0]
    path["x"] = [0.0, 1.0, 2.0]
    path["z"] = 1.0
    path["qw"] = 1.0
    frames_dt = np.dtype([("t", "<f8"), ("first", "<u8"), ("count", "<u4")])
    frames = np.zeros(2, dtype=frames_dt)
    frames["t"] = [0.5, 1.5]
    frames["first"] = [0, 2]
    frames["count"] = [2, 2]
    # Points 1 m in front along +x, i.e. on a wall plane x = x_sys + 1 seen from the sensor.
    points = np.array([[1, 0, 0], [np.nan] * 3, [1, 0, 0], [1, 0.5, 0]], dtype=np.float32)
    parts = dict(path=path, frames=frames, points=points, version=1, R=np.eye(3).reshape(-1))
    if mutate:
        mutate(parts)
    with h5py.File(fname, "w") as f:
        f.attrs["format"] = "carvemap-scan"
        f.attrs["version"] = parts["version"]
        f["path"] = parts["path"]
        g = f.create_group("sensors/lidar")
        g.attrs["kind"] = "points"
        g.attrs["R_s2c"] = parts["R"]
        g.attrs["T_s2c"] = np.zeros(3)
        g.attrs["sigma_t"] = 0.001
        g.attrs["range_sigma"] = parts.get("range_sigma", np.array([0.01, 0.0]))
        g.attrs["max_range"] = parts.get("max_range", 30.0)
        g["frames"] = parts["frames"]
        g["points"] = parts["points"]


def run(scan, *extra):
    r = subprocess.run([sys.executable, READER, "--scan", scan, *extra], capture_output=True,
                       text=True)
    return r.returncode, r.stdout + r.stderr


def main():
    d = tempfile.mkdtemp()
    failures = 0

    def expect(name, code_ok, mutate=None, extra=()):
        nonlocal failures
        f = os.path.join(d, name + ".h5")
        write_scan(f, mutate)
        rc, out = run(f, *extra)
        if (rc == 0) != code_ok:
            failures += 1
            print(f"FAIL {name}: exit {rc}\n{out}")
        else:
            print(f"ok   {name}")

    expect("good", True)

    def t_desc(p):
        p["path"]["t"] = [0.0, 2.0, 1.0]
    expect("time_not_ascending", False, t_desc)

    def bad_q(p):
        p["path"]["qw"] = 0.9
    expect("non_unit_quaternion", False, bad_q)

    def nearly_unit_q(p):  # within DESIGN §3's 1e-3 of unit: a valid file
        p["path"]["qw"] = 1.0005
    expect("quaternion_within_1e-3", True, nearly_unit_q)

    def nan_rotation(p):
        p["R"] = np.array([np.nan, 0, 0, 0, 1, 0, 0, 0, 1.0])
    expect("extrinsic_nan", False, nan_rotation)

    def negative_sigma(p):
        p["range_sigma"] = np.array([0.01, -0.001])
    expect("negative_range_sigma", False, negative_sigma)

    def zero_max_range(p):
        p["max_range"] = 0.0
    expect("zero_max_range", False, zero_max_range)

    def bad_version(p):
        p["version"] = 2
    expect("version_2", False, bad_version)

    def past_points(p):
        p["frames"]["count"] = [2, 3]
    expect("frame_past_points", False, past_points)

    def partial_nan(p):
        p["points"][3, 1] = np.nan
    expect("partial_nan_row", False, partial_nan)

    def not_rotation(p):
        p["R"] = (2 * np.eye(3)).reshape(-1)
    expect("extrinsic_not_rotation", False, not_rotation)

    # gt: a wall plane x = const mesh; points at x_sys + 1 lie on it only for the right wall.
    gt = os.path.join(d, "gt")
    os.makedirs(gt)
    def ply(fname, V, F):
        with open(fname, "wb") as fh:
            fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      f"element face {len(F)}\nproperty list uchar int vertex_indices\n"
                      "end_header\n").encode())
            fh.write(np.asarray(V, dtype="<f4").tobytes())
            for f in F:
                fh.write(struct.pack("<B3i", 3, *f))
    # Frame times 0.5 and 1.5 put the system at x = 0.5 and 1.5: hits at x = 1.5 and 2.5.
    walls = []
    for x in (1.5, 2.5):
        walls += [[x, -5, -5], [x, 5, -5], [x, 5, 5], [x, -5, 5]]
    F = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]
    ply(os.path.join(gt, "surfaces.ply"), walls, F)
    ply(os.path.join(gt, "objects.ply"), [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]])
    building = dict(levels=[dict(index=0, floor_z=0.0, ceiling_z=3.0)],
                    rooms=[dict(id=0, level=0, polygon=[[0, 0], [4, 0], [4, 3], [0, 3]],
                                holes=[], floor_z=0.0, ceiling_z=3.0, entered=True)],
                    doors=[], objects=[dict(id=0, kind="box", level=0,
                                            aabb=[[0, 0, 0], [0.1, 0.1, 0.1]])])
    json.dump(building, open(os.path.join(gt, "building.json"), "w"))
    expect("on_surface", True, None, ("--gt", gt, "--on-surface-mm", "1"))

    def shifted(p):
        p["points"][:, 0] += 0.01  # 1 cm off the wall
    expect("off_surface", False, shifted, ("--gt", gt, "--on-surface-mm", "1"))

    building["rooms"][0]["polygon"].reverse()  # clockwise
    json.dump(building, open(os.path.join(gt, "building.json"), "w"))
    expect("clockwise_room", False, None, ("--gt", gt))

    print(f"{10 - failures} passed, {failures} failed")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
