#!/usr/bin/env python3
"""Checks the floor plan `carvemap floorplan --scan SCAN.h5 -o OUT` made of a 2D laser scan,
from the spec (docs/DESIGN.md §3, §7) and the scan itself, sharing no code with carvemap:

  - job.json lists its outputs, each exists and is not empty, occupancy.png among them;
  - level_0/floorplan.geojson has at least --min-rooms rooms; every room ring is closed, has at
    least three distinct corners, a non-zero area and no two edges crossing (a simple
    polygon); the areas in job.json match the polygons' (outer ring minus holes) within 1 %;
  - every corner lies inside the scan's extent: the box around its path and its returns
    placed in the world with h5py and numpy (the path at each frame's time, the sensor's
    mounting), grown by one grid cell;
  - every room holds a pose of the path within --entered-m of it (§3.3.2 keeps entered rooms).

Usage: check_scan_floorplan.py OUT_DIR SCAN.h5 [--min-rooms 1] [--entered-m 0.5] [--selftest]
  --selftest: also checks that the checks can fail (a crossing ring, a corner moved outside
  the extent, a room moved away from the path are each refused).
"""
import argparse
import json
import os
import sys

import h5py
import numpy as np


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def scan_extent(path):
    """Box (xmin, ymin, xmax, ymax) of the path and every return in the world, and the path x-y."""
    with h5py.File(path, "r") as f:
        p = f["path"][()]
        t = p["t"]
        xy = np.stack([p["x"], p["y"]], axis=1)
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        for name in f["sensors"]:
            g = f["sensors"][name]
            R_s2c = np.asarray(g.attrs["R_s2c"], dtype=float).reshape(3, 3)
            T_s2c = np.asarray(g.attrs["T_s2c"], dtype=float)
            frames = g["frames"][()]
            pts = g["points"][()].astype(float)
            for fr in frames:
                seg = pts[fr["first"]:fr["first"] + fr["count"]]
                seg = seg[np.all(np.isfinite(seg), axis=1)]
                if len(seg) == 0:
                    continue
                # Pose at the frame's time: linear position; the 2D logs' yaw by SLERP equals
                # the nearer pose's for the few cm this moves a point, so interpolate the
                # quaternion linearly and normalise (exact enough for a bounds check).
                i = int(np.clip(np.searchsorted(t, fr["t"]), 1, len(t) - 1))
                a = (fr["t"] - t[i - 1]) / (t[i] - t[i - 1]) if t[i] > t[i - 1] else 0.0
                a = min(max(a, 0.0), 1.0)
                pos = np.array([p["x"][i - 1], p["y"][i - 1], p["z"][i - 1]]) * (1 - a) + \
                    np.array([p["x"][i], p["y"][i], p["z"][i]]) * a
                q0 = np.array([p["qw"][i - 1], p["qx"][i - 1], p["qy"][i - 1], p["qz"][i - 1]])
                q1 = np.array([p["qw"][i], p["qx"][i], p["qy"][i], p["qz"][i]])
                if np.dot(q0, q1) < 0:
                    q1 = -q1
                q = q0 * (1 - a) + q1 * a
                R = quat_to_matrix(q / np.linalg.norm(q))
                world = (R @ (seg @ R_s2c.T + T_s2c).T).T + pos
                lo = np.minimum(lo, world[:, :2].min(axis=0))
                hi = np.maximum(hi, world[:, :2].max(axis=0))
    return (lo[0], lo[1], hi[0], hi[1]), xy


def ring_area(r):
    x, y = r[:, 0], r[:, 1]
    return 0.5 * float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1]))


def segments_cross(p1, p2, p3, p4):
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    d1, d2 = orient(p3, p4, p1), orient(p3, p4, p2)
    d3, d4 = orient(p1, p2, p3), orient(p1, p2, p4)
    return d1 * d2 < 0 and d3 * d4 < 0


def ring_errors(r):
    errs = []
    if len(r) < 4 or not np.allclose(r[0], r[-1]):
        return ["ring not closed or under three corners"]
    if len(np.unique(np.round(r[:-1], 9), axis=0)) < 3:
        errs.append("fewer than three distinct corners")
    if abs(ring_area(r)) < 1e-9:
        errs.append("zero area")
    n = len(r) - 1
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # neighbours through the closing corner
            if segments_cross(r[i], r[i + 1], r[j], r[j + 1]):
                errs.append(f"edges {i} and {j} cross")
                return errs
    return errs


def point_in_ring(pt, r):
    x, y = pt
    inside = False
    for (x0, y0), (x1, y1) in zip(r[:-1], r[1:]):
        if (y0 <= y) != (y1 <= y):
            if x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                inside = not inside
    return inside


