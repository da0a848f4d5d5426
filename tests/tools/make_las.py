#!/usr/bin/env python3
"""Writes the LAS fixtures of tests/data/las/: a simulated mobile-mapping survey of a corridor.

Our own writer, following the ASPRS LAS specification (1.2, 1.3 and 1.4 R15): every header
field and point record is laid out here with struct, byte for byte, so that the files can be
checked against an independent reader (tests/tools/lascheck/, which reads them with npm
packages) and then serve as ground truth for carvemap's C++ importer
(`carvemap import las POINTS.las --trajectory TRAJ.txt -o scan.h5`).

The scene (all of it also in corridor_truth.json):
- A box room (a corridor) [0, 20] x [0, 8] x [0, 3] m, in the scene frame.
- A mobile mapper whose scanner (sensor) pose at s = t - T0 seconds is
  p(s) = (2 + 1.5 s, 4 + 0.5 sin(s / 4), 1.8), yaw(s) = 0.05 s about +z, roll = pitch = 0;
  T0 = 1e8 s of adjusted standard GPS time (standard GPS time - 1e9: 2014-11-14).
- A 2D profiler spinning in the sensor's y-z plane: 100 profiles a second, 90 beams each;
  beam k of the profile at s_i = i / 100 fires at t = T0 + s_i + k (0.01 / 90) along
  d = (0, cos a_k, sin a_k), a_k = 2 pi k / 90, in the sensor frame (x forward, y left, z up),
  i.e. R_z(yaw(s)) d in the scene frame. Each beam is ray-cast exactly against the box's faces
  (ray_to_room, as tests/tools/make_rosbag.py does); beams longer than 30 m write no point
  (none is, in this room). A point's origin is the sensor position at its own GPS time.
- LAS coordinates ("world") = scene + (500000, 4100000, 100) m, UTM-like; header offsets
  (500000, 4100000, 0), scale 0.001 m: stored X = round((world - offset) / scale).
  The trajectory file is in the same world coordinates.

Span: the full 10 s would be ~90,000 points (2.5-3 MB a file), so the committed fixtures hold
DURATION = 0.5 s: profiles i = 0 .. 49, 4500 points, 126-154 KB a file. --duration changes it
for local experiments (not for the committed files).

Point attributes (deterministic; the C++ tests may rely on them):
- return number 1 of 1; edge-of-flight-line bit set on the last beam of each profile (k = 89),
  scan direction flag 0; intensity 1000 + k; point source ID 1 (file source ID 1);
- classification 2 (ground) for floor points, 6 (building) for walls and ceiling;
  user data = the face hit: 0 x=0, 1 x=20, 2 y=0, 3 y=8, 4 z=0 (floor), 5 z=3 (ceiling);
- scan angle from nadir, negative to the left of the direction of travel (LAS convention):
  -((a_k + 90 deg) wrapped to [-180, 180)); format 6 stores it in 0.006 deg units (i16), formats
  0-3 as an integer "scan angle rank" clamped to [-90, 90] (a 360 deg profiler does not fit);
- format 3 RGB: a colour per face, 8-bit values times 257 (16-bit, as the spec asks).

  make_las.py OUTDIR [--expected DIR] [--duration S]

writes corridor_v12_pf1.las, corridor_v14_pf6.las, corridor_v13_pf3.las, corridor_pf0.las,
corridor_trajectory.txt and corridor_truth.json into OUTDIR; with --expected, also
expected.json (every header field and every point's values, for lascheck/check_las.mjs) into
DIR. Deterministic: the same bytes on every run (Python's math functions only, no clock).
"""
import argparse
import datetime
import hashlib
import json
import math
import os
import re
import struct

