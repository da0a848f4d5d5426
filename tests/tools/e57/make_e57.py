#!/usr/bin/python3
"""Writes the E57 test fixtures in tests/data/e57/ (our own minimal E57 writer).

Usage: /usr/bin/python3 make_e57.py [OUT_DIR]     (default: ../../data/e57 next to this file)
       /usr/bin/python3 make_e57.py --expected FILE.json
         writes, from the scene geometry alone (no E57 bytes involved), what a reader must
         find in each good fixture; check.mjs compares the fixtures against it.

The file has two halves:
  * the SCENE (constants, scanner setups, pixel directions, ray casting): check.py imports
    these functions to recompute the expected points independently of the written bytes;
  * the WRITER (CRC-32C pages, bit packing, data packets, XML): used only here.
Everything is deterministic: running it twice gives byte-identical files.
"""
import json
import math
import os
import sys
import uuid

import numpy as np

# --------------------------------------------------------------------------------------------
# SCENE
# --------------------------------------------------------------------------------------------
E0, N0, Z0 = 512000.0, 4181000.0, 100.0
ROOM = ((E0, N0, Z0), (E0 + 8.0, N0 + 6.0, Z0 + 3.0))            # file coordinates, min/max
PILLAR = ((E0 + 5.0, N0 + 2.0, Z0), (E0 + 5.4, N0 + 2.4, Z0 + 3.0))
# Window in the wall x = E0+8: rays ending there with y in [N0+1, N0+3], z in [Z0+1, Z0+2]
# give no return.
WINDOW_Y = (N0 + 1.0, N0 + 3.0)
WINDOW_Z = (Z0 + 1.0, Z0 + 2.0)

EL_MIN_DEG, EL_MAX_DEG = -60.0, 80.0
SCALE = 0.0001
UNSTRUCTURED_RAYS = 1500

# name, position (file coords), yaw deg (about z), roll deg (about x); R = Rz(yaw) * Rx(roll)
SETUPS = {
    "A": ((E0 + 2.0, N0 + 3.0, Z0 + 1.5), 0.0, 0.0),
    "B": ((E0 + 6.5, N0 + 1.0, Z0 + 1.6), 30.0, 2.0),
    "C": ((E0 + 3.5, N0 + 4.5, Z0 + 1.4), -100.0, 0.0),
}
GRIDS = {"A": (70, 160), "B": (70, 160), "C": (50, 120)}   # rows, cols


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2)


