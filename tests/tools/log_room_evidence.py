#!/usr/bin/env python3
"""What a 2D laser log saw of the ground-truth rooms it is scored against (issue 25).

`carvemap floorplan --scan LOG.h5 -o OUT` writes OUT/occupancy.png, the grid it built from the
log's rays (254 free, 205 unknown, 0 occupied; job.json "params.origin" is its lower-left corner
in the log's frame). A truth room of a *_gt_segmentation.png map (SOURCES.md: 8-connected free
pixels) is given by a point in it, in the map's metre frame (x = col·0.05, y = (H−1−row)·0.05,
as `floorplan_score --rooms` prints the rooms' centres). For each room this prints:
  - its area, and the shares of it the grid saw free, occupied, or never (the drawn room mapped
    into the log's frame by the registration, the inverse of floorplan_score's --affine);
  - with --against X,Y: the drawn wall between it and the room holding X,Y (the map's non-free
    pixels within 4 pixels of both rooms), and the share of it with an occupied grid cell within
    --tolerance m (the registration is a similarity fitted to an idealized drawing, good to
    ~10 cm on about a third of the walls): a wall the laser saw through (glass, an open
    partition) scores low, and §3.3 cannot separate the two rooms there.

Usage: log_room_evidence.py GT_PNG OCCUPANCY_PNG JOB_JSON a11,a12,b1,a21,a22,b2 X,Y [X,Y ...]
           [--against X,Y] [--tolerance 0.2]
Needs numpy and PIL (python3-numpy, python3-pil).
"""
import argparse
import json
from collections import deque

import numpy as np
from PIL import Image

PX = 0.05  # the floor maps' metres per pixel


def room_mask(free, x, y):
    h, w = free.shape
    r0, c0 = int(round(h - 1 - y / PX)), int(round(x / PX))
    if not (0 <= r0 < h and 0 <= c0 < w and free[r0, c0]):
        raise SystemExit(f"({x}, {y}) is not in a free pixel of the map")
    seen = np.zeros_like(free)
    seen[r0, c0] = True
    q = deque([(r0, c0)])
    while q:
        r, c = q.popleft()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and free[rr, cc] and not seen[rr, cc]:
                    seen[rr, cc] = True
                    q.append((rr, cc))
    return seen


def grown(mask, k):
    out = mask.copy()
    for _ in range(k):
        n = out.copy()
        n[1:] |= out[:-1]
        n[:-1] |= out[1:]
        n[:, 1:] |= out[:, :-1]
        n[:, :-1] |= out[:, 1:]
        out = n
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("gt")
    ap.add_argument("occupancy")
    ap.add_argument("job")
    ap.add_argument("affine")
    ap.add_argument("rooms", nargs="+")
    ap.add_argument("--against")
    ap.add_argument("--tolerance", type=float, default=0.2)
    a = ap.parse_args()
    free = np.array(Image.open(a.gt).convert("L")) >= 250
    occ = np.array(Image.open(a.occupancy).convert("L"))
    ox, oy = json.load(open(a.job))["params"]["origin"]
    res = json.load(open(a.job))["params"]["resolution_m"]
    m = [float(v) for v in a.affine.split(",")]
    A, b = np.array([[m[0], m[1]], [m[3], m[4]]]), np.array([m[2], m[5]])
    h = free.shape[0]

    def grid_values(mask, k=0):
        """The grid cells under the mask's pixels, as (free, occupied, unknown) per pixel, an
        occupied cell within k cells counting as occupied."""
        rows, cols = np.nonzero(mask)
        xy = np.stack([(cols + 0.5) * PX, (h - 1 - rows + 0.5) * PX]) - b[:, None]
        xl = np.linalg.solve(A, xy)
        c = ((xl[0] - ox) / res).astype(int)
        r = (occ.shape[0] - 1 - (xl[1] - oy) / res).astype(int)
        at = lambda dr, dc: occ[np.clip(r + dr, 0, occ.shape[0] - 1), np.clip(c + dc, 0, occ.shape[1] - 1)]
        v = at(0, 0)
        occupied = np.zeros(len(c), bool)
        for dr in range(-k, k + 1):
            for dc in range(-k, k + 1):
                occupied |= at(dr, dc) < 100
        return v > 250, occupied, (v >= 100) & (v <= 250)

    other = room_mask(free, *map(float, a.against.split(","))) if a.against else None
    for spec in a.rooms:
        x, y = map(float, spec.split(","))
        room = room_mask(free, x, y)
        f, o, u = grid_values(room)
        line = (f"room at {x:.2f},{y:.2f}: {room.sum() * PX * PX:.1f} m2, seen free {f.mean():.2f}, "
                f"occupied {o.mean():.2f}, never {u.mean():.2f}")
        if other is not None:
            wall = ~free & grown(room, 4) & grown(other, 4)
            if wall.any():
                _, seen, _ = grid_values(wall, int(round(a.tolerance / res)))
                line += f"; wall to {a.against}: {wall.sum()} px, seen occupied {seen.mean():.2f}"
            else:
                line += f"; no drawn wall to {a.against}"
        print(line)


if __name__ == "__main__":
    main()