ROOM = (20.0, 8.0, 3.0)
T0 = 1.0e8
SCENE_OFFSET = (500000.0, 4100000.0, 100.0)   # world = scene + SCENE_OFFSET
HEADER_OFFSET = (500000.0, 4100000.0, 0.0)
SCALE = 0.001
PROFILE_RATE = 100.0
BEAMS = 90
MAX_RANGE = 30.0
DURATION = 0.5
TRAJECTORY_RATE = 200.0
TRAJECTORY_MARGIN = 0.1
PF0_PROFILES = 4          # the format-0 file: the first 4 profiles (360 points)
FILE_SOURCE_ID = 1
POINT_SOURCE_ID = 1
SOFTWARE = b"carvemap make_las.py"
# Adjusted standard GPS time T0 = 1e8 is standard GPS time 1.1e9 s after 1980-01-06, which is
# 2014-11-14 11:33:04 UTC (16 leap seconds): the survey day, written as the creation date.
CREATION = (datetime.datetime(1980, 1, 6) + datetime.timedelta(seconds=T0 + 1e9 - 16)).timetuple()
CREATION_DAY, CREATION_YEAR = CREATION.tm_yday, CREATION.tm_year   # 318, 2014
GLOBAL_ENCODING_GPS_ADJUSTED = 1 << 0
GLOBAL_ENCODING_WKT = 1 << 4
FACE_NAMES = ["x=0", "x=20", "y=0", "y=8", "z=0 (floor)", "z=3 (ceiling)"]
FACE_RGB8 = [(200, 60, 60), (60, 200, 60), (60, 60, 200), (200, 200, 60), (128, 128, 128),
             (240, 240, 240)]
CLASS_GROUND, CLASS_BUILDING = 2, 6
# OGC WKT (2001, "WKT1") of WGS 84 / UTM zone 33N: easting 500000 is the central meridian.
WKT = ('PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",'
       '6378137,298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],'
       'PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,'
       'AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]],PROJECTION["Transverse_Mercator"],'
       'PARAMETER["latitude_of_origin",0],PARAMETER["central_meridian",15],'
       'PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
       'PARAMETER["false_northing",0],UNIT["metre",1,AUTHORITY["EPSG","9001"]],'
       'AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","32633"]]')

# Point data record layouts (little-endian), by point data format.
RECORD = {
    0: struct.Struct("<iiiHBBbBH"),          # 20 bytes
    1: struct.Struct("<iiiHBBbBHd"),         # 28: format 0 + GPS time
    3: struct.Struct("<iiiHBBbBHdHHH"),      # 34: format 1 + RGB
    6: struct.Struct("<iiiHBBBBhHd"),        # 30
}
HEADER_SIZE = {(1, 2): 227, (1, 3): 235, (1, 4): 375}
VLR_HEADER = struct.Struct("<H16sHH32s")     # 54 bytes

FIXTURES = [
    # name, version, point format, profiles (None: all)
    ("corridor_v12_pf1.las", (1, 2), 1, None),
    ("corridor_v14_pf6.las", (1, 4), 6, None),
    ("corridor_v13_pf3.las", (1, 3), 3, None),
    ("corridor_pf0.las", (1, 2), 0, PF0_PROFILES),
]
TRAJECTORY = "corridor_trajectory.txt"
TRUTH = "corridor_truth.json"


def sensor_pose(s):
    """Scanner position (scene frame) and yaw at s seconds after T0."""
    return (2.0 + 1.5 * s, 4.0 + 0.5 * math.sin(s / 4.0), 1.8), 0.05 * s


def ray_to_room(origin, direction):
    """Distance from origin (inside the room) along a unit direction to the room's faces, and
    the face hit (2 * axis + (0 for the wall at 0, 1 for the far wall)); make_rosbag.py's
    ray_to_room with the face added."""
    best, face = math.inf, -1
    for d in range(3):
        if abs(direction[d]) < 1e-12:
            continue
        for side, wall in enumerate((0.0, ROOM[d])):
            s = (wall - origin[d]) / direction[d]
            if s > 1e-9 and s < best:
                best, face = s, 2 * d + side
    return best, face


def quantize(v):
    return int(math.floor(v + 0.5))


def scan_angle_deg(k):
    """Beam k's angle from nadir, negative to the left of the direction of travel."""
    a = 360.0 * k / BEAMS                       # a_k in degrees, exact for 90 beams
    from_nadir = (a + 90.0 + 180.0) % 360.0 - 180.0   # [-180, 180): 0 down, +90 left
    return -from_nadir


