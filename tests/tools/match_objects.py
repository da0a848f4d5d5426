#!/usr/bin/env python3
"""The object score of a finished job against the simulator's truth, by hand.

The same matching as services/merge/object_segmentation_test.cc: true objects with all sides
>= 0.3 m are found when a reported object (job.json "objects") has box IoU >= 0.5 with them,
one to one, greedy by IoU; a reported object is false when it overlaps no true object (any
size) by >= 10 % of its own box. Prints found and false, and found per kind. It also prints
how many reported objects overlap no true object at all, issue 27's own definition of false:
the 10 % rule is stricter where a reported object is a cluster of small true ones (a floor
map's scattered furniture pixels grouped into one object under drift).

It also prints issue 27's other object goals:
  - against a wall: for each true object whose footprint comes within 10 cm of a wall (an edge
    of a room's polygon), the reported object that overlaps it most, and how much taller its
    box is than the truth (goal: none more than 0.3 m);
  - mesh/objects.ply: its closed components (triangles joined through shared vertices) per
    reported object (goal: at most 3 on average), and its triangles against mesh/dense.ply's.

Usage: match_objects.py OUT_DIR GT_DIR
"""
import json
import os
import sys

import numpy as np

from check_outputs import read_ply

WALL_GAP = 0.10


def volume(b):
    return max(0.0, b[1][0] - b[0][0]) * max(0.0, b[1][1] - b[0][1]) * max(0.0, b[1][2] - b[0][2])


def intersection(a, b):
    lo = [max(a[0][i], b[0][i]) for i in range(3)]
    hi = [min(a[1][i], b[1][i]) for i in range(3)]
    return volume((lo, hi)) if all(hi[i] > lo[i] for i in range(3)) else 0.0


def iou(a, b):
    i = intersection(a, b)
    return i / (volume(a) + volume(b) - i) if i > 0 else 0.0


def segment_distance(p, a, b):
    """Distance from point p to segment ab (2D)."""
    ab = (b[0] - a[0], b[1] - a[1])
    n = ab[0] * ab[0] + ab[1] * ab[1]
    t = 0.0 if n == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / n))
    return ((p[0] - a[0] - t * ab[0]) ** 2 + (p[1] - a[1] - t * ab[1]) ** 2) ** 0.5


def near_wall(box, rooms):
    """Is the box's footprint within WALL_GAP of an edge of a room polygon on its level? The
    footprint's corners against each edge (walls end in corners, so a box near one is near
    a corner's edge too)."""
    (x0, y0, _), (x1, y1, _) = box
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    for room in rooms:
        ring = room["polygon"]
        for i in range(len(ring)):
            a, b = ring[i], ring[(i + 1) % len(ring)]
            if min(segment_distance(c, a, b) for c in corners) <= WALL_GAP:
                return True
    return False


def components(path):
    """Closed components and triangles of a triangle mesh: triangles joined through shared
    vertices (label propagation with pointer jumping; no graph library in the test tools'
    dependencies)."""
    _, tri = read_ply(path)
    if len(tri) == 0:
        return 0, 0
    label = np.arange(tri.max() + 1)
    while True:
        m = label[tri].min(axis=1)
        before = label.copy()
        for k in range(3):
            np.minimum.at(label, tri[:, k], m)
        while True:  # pointer jumping: a label points at a smaller one
            jumped = label[label]
            if (jumped == label).all():
                break
            label = jumped
        if (label == before).all():
            break
    return len(np.unique(label[tri[:, 0]])), len(tri)


def ply_faces(path):
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b"element face"):
                return int(line.split()[2])
            if line.startswith(b"end_header"):
                return 0
    return 0


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
    disjoint = sum(1 for f in found if all(intersection(t["aabb"], f) == 0 for t in true_all))
    print(f"true objects (all sides >= 0.3 m) {len(big)}, found {len(t_used)} "
          f"({100 * len(t_used) / max(1, len(big)):.0f} %); reported {len(found)}, false {false} "
          f"({100 * false / max(1, len(found)):.0f} %); overlapping no true object at all "
          f"{disjoint} ({100 * disjoint / max(1, len(found)):.0f} %)")
    kinds = {}
    for ti, t in enumerate(big):
        k = kinds.setdefault(t.get("kind", "?"), [0, 0])
        k[0] += 1
        k[1] += ti in t_used
    for kind, (n, f) in sorted(kinds.items()):
        print(f"  {kind}: {f} of {n}")

    against, taller = 0, []
    for t in true_all:
        rooms = [r for r in truth.get("rooms", []) if r.get("level", 0) == t.get("level", 0)]
        if not near_wall(t["aabb"], rooms):
            continue
        against += 1
        best = max(found, key=lambda f: intersection(t["aabb"], f), default=None)
        if best is None or intersection(t["aabb"], best) == 0:
            continue
        excess = (best[1][2] - best[0][2]) - (t["aabb"][1][2] - t["aabb"][0][2])
        if excess > 0.3:
            taller.append((t.get("kind", "?"), round(excess, 2)))
    print(f"against a wall: {against} true objects; reported more than 0.3 m taller: "
          f"{len(taller)} {sorted(taller)}")

    mesh = os.path.join(out, "mesh")
    if os.path.exists(os.path.join(mesh, "objects.ply")):
        c, triangles = components(os.path.join(mesh, "objects.ply"))
        n = len(found)
        print(f"objects.ply: {triangles} triangles (dense.ply "
              f"{ply_faces(os.path.join(mesh, 'dense.ply'))}), {c} closed components, "
              f"{c / max(1, n):.2f} per object")


if __name__ == "__main__":
    main()
