#!/usr/bin/env python3
"""Writes a large E57 of the fixtures' room for benchmarks (tests/bench/e57_bench.sh): the
three setups of make_e57.py as structured scans of ROWS x COLS pixels each, Cartesian scaled
integers as in room_scaled.e57, packets of 2,500 records.

usage: make_large.py OUT.e57 ROWS COLS"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import make_e57 as e  # noqa: E402

if len(sys.argv) != 4:
    sys.exit(__doc__)
out, rows, cols = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
e.GRIDS = {k: (rows, cols) for k in e.GRIDS}
scans = [e.scaled_scan_entry("room_scaled.e57", s) for s in "ABC"]
for s in scans:
    s["recs_per_packet"] = 2500
e.write_e57(out, e.file_guid(f"large_{rows}x{cols}"), scans)
