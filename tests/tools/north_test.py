#!/usr/bin/env python3
"""§2.3 end to end: a scan recorded in a turned frame comes out north-up.

The simulator records the same walk twice, once in the building's frame (north-up) and once
in a frame turned 37° about the vertical (`--frame-yaw-deg 37`, a localizer that starts from
its first heading). Then:
- `carvemap run` on the turned scan: job.json's "north" turned the outputs by -37° within 1°,
  and building.ply and levels.json lie where the north-up scan's do (bounding box within
  0.75 m: the 1° the fit may miss by, over the office's 33 m, plus a leaf or two; an
  unturned 37° would be metres off), floor and ceiling within 5 cm, every mesh watertight
  (check_outputs.py);
- on the north-up scan the fit is under a degree, so nothing is turned: `carvemap carve` with
  the default and with `--north none` writes the same tiles, byte for byte;
- `carvemap merge` of the turned scan's carve reads the turn from north.json, and refuses a
  `--north none` that contradicts it, naming both turns;
- true north: `carve --location` in Reykjavík turns by the magnetic fit less the declination
  there (WMM2025, ~-10°); `run` refuses a location that is not one before any work.

Usage: north_test.py --carvemap BIN --work DIR
"""
import argparse
import filecmp
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from check_outputs import read_ply  # noqa: E402
from cluster_harness import TestFailure, fresh_dir, log  # noqa: E402

TOOLS = os.path.dirname(os.path.abspath(__file__))


def expect(cond, what):
    if not cond:
        raise TestFailure(what)


def run(args, ok=True):
    r = subprocess.run(args, capture_output=True, text=True)
    if ok and r.returncode != 0:
        raise TestFailure(f"{' '.join(args)}: exit {r.returncode}\n{r.stdout}{r.stderr}")
    return r


def simulate(carvemap, out, yaw):
    run([carvemap, "simulate", "--preset", "office", "--seed", "3", "--rate-hz", "5",
         "--beam-step-deg", "2", "--max-duration", "60", "--frame-yaw-deg", str(yaw), "-q",
         "-o", out])
    return os.path.join(out, "scan.h5")


def bbox(out):
    vertices = read_ply(os.path.join(out, "mesh", "building.ply"))[0]
    return np.asarray(vertices).min(0), np.asarray(vertices).max(0)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True)
    args = p.parse_args()
    start = time.monotonic()
    work = fresh_dir(os.path.abspath(args.work))
    cm = args.carvemap
    try:
        plain = simulate(cm, os.path.join(work, "S0"), 0)
        turned = simulate(cm, os.path.join(work, "S37"), 37)

        # The service's route.
        outs = {}
        for name, scan in (("O0", plain), ("O37", turned)):
            outs[name] = os.path.join(work, name)
            run([cm, "run", scan, "-o", outs[name], "--workers", "2", "-q"])
        with open(os.path.join(outs["O37"], "job.json")) as f:
            north = json.load(f)["north"]
        log(f"run on the turned scan: north {json.dumps(north)}")
        expect(north["turned"] and abs(north["yaw_deg"] + 37) < 1.0,
               f"the turned scan's outputs were not turned back by -37° ± 1°: {north}")
        with open(os.path.join(outs["O0"], "job.json")) as f:
            north0 = json.load(f)["north"]
        expect(not north0["turned"] and abs(north0["fit"]["yaw_deg"]) < 1.0,
               f"the north-up scan's outputs were turned: {north0}")
        lo0, hi0 = bbox(outs["O0"])
        lo, hi = bbox(outs["O37"])
        log(f"building.ply bounds: north-up {np.round(lo0, 2)}..{np.round(hi0, 2)}, "
            f"turned back {np.round(lo, 2)}..{np.round(hi, 2)}")
        expect(np.abs(lo - lo0).max() < 0.75 and np.abs(hi - hi0).max() < 0.75,
               "building.ply of the turned scan does not lie where the north-up one does")
        levels = [json.load(open(os.path.join(o, "levels.json"))) for o in (outs["O0"], outs["O37"])]
        expect(len(levels[0]) == len(levels[1]), f"levels differ: {levels}")
        for a, b in zip(*levels):
            expect(abs(a["floor_z"] - b["floor_z"]) < 0.05 and
                   abs(a["ceiling_z"] - b["ceiling_z"]) < 0.05, f"levels differ: {a} {b}")
        run([sys.executable, os.path.join(TOOLS, "check_outputs.py"), outs["O37"], "--gt",
             os.path.join(work, "S37", "gt")])

        # Nothing turned: the tiles are the scan frame's, bit for bit.
        c_auto, c_none = os.path.join(work, "C0"), os.path.join(work, "C0none")
        run([cm, "carve", plain, "-o", c_auto, "-q"])
        run([cm, "carve", plain, "-o", c_none, "--north", "none", "-q"])
        tiles = sorted(os.listdir(os.path.join(c_auto, "tiles")))
        expect(tiles == sorted(os.listdir(os.path.join(c_none, "tiles"))) and tiles,
               "carve --north none made other tiles")
        match, mismatch, errors = filecmp.cmpfiles(os.path.join(c_auto, "tiles"),
                                                   os.path.join(c_none, "tiles"), tiles,
                                                   shallow=False)
        expect(not mismatch and not errors, f"tiles differ with --north none: {mismatch}")
        log(f"carve of the north-up scan: {len(match)} tiles identical with and without "
            "--north none")

        # The carve's turn reaches the merge; a contradicting --north is refused.
        c37 = os.path.join(work, "C37")
        run([cm, "carve", turned, "-o", c37, "-q"])
        with open(os.path.join(c37, "north.json")) as f:
            recorded = json.load(f)
        expect(recorded["turned"] and abs(recorded["yaw_deg"] + 37) < 1.0, f"{recorded}")
        m37 = os.path.join(work, "M37")
        run([cm, "merge", os.path.join(c37, "tiles"), "--scan", turned, "-o", m37, "-q"])
        with open(os.path.join(m37, "job.json")) as f:
            merged = json.load(f)
        expect(merged["north"]["yaw_rad"] == recorded["yaw_rad"], f"{merged['north']}")
        r = run([cm, "merge", os.path.join(c37, "tiles"), "--scan", turned, "--north", "none",
                 "-o", os.path.join(work, "M37none"), "-q"], ok=False)
        expect(r.returncode != 0 and "north.json" in r.stderr and "--north none" in r.stderr,
               f"merge --north none against a turned carve: exit {r.returncode}: {r.stderr}")
        log(f"merge refuses a contradicting --north: {r.stderr.strip().splitlines()[-1]}")

        # True north.
        c37t = os.path.join(work, "C37true")
        run([cm, "carve", turned, "-o", c37t, "--location", "64.15,-21.94", "--survey-date",
             "2026-06-01", "-q"])
        with open(os.path.join(c37t, "north.json")) as f:
            true_north = json.load(f)
        d = true_north["place"]["declination_deg"]
        expect(true_north["reference"] == "true north" and -20 < d < -5 and
               abs(true_north["yaw_deg"] - (recorded["yaw_deg"] - d)) < 1e-3,
               f"true north: {true_north}")
        log(f"true north at Reykjavík: declination {d:.2f}°, turn {true_north['yaw_deg']:.2f}°")
        r = run([cm, "run", plain, "-o", os.path.join(work, "Obad"), "--location", "91,0", "-q"],
                ok=False)
        expect(r.returncode != 0 and "location '91,0'" in r.stderr,
               f"run --location 91,0: exit {r.returncode}: {r.stderr}")
    except TestFailure as e:
        print(f"FAIL: {e}")
        return 1
    log(f"north: passed in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
