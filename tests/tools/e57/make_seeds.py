#!/usr/bin/env python3
"""Writes the fuzz seeds of tests/fuzz/corpus/e57_import/: the fixtures' three encodings
(make_e57.py) at a size a fuzzer mutates quickly: grids of 6 x 10 pixels, 40 unstructured
directions, packets of a few records so that values still run across packets."""
import os
import sys

import make_e57 as e

out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
    os.path.dirname(os.path.abspath(__file__)), "..", "..", "fuzz", "corpus", "e57_import")
os.makedirs(out, exist_ok=True)
e.GRIDS = {k: (6, 10) for k in e.GRIDS}
e.UNSTRUCTURED_RAYS = 40
e.random_directions.__defaults__ = (40,)  # its default was bound at definition
for name, (make_entry, setups) in e.GOOD_FILES.items():
    scans = [make_entry(name, s) for s in setups[:2]]
    for s in scans:
        s["recs_per_packet"] = 7
    e.write_e57(os.path.join(out, "small_" + name), e.file_guid(name), scans)
