#!/usr/bin/env python3
"""Checks a job's outputs (docs/DESIGN.md §7) independently of carvemap's code, from the
spec alone:

  - every file job.json lists exists and is not empty;
  - levels.json is a list of {index, floor_z, ceiling_z, split_z}, and when the job came from
    the simulator (input/gt/building.json, or --gt DIR), each true level is matched by one
    whose floor and ceiling are within --level-tol metres;
  - each mesh/*.ply listed is binary little-endian PLY with float x y z vertices and
    `list uchar int` faces, and is watertight: every undirected edge is used by exactly two
    triangles, once in each direction, no triangle repeats or has a repeated vertex;
  - every object of job.json has its fields and its listed mesh; combined.ply has exactly the
    triangles of building.ply and objects.ply;
  - octree.ot is OctoMap's tree file (header "# Octomap OcTree file", id OcTree, size, res,
    data), then `size` nodes depth first, each a little-endian float32 log-odds and a byte of
    which children follow, forming one whole tree; every value finite and within the clamp
    (±13.82); every inner node's value the largest of its children's;
  - each level_<k>/floorplan.dxf listed opens in ezdxf (Debian's python3-ezdxf) with no error
    in its audit, has the layers ROOMS, WALLS, DOORS and LABELS, one label per room of the
    level in job.json, and closed room rings whose signed areas sum to the level's room area;
  - mesh/model.glb, when listed, is binary glTF 2.0 (header, JSON chunk, BIN chunk of the
    buffer's length, parsed with the standard library): every accessor inside its view and
    every view inside the buffer; under its root the nodes "building" (the triangles of
    building.ply), "rooms" (one node per room of job.json) and "objects" (one node per object
    of job.json, named "object <id>", with the triangles of its mesh/objects/<id>.ply);
  - building.ifc, when listed, is ISO 10303-21 text (header, FILE_SCHEMA(('IFC4')), a DATA
    section of numbered instances, every #reference defined): one IfcBuildingStorey per level
    of levels.json, one IfcSpace per room of job.json with an area, named "level <k> room <r>";
  - each level_<k>/occupancy.yaml listed is a ROS map_server map: its keys (image, mode,
    resolution, origin, negate, occupied_thresh, free_thresh) read with python3-yaml, its image
    read with Pillow (python3-pil) as 8-bit gray of topdown.json's size, resolution and origin;
    read with map_server's rule (p = (255 − v) / 255; occupied above occupied_thresh, free
    below free_thresh) it has free and occupied cells, and no free cell where topdown.png
    shows no open space.

Usage: check_outputs.py OUT_DIR [--level-tol 0.05] [--gt GT_DIR] [--selftest]
  --gt: the simulator's gt/ folder, when the job's input was not copied into OUT_DIR/input.
  --selftest: also checks that the checks can fail (a mesh with a triangle removed or flipped
  is not watertight; levels moved by 2 × the tolerance do not match the truth; an octree.ot
  whose root value is changed or whose last node is cut off is refused; so is a building.ifc
  with a storey removed or a reference to no instance).
"""
import argparse
import json
import os
import sys

import numpy as np