def simulate(duration):
    """Every point of the survey, in time order, as dicts."""
    profiles = int(round(duration * PROFILE_RATE))
    points = []
    for i in range(profiles):
        for k in range(BEAMS):
            t = T0 + (i / PROFILE_RATE + k * (1.0 / PROFILE_RATE / BEAMS))
            s = t - T0          # exact: the s of the stored GPS time, not of the formula
            origin, yaw = sensor_pose(s)
            a = 2.0 * math.pi * k / BEAMS
            ca, sa = math.cos(a), math.sin(a)
            cy, sy = math.cos(yaw), math.sin(yaw)
            direction = (-sy * ca, cy * ca, sa)   # R_z(yaw) (0, cos a, sin a)
            rng, face = ray_to_room(origin, direction)
            if rng > MAX_RANGE:
                continue
            scene = [origin[j] + rng * direction[j] for j in range(3)]
            world = [scene[j] + SCENE_OFFSET[j] for j in range(3)]
            # (world - header offset) / scale, from the scene coordinates (no loss to 5e5 m)
            stored = [quantize((scene[j] + (SCENE_OFFSET[j] - HEADER_OFFSET[j])) / SCALE)
                      for j in range(3)]
            angle = scan_angle_deg(k)
            points.append({
                "profile": i, "beam": k, "gps_time": t, "s": s, "origin_scene": list(origin),
                "yaw": yaw, "range": rng, "face": face, "scene": scene, "world": world,
                "stored": stored,
                "intensity": 1000 + k,
                "return_number": 1, "number_of_returns": 1,
                "scan_direction": 0, "edge": 1 if k == BEAMS - 1 else 0,
                "classification": CLASS_GROUND if face == 4 else CLASS_BUILDING,
                "user_data": face,
                "scan_angle_deg": angle,
                "scan_angle_rank": max(-90, min(90, quantize(angle))),
                "scan_angle_i16": quantize(angle / 0.006),
                "point_source_id": POINT_SOURCE_ID,
                "rgb": [c * 257 for c in FACE_RGB8[face]],
            })
    return points


def world_of_stored(stored):
    return [HEADER_OFFSET[j] + stored[j] * SCALE for j in range(3)]


def pack_point(fmt, p):
    x, y, z = p["stored"]
    if fmt in (0, 1, 3):
        bits = (p["return_number"] | p["number_of_returns"] << 3 | p["scan_direction"] << 6
                | p["edge"] << 7)
        base = (x, y, z, p["intensity"], bits, p["classification"], p["scan_angle_rank"],
                p["user_data"], p["point_source_id"])
        if fmt == 0:
            return RECORD[0].pack(*base)
        if fmt == 1:
            return RECORD[1].pack(*base, p["gps_time"])
        return RECORD[3].pack(*base, p["gps_time"], *p["rgb"])
    returns = p["return_number"] | p["number_of_returns"] << 4
    flags = p["scan_direction"] << 6 | p["edge"] << 7   # class flags 0, scanner channel 0
    return RECORD[6].pack(x, y, z, p["intensity"], returns, flags, p["classification"],
                          p["user_data"], p["scan_angle_i16"], p["point_source_id"],
                          p["gps_time"])


def vlrs_for(version):
    """(user id, record id, description, payload) of the file's VLRs."""
    if version == (1, 4):
        # Point formats 6-10 must carry their CRS as WKT (and set global encoding bit 4).
        return [("LASF_Projection", 2112, "OGC Coordinate System WKT", WKT.encode() + b"\0")]
    return []