def pose_quaternion(setup):
    """Unit quaternion (w, x, y, z) of R = Rz(yaw) * Rx(roll), as written to the XML."""
    _, yaw, roll = SETUPS[setup]
    hy, hr = math.radians(yaw) / 2, math.radians(roll) / 2
    q = qmul((math.cos(hy), 0.0, 0.0, math.sin(hy)), (math.cos(hr), math.sin(hr), 0.0, 0.0))
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def grid_angles(rows, cols):
    """Per-pixel (row, col, azimuth, elevation). Angles are float32 values (they are what the
    spherical file stores as Float single), held in float64; every file uses these exact
    directions. Row 0 = elevation -60 deg, last row = +80 deg; col c = azimuth 360*c/cols deg,
    wrapped into (-180, 180]."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    r, c = r.ravel(), c.ravel()
    el_deg = EL_MIN_DEG + (EL_MAX_DEG - EL_MIN_DEG) * r / (rows - 1)
    az_deg = 360.0 * c / cols
    az_deg = np.where(az_deg > 180.0, az_deg - 360.0, az_deg)
    az = np.radians(az_deg).astype(np.float32).astype(np.float64)
    el = np.radians(el_deg).astype(np.float32).astype(np.float64)
    return r, c, az, el


def random_directions(setup, n=UNSTRUCTURED_RAYS):
    """Unit vectors (scan-local), uniform on the sphere, fixed seed per setup."""
    rng = np.random.default_rng(5700 + ord(setup))
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


def angles_to_dirs(az, el):
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=1)


def raycast(setup, d_local):
    """Range along each scan-local unit direction to the first surface, and a 'window' flag
    (True = no return). Computed in file coordinates shifted by (E0, N0, Z0)."""
    t = np.array(SETUPS[setup][0]) - np.array([E0, N0, Z0])
    d = d_local @ quat_to_matrix(pose_quaternion(setup)).T
    lo = np.array(ROOM[0]) - np.array([E0, N0, Z0])
    hi = np.array(ROOM[1]) - np.array([E0, N0, Z0])
    with np.errstate(divide="ignore", invalid="ignore"):
        # Exit distance from the inside of the room box.
        tw = np.where(d > 0, (hi - t) / d, np.where(d < 0, (lo - t) / d, np.inf))
        exit_axis = np.argmin(tw, axis=1)
        rng = tw[np.arange(len(d)), exit_axis]
        # Entry distance into the pillar box (slab method).
        plo = np.array(PILLAR[0]) - np.array([E0, N0, Z0])
        phi = np.array(PILLAR[1]) - np.array([E0, N0, Z0])
        t1, t2 = (plo - t) / d, (phi - t) / d
        tnear = np.nanmax(np.minimum(t1, t2), axis=1)
        tfar = np.nanmin(np.maximum(t1, t2), axis=1)
    hits_pillar = (tnear <= tfar) & (tnear > 0) & (tnear < rng)
    rng = np.where(hits_pillar, tnear, rng)
    p = t + rng[:, None] * d
    window = (~hits_pillar & (exit_axis == 0) & (d[:, 0] > 0)
              & (p[:, 1] >= WINDOW_Y[0] - N0) & (p[:, 1] <= WINDOW_Y[1] - N0)
              & (p[:, 2] >= WINDOW_Z[0] - Z0) & (p[:, 2] <= WINDOW_Z[1] - Z0))
    return rng, window


def structured_scan(setup, rows=None, cols=None):
    """Everything about one structured scan, in row-major pixel order."""
    if rows is None:
        rows, cols = GRIDS[setup]
    r, c, az, el = grid_angles(rows, cols)
    d = angles_to_dirs(az, el)
    rng, window = raycast(setup, d)
    return {"row": r, "col": c, "az": az, "el": el, "dir": d, "range": rng, "window": window,
            "local": rng[:, None] * d, "rows": rows, "cols": cols}


def unstructured_scan(setup):
    d = random_directions(setup)
    rng, window = raycast(setup, d)
    return {"dir": d, "range": rng, "window": window, "local": rng[:, None] * d}


def intensity_of(rng):
    """Any values: a made-up fall-off with range, as float32 in [0, 1]."""
    return (1.0 / (1.0 + 0.1 * rng)).astype(np.float32)


def spherical_order(setup, n):
    """Record order of the spherical file: a fixed shuffle of the returned pixels."""
    return np.random.default_rng(9100 + ord(setup)).permutation(n)


def to_file(setup, local):
    """p_file = R * p_local + t, with R from the quaternion as written to the XML."""
    R = quat_to_matrix(pose_quaternion(setup))
    return local @ R.T + np.array(SETUPS[setup][0])


def scan_guid(file_name, setup):
    return "{%s}" % uuid.uuid5(uuid.NAMESPACE_URL, f"carvemap-e57-fixture/{file_name}/{setup}")


# --------------------------------------------------------------------------------------------
# WRITER
# --------------------------------------------------------------------------------------------
PAGE = 1024
LOGICAL_PAGE = 1020


def _crc32c_table():
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


_CRC_TABLE = _crc32c_table()


def crc32c(data):
    c = 0xFFFFFFFF
    t = _CRC_TABLE
    for b in data:
        c = t[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


def phys(logical):
    return (logical // LOGICAL_PAGE) * PAGE + logical % LOGICAL_PAGE


def paginate(logical_bytes):
    """Cut the logical stream into 1020-byte pages (last one zero-padded), each followed by
    its CRC-32C stored BIG-endian."""
    out = bytearray()
    data = bytes(logical_bytes)
    npages = max(1, -(-len(data) // LOGICAL_PAGE))
    data += b"\0" * (npages * LOGICAL_PAGE - len(data))
    for p in range(npages):
        chunk = data[p * LOGICAL_PAGE:(p + 1) * LOGICAL_PAGE]
        out += chunk + crc32c(chunk).to_bytes(4, "big")
    return out


def fix_page_crcs(physical):
    """Recompute every page CRC of a physical file image (used for the bad files)."""
    b = bytearray(physical)
    for p in range(len(b) // PAGE):
        chunk = bytes(b[p * PAGE:p * PAGE + LOGICAL_PAGE])
        b[p * PAGE + LOGICAL_PAGE:(p + 1) * PAGE] = crc32c(chunk).to_bytes(4, "big")
    return b


def bits_needed(lo, hi):
    return int(hi - lo).bit_length()      # == ceil(log2(hi-lo+1)); 0 when lo == hi


class Field:
    """One prototype child. kind: 'int' | 'scaled' | 'single' | 'double'.
    For 'int'/'scaled', values are the raw integers; for floats, the float values."""

    def __init__(self, name, kind, values, lo=None, hi=None, scale=None, offset=0.0):
        self.name, self.kind, self.lo, self.hi, self.scale, self.offset = name, kind, lo, hi, scale, offset
        self.values = np.asarray(values)

    def xml(self):
        if self.kind == "int":
            return f'<{self.name} type="Integer" minimum="{self.lo}" maximum="{self.hi}"/>'
        if self.kind == "scaled":
            return (f'<{self.name} type="ScaledInteger" minimum="{self.lo}" maximum="{self.hi}" '
                    f'scale="{self.scale!r}" offset="{self.offset!r}"/>')
        prec = "single" if self.kind == "single" else "double"
        rng = f' minimum="{self.lo!r}" maximum="{self.hi!r}"' if self.lo is not None else ""
        return f'<{self.name} type="Float" precision="{prec}"{rng}/>'

    def bits(self):
        if self.kind in ("int", "scaled"):
            return bits_needed(self.lo, self.hi)
        return 32 if self.kind == "single" else 64

    def stream(self):
        """The whole bytestream of this field: values packed LSB-first, little-endian."""
        if self.kind == "single":
            return self.values.astype("<f4").tobytes()
        if self.kind == "double":
            return self.values.astype("<f8").tobytes()
        v = self.values.astype(np.int64)
        assert v.min() >= self.lo and v.max() <= self.hi, self.name
        b = self.bits()
        if b == 0:
            return b""
        u = (v - self.lo).astype(np.uint64)
        bitarr = ((u[:, None] >> np.arange(b, dtype=np.uint64)) & np.uint64(1)).astype(np.uint8)
        return np.packbits(bitarr.ravel(), bitorder="little").tobytes()


def write_section(buf, fields, nrec, recs_per_packet):
    """Append one compressed-vector binary section to the logical stream `buf`; return the
    physical offset of its section header (the 'fileOffset' of the points element)."""
    while len(buf) % 4:
        buf.append(0)
    start = len(buf)
    buf += b"\0" * 32
    streams = [f.stream() for f in fields]
    bits = [f.bits() for f in fields]
    prev = [0] * len(fields)
    k = 0
    while k < nrec:
        k = min(nrec, k + recs_per_packet)
        chunks = []
        for i, f in enumerate(fields):
            if k == nrec:
                end = len(streams[i])
            else:
                # Cut each stream on a 4-byte word boundary at or before record k; the partly
                # filled word goes in the next packet, so bit-packed values straddle packets.
                end = (k * bits[i] // 32) * 4
            chunks.append(streams[i][prev[i]:end])
            prev[i] = end
        hdr_len = 6 + 2 * len(fields)
        plen = hdr_len + sum(len(c) for c in chunks)
        plen += (-plen) % 4
        assert plen <= 65536
        pkt = bytearray([1, 0]) + (plen - 1).to_bytes(2, "little") + len(fields).to_bytes(2, "little")
        for c in chunks:
            pkt += len(c).to_bytes(2, "little")
        for c in chunks:
            pkt += c
        pkt += b"\0" * (plen - len(pkt))
        buf += pkt
    assert prev == [len(s) for s in streams]
    section_len = len(buf) - start
    hdr = bytearray(32)
    hdr[0] = 1
    hdr[8:16] = section_len.to_bytes(8, "little")
    hdr[16:24] = phys(start + 32).to_bytes(8, "little")
    hdr[24:32] = (0).to_bytes(8, "little")          # no index packets
    buf[start:start + 32] = hdr
    return phys(start)


def xml_float(name, v):
    return f'<{name} type="Float">{float(v)!r}</{name}>'


def xml_int(name, v):
    return f'<{name} type="Integer">{int(v)}</{name}>'


def xml_str(name, s):
    return f'<{name} type="String"><![CDATA[{s}]]></{name}>'


def write_e57(path, file_guid, scans, offset_override=None):
    """scans: list of dicts with name, guid, setup, fields, nrec, recs_per_packet,
    index_bounds (None or (rows, cols)). Returns the physical file image."""
    buf = bytearray(48)
    offsets = []
    for s in scans:
        offsets.append(write_section(buf, s["fields"], s["nrec"], s["recs_per_packet"]))
    if offset_override is not None:
        offsets[offset_override[0]] = offset_override[1]
    parts = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<e57Root type="Structure" xmlns="http://www.astm.org/COMMIT/E57/2010-e57-v1.0">',
             xml_str("formatName", "ASTM E57 3D Imaging Data File"),
             xml_str("guid", file_guid),
             xml_int("versionMajor", 1), xml_int("versionMinor", 0),
             xml_str("e57LibraryVersion", "carvemap tests/tools/e57/make_e57.py"),
             xml_str("coordinateMetadata", "local survey grid, metres"),
             '<creationDateTime type="Structure">', xml_float("dateTimeValue", 1.4e9),
             xml_int("isAtomicClockReferenced", 0), "</creationDateTime>",
             '<data3D type="Vector" allowHeterogeneousChildren="1">']
    for s, off in zip(scans, offsets):
        q = pose_quaternion(s["setup"])
        t = SETUPS[s["setup"]][0]
        parts += ['<vectorChild type="Structure">', xml_str("guid", s["guid"]),
                  xml_str("name", s["name"]),
                  xml_str("description", s["description"]),
                  '<pose type="Structure"><rotation type="Structure">',
                  xml_float("w", q[0]), xml_float("x", q[1]), xml_float("y", q[2]), xml_float("z", q[3]),
                  '</rotation><translation type="Structure">',
                  xml_float("x", t[0]), xml_float("y", t[1]), xml_float("z", t[2]),
                  "</translation></pose>"]
        if s.get("index_bounds"):
            rows, cols = s["index_bounds"]
            parts += ['<indexBounds type="Structure">', xml_int("rowMinimum", 0),
                      xml_int("rowMaximum", rows - 1), xml_int("columnMinimum", 0),
                      xml_int("columnMaximum", cols - 1), xml_int("returnMinimum", 0),
                      xml_int("returnMaximum", 0), "</indexBounds>"]
        if any(f.name == "intensity" for f in s["fields"]):
            parts += ['<intensityLimits type="Structure">', xml_float("intensityMinimum", 0.0),
                      xml_float("intensityMaximum", 1.0), "</intensityLimits>"]
        parts.append(f'<points type="CompressedVector" fileOffset="{off}" recordCount="{s["nrec"]}">')
        parts.append('<prototype type="Structure">')
        parts += [f.xml() for f in s["fields"]]
        parts += ["</prototype>", '<codecs type="Vector" allowHeterogeneousChildren="1"/>',
                  "</points>", "</vectorChild>"]
    parts += ["</data3D>", '<images2D type="Vector" allowHeterogeneousChildren="1"/>', "</e57Root>", ""]
    xml = "\n".join(parts).encode("utf-8")
    while len(buf) % 4:
        buf.append(0)
    xml_start = len(buf)
    buf += xml
    npages = -(-len(buf) // LOGICAL_PAGE)
    hdr = bytearray(b"ASTM-E57")
    hdr += (1).to_bytes(4, "little") + (0).to_bytes(4, "little")
    hdr += (npages * PAGE).to_bytes(8, "little")
    hdr += phys(xml_start).to_bytes(8, "little")
    hdr += len(xml).to_bytes(8, "little")
    hdr += PAGE.to_bytes(8, "little")
    buf[0:48] = hdr
    image = paginate(buf)
    assert len(image) == npages * PAGE
    if path:
        with open(path, "wb") as f:
            f.write(image)
    return image


# --------------------------------------------------------------------------------------------
# FILES
# --------------------------------------------------------------------------------------------
def scaled_scan_entry(file_name, setup):
    s = structured_scan(setup)
    rows, cols = s["rows"], s["cols"]
    raw = np.rint(s["local"] / SCALE).astype(np.int64)
    raw[s["window"]] = 0
    state = np.where(s["window"], 2, 0)
    inten = intensity_of(s["range"])
    inten[s["window"]] = 0.0
    fields = [Field("cartesianX", "scaled", raw[:, 0], -200000, 200000, SCALE),
              Field("cartesianY", "scaled", raw[:, 1], -200000, 200000, SCALE),
              Field("cartesianZ", "scaled", raw[:, 2], -200000, 200000, SCALE),
              Field("rowIndex", "int", s["row"], 0, rows - 1),
              Field("columnIndex", "int", s["col"], 0, cols - 1),
              Field("cartesianInvalidState", "int", state, 0, 2),
              Field("intensity", "single", inten, 0.0, 1.0)]
    n = rows * cols
    return {"name": f"setup {setup}", "guid": scan_guid(file_name, setup), "setup": setup,
            "description": f"structured {rows}x{cols}, ScaledInteger cartesian, window pixels state 2",
            "fields": fields, "nrec": n, "recs_per_packet": 600, "index_bounds": (rows, cols),
            "truth": {"structured": True, "rows": rows, "cols": cols, "records": n,
                      "returns": int(n - s["window"].sum()), "no_return": int(s["window"].sum())}}


def spherical_scan_entry(file_name, setup):
    s = structured_scan(setup)
    rows, cols = s["rows"], s["cols"]
    keep = np.flatnonzero(~s["window"])
    idx = keep[spherical_order(setup, len(keep))]
    fields = [Field("sphericalRange", "double", s["range"][idx], 0.0, 100.0),
              Field("sphericalAzimuth", "single", s["az"][idx], -math.pi, math.pi),
              Field("sphericalElevation", "single", s["el"][idx], -math.pi / 2, math.pi / 2),
              Field("rowIndex", "int", s["row"][idx], 0, rows - 1),
              Field("columnIndex", "int", s["col"][idx], 0, cols - 1),
              Field("sphericalInvalidState", "int", np.zeros(len(idx), np.int64), 0, 2)]
    # Float limits are written as float32-exact decimals for the single fields.
    fields[1].lo, fields[1].hi = float(np.float32(-math.pi)), float(np.float32(math.pi))
    fields[2].lo, fields[2].hi = float(np.float32(-math.pi / 2)), float(np.float32(math.pi / 2))
    assert np.all(np.abs(s["az"]) <= fields[1].hi) and np.all(np.abs(s["el"]) <= fields[2].hi)
    return {"name": f"setup {setup}", "guid": scan_guid(file_name, setup), "setup": setup,
            "description": f"structured {rows}x{cols}, spherical, window pixels omitted, shuffled",
            "fields": fields, "nrec": len(idx), "recs_per_packet": 400, "index_bounds": None,
            "truth": {"structured": True, "rows": rows, "cols": cols, "records": len(idx),
                      "returns": len(idx), "no_return": int(s["window"].sum())}}


def points_scan_entry(file_name, setup):
    s = unstructured_scan(setup)
    keep = ~s["window"]
    p = s["local"][keep]
    fields = [Field("cartesianX", "double", p[:, 0]), Field("cartesianY", "double", p[:, 1]),
              Field("cartesianZ", "double", p[:, 2])]
    return {"name": f"setup {setup}", "guid": scan_guid(file_name, setup), "setup": setup,
            "description": f"unstructured, {UNSTRUCTURED_RAYS} random directions, window rays omitted",
            "fields": fields, "nrec": len(p), "recs_per_packet": 300, "index_bounds": None,
            "truth": {"structured": False, "rows": None, "cols": None, "records": len(p),
                      "returns": len(p), "no_return": int(s["window"].sum()),
                      "directions": UNSTRUCTURED_RAYS}}


GOOD_FILES = {
    "room_scaled.e57": (scaled_scan_entry, "ABC"),
    "room_spherical.e57": (spherical_scan_entry, "ABC"),
    "room_points.e57": (points_scan_entry, "AC"),
}
# The bad files are built from a cut-down room_scaled.e57 (same writer settings, scan C only)
# so that the four of them stay small.
BAD_BASE_SCANS = "C"


def file_guid(name):
    return "{%s}" % uuid.uuid5(uuid.NAMESPACE_URL, f"carvemap-e57-fixture/{name}")


def expected():
    """What a reader must find, per good file and scan, recomputed from the geometry:
    world points of the returns in record order, and every stored field per record."""
    def f32(a):
        return [float(v) for v in np.asarray(a, dtype=np.float32)]

    out = {"files": {}}
    for fname, (_, setups) in GOOD_FILES.items():
        scans = []
        for setup in setups:
            q = pose_quaternion(setup)
            t = SETUPS[setup][0]
            e = {"name": f"setup {setup}", "guid": scan_guid(fname, setup),
                 "pose": {"translation": list(t), "rotation": list(q)}}
            if fname == "room_points.e57":
                s = unstructured_scan(setup)
                keep = ~s["window"]
                local = s["local"][keep]
                e.update(kind="points", records=int(keep.sum()), tol=1e-9,
                         fields=["cartesianX", "cartesianY", "cartesianZ"],
                         local=local.ravel().tolist())
                world = to_file(setup, local)
            else:
                s = structured_scan(setup)
                rows, cols = s["rows"], s["cols"]
                win = s["window"]
                if fname == "room_scaled.e57":
                    e.update(kind="scaled", records=rows * cols, tol=SCALE, rows=rows, cols=cols,
                             fields=["cartesianX", "cartesianY", "cartesianZ", "rowIndex",
                                     "columnIndex", "cartesianInvalidState", "intensity"],
                             row=s["row"].tolist(), col=s["col"].tolist(),
                             state=np.where(win, 2, 0).tolist(),
                             local=s["local"].ravel().tolist(),
                             intensity=f32(np.where(win, 0.0, intensity_of(s["range"]))))
                    world = to_file(setup, s["local"][~win])
                else:
                    keep = np.flatnonzero(~win)
                    idx = keep[spherical_order(setup, len(keep))]
                    e.update(kind="spherical", records=len(idx), tol=1e-9, rows=rows, cols=cols,
                             fields=["sphericalRange", "sphericalAzimuth", "sphericalElevation",
                                     "rowIndex", "columnIndex", "sphericalInvalidState"],
                             row=s["row"][idx].tolist(), col=s["col"][idx].tolist(),
                             state=[0] * len(idx), range=s["range"][idx].tolist(),
                             az=s["az"][idx].tolist(), el=s["el"][idx].tolist())
                    world = to_file(setup, s["local"][idx])
                e["no_return"] = int(win.sum())
            e["world"] = world.ravel().tolist()
            scans.append(e)
        out["files"][fname] = {"guid": file_guid(fname), "scans": scans}
    return out


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--expected":
        with open(sys.argv[2], "w") as f:
            json.dump(expected(), f)
        return
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "..", "data", "e57")
    os.makedirs(out, exist_ok=True)
    truth = {
        "about": ("Written by tests/tools/e57/make_e57.py; cross-checked by tests/tools/e57/check.mjs "
                  "with the npm reader web-e57 1.2.0. Coordinates in metres, file frame."),
        "room_box": {"min": list(ROOM[0]), "max": list(ROOM[1])},
        "pillar_box": {"min": list(PILLAR[0]), "max": list(PILLAR[1])},
        "window": {"wall_x": ROOM[1][0], "y": list(WINDOW_Y), "z": list(WINDOW_Z)},
        "grid": ("row r: elevation = float32(radians(-60 + 140*r/(rows-1))); "
                 "col c: azimuth = float32(radians(360*c/cols wrapped into (-180,180])); "
                 "pose: p_file = R(q) * p_local + t"),
        "setups": {k: {"position": list(v[0]), "yaw_deg": v[1], "roll_deg": v[2],
                       "rotation": "R = Rz(yaw) * Rx(roll)"} for k, v in SETUPS.items()},
        "files": {}, "bad_files": {}}
    for fname, (make_entry, setups) in GOOD_FILES.items():
        scans = [make_entry(fname, s) for s in setups]
        write_e57(os.path.join(out, fname), file_guid(fname), scans)
        truth["files"][fname] = {"guid": file_guid(fname), "scans": []}
        for s in scans:
            q = pose_quaternion(s["setup"])
            t = SETUPS[s["setup"]][0]
            truth["files"][fname]["scans"].append(dict(
                name=s["name"], guid=s["guid"], **s["truth"],
                pose={"translation": {"x": t[0], "y": t[1], "z": t[2]},
                      "rotation": {"w": q[0], "x": q[1], "y": q[2], "z": q[3]}}))

    # ---- bad files -------------------------------------------------------------------------
    base_name = "room_scaled.e57"
    base_scans = [scaled_scan_entry(base_name, s) for s in BAD_BASE_SCANS]
    base = write_e57(None, file_guid(base_name), base_scans)
    xml_phys = int.from_bytes(base[24:32], "little")
    section_phys = int(base_scans and _first_file_offset(base))

    # bad_crc: flip one byte inside a data page of the binary section; CRC left as it was.
    page = section_phys // PAGE + 5
    assert (page + 1) * PAGE <= xml_phys
    pos = page * PAGE + 300
    bad = bytearray(base)
    bad[pos] ^= 0x5A
    _save(out, "bad_crc.e57", bad)
    truth["bad_files"]["bad_crc.e57"] = {
        "defect": f"byte at physical offset {pos} (page {page}, a data page of the binary section) "
                  "XOR 0x5A; that page's stored CRC is the original one", "page": page, "offset": pos}

    # truncated: cut on a page boundary in the middle of the binary section.
    cut_page = (section_phys // PAGE + xml_phys // PAGE) // 2
    _save(out, "truncated.e57", base[:cut_page * PAGE])
    truth["bad_files"]["truncated.e57"] = {
        "defect": f"file cut after {cut_page * PAGE} bytes (page boundary inside the binary section); "
                  f"header filePhysicalLength still says {len(base)}; XML is gone",
        "length": cut_page * PAGE, "header_length": len(base)}

    # bad_signature: "ASTM-E57" -> "ASTM-X57", page 0 CRC recomputed.
    bad = bytearray(base)
    bad[5] = ord("X")
    _save(out, "bad_signature.e57", fix_page_crcs(bad))
    truth["bad_files"]["bad_signature.e57"] = {
        "defect": "first 8 bytes are 'ASTM-X57'; all page CRCs valid"}

    # bad_offset: the points fileOffset points past the end; written by the writer, so all CRCs
    # and the header are consistent.
    far = 99999744
    bad = write_e57(None, file_guid(base_name), base_scans, offset_override=(0, far))
    assert far > len(bad)
    _save(out, "bad_offset.e57", bad)
    truth["bad_files"]["bad_offset.e57"] = {
        "defect": f"scan 0 points fileOffset=\"{far}\" while the file has {len(bad)} bytes; "
                  "header and all page CRCs valid", "fileOffset": far, "file_length": len(bad)}
    for k in truth["bad_files"]:
        truth["bad_files"][k]["base"] = (f"room_scaled.e57 cut down to scan "
                                         f"{','.join(BAD_BASE_SCANS)} (same writer settings)")
    with open(os.path.join(out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
        f.write("\n")
    total = 0
    for n in sorted(os.listdir(out)):
        sz = os.path.getsize(os.path.join(out, n))
        total += sz
        print(f"{n:24s} {sz:9d}")
    print(f"{'total':24s} {total:9d}")


def _first_file_offset(image):
    xml_phys = int.from_bytes(image[24:32], "little")
    xml_len = int.from_bytes(image[32:40], "little")
    # Read the XML back through the page layer (logical bytes only).
    logical = b"".join(image[p:p + LOGICAL_PAGE] for p in range(0, len(image), PAGE))
    start = (xml_phys // PAGE) * LOGICAL_PAGE + xml_phys % PAGE
    xml = logical[start:start + xml_len].decode()
    i = xml.index('fileOffset="') + len('fileOffset="')
    return int(xml[i:xml.index('"', i)])


def _save(out, name, data):
    with open(os.path.join(out, name), "wb") as f:
        f.write(bytes(data))


if __name__ == "__main__":
    main()
