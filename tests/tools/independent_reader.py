#!/usr/bin/env python3
"""An independent reader of carvemap's input and ground-truth contracts.

Written from docs/DESIGN.md §3 (scan.h5) and §4 (gt/) alone, with h5py and numpy, sharing
no code with the C++ reader: if both agree, the files follow the written contract and not just
our own reading of it.

  independent_reader.py --scan OUT/scan.h5 --gt OUT/gt [--on-surface-mm 1.0] [--sample 3000]

--on-surface-mm checks that returned points, placed in the world with the interpolated /path
(linear position, SLERP orientation) and the sensor extrinsics, lie on gt/surfaces.ply ∪
gt/objects.ply within that distance (only meaningful for a noiseless simulation).
Exit 0 when everything holds; otherwise prints each violation and exits 1.
"""
import argparse
import json
import os
import struct
import sys

import h5py
import numpy as np

errors = []


def fail(msg):
    errors.append(msg)
    print("FAIL:", msg)


def attr_str(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.ndarray) and v.shape == ():
        v = v[()]
        return v.decode() if isinstance(v, bytes) else str(v)
    return str(v)


def quat_to_rot(q):
    """Rotation matrices from (N, 4) quaternions w, x, y, z."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def slerp(q0, q1, u):
    d = np.sum(q0 * q1, axis=-1)
    q1 = np.where(d[:, None] < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1, 1))
    s = np.sin(theta)
    small = s < 1e-9
    a = np.where(small, 1 - u, np.sin((1 - u) * theta) / np.where(small, 1, s))
    b = np.where(small, u, np.sin(u * theta) / np.where(small, 1, s))
    q = a[:, None] * q0 + b[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def pose_at(path, t):
    """Interpolated (R (N,3,3), p (N,3)) at times t (N,), clamped to the path's ends (§2.4)."""
    pt = path["t"]
    if len(pt) == 1:
        path = np.concatenate([path, path])
        pt = np.array([pt[0], pt[0] + 1.0])
    t = np.clip(t, pt[0], pt[-1])
    i = np.clip(np.searchsorted(pt, t, side="right") - 1, 0, len(pt) - 2)
    dt = pt[i + 1] - pt[i]
    u = np.where(dt > 0, (t - pt[i]) / np.where(dt > 0, dt, 1), 0.0)
    P = np.stack([path["x"], path["y"], path["z"]], 1)
    Q = np.stack([path["qw"], path["qx"], path["qy"], path["qz"]], 1)
    p = (1 - u)[:, None] * P[i] + u[:, None] * P[i + 1]
    q = slerp(Q[i], Q[i + 1], u)
    return quat_to_rot(q), p


