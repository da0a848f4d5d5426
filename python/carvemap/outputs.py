"""A job's output folder (docs/DESIGN.md §7) as plain Python: its levels, the rooms of each
level as polygons (lists of (x, y) points, metres, the model's local frame), the walls, and the
objects with their boxes and meshes.

    out = load_outputs("out/demo")
    for level in out.levels:
        for room in out.rooms[level.index]:
            print(level.index, room.room, room.area_m2, room.outline[:3])
    for obj in out.objects:
        print(obj.id, obj.box, obj.mesh_path)
"""
import json
import os
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass
class Level:
    """levels.json: the level covers [split_z, the next level's split_z)."""
    index: int
    floor_z: float
    ceiling_z: float
    split_z: Optional[float] = None
    properties: dict = field(default_factory=dict)  # every key of levels.json's entry


@dataclass
class Room:
    """A room of level_<k>/floorplan.geojson. polygons: one (outer ring, [hole rings]) per
    piece (a room may be in several); rings are lists of (x, y) without the closing repeat,
    outer rings counter-clockwise, holes clockwise. properties: the Feature's properties
    (room, level, floor_z, ceiling_z, area_m2), plus job.json's for the room (centroid)."""
    level: int
    room: int
    floor_z: float
    ceiling_z: float
    area_m2: float
    polygons: list
    properties: dict = field(default_factory=dict)

    @property
    def outline(self):
        """The outer ring of the largest piece."""
        return max((p[0] for p in self.polygons), key=lambda r: abs(ring_area(r)), default=[])


@dataclass
class Wall:
    """A wall run of a floor plan: a polyline of (x, y)."""
    level: int
    points: list
    properties: dict = field(default_factory=dict)


@dataclass
class Object:
    """An object of job.json (furniture and the like, §5.6): box ((xmin, ymin, zmin),
    (xmax, ymax, zmax)) in metres, its mesh (relative to the folder) and mesh_path."""
    id: int
    level: Optional[int]
    room: Optional[int]
    box: tuple
    volume_m3: Optional[float]
    mesh: Optional[str]
    mesh_path: Optional[str]
    properties: dict = field(default_factory=dict)

    def load_mesh(self):
        """(vertices (n, 3) float32, triangles (m, 3) int32) of its PLY."""
        return read_ply(self.mesh_path)[:2]


@dataclass
class Outputs:
    folder: str
    job: dict
    levels: list
    rooms: dict    # level index -> [Room]
    walls: dict    # level index -> [Wall]
    objects: list
    warnings: list
    outputs: list  # the files job.json lists, relative to the folder

    def path(self, name):
        """The local path of an output, e.g. out.path("mesh/building.ply")."""
        return os.path.join(self.folder, *name.split("/"))

    def all_rooms(self):
        return [r for level in sorted(self.rooms) for r in self.rooms[level]]


