#!/usr/bin/env python3
"""The object score of a finished job against the simulator's truth, by hand.

The same matching as services/merge/object_segmentation_test.cc: true objects with all sides
>= 0.3 m are found when a reported object (job.json "objects") has box IoU >= 0.5 with them,
one to one, greedy by IoU; a reported object is false when it overlaps no true object (any
size) by >= 10 % of its own box. Prints found and false, and found per kind.

Usage: match_objects.py OUT_DIR GT_DIR
"""
import json
import os
import sys


def volume(b):
    return max(0.0, b[1][0] - b[0][0]) * max(0.0, b[1][1] - b[0][1]) * max(0.0, b[1][2] - b[0][2])


def intersection(a, b):
    lo = [max(a[0][i], b[0][i]) for i in range(3)]
    hi = [min(a[1][i], b[1][i]) for i in range(3)]
    return volume((lo, hi)) if all(hi[i] > lo[i] for i in range(3)) else 0.0


def iou(a, b):
    i = intersection(a, b)
    return i / (volume(a) + volume(b) - i) if i > 0 else 0.0


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    out, gt = sys.argv[1], sys.argv[2]
    job = json.load(open(os.path.join(out, "job.json")))
    truth = json.load(open(os.path.join(gt, "building.json")))
    true_all = [t for t in truth["objects"] if "aabb" in t]
    big = [t for t in true_all
           if min(t["aabb"][1][i] - t["aabb"][0][i] for i in range(3)) >= 0.3]
    found = [o["aabb"] for o in job.get("objects", [])]
    pairs = sorted(((iou(t["aabb"], f), ti, fi) for ti, t in enumerate(big)
                    for fi, f in enumerate(found)), reverse=True)
    t_used, f_used = set(), set()
    for u, ti, fi in pairs:
        if u < 0.5:
            break
        if ti in t_used or fi in f_used:
            continue
        t_used.add(ti)
        f_used.add(fi)
    false = sum(1 for f in found
                if max((intersection(t["aabb"], f) / volume(f) for t in true_all), default=0) < 0.1)
    print(f"true objects (all sides >= 0.3 m) {len(big)}, found {len(t_used)} "
          f"({100 * len(t_used) / max(1, len(big)):.0f} %); reported {len(found)}, false {false} "
          f"({100 * false / max(1, len(found)):.0f} %)")
    kinds = {}
    for ti, t in enumerate(big):
        k = kinds.setdefault(t.get("kind", "?"), [0, 0])
        k[0] += 1
        k[1] += ti in t_used
    for kind, (n, f) in sorted(kinds.items()):
        print(f"  {kind}: {f} of {n}")


if __name__ == "__main__":
    main()
