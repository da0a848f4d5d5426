#!/usr/bin/env python3
"""Checks a finished job's rooms (job.json) against a known box room: the number of rooms,
each one's area, floor and ceiling heights within tolerances. Used on jobs whose input came
through an importer (tests/CMakeLists.txt), where the truth is the fixture's geometry."""
import argparse
import json
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--job", required=True, help="the job's job.json")
    ap.add_argument("--rooms", type=int, required=True, help="rooms expected")
    ap.add_argument("--area", type=float, required=True, help="each room's true area, m²")
    ap.add_argument("--area-tol", type=float, default=0.5, help="m²")
    ap.add_argument("--floor", type=float, required=True, help="true floor z, m")
    ap.add_argument("--ceiling", type=float, required=True, help="true ceiling z, m")
    ap.add_argument("--height-tol", type=float, default=0.05, help="m")
    args = ap.parse_args()
    with open(args.job) as f:
        job = json.load(f)
    if job.get("state") not in (None, "SUCCEEDED"):
        sys.exit(f"{args.job}: state {job.get('state')}")
    rooms = job.get("rooms", [])
    failures = []
    if len(rooms) != args.rooms:
        failures.append(f"{len(rooms)} rooms, expected {args.rooms}")
    for r in rooms:
        if abs(r["area_m2"] - args.area) > args.area_tol:
            failures.append(f"room {r['room']}: area {r['area_m2']:.3f} m², true {args.area}")
        if abs(r["floor_z"] - args.floor) > args.height_tol:
            failures.append(f"room {r['room']}: floor {r['floor_z']:.3f} m, true {args.floor}")
        if abs(r["ceiling_z"] - args.ceiling) > args.height_tol:
            failures.append(f"room {r['room']}: ceiling {r['ceiling_z']:.3f} m, true {args.ceiling}")
    for r in rooms:
        print(f"room {r['room']}: {r['area_m2']:.3f} m², floor {r['floor_z']:.3f} m, "
              f"ceiling {r['ceiling_z']:.3f} m")
    if failures:
        sys.exit(f"{args.job}: " + "; ".join(failures))
    print("rooms as true")


if __name__ == "__main__":
    main()