def read_ply(path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        fmt, nv, nf, vprops, fprops, element, has_list = None, 0, 0, [], [], None, False
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            words = line.decode("ascii").split()
            if not words:
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                element = words[1]
                if element == "vertex":
                    nv = int(words[2])
                elif element == "face":
                    nf = int(words[2])
            elif words[0] == "property":
                if words[1] == "list":
                    if element != "face" or words[2:4] != ["uchar", "int"]:
                        raise ValueError(f"{path}: faces must be 'list uchar int' "
                                         "(docs/DESIGN.md §7)")
                    has_list = True
                elif element == "vertex":
                    vprops.append((words[2], words[1]))
                else:
                    fprops.append((words[2], words[1]))
        if fmt != "binary_little_endian":
            raise ValueError(f"{path}: format {fmt}, expected binary_little_endian")
        if [p for p in vprops[:3]] != [("x", "float"), ("y", "float"), ("z", "float")]:
            raise ValueError(f"{path}: vertices must start with float x y z")
        sizes = {"float": 4, "int": 4, "uint": 4, "uchar": 1, "char": 1, "double": 8,
                 "short": 2, "ushort": 2}
        vdtype = np.dtype([(n, "<" + {"float": "f4", "int": "i4", "uint": "u4", "uchar": "u1",
                                      "char": "i1", "double": "f8", "short": "i2",
                                      "ushort": "u2"}[t]) for n, t in vprops])
        verts = np.frombuffer(f.read(nv * vdtype.itemsize), dtype=vdtype, count=nv)
        if not has_list and nf:
            raise ValueError(f"{path}: faces without vertex_indices")
        extra = sum(sizes[t] for _, t in fprops)
        # Every face must be a triangle (count byte 3) for this fixed-width read.
        fdtype = np.dtype([("n", "u1"), ("v", "<i4", (3,)), ("extra", "u1", (extra,))])
        faces = np.frombuffer(f.read(nf * fdtype.itemsize), dtype=fdtype, count=nf)
        if len(faces) != nf:
            raise ValueError(f"{path}: truncated")
        if nf and (faces["n"] != 3).any():
            raise ValueError(f"{path}: non-triangle faces")
    xyz = np.stack([verts["x"], verts["y"], verts["z"]], axis=1)
    return xyz, faces["v"].astype(np.int64)


def watertight_problems(path, xyz, tri):
    problems = []
    if tri.size and (tri.min() < 0 or tri.max() >= len(xyz)):
        return [f"{path}: vertex index out of range"]
    if ((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 0] == tri[:, 2])).any():
        problems.append(f"{path}: triangles with a repeated vertex")
    key = np.sort(tri, axis=1)
    if len(np.unique(key, axis=0)) != len(key):
        problems.append(f"{path}: duplicate triangles")
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    lo, hi = directed.min(axis=1), directed.max(axis=1)
    n = len(xyz) + 1
    undirected = lo * n + hi
    _, counts = np.unique(undirected, return_counts=True)
    if (counts != 2).any():
        problems.append(f"{path}: {(counts == 1).sum()} boundary and {(counts > 2).sum()} "
                        "non-manifold edges")
    dkey = directed[:, 0] * n + directed[:, 1]
    if len(np.unique(dkey)) != len(dkey):
        problems.append(f"{path}: inconsistently oriented triangles")
    return problems


def ot_problems(name, data, resolution=None):
    """What is wrong with the bytes of an octree.ot (see the module's docstring)."""
    head, sep, body = data.partition(b"\ndata\n")
    if not sep or not head.startswith(b"# Octomap OcTree file"):
        return [f"{name}: not an OctoMap tree file"]
    fields = {}
    for line in head.decode("ascii", "replace").splitlines()[1:]:
        words = line.split()
        if len(words) == 2 and not line.startswith("#"):
            fields[words[0]] = words[1]
    problems = []
    if fields.get("id") != "OcTree":
        problems.append(f"{name}: id {fields.get('id')}, not OcTree")
    if resolution is not None and abs(float(fields.get("res", "nan")) - resolution) > 1e-12:
        problems.append(f"{name}: res {fields.get('res')}, the job's is {resolution}")
    size = int(fields.get("size", -1))
    if len(body) % 5 != 0 or len(body) // 5 != size:
        return problems + [f"{name}: {len(body)} bytes of nodes for size {size} (5 bytes each)"]
    rec = np.frombuffer(body, dtype=np.dtype([("v", "<f4"), ("m", "u1")]))
    values = rec["v"].astype(np.float64)
    if not np.all(np.isfinite(values)) or (size and np.abs(values).max() > 13.82):
        problems.append(f"{name}: a value not finite or beyond the clamp")
    children = np.unpackbits(rec["m"][:, None], axis=1).sum(axis=1)
    stack, bad_max = [], 0  # [node, children still to come, their largest value]
    for i in range(size):
        if stack:
            stack[-1][1] -= 1
            stack[-1][2] = max(stack[-1][2], values[i])
        elif i > 0:
            return problems + [f"{name}: node {i} follows a complete tree"]
        if children[i]:
            stack.append([i, int(children[i]), -np.inf])
        while stack and stack[-1][1] == 0:
            node, _, largest = stack.pop()
            bad_max += values[node] != largest
    if stack:
        problems.append(f"{name}: the tree ends with {len(stack)} node(s) missing children")
    if bad_max:
        problems.append(f"{name}: {bad_max} inner node(s) not the largest of their children")
    return problems