def build(version, fmt, points):
    """The file's bytes and a dict of every header field."""
    vlrs = vlrs_for(version)
    vlr_bytes = b"".join(
        VLR_HEADER.pack(0, uid.encode(), rid, len(payload), desc.encode()) + payload
        for uid, rid, desc, payload in vlrs)
    header_size = HEADER_SIZE[version]
    n = len(points)
    stored = [p["stored"] for p in points]
    mins = [min(s[j] for s in stored) for j in range(3)]
    maxs = [max(s[j] for s in stored) for j in range(3)]
    by_return = [sum(1 for p in points if p["return_number"] == r) for r in range(1, 16)]
    encoding = GLOBAL_ENCODING_GPS_ADJUSTED | (GLOBAL_ENCODING_WKT if version == (1, 4) else 0)
    legacy = fmt < 6   # formats 6-10: the legacy counts must be 0
    h = {
        "file_signature": "LASF",
        "file_source_id": FILE_SOURCE_ID,
        "global_encoding": encoding,
        "project_id_hex": bytes(16).hex(),   # GUID data 1-4: all zero (not assigned)
        "version_major": version[0], "version_minor": version[1],
        "system_identifier": SOFTWARE.decode(), "generating_software": SOFTWARE.decode(),
        "file_creation_day_of_year": CREATION_DAY, "file_creation_year": CREATION_YEAR,
        "header_size": header_size,
        "offset_to_point_data": header_size + len(vlr_bytes),
        "number_of_vlrs": len(vlrs),
        "point_data_format": fmt,
        "point_data_record_length": RECORD[fmt].size,
        "legacy_point_count": n if legacy else 0,
        "legacy_points_by_return": by_return[:5] if legacy else [0] * 5,
        "scale": [SCALE] * 3,
        "offset": list(HEADER_OFFSET),
        "min": world_of_stored(mins), "max": world_of_stored(maxs),
        "vlrs": [{"user_id": u, "record_id": r, "description": d, "length": len(pl)}
                 for u, r, d, pl in vlrs],
    }
    out = bytearray()
    out += struct.pack("<4sHH16sBB32s32sHHHIIBHI5I", b"LASF", h["file_source_id"], encoding,
                       bytes(16), version[0], version[1], SOFTWARE, SOFTWARE, CREATION_DAY,
                       CREATION_YEAR, header_size, h["offset_to_point_data"], len(vlrs), fmt,
                       RECORD[fmt].size, h["legacy_point_count"], *h["legacy_points_by_return"])
    out += struct.pack("<3d3d", *h["scale"], *h["offset"])
    out += struct.pack("<6d", h["max"][0], h["min"][0], h["max"][1], h["min"][1], h["max"][2],
                       h["min"][2])
    if version >= (1, 3):
        h["start_of_waveform_data"] = 0
        out += struct.pack("<Q", 0)
    if version >= (1, 4):
        h.update(start_of_first_evlr=0, number_of_evlrs=0, point_count=n,
                 points_by_return=by_return)
        out += struct.pack("<QIQ15Q", 0, 0, n, *by_return)
    assert len(out) == header_size, (len(out), header_size)
    out += vlr_bytes
    assert len(out) == h["offset_to_point_data"]
    for p in points:
        out += pack_point(fmt, p)
    assert len(out) == h["offset_to_point_data"] + n * RECORD[fmt].size
    return bytes(out), h


def trajectory_lines(duration):
    # The scanner's pose in the LAS world frame: adjusted standard GPS time (s), position (m),
    # unit quaternion of the sensor-to-world rotation.
    lines = ["# time x y z qx qy qz qw"]
    first = -int(round(TRAJECTORY_MARGIN * TRAJECTORY_RATE))
    last = int(round((duration + TRAJECTORY_MARGIN) * TRAJECTORY_RATE))
    for j in range(first, last + 1):
        s = j / TRAJECTORY_RATE
        (x, y, z), yaw = sensor_pose(s)
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        lines.append("%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f" % (
            T0 + s, x + SCENE_OFFSET[0], y + SCENE_OFFSET[1], z + SCENE_OFFSET[2], *q))
    return lines, first / TRAJECTORY_RATE, last / TRAJECTORY_RATE


def scene_range(points):
    scene = [[p["stored"][j] * SCALE + HEADER_OFFSET[j] - SCENE_OFFSET[j] for j in range(3)]
             for p in points]
    return {"min": [round(min(s[j] for s in scene), 6) for j in range(3)],
            "max": [round(max(s[j] for s in scene), 6) for j in range(3)]}


