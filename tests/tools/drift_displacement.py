#!/usr/bin/env python3
"""How far localization drift alone moves a scan's returns: each return placed with the
recorded (drifted) /path and with the exact one, and the distance between the two places.

A carve (or any map) built from the recorded path cannot put a surface nearer the truth than its
returns are, so this bounds what an accuracy test against ground truth can ask of a drifting
scan (docs/BENCHMARKS.md, carving section).

Usage: drift_displacement.py DRIFTED_SCAN.h5 EXACT_SCAN.h5 [--voxel 0.0625]
  The two scans are one simulated walk (same preset, seed, rate and beams) written with and
  without drift: `carvemap simulate ... -o D` and `carvemap simulate ... --no-drift -o N`.
  The returns are DRIFTED_SCAN's; the exact path is EXACT_SCAN's /path.
"""
import argparse
import sys

import h5py
import numpy as np


def rotations(q):
    """Rotation matrices of unit quaternions q[:, (w, x, y, z)]."""
    w, x, y, z = q.T
    r = np.empty((len(q), 3, 3))
    r[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1)
    r[:, 1] = np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1)
    r[:, 2] = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)
    return r


def poses_at(path, t):
    """docs/DESIGN.md §3: position linear, orientation SLERP between the poses around each t.
    Poses are milliseconds apart, so a normalised linear blend of the quaternions is SLERP to
    ~1e-9 rad."""
    times = path["t"]
    i = np.clip(np.searchsorted(times, t) - 1, 0, len(times) - 2)
    a = ((t - times[i]) / (times[i + 1] - times[i]))[:, None]
    pos = np.stack([path["x"], path["y"], path["z"]], 1)
    q = np.stack([path["qw"], path["qx"], path["qy"], path["qz"]], 1)
    q0, q1 = q[i], q[i + 1]
    q1 = np.where(((q0 * q1).sum(1) < 0)[:, None], -q1, q1)
    qq = q0 * (1 - a) + q1 * a
    qq /= np.linalg.norm(qq, axis=1)[:, None]
    return pos[i] * (1 - a) + pos[i + 1] * a, rotations(qq)


def placed_returns(drifted, exact):
    """Every return of the open scan `drifted` placed with `exact`'s /path and with its own
    recorded one: two (n, 3) arrays."""
    est, true = drifted["/path"][:], exact["/path"][:]
    if len(est) != len(true) or np.abs(est["t"] - true["t"]).max() > 1e-9:
        sys.exit(f"{drifted.filename} and {exact.filename}: the paths' times differ; not one walk")
    xs, xr = [], []
    for name, sensor in drifted["/sensors"].items():
        r_s2c = np.asarray(sensor.attrs["R_s2c"], float).reshape(3, 3)
        t_s2c = np.asarray(sensor.attrs["T_s2c"], float)
        frames, points = sensor["frames"][:], sensor["points"][:]
        t = np.repeat(frames["t"], frames["count"].astype(np.int64))
        if len(t) != len(points):
            sys.exit(f"{drifted.filename}: /sensors/{name}: frames count {len(t)} rays, points has "
                     f"{len(points)}")
        ok = np.isfinite(points).all(1)
        q = points[ok].astype(float) @ r_s2c.T + t_s2c  # in the system frame
        for path, out in ((true, xs), (est, xr)):
            c, r = poses_at(path, t[ok])
            out.append(np.einsum("nij,nj->ni", r, q) + c)
    return np.concatenate(xs), np.concatenate(xr)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("drifted")
    ap.add_argument("exact")
    ap.add_argument("--voxel", type=float, default=0.0625, help="leaf size to report against, m")
    args = ap.parse_args()
    x_exact, x_recorded = placed_returns(h5py.File(args.drifted, "r"), h5py.File(args.exact, "r"))
    d = np.linalg.norm(x_recorded - x_exact, axis=1)
    v = args.voxel
    print(f"{len(d)} returns: displacement median {100 * np.median(d):.1f} cm, p90 "
          f"{100 * np.percentile(d, 90):.1f} cm, max {100 * d.max():.1f} cm; within {100 * v / 2:.2f} cm "
          f"{100 * (d <= v / 2).mean():.1f} %, within {100 * v:.2f} cm {100 * (d <= v).mean():.1f} %, "
          f"within {200 * v:.2f} cm {100 * (d <= 2 * v).mean():.1f} %")


if __name__ == "__main__":
    main()