def dist_to_ring(pt, r):
    a, b = r[:-1], r[1:]
    d = b - a
    L = np.maximum(np.sum(d * d, axis=1), 1e-18)
    u = np.clip(np.sum((pt - a) * d, axis=1) / L, 0, 1)
    return float(np.min(np.linalg.norm(a + u[:, None] * d - pt, axis=1)))


def check(rooms, job_rooms, extent, path_xy, args, resolution):
    """rooms: list of polygons (list of rings as numpy arrays). Returns a list of errors."""
    errs = []
    if len(rooms) < args.min_rooms:
        errs.append(f"{len(rooms)} rooms, want at least {args.min_rooms}")
    margin = resolution
    x0, y0, x1, y1 = extent
    for k, polygons in enumerate(rooms):
        area = 0.0
        for poly in polygons:
            for ri, r in enumerate(poly):
                for e in ring_errors(r):
                    errs.append(f"room {k} ring {ri}: {e}")
                out = (r[:, 0] < x0 - margin) | (r[:, 0] > x1 + margin) | \
                      (r[:, 1] < y0 - margin) | (r[:, 1] > y1 + margin)
                if out.any():
                    errs.append(f"room {k}: corner {r[np.argmax(out)]} outside the scan's extent "
                                f"[{x0:.2f}, {x1:.2f}] × [{y0:.2f}, {y1:.2f}]")
                area += abs(ring_area(r)) * (1 if ri == 0 else -1)
        if job_rooms is not None and k < len(job_rooms):
            want = job_rooms[k]["area_m2"]
            if abs(area - want) > 0.01 * max(want, 1e-9):
                errs.append(f"room {k}: polygon area {area:.3f} m², job.json says {want:.3f}")
        entered = any(point_in_ring(p, poly[0]) or dist_to_ring(p, poly[0]) <= args.entered_m
                      for poly in polygons for p in path_xy)
        if not entered:
            errs.append(f"room {k}: no pose of the path within {args.entered_m} m")
    return errs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("scan")
    ap.add_argument("--min-rooms", type=int, default=1)
    ap.add_argument("--entered-m", type=float, default=0.5)
    ap.add_argument("--selftest", action="store_true")
    args = ap.parse_args()

    with open(os.path.join(args.out, "job.json")) as f:
        job = json.load(f)
    errs = []
    outputs = job.get("outputs", [])
    if "occupancy.png" not in outputs:
        errs.append("job.json does not list occupancy.png")
    for o in outputs:
        p = os.path.join(args.out, o)
        if not os.path.isfile(p) or os.path.getsize(p) == 0:
            errs.append(f"{o}: missing or empty")
    resolution = float(job["params"]["resolution_m"])
    with open(os.path.join(args.out, "level_0", "floorplan.geojson")) as f:
        gj = json.load(f)
    rooms = []
    for feat in gj["features"]:
        g = feat["geometry"]
        if g["type"] == "Polygon":
            rooms.append([[np.asarray(r, dtype=float) for r in g["coordinates"]]])
        elif g["type"] == "MultiPolygon":
            rooms.append([[np.asarray(r, dtype=float) for r in poly] for poly in g["coordinates"]])
    extent, path_xy = scan_extent(args.scan)
    errs += check(rooms, job.get("rooms"), extent, path_xy, args, resolution)

    if args.selftest and rooms:
        bad = [[[r.copy() for r in poly] for poly in polygons] for polygons in rooms]
        ring = bad[0][0][0]
        (x0, y0), (x1, y1) = ring.min(axis=0), ring.max(axis=0)
        bad[0][0][0] = np.array([[x0, y0], [x1, y1], [x1, y0], [x0, y1], [x0, y0]])  # a bow tie
        if not any("cross" in e for e in check(bad, None, extent, path_xy, args, resolution)):
            errs.append("selftest: a bow-tie ring was not refused")
        moved = [[[r + np.array([extent[2] - extent[0] + 10.0, 0]) for r in poly]
                  for poly in polygons] for polygons in rooms]
        e = check(moved, None, extent, path_xy, args, resolution)
        if not any("outside" in x for x in e) or not any("no pose" in x for x in e):
            errs.append("selftest: rooms moved off the scan were not refused")

    print(f"{len(rooms)} rooms, scan extent x [{extent[0]:.2f}, {extent[2]:.2f}] "
          f"y [{extent[1]:.2f}, {extent[3]:.2f}], {len(path_xy)} poses")
    for e in errs:
        print("ERROR:", e)
    return 1 if errs else 0


if __name__ == "__main__":
    sys.exit(main())