def dxf_problems(path, rooms):
    """What is wrong with a level's floorplan.dxf against job.json's rooms of that level."""
    try:
        import ezdxf
    except ImportError:
        return [f"{path}: python3-ezdxf is not installed (scripts/install-deps.sh)"]
    try:
        doc = ezdxf.readfile(path)
    except (IOError, ezdxf.DXFStructureError) as e:
        return [f"{path}: ezdxf cannot read it: {e}"]
    problems = []
    audit = doc.audit()
    if audit.has_errors:
        problems.append(f"{path}: ezdxf's audit found {len(audit.errors)} error(s)")
    for layer in ("ROOMS", "WALLS", "DOORS", "LABELS"):
        if layer not in doc.layers:
            problems.append(f"{path}: no layer {layer}")
    msp = doc.modelspace()
    area = 0.0
    for pl in msp.query('LWPOLYLINE[layer=="ROOMS"]'):
        if not pl.closed:
            problems.append(f"{path}: a room ring is not closed")
        pts = np.array([(x, y) for x, y, *_ in pl.get_points()])
        area += 0.5 * float(np.sum(pts[:, 0] * np.roll(pts[:, 1], -1)
                                   - np.roll(pts[:, 0], -1) * pts[:, 1]))
    want = sum(r["area_m2"] for r in rooms)
    if abs(area - want) > 1e-6 * max(1.0, want):
        problems.append(f"{path}: room rings enclose {area:.4f} m², job.json's rooms {want:.4f}")
    labels = len(msp.query('TEXT[layer=="LABELS"]'))
    if labels != len([r for r in rooms if r["area_m2"] > 0]):
        problems.append(f"{path}: {labels} labels for {len(rooms)} rooms")
    return problems


def glb_problems(out, job):
    """What is wrong with mesh/model.glb against the spec's layout and job.json."""
    import struct
    path = os.path.join(out, "mesh", "model.glb")
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or version != 2 or length != len(data):
        return [f"{path}: header {magic:#x} v{version} length {length} of {len(data)} bytes"]
    json_len, json_type = struct.unpack_from("<II", data, 12)
    if json_type != 0x4E4F534A or json_len % 4:
        return [f"{path}: the first chunk is not a 4-aligned JSON chunk"]
    gltf = json.loads(data[20:20 + json_len])
    bin_at = 20 + json_len
    bin_len = struct.unpack_from("<II", data, bin_at)[0] if bin_at < len(data) else 0
    problems = []
    buffers = gltf.get("buffers", [])
    if buffers and buffers[0]["byteLength"] > bin_len:
        problems.append(f"{path}: buffer of {buffers[0]['byteLength']} bytes, BIN chunk {bin_len}")
    views = gltf.get("bufferViews", [])
    for v in views:
        if v["byteOffset"] + v["byteLength"] > buffers[0]["byteLength"]:
            problems.append(f"{path}: a buffer view ends past the buffer")
    sizes = {5126: 4, 5125: 4}
    comps = {"VEC3": 3, "SCALAR": 1}
    for a in gltf.get("accessors", []):
        if a["count"] * sizes[a["componentType"]] * comps[a["type"]] > \
                views[a["bufferView"]]["byteLength"]:
            problems.append(f"{path}: an accessor reads past its view")
    nodes = gltf["nodes"]
    named = {nodes[c]["name"]: nodes[c] for c in nodes[gltf["scenes"][0]["nodes"][0]]["children"]}

    def triangles(node):
        if "mesh" not in node:
            return 0
        return gltf["accessors"][gltf["meshes"][node["mesh"]]["primitives"][0]["indices"]][
            "count"] // 3
    building_ply = len(read_ply(os.path.join(out, "mesh", "building.ply"))[1])
    if "building" not in named or triangles(named["building"]) != building_ply:
        problems.append(f"{path}: no node 'building' with building.ply's {building_ply} triangles")
    objects = named.get("objects", {}).get("children", [])
    if "objects" in named or job.get("objects"):
        if len(objects) != len(job.get("objects", [])):
            problems.append(f"{path}: {len(objects)} object nodes, job.json "
                            f"{len(job.get('objects', []))} objects")
        for node, obj in zip(objects, job.get("objects", [])):
            n = nodes[node]
            if n["name"] != f"object {obj['id']}" or triangles(n) != obj["triangles"]:
                problems.append(f"{path}: node {n['name']} ({triangles(n)} triangles) is not "
                                f"object {obj['id']} ({obj['triangles']})")
                break
    rooms = named.get("rooms", {}).get("children", [])
    if "rooms" in named and len(rooms) != len([r for r in job.get("rooms", [])
                                               if r.get("area_m2", 0) > 0]):
        problems.append(f"{path}: {len(rooms)} room nodes, job.json {len(job.get('rooms', []))}")
    print(f"mesh/model.glb: {len(nodes)} nodes ({len(rooms)} rooms, {len(objects)} objects), "
          f"{bin_len} bytes of buffer")
    return problems