def check_scan(fname, want_world_points):
    f = h5py.File(fname, "r")
    if attr_str(f.attrs.get("format", b"")) != "carvemap-scan":
        fail(f"{fname}: root attr format is {f.attrs.get('format')!r}")
    ver = f.attrs.get("version")
    if ver is None or not np.issubdtype(np.asarray(ver).dtype, np.integer) or int(ver) != 1:
        fail(f"{fname}: root attr version is {ver!r}, want integer 1")
    path = f["path"][...]
    for name in ("t", "x", "y", "z", "qw", "qx", "qy", "qz"):
        if name not in path.dtype.names:
            fail(f"/path lacks field {name}")
        elif path.dtype[name] != np.float64:
            fail(f"/path field {name} is {path.dtype[name]}, want f64")
    n = len(path)
    if n < 1:
        fail("/path is empty")
    if not np.all(np.diff(path["t"]) > 0):
        fail("/path t not strictly ascending")
    qn = np.sqrt(path["qw"] ** 2 + path["qx"] ** 2 + path["qy"] ** 2 + path["qz"] ** 2)
    if np.max(np.abs(qn - 1)) > 1e-3:  # DESIGN §3: |q| within 1e-3 of 1
        fail(f"/path quaternions not unit (max |norm-1| {np.max(np.abs(qn - 1))})")
    if "path_cov" in f:
        c = f["path_cov"]
        if c.dtype != np.float32 or c.shape != (n, 12):
            fail(f"/path_cov is {c.dtype}{c.shape}, want float32 ({n}, 12)")
        cv = c[...]
        diag = cv[:, [0, 3, 5, 6, 9, 11]]
        if not np.all(np.isfinite(cv)) or np.any(diag < 0):  # DESIGN §3: not negative
            fail("/path_cov has non-finite values or negative variances")
    if "magnetometer" in f:
        m = f["magnetometer"][...]
        for name in ("t", "mx", "my", "mz"):
            if name not in m.dtype.names:
                fail(f"/magnetometer lacks field {name}")
    sensors = f["sensors"]
    if len(sensors) == 0:
        fail("/sensors is empty")
    world = []
    summary = {}
    for name, g in sensors.items():
        kind = attr_str(g.attrs["kind"])
        if kind not in ("line", "grid", "points"):
            fail(f"/sensors/{name}: kind {kind!r}")
        R = np.asarray(g.attrs["R_s2c"], dtype=np.float64)
        T = np.asarray(g.attrs["T_s2c"], dtype=np.float64)
        if R.shape != (9,) or T.shape != (3,):
            fail(f"/sensors/{name}: R_s2c {R.shape} / T_s2c {T.shape}")
            continue
        R = R.reshape(3, 3)  # row-major
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1) > 1e-6:
            fail(f"/sensors/{name}: R_s2c is not a rotation")
        for a, shape in (("sigma_t", ()), ("range_sigma", (2,)), ("max_range", ())):
            v = np.asarray(g.attrs[a])
            if v.shape not in (shape, (1,) if shape == () else shape):
                fail(f"/sensors/{name}: attr {a} shape {v.shape}")
        sigmas = np.concatenate([np.asarray(g.attrs[a], dtype=np.float64).reshape(-1)
                                 for a in ("sigma_t", "range_sigma")])
        max_range = float(np.asarray(g.attrs["max_range"]).reshape(-1)[0])
        # DESIGN §3: finite mounting and noise, sigmas not negative, max_range > 0.
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T)) and np.all(np.isfinite(sigmas))):
            fail(f"/sensors/{name}: non-finite mounting or noise parameters")
        if np.any(sigmas < 0) or not max_range > 0:
            fail(f"/sensors/{name}: negative sigma_t/range_sigma or max_range {max_range} <= 0")
        frames = g["frames"][...]
        for fn, dt in (("t", np.float64), ("first", np.uint64), ("count", np.uint32)):
            if fn not in frames.dtype.names or frames.dtype[fn] != dt:
                fail(f"/sensors/{name}/frames field {fn}: want {np.dtype(dt)}")
        pts = g["points"]
        if pts.dtype != np.float32 or len(pts.shape) != 2 or pts.shape[1] != 3:
            fail(f"/sensors/{name}/points is {pts.dtype}{pts.shape}, want float32 (M, 3)")
            continue
        M = pts.shape[0]
        if np.any(frames["first"].astype(np.int64) + frames["count"] > M):
            fail(f"/sensors/{name}/frames reach past /points ({M} rows)")
        if not np.all(np.diff(frames["t"]) > 0):
            fail(f"/sensors/{name}/frames t not strictly ascending")
        if len(frames) and (frames["t"][0] < path["t"][0] or frames["t"][-1] > path["t"][-1]):
            fail(f"/sensors/{name}/frames outside the path's time span")
        if kind == "grid":
            rows, cols = int(g.attrs["rows"]), int(g.attrs["cols"])
            if np.any(frames["count"] != rows * cols):
                fail(f"/sensors/{name}: grid frames not rows*cols")
        # Read a bounded sample of frames, never the whole /points.
        step = max(1, len(frames) // 200)
        hits = nan = 0
        for k in range(0, len(frames), step):
            fr = frames[k]
            p = pts[int(fr["first"]):int(fr["first"]) + int(fr["count"])]
            isnan = np.isnan(p)
            partial = isnan.any(1) & ~isnan.all(1)
            if partial.any():
                fail(f"/sensors/{name}/points: rows with some NaN in frame {k}")
            ok = ~isnan.any(1)
            rng = np.linalg.norm(p[ok], axis=1)
            if np.any(rng > max_range + 0.5):
                fail(f"/sensors/{name}: returns beyond max_range in frame {k}")
            hits += ok.sum()
            nan += (~ok).sum()
            if want_world_points and ok.any():
                Rw, pw = pose_at(path, np.array([fr["t"]]))
                xs = p[ok].astype(np.float64) @ R.T + T      # sensor ➜ system
                xw = xs @ Rw[0].T + pw[0]                     # system ➜ world
                world.append(xw)
        summary[name] = dict(kind=kind, frames=len(frames), points=M, sampled_hits=int(hits),
                             sampled_no_return=int(nan))
    f.close()
    return summary, (np.concatenate(world) if world else np.zeros((0, 3)))


def read_ply(fname):
    with open(fname, "rb") as fh:
        header = []
        while True:
            line = fh.readline()
            if not line:
                fail(f"{fname}: no end_header")
                return None, None
            line = line.decode("ascii").rstrip("\n")
            header.append(line)
            if line == "end_header":
                break
        body = fh.read()
    if header[0] != "ply" or header[1] != "format binary_little_endian 1.0":
        fail(f"{fname}: header starts {header[:2]}")
    elements, cur = [], None
    for line in header[2:]:
        w = line.split()
        if w[0] == "element":
            cur = [w[1], int(w[2]), []]
            elements.append(cur)
        elif w[0] == "property":
            cur[2].append(w[1:])
    names = [e[0] for e in elements]
    if names[:2] != ["vertex", "face"]:
        fail(f"{fname}: elements {names}")
        return None, None
    if [p for p in elements[0][2]] != [["float", "x"], ["float", "y"], ["float", "z"]]:
        fail(f"{fname}: vertex properties {elements[0][2]}")
    if elements[1][2][0] != ["list", "uchar", "int", "vertex_indices"]:
        fail(f"{fname}: face properties {elements[1][2]}")
    nv, nf = elements[0][1], elements[1][1]
    V = np.frombuffer(body, dtype="<f4", count=3 * nv).reshape(nv, 3)
    extra = elements[1][2][1:]
    sizes = {"int": 4, "uint": 4, "float": 4, "int32": 4, "uchar": 1, "short": 2}
    rec = np.dtype([("n", "u1"), ("v", "<i4", (3,))] +
                   [(p[1], {"int": "<i4", "int32": "<i4", "uint": "<u4", "float": "<f4",
                            "uchar": "u1", "short": "<i2"}[p[0]]) for p in extra])
    off = 12 * nv
    if len(body) != off + nf * rec.itemsize:
        fail(f"{fname}: body is {len(body)} bytes, want {off + nf * rec.itemsize}")
        return V, None
    F = np.frombuffer(body, dtype=rec, count=nf, offset=off)
    if np.any(F["n"] != 3):
        fail(f"{fname}: non-triangle faces")
    if F["v"].min() < 0 or F["v"].max() >= nv:
        fail(f"{fname}: face index out of range")
    return V, F["v"]


def ring_area(ring):
    r = np.asarray(ring, dtype=np.float64)
    x, y = r[:, 0], r[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def check_gt(gt):
    b = json.load(open(os.path.join(gt, "building.json")))
    for k in ("levels", "rooms", "doors", "objects"):
        if k not in b:
            fail(f"building.json lacks {k}")
            return {}
    levels = {}
    for lv in b["levels"]:
        for k in ("index", "floor_z", "ceiling_z"):
            if k not in lv:
                fail(f"level lacks {k}")
        levels[lv["index"]] = lv
        if not lv["ceiling_z"] > lv["floor_z"]:
            fail(f"level {lv['index']}: ceiling not above floor")
    for r in b["rooms"]:
        for k in ("id", "level", "polygon", "floor_z", "ceiling_z", "entered"):
            if k not in r:
                fail(f"room lacks {k}: {list(r)}")
                continue
        poly = r["polygon"]
        if len(poly) < 3 or poly[0] == poly[-1]:
            fail(f"room {r['id']}: polygon has <3 points or repeats its first point")
        a = ring_area(poly)
        if not a > 0:
            fail(f"room {r['id']}: polygon not counter-clockwise or zero area ({a})")
        for h in r.get("holes", []):
            if ring_area(h) >= 0:
                fail(f"room {r['id']}: hole not clockwise")
        if r["level"] not in levels:
            fail(f"room {r['id']}: unknown level {r['level']}")
        elif not (levels[r["level"]]["floor_z"] - 1e-6 <= r["floor_z"] < r["ceiling_z"]
                  <= levels[r["level"]]["ceiling_z"] + 1e-6):
            fail(f"room {r['id']}: heights outside its level")
        if not isinstance(r["entered"], bool):
            fail(f"room {r['id']}: entered is not a bool")
    for d in b["doors"]:
        for k in ("id", "level", "rooms", "segment", "width"):
            if k not in d:
                fail(f"door lacks {k}")
        if len(d.get("rooms", [])) != 2 or len(d.get("segment", [])) != 2:
            fail(f"door {d.get('id')}: rooms/segment not pairs")
    for o in b["objects"]:
        for k in ("id", "kind", "level"):
            if k not in o:
                fail(f"object lacks {k}")
        if "aabb" in o:
            lo, hi = np.asarray(o["aabb"][0]), np.asarray(o["aabb"][1])
            if lo.shape != (3,) or hi.shape != (3,) or np.any(lo >= hi):
                fail(f"object {o['id']}: bad aabb {o['aabb']}")
        elif "mesh" not in o:
            fail(f"object {o['id']}: neither aabb nor mesh")
    meshes = {}
    for name in ("surfaces.ply", "objects.ply"):
        V, F = read_ply(os.path.join(gt, name))
        meshes[name] = (V, F)
    return dict(levels=len(b["levels"]), rooms=len(b["rooms"]),
                entered=sum(1 for r in b["rooms"] if r["entered"]),
                doors=len(b["doors"]), objects=len(b["objects"])), meshes


def point_triangle_distance(P, A, B, C):
    """Distance from each point in P (n,3) to each triangle (m,3) -> (n, m). Ericson §5.1.5."""
    P = P[:, None, :]
    ab, ac, ap = B - A, C - A, P - A
    d1, d2 = np.sum(ab * ap, -1), np.sum(ac * ap, -1)
    bp = P - B
    d3, d4 = np.sum(ab * bp, -1), np.sum(ac * bp, -1)
    cp = P - C
    d5, d6 = np.sum(ab * cp, -1), np.sum(ac * cp, -1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = vb / denom
        w = vc / denom
    closest = A + ab * v[..., None] + ac * w[..., None]
    # Vertex and edge regions.
    def seg(X, Y):
        xy = Y - X
        t = np.clip(np.sum((P - X) * xy, -1) / np.maximum(np.sum(xy * xy, -1), 1e-30), 0, 1)
        return X + xy * t[..., None]
    outside = (va < 0) | (vb < 0) | (vc < 0) | ~np.isfinite(v) | ~np.isfinite(w)
    cands = [seg(A, B), seg(B, C), seg(C, A)]
    dist_edges = np.min(np.stack([np.linalg.norm(P - c, axis=-1) for c in cands]), 0)
    dist_face = np.linalg.norm(P - closest, axis=-1)
    return np.where(outside, dist_edges, np.minimum(dist_face, dist_edges))


def check_on_surface(points, meshes, tol_mm, sample, seed=7):
    V = np.concatenate([meshes["surfaces.ply"][0], meshes["objects.ply"][0]]).astype(np.float64)
    F = np.concatenate([meshes["surfaces.ply"][1],
                        meshes["objects.ply"][1] + len(meshes["surfaces.ply"][0])])
    rng = np.random.default_rng(seed)
    if len(points) > sample:
        points = points[rng.choice(len(points), sample, replace=False)]
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    best = np.full(len(points), np.inf)
    for s in range(0, len(points), 64):
        P = points[s:s + 64]
        # Only triangles whose bounding box is near the points' box matter.
        lo, hi = P.min(0) - 0.05, P.max(0) + 0.05
        tmin = np.minimum(np.minimum(A, B), C)
        tmax = np.maximum(np.maximum(A, B), C)
        keep = np.all((tmax >= lo) & (tmin <= hi), axis=1)
        if not keep.any():
            continue
        d = point_triangle_distance(P, A[keep], B[keep], C[keep])
        best[s:s + 64] = d.min(1)
    worst = float(np.max(best)) * 1000 if len(best) else 0.0
    if worst > tol_mm:
        bad = int(np.sum(best * 1000 > tol_mm))
        fail(f"{bad} of {len(best)} world points lie farther than {tol_mm} mm from the truth "
             f"(worst {worst:.2f} mm)")
    return len(best), worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scan", required=True)
    ap.add_argument("--gt", help="gt/ folder to check too (simulator output)")
    ap.add_argument("--on-surface-mm", type=float, default=None)
    ap.add_argument("--sample", type=int, default=3000)
    ap.add_argument("--min-rooms", type=int, default=1)
    ap.add_argument("--min-levels", type=int, default=1)
    a = ap.parse_args()
    summary, world = check_scan(a.scan, a.on_surface_mm is not None)
    print("scan:", json.dumps(summary))
    gts, meshes = check_gt(a.gt) if a.gt else ({}, {})
    if a.gt:
        print("gt:", json.dumps(gts))
    if gts and gts["rooms"] < a.min_rooms:
        fail(f"{gts['rooms']} rooms, want >= {a.min_rooms}")
    if gts and gts["levels"] < a.min_levels:
        fail(f"{gts['levels']} levels, want >= {a.min_levels}")
    if a.on_surface_mm is not None and meshes:
        n, worst = check_on_surface(world, meshes, a.on_surface_mm, a.sample)
        print(f"on-surface: {n} points, worst {worst:.3f} mm")
    if errors:
        print(f"{len(errors)} violations")
        sys.exit(1)
    print("independent reader: all checks hold")


if __name__ == "__main__":
    main()
