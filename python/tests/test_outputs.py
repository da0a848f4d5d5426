"""carvemap.outputs on a real output folder: `carvemap run` on a short walk through the
simulator's furnished `room` (conftest.room_outputs). Checked against the files themselves,
read here with json alone (docs/DESIGN.md §7)."""
import json
import os
import shutil

import numpy as np
import pytest

from carvemap.outputs import load_outputs, read_ply, ring_area


def test_levels_rooms_walls_objects(room_outputs):
    out = load_outputs(room_outputs)
    job = json.loads((room_outputs / "job.json").read_text())
    levels = json.loads((room_outputs / "levels.json").read_text())
    assert out.job == job
    assert [(lv.index, lv.floor_z, lv.ceiling_z, lv.split_z) for lv in out.levels] == \
        [(lv["index"], lv["floor_z"], lv["ceiling_z"], lv["split_z"]) for lv in levels]
    assert out.levels[0].properties == levels[0]
    assert out.warnings == job["warnings"] and out.outputs == job["outputs"]

    # Rooms: one per room Feature of each level's floor plan, as plain polygons.
    assert sorted(out.rooms) == [lv["index"] for lv in levels]
    rooms = out.all_rooms()
    assert len(rooms) == len(job["rooms"]) >= 1
    for room in rooms:
        plan = json.loads((room_outputs / f"level_{room.level}" / "floorplan.geojson")
                          .read_text())
        feature = next(f for f in plan["features"]
                       if f["properties"].get("room") == room.room and
                       f["geometry"]["type"] in ("Polygon", "MultiPolygon"))
        for key, value in feature["properties"].items():
            assert room.properties[key] == value
        assert (room.floor_z, room.ceiling_z, room.area_m2) == (
            feature["properties"]["floor_z"], feature["properties"]["ceiling_z"],
            feature["properties"]["area_m2"])
        listed = next(r for r in job["rooms"] if (r["level"], r["room"]) ==
                      (room.level, room.room))
        assert room.properties["centroid"] == listed["centroid"]
        coords = feature["geometry"]["coordinates"]
        pieces = [coords] if feature["geometry"]["type"] == "Polygon" else coords
        assert len(room.polygons) == len(pieces)
        area = 0.0
        for (outer, holes), rings in zip(room.polygons, pieces):
            assert isinstance(outer, list) and all(
                isinstance(p, tuple) and len(p) == 2 and all(isinstance(v, float) for v in p)
                for p in outer)
            assert outer[0] != outer[-1], "a plain polygon does not repeat its first point"
            assert outer == [tuple(p) for p in rings[0][:-1]]
            assert len(outer) >= 3 and ring_area(outer) > 0  # counter-clockwise
            assert len(holes) == len(rings) - 1
            area += ring_area(outer) + sum(ring_area(h) for h in holes)  # holes clockwise
        assert area == pytest.approx(room.area_m2, rel=1e-6)
        assert room.outline == max((p[0] for p in room.polygons), key=ring_area)
    walls = [w for level in out.walls.values() for w in level]
    assert walls and all(len(w.points) >= 2 and w.properties["kind"] == "wall" for w in walls)

    # Objects: job.json's, with their boxes and meshes.
    assert len(out.objects) == len(job["objects"]) >= 1
    for obj, listed in zip(out.objects, job["objects"]):
        assert obj.id == listed["id"] and obj.level == listed["level"]
        assert obj.room == listed["room"] and obj.volume_m3 == listed["volume_m3"]
        lo, hi = obj.box
        assert lo == tuple(listed["aabb"][0]) and hi == tuple(listed["aabb"][1])
        assert all(a < b for a, b in zip(lo, hi))
        assert obj.mesh == listed["mesh"]
        assert obj.mesh_path == os.path.join(str(room_outputs), *listed["mesh"].split("/"))
        vertices, triangles = obj.load_mesh()
        assert len(triangles) == listed["triangles"]
        assert vertices.dtype == np.float32 and triangles.max() < len(vertices)
        assert (vertices.min(0) >= np.array(lo, np.float32) - 1e-4).all()
        assert (vertices.max(0) <= np.array(hi, np.float32) + 1e-4).all()
    assert out.path("mesh/building.ply") == os.path.join(str(room_outputs), "mesh",
                                                         "building.ply")


def test_read_ply_face_property(room_outputs):
    vertices, triangles, extra = read_ply(room_outputs / "mesh" / "combined.ply")
    objects = extra["object"]
    assert len(objects) == len(triangles) and objects.min() == -1  # −1: the building
    _, object_triangles, by_object = read_ply(room_outputs / "mesh" / "objects.ply")
    assert (objects >= 0).sum() == len(object_triangles)


def test_folder_without_job_json(room_outputs, tmp_path):
    """§7: a folder without job.json is from a merge that did not finish."""
    copy = tmp_path / "unfinished"
    shutil.copytree(room_outputs, copy, ignore=shutil.ignore_patterns("tiles", "object_tiles",
                                                                      ".carvemap"))
    (copy / "job.json").unlink()
    with pytest.raises(FileNotFoundError, match="job.json: missing"):
        load_outputs(copy)