def ifc_problems(path, text, job, levels):
    """What is wrong with building.ifc's text against ISO 10303-21's layout, levels.json and
    job.json."""
    import re
    if not text.startswith("ISO-10303-21;\nHEADER;") or not text.rstrip().endswith(
            "END-ISO-10303-21;"):
        return [f"{path}: not ISO 10303-21 text (header or end)"]
    header, sep, data = text.partition("\nDATA;\n")
    if not sep or "FILE_SCHEMA(('IFC4'));" not in header:
        return [f"{path}: no FILE_SCHEMA(('IFC4')) header or no DATA section"]
    data = data[:data.rfind("ENDSEC;")]
    instances = {}
    for m in re.finditer(r"#(\d+)\s*=\s*([A-Z0-9_]+)\s*\((.*?)\);\s*$", data, re.M | re.S):
        instances[int(m.group(1))] = (m.group(2), m.group(3))
    problems = []
    if len(instances) != data.count(";"):
        problems.append(f"{path}: {data.count(';')} statements, {len(instances)} instances read")
    refs = {int(r) for _, args in instances.values()
            for r in re.findall(r"#(\d+)", re.sub(r"'(?:[^']|'')*'", "''", args))}
    if refs - instances.keys():
        problems.append(f"{path}: #{min(refs - instances.keys())} referenced but not defined")
    of_type = lambda t: [args for typ, args in instances.values() if typ == t]
    storeys, spaces = of_type("IFCBUILDINGSTOREY"), of_type("IFCSPACE")
    if len(storeys) != len(levels):
        problems.append(f"{path}: {len(storeys)} storeys, levels.json {len(levels)} levels")
    names = sorted(re.match(r"'(?:[^']|'')*',[^,]*,'((?:[^']|'')*)'", a).group(1) for a in spaces)
    rooms = sorted(f"level {r['level']} room {r['room']}" for r in job.get("rooms", [])
                   if r.get("area_m2", 0) > 0)
    if names != rooms:
        problems.append(f"{path}: spaces {names[:5]}… ({len(names)}), job.json rooms "
                        f"{rooms[:5]}… ({len(rooms)})")
    if not problems:
        print(f"building.ifc: {len(instances)} instances, {len(storeys)} storeys, "
              f"{len(spaces)} spaces, {len(of_type('IFCWALL'))} walls, "
              f"{len(of_type('IFCDOOR'))} doors")
    return problems