def compact_json(obj):
    """Indented JSON with lists of numbers on one line."""
    text = json.dumps(obj, indent=2)
    return re.sub(r"\[[-0-9.,\s]*\]", lambda m: re.sub(r"\s+", " ", m.group(0))
                  .replace("[ ", "[").replace(" ]", "]"), text) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--expected", help="folder for expected.json (for lascheck/check_las.mjs)")
    ap.add_argument("--duration", type=float, default=DURATION,
                    help="seconds of survey (default %(default)s; the committed fixtures' span)")
    args = ap.parse_args()
    os.makedirs(args.outdir, exist_ok=True)
    points = simulate(args.duration)
    expected = {"files": {}}
    truth_files = {}
    for name, version, fmt, profiles in FIXTURES:
        pts = points if profiles is None else [p for p in points if p["profile"] < profiles]
        data, header = build(version, fmt, pts)
        with open(os.path.join(args.outdir, name), "wb") as f:
            f.write(data)
        print("%-22s LAS %d.%d format %d: %6d points, %7d bytes, sha256 %s" % (
            name, version[0], version[1], fmt, len(pts), len(data),
            hashlib.sha256(data).hexdigest()))
        truth_files[name] = {
            "las_version": "%d.%d" % version, "point_data_format": fmt, "points": len(pts),
            "has_gps_time": fmt != 0,
            # format 0 stores no times: the simulated beams' times are given all the same
            "gps_time" if fmt != 0 else "beam_time_not_stored": [pts[0]["gps_time"],
                                                                 pts[-1]["gps_time"]],
            "profiles": [pts[0]["profile"], pts[-1]["profile"]],
            "scene_range": scene_range(pts),
            "importable": fmt != 0,
        }
        fields = ["gps_time", "stored", "world", "intensity", "return_number",
                  "number_of_returns", "scan_direction", "edge", "classification", "user_data",
                  "scan_angle_rank", "scan_angle_i16", "point_source_id", "rgb", "face"]
        expected["files"][name] = {
            "header": header, "size": len(data), "sha256": hashlib.sha256(data).hexdigest(),
            "wkt": WKT if version == (1, 4) else None,
            "points": {f: [p[f] for p in pts] for f in fields},
        }
    lines, traj_first, traj_last = trajectory_lines(args.duration)
    with open(os.path.join(args.outdir, TRAJECTORY), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("%-22s %d poses at %g Hz, s = %g .. %g" % (TRAJECTORY, len(lines) - 1,
                                                      TRAJECTORY_RATE, traj_first, traj_last))
    truth = {
        "description": "Simulated mobile-mapping survey of a corridor, written by "
                       "tests/tools/make_las.py (see its docstring and tests/data/SOURCES.md).",
        "room_scene_frame": {"min": [0.0, 0.0, 0.0], "max": list(ROOM)},
        "scene_offset": list(SCENE_OFFSET),
        "world_from_scene": "world = scene + scene_offset (LAS X, Y, Z and the trajectory)",
        "room_world_frame": {"min": list(SCENE_OFFSET),
                             "max": [ROOM[j] + SCENE_OFFSET[j] for j in range(3)]},
        "las_header_offset": list(HEADER_OFFSET),
        "las_scale": [SCALE] * 3,
        "T0": T0,
        "gps_time_type": "adjusted standard GPS time (global encoding bit 0 = 1)",
        "path": "s = t - T0; sensor position p(s) = (2 + 1.5*s, 4 + 0.5*sin(s/4), 1.8) "
                "(scene frame, m); yaw(s) = 0.05*s rad about +z, roll = pitch = 0",
        "scanner": "2D profiler in the sensor's y-z plane (x forward, y left, z up): "
                   "%g profiles/s at s_i = i/%g, %d beams per profile; beam k at "
                   "t = T0 + s_i + k*(0.01/%d), direction (0, cos a_k, sin a_k), "
                   "a_k = 2*pi*k/%d; ray-cast to the room's faces; beams longer than %g m "
                   "give no point (none here)" % (PROFILE_RATE, PROFILE_RATE, BEAMS, BEAMS,
                                                   BEAMS, MAX_RANGE),
        "duration_s": args.duration,
        "profiles": int(round(args.duration * PROFILE_RATE)),
        "point_origin": "the trajectory's position at the point's GPS time",
        "trajectory": {"file": TRAJECTORY, "rate_hz": TRAJECTORY_RATE,
                       "s_first": traj_first, "s_last": traj_last, "poses": len(lines) - 1,
                       "columns": "time x y z qx qy qz qw"},
        "attributes": {
            "intensity": "1000 + beam index k",
            "return": "return number 1 of 1",
            "edge_of_flight_line": "1 on the last beam of each profile (k = %d)" % (BEAMS - 1),
            "classification": "2 floor, 6 walls and ceiling",
            "user_data": "face hit: " + ", ".join("%d %s" % f for f in enumerate(FACE_NAMES)),
            "scan_angle": "-((a_k + 90 deg) wrapped to [-180, 180)): format 6 in 0.006 deg "
                          "units, formats 0-3 rounded and clamped to [-90, 90]",
            "rgb": "format 3: per face, 16-bit (8-bit value * 257): " + ", ".join(
                "%s %s" % (FACE_NAMES[f], list(FACE_RGB8[f])) for f in range(6)),
            "point_source_id": POINT_SOURCE_ID,
        },
        "files": truth_files,
    }
    with open(os.path.join(args.outdir, TRUTH), "w") as f:
        f.write(compact_json(truth))
    if args.expected:
        os.makedirs(args.expected, exist_ok=True)
        expected["trajectory"] = {"file": TRAJECTORY, "lines": len(lines)}
        with open(os.path.join(args.expected, "expected.json"), "w") as f:
            json.dump(expected, f)


if __name__ == "__main__":
    main()
