#!/usr/bin/env python3
"""What localization drift alone allows the object scores: each true object's returns placed
with the exact and with the recorded (drifted) path, and the boxes any map built on the
recorded path could give.

For each true object (building.json), the returns whose exact place lies in its box (2 cm
margin; returns within 9.4 cm of the floor or of the room's ceiling left out, as segmentation
does) give three boxes, each scored by box IoU against the true box:
  exact    the box of those returns placed with the exact path (what the points allow without
           drift: the segmentation's own ceiling);
  drifted  the box of the same returns placed with the recorded path (every pass that saw the
           object, each with its own error: what a map fusing them all holds);
  moved    the true box moved by the mean displacement of its returns (a perfect shape, only
           put where the recorded path puts it: a bound for any map in the recorded frame).
A box that stands on the floor (or hangs from the ceiling) is extended to it, moved with the
mean vertical displacement. Prints the share found at IoU >= 0.5 (objects with all sides
>= 0.3 m, as match_objects.py) for each, per kind.

--moved-gt DIR writes DIR/building.json: the truth with each object's box moved as in `moved`,
so `match_objects.py OUT DIR` scores a job against where the recorded path puts the objects.

Usage: drift_object_bound.py DRIFTED_SCAN.h5 EXACT_SCAN.h5 GT_DIR [--moved-gt DIR]
  The two scans are one simulated walk written with and without drift (`carvemap simulate ...
  -o D` and the same with `--no-drift -o N`); GT_DIR is either's gt/.
"""
import argparse
import json
import os

import h5py
import numpy as np

from drift_displacement import placed_returns
from match_objects import iou

MARGIN = 0.02
FLOOR_CUT = 0.094  # segmentation's cut above the floor and under the ceiling (one coarse cell + 3 cm)


def inside(poly, x, y):
    """Even–odd rule: is (x, y) inside the polygon [[x, y], ...]."""
    c = False
    n = len(poly)
    for i in range(n):
        (x1, y1), (x2, y2) = poly[i], poly[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            c = not c
    return c


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("drifted")
    ap.add_argument("exact")
    ap.add_argument("gt")
    ap.add_argument("--moved-gt", help="write the truth with the objects moved here")
    args = ap.parse_args()
    truth = json.load(open(os.path.join(args.gt, "building.json")))
    xs, xr = placed_returns(h5py.File(args.drifted, "r"), h5py.File(args.exact, "r"))
    levels = {lv["index"]: lv for lv in truth["levels"]}
    rows, moved_objects = [], []
    for obj in truth["objects"]:
        box = np.asarray(obj["aabb"], float)
        lv = levels[obj.get("level", 0)]
        floor, ceiling = lv["floor_z"], lv["ceiling_z"]
        cx, cy = (box[0][:2] + box[1][:2]) / 2
        for room in truth["rooms"]:
            if room["level"] == lv["index"] and inside(room["polygon"], cx, cy):
                ceiling = room.get("ceiling_z", ceiling)
        lo = np.maximum(box[0] - MARGIN, [-np.inf, -np.inf, floor + FLOOR_CUT])
        hi = np.minimum(box[1] + MARGIN, [np.inf, np.inf, ceiling - FLOOR_CUT])
        sel = np.all((xs >= lo) & (xs <= hi), axis=1)
        moved = dict(obj)
        big = bool(np.all(box[1] - box[0] >= 0.3))
        if not sel.any():
            rows.append((obj.get("kind", "?"), big, 0, 0.0, 0.0, 0.0, 0.0))
            moved_objects.append(moved)
            continue
        a, b = xs[sel], xr[sel]
        shift = (b - a).mean(0)
        stands, hangs = box[0][2] <= floor + 0.01, box[1][2] >= ceiling - 0.01

        def point_box(p, dz):
            pb = np.array([p.min(0), p.max(0)])
            if stands:
                pb[0][2] = box[0][2] + dz
            if hangs:
                pb[1][2] = box[1][2] + dz
            return pb

        moved["aabb"] = (box + shift).tolist()
        moved_objects.append(moved)
        spread = np.percentile(np.linalg.norm((b - a) - shift, axis=1), 90)
        rows.append((obj.get("kind", "?"), big, int(sel.sum()), iou(point_box(a, 0), box),
                     iou(point_box(b, shift[2]), box), iou(box + shift, box), spread))
    big = [r for r in rows if r[1]]
    print(f"{len(rows)} true objects, {len(big)} with all sides >= 0.3 m; found at IoU >= 0.5:")
    kinds = sorted({r[0] for r in big})
    print(f"{'':10s} {'n':>4s} {'exact':>6s} {'drifted':>8s} {'moved':>6s}   "
          f"(median spread of an object's displacements, p90: cm)")
    for kind in kinds + ["all"]:
        sub = [r for r in big if kind in ("all", r[0])]
        f = [sum(r[k] >= 0.5 for r in sub) for k in (3, 4, 5)]
        spread = np.median([r[6] for r in sub if r[2] > 0]) * 100
        print(f"{kind:10s} {len(sub):4d} {f[0]:6d} {f[1]:8d} {f[2]:6d}   {spread:.1f}")
    if args.moved_gt:
        os.makedirs(args.moved_gt, exist_ok=True)
        out = dict(truth)
        out["objects"] = moved_objects
        with open(os.path.join(args.moved_gt, "building.json"), "w") as f:
            json.dump(out, f)


if __name__ == "__main__":
    main()