def ros_map_problems(out, name):
    """What is wrong with a level's occupancy.yaml and its image, as map_server reads them."""
    try:
        import yaml
        from PIL import Image
    except ImportError as e:
        return [f"{name}: {e} (scripts/install-deps.sh installs python3-yaml, python3-pil)"]
    path = os.path.join(out, name)
    meta = yaml.safe_load(open(path))
    problems = []
    for key in ("image", "mode", "resolution", "origin", "negate", "occupied_thresh",
                "free_thresh"):
        if key not in meta:
            problems.append(f"{name}: no '{key}'")
    if problems:
        return problems
    level_dir = os.path.dirname(path)
    image = Image.open(os.path.join(level_dir, meta["image"]))
    topdown = json.load(open(os.path.join(level_dir, "topdown.json")))
    if image.mode != "L" or image.size != (topdown["width"], topdown["height"]):
        problems.append(f"{name}: image {image.mode} {image.size}, topdown.json "
                        f"{topdown['width']}x{topdown['height']}")
        return problems
    if abs(meta["resolution"] - topdown["resolution_m"]) > 1e-12 or \
            any(abs(a - b) > 1e-9 for a, b in zip(meta["origin"][:2], topdown["origin_m"])):
        problems.append(f"{name}: resolution/origin {meta['resolution']} {meta['origin']} differ "
                        f"from topdown.json's {topdown['resolution_m']} {topdown['origin_m']}")
    v = np.asarray(image, dtype=np.float64)
    p = (255.0 - v) / 255.0 if meta["negate"] == 0 else v / 255.0
    occupied = p > meta["occupied_thresh"]
    free = p < meta["free_thresh"]
    if not occupied.any() or not free.any():
        problems.append(f"{name}: {occupied.sum()} occupied and {free.sum()} free cells")
    open_height = np.asarray(Image.open(os.path.join(level_dir, topdown["image"])))
    if (free & (open_height == 0)).any():
        problems.append(f"{name}: {(free & (open_height == 0)).sum()} free cells where "
                        "topdown.png has no open space")
    print(f"{name}: {free.sum()} free, {occupied.sum()} occupied, "
          f"{(~free & ~occupied).sum()} unknown cells, as map_server reads them")
    return problems


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--level-tol", type=float, default=0.05)
    ap.add_argument("--gt", help="the simulator's gt/ folder (default OUT/input/gt)")
    ap.add_argument("--selftest", action="store_true")
    args = ap.parse_args()
    problems = []
    job = json.load(open(os.path.join(args.out, "job.json")))
    for name in job.get("outputs", []):
        p = os.path.join(args.out, name)
        if not os.path.isfile(p) or os.path.getsize(p) == 0:
            problems.append(f"{p}: listed in job.json but missing or empty")

    levels = json.load(open(os.path.join(args.out, "levels.json")))
    for lv in levels:
        for key in ("index", "floor_z", "ceiling_z", "split_z"):
            if key not in lv:
                problems.append(f"levels.json: level without '{key}'")
    gt = os.path.join(args.gt or os.path.join(args.out, "input", "gt"), "building.json")
    if args.gt and not os.path.isfile(gt):
        problems.append(f"{gt}: --gt given but there is no building.json")
    if os.path.isfile(gt):
        truth = json.load(open(gt)).get("levels", [])
        for t in truth:
            match = [lv for lv in levels
                     if abs(lv["floor_z"] - t["floor_z"]) <= args.level_tol
                     and abs(lv["ceiling_z"] - t["ceiling_z"]) <= args.level_tol]
            if len(match) != 1:
                problems.append(f"levels.json: true level {t} matched by {len(match)} levels "
                                f"(tolerance {args.level_tol} m): {levels}")
        print(f"levels: {[(round(l['floor_z'], 3), round(l['ceiling_z'], 3)) for l in levels]} "
              f"truth {[(t['floor_z'], t['ceiling_z']) for t in truth]}")

    for name in job.get("outputs", []):
        if name.startswith("mesh/") and name.endswith(".ply"):
            p = os.path.join(args.out, name)
            xyz, tri = read_ply(p)
            found = watertight_problems(p, xyz, tri)
            problems += found
            print(f"{name}: {len(xyz)} vertices, {len(tri)} triangles, "
                  f"{'watertight' if not found else 'NOT watertight'}")

    # §7 objects: every listed object has its mesh; combined.ply = building.ply + objects.ply.
    outputs = set(job.get("outputs", []))
    for obj in job.get("objects", []):
        for key in ("id", "level", "room", "aabb", "volume_m3", "triangles", "mesh"):
            if key not in obj:
                problems.append(f"job.json: object without '{key}': {obj}")
        if obj.get("mesh") not in outputs:
            problems.append(f"job.json: object {obj.get('id')} mesh {obj.get('mesh')} not listed")
    if {"mesh/combined.ply", "mesh/objects.ply", "mesh/building.ply"} <= outputs:
        counts = [len(read_ply(os.path.join(args.out, "mesh", n))[1])
                  for n in ("building.ply", "objects.ply", "combined.ply")]
        if counts[0] + counts[1] != counts[2]:
            problems.append(f"combined.ply has {counts[2]} triangles, building + objects "
                            f"{counts[0]} + {counts[1]}")
        print(f"objects: {len(job.get('objects', []))}; combined = building + objects "
              f"({counts[2]} = {counts[0]} + {counts[1]})")
    job_counts = job.get("counts", {})
    for name in sorted(outputs):
        if name.endswith("/floorplan.dxf"):
            level = int(name.split("/")[0].split("_")[1])
            rooms = [r for r in job.get("rooms", []) if r.get("level") == level]
            found = dxf_problems(os.path.join(args.out, name), rooms)
            problems += found
            print(f"{name}: {'read by ezdxf' if not found else 'NOT as job.json says'}, "
                  f"{len(rooms)} rooms")
    if "mesh/model.glb" in outputs:
        problems += glb_problems(args.out, job)
    ifc_path = os.path.join(args.out, "building.ifc")
    if "building.ifc" in outputs:
        problems += ifc_problems(ifc_path, open(ifc_path, encoding="ascii", errors="replace").read(),
                                 job, levels)
    for name in sorted(outputs):
        if name.endswith("/occupancy.yaml"):
            problems += ros_map_problems(args.out, name)
    ot_path = os.path.join(args.out, "octree.ot")
    if "octree.ot" in outputs:
        data = open(ot_path, "rb").read()
        problems += ot_problems("octree.ot", data, job.get("params", {}).get("resolution_m"))
        if len(data.partition(b"\ndata\n")[2]) // 5 != job_counts.get("octree_ot_nodes"):
            problems.append(f"octree.ot: job.json says {job_counts.get('octree_ot_nodes')} nodes")
        print(f"octree.ot: {job_counts.get('octree_ot_nodes')} nodes, one tree, inner nodes the "
              "largest of their children")
    # §5.5 on request: points.ply holds the points kept, vertices only.
    if "points.ply" in outputs:
        xyz, tri = read_ply(os.path.join(args.out, "points.ply"))
        if len(xyz) != job_counts.get("points_kept", -1) or len(tri) != 0:
            problems.append(f"points.ply: {len(xyz)} vertices and {len(tri)} faces, job.json "
                            f"says {job_counts.get('points_kept')} points kept")
        print(f"points.ply: {len(xyz)} points, {job_counts.get('points_trimmed')} trimmed")
    # §5.6.1: the objects were meshed from chunks carved again finer, one tile each.
    if job_counts.get("recarved_chunks", 0) > 0:
        finer = job_counts.get("object_resolution_m", 0)
        coarse = job.get("params", {}).get("resolution_m", 0)
        tiles_dir = os.path.join(args.out, "object_tiles")
        tiles = [n for n in os.listdir(tiles_dir)] if os.path.isdir(tiles_dir) else []
        if not 0 < finer < coarse:
            problems.append(f"job.json: object_resolution_m {finer} not finer than {coarse}")
        if len(tiles) != job_counts["recarved_chunks"]:
            problems.append(f"object_tiles/ holds {len(tiles)} files, job.json says "
                            f"{job_counts['recarved_chunks']} chunks were carved again")
        print(f"objects re-carved at {finer} m: {len(tiles)} chunks")

    if args.selftest:
        xyz, tri = read_ply(os.path.join(args.out, "mesh", "dense.ply"))
        if not watertight_problems("cut", xyz, tri[:-1]):
            problems.append("selftest: a mesh with a triangle removed passed as watertight")
        flipped = tri.copy()
        flipped[0] = flipped[0][::-1]
        if not watertight_problems("flipped", xyz, flipped):
            problems.append("selftest: a mesh with a flipped triangle passed as watertight")
        if os.path.isfile(gt):
            for t in json.load(open(gt)).get("levels", []):
                moved = [dict(lv, floor_z=lv["floor_z"] + 2 * args.level_tol) for lv in levels]
                if any(abs(lv["floor_z"] - t["floor_z"]) <= args.level_tol for lv in moved):
                    problems.append("selftest: levels moved off the truth still matched")
        if "octree.ot" in outputs:
            data = open(ot_path, "rb").read()
            at = data.index(b"\ndata\n") + 6
            root = np.frombuffer(data[at:at + 4], "<f4")[0]
            changed = data[:at] + np.float32(root + 1).tobytes() + data[at + 4:]
            if not ot_problems("changed", changed):
                problems.append("selftest: an octree.ot with its root's value changed passed")
            if not ot_problems("cut", data[:-5]):
                problems.append("selftest: an octree.ot without its last node passed")
        if "building.ifc" in outputs:
            import re
            text = open(ifc_path, encoding="ascii", errors="replace").read()
            storey = re.search(r"\n#\d+=IFCBUILDINGSTOREY\(.*?\);", text)
            if not ifc_problems("no storey", text.replace(storey.group(0), ""), job, levels):
                problems.append("selftest: a building.ifc without a storey passed")
            if not ifc_problems("dangling", text.replace("DATA;\n", "DATA;\n#999999999=IFCPOLYLINE("
                                                         "(#999999998));\n", 1), job, levels):
                problems.append("selftest: a building.ifc with an undefined #reference passed")
        print("selftest: the checks reject a cut mesh, a flipped triangle, moved levels, a "
              "changed or cut octree.ot and a building.ifc without a storey or with a dangling "
              "reference")

    for p in problems:
        print("FAIL:", p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