def ring_area(ring):
    """Signed area of a ring of (x, y): positive counter-clockwise."""
    if len(ring) < 3:
        return 0.0
    r = np.asarray(ring, dtype=np.float64)
    x, y = r[:, 0], r[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _ring(coordinates):
    points = [(float(p[0]), float(p[1])) for p in coordinates]
    if len(points) > 1 and points[0] == points[-1]:
        points.pop()  # GeoJSON closes its rings; a plain polygon does not repeat its start
    return points


def _polygons(geometry):
    kind = geometry.get("type")
    if kind == "Polygon":
        pieces = [geometry["coordinates"]]
    elif kind == "MultiPolygon":
        pieces = geometry["coordinates"]
    else:
        return None
    return [(_ring(rings[0]), [_ring(h) for h in rings[1:]]) for rings in pieces if rings]


def _read_json(path):
    with open(path) as f:
        return json.load(f)


def load_floorplan(path, level=None):
    """(rooms, walls) of one floorplan.geojson."""
    doc = _read_json(path)
    rooms, walls = [], []
    for feature in doc.get("features", []):
        geometry = feature.get("geometry") or {}
        props = dict(feature.get("properties") or {})
        lv = props.get("level", level)
        polygons = _polygons(geometry)
        if polygons is not None:
            rooms.append(Room(lv, props.get("room"), props.get("floor_z"),
                              props.get("ceiling_z"), props.get("area_m2"), polygons, props))
        elif geometry.get("type") == "LineString":
            walls.append(Wall(lv, [(float(p[0]), float(p[1])) for p in
                                   geometry.get("coordinates", [])], props))
        elif geometry.get("type") == "MultiLineString":
            for line in geometry.get("coordinates", []):
                walls.append(Wall(lv, [(float(p[0]), float(p[1])) for p in line], props))
    return rooms, walls


def load_outputs(folder):
    """Loads an output folder (OUT/ of `carvemap run|demo|merge -o OUT`, or one `JobClient.fetch`
    filled). A folder without job.json is from a merge that did not finish: FileNotFoundError.
    A level without a floor plan (job.json "warnings" says why) has no rooms."""
    folder = os.fspath(folder)
    job_path = os.path.join(folder, "job.json")
    if not os.path.isfile(job_path):
        raise FileNotFoundError(f"{job_path}: missing (the merge did not finish, or this is "
                                "not a job's output folder)")
    job = _read_json(job_path)
    levels = []
    levels_path = os.path.join(folder, "levels.json")
    if os.path.isfile(levels_path):
        for entry in _read_json(levels_path):
            levels.append(Level(int(entry["index"]), float(entry["floor_z"]),
                                float(entry["ceiling_z"]), entry.get("split_z"), dict(entry)))
    job_rooms = {(r.get("level"), r.get("room")): r for r in job.get("rooms", [])}
    rooms, walls = {}, {}
    indices = sorted({lv.index for lv in levels} | _plan_levels(folder))
    for k in indices:
        plan = os.path.join(folder, f"level_{k}", "floorplan.geojson")
        rooms[k], walls[k] = load_floorplan(plan, k) if os.path.isfile(plan) else ([], [])
        for room in rooms[k]:
            for key, value in job_rooms.get((room.level, room.room), {}).items():
                room.properties.setdefault(key, value)
    objects = []
    for o in job.get("objects", []):
        box = o.get("aabb")
        mesh = o.get("mesh")
        objects.append(Object(
            int(o["id"]), o.get("level"), o.get("room"),
            (tuple(float(v) for v in box[0]), tuple(float(v) for v in box[1])) if box else None,
            o.get("volume_m3"), mesh,
            os.path.join(folder, *mesh.split("/")) if mesh else None, dict(o)))
    return Outputs(folder, job, levels, rooms, walls, objects, list(job.get("warnings", [])),
                   list(job.get("outputs", [])))


def _plan_levels(folder):
    found = set()
    for name in os.listdir(folder):
        if name.startswith("level_") and name[6:].isdigit() and \
                os.path.isfile(os.path.join(folder, name, "floorplan.geojson")):
            found.add(int(name[6:]))
    return found


_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2",
              "int16": "<i2", "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4",
              "uint": "<u4", "uint32": "<u4", "float": "<f4", "float32": "<f4",
              "double": "<f8", "float64": "<f8"}


def read_ply(path):
    """A binary little-endian PLY as §7 writes them (vertices with float x y z first, faces
    as uchar-int triangle lists with at most one extra face property): (vertices (n, 3)
    float32, triangles (m, 3) int32, {face property: (m,) array})."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            line = line.decode("ascii").strip()
            header.append(line)
            if line == "end_header":
                break
        body = f.read()
    if header[:2] != ["ply", "format binary_little_endian 1.0"]:
        raise ValueError(f"{path}: not a binary little-endian PLY ({header[:2]})")
    elements = []
    for line in header[2:]:
        w = line.split()
        if w[0] == "element":
            elements.append([w[1], int(w[2]), []])
        elif w[0] == "property":
            elements[-1][2].append(w[1:])
    counts = {e[0]: e[1] for e in elements}
    vertex = np.dtype([(p[-1], _PLY_TYPES[p[0]]) for p in elements[0][2]])
    nv = counts.get("vertex", 0)
    v = np.frombuffer(body, dtype=vertex, count=nv)
    vertices = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float32)
    faces = np.zeros((0, 3), np.int32)
    extra = {}
    if len(elements) > 1 and elements[1][0] == "face" and elements[1][1]:
        props = elements[1][2]
        if props[0][:3] != ["list", "uchar", "int"] and props[0][:3] != ["list", "uint8", "int32"]:
            raise ValueError(f"{path}: face list {props[0]} is not uchar-int")
        face = np.dtype([("n", "u1"), ("v", "<i4", (3,))] +
                        [(p[-1], _PLY_TYPES[p[0]]) for p in props[1:]])
        fr = np.frombuffer(body, dtype=face, count=elements[1][1], offset=nv * vertex.itemsize)
        if (fr["n"] != 3).any():
            raise ValueError(f"{path}: a face is not a triangle")
        faces = fr["v"].astype(np.int32)
        extra = {p[-1]: fr[p[-1]].copy() for p in props[1:]}
    return vertices, faces, extra
