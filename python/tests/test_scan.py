"""carvemap.scan against docs/DESIGN.md §3: files the writer makes pass the C++ validator
(`carvemap validate`), h5py read directly and tests/tools/independent_reader.py; the reader gives
back what was written; every rule the writer enforces is refused with a message naming the
field; files broken behind the writer's back are refused by the reader (and by the C++
validator where it checks the rule); what §3 allows a foreign writer to do is read by both."""
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from carvemap.scan import (FRAME_DTYPE, PATH_DTYPE, ScanReader, ScanWriter, read_scan,
                           write_scan)
from conftest import REPO, run_carvemap

INDEPENDENT_READER = os.path.join(REPO, "tests", "tools", "independent_reader.py")


def rot_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


def path_arrays(n=21, t0=0.0, t1=2.0):
    t = np.linspace(t0, t1, n)
    position = np.column_stack([t, 0.5 * t, np.full(n, 1.6)])
    half = np.radians(10.0) * t / 2
    orientation = np.column_stack([np.cos(half), np.zeros(n), np.zeros(n), np.sin(half)])
    cov = np.tile(np.array([4e-4, 1e-5, 0, 4e-4, 0, 1e-4, 1e-5, 0, 0, 1e-5, 0, 4e-5]), (n, 1))
    return t, position, orientation, cov


def write_full(path):
    """Every part of §3: the path with covariances, a line sensor written frame by frame (with
    rays without return), another written in bulk, a grid, a points sensor (with an empty
    frame), the magnetometer. Sensors are added in an order that is not the names' order.
    Returns what was written."""
    rng = np.random.default_rng(3)
    t, position, orientation, cov = path_arrays()
    line = [(0.1 + 0.2 * i, rng.uniform(-5, 5, (7, 3))) for i in range(5)]
    line[1][1][[2, 5]] = np.nan
    bulk_t = np.array([0.15, 0.35, 0.55])
    bulk_counts = np.array([4, 0, 6])
    bulk_points = rng.uniform(-3, 3, (10, 3))
    grid = [(0.2 + 0.5 * i, rng.uniform(-2, 2, (3, 4, 3))) for i in range(3)]
    grid[2][1][1, 2] = np.nan
    points = [(0.3, rng.uniform(-1, 1, (5, 3))), (0.4, np.zeros((0, 3))),
              (1.9, rng.uniform(-1, 1, (2, 3)))]
    mag_t = np.array([0.0, 0.7, 0.35])  # §3 does not ask the readings to be in order
    mag = rng.normal(size=(3, 3))
    with ScanWriter(path) as w:
        w.add_path(t[:5], position[:5], orientation[:5], cov[:5])
        w.add_path(t[5:], position[5:], orientation[5:], cov[5:])
        w.add_sensor("zeta", "line", R_s2c=np.eye(3), T_s2c=[0.1, 0, 0.2], sigma_t=1e-3,
                     range_sigma=(0.01, 0.001), max_range=30.0)
        w.add_sensor("alpha", "line", R_s2c=rot_z(30), T_s2c=[0, 0.2, 0.1], sigma_t=0.0,
                     range_sigma=[0.02, 0.0], max_range=20.0)
        w.add_sensor("cam", "grid", rows=3, cols=4, R_s2c=rot_z(-90), T_s2c=[0.2, 0, 0],
                     sigma_t=2e-3, range_sigma=(0.005, 0.002), max_range=5.0)
        w.add_sensor("pts", "points", R_s2c=np.eye(3).reshape(9), T_s2c=[0, 0, 0],
                     sigma_t=1e-3, range_sigma=(0.01, 0), max_range=100)
        for ft, p in line:
            w.add_frame("zeta", ft, p)
        w.add_frames("alpha", bulk_t, bulk_counts, bulk_points)
        for ft, p in grid:
            w.add_frame(2, ft, p)  # by index
        for ft, p in points:
            w.add_frame("pts", ft, p)
        w.add_magnetometer(mag_t, mag)
    return dict(t=t, position=position, orientation=orientation, cov=cov, line=line,
                bulk=(bulk_t, bulk_counts, bulk_points), grid=grid, points=points,
                mag=(mag_t, mag))


@pytest.fixture
def full(tmp_path):
    path = tmp_path / "full.h5"
    return path, write_full(path)


def assert_same(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


# ---- the writer's files -----------------------------------------------------------------------

def test_written_file_passes_the_cpp_validator(full, carvemap_bin):
    path, _ = full
    r = run_carvemap("validate", path)
    assert r.stdout.strip().endswith("valid"), r.stdout
    # The C++ reader indexes the sensors in creation order (§3), not by name.
    names = re.findall(r"sensor (\w+): ([\w ]+), (\d+) frames, (\d+) points", r.stdout)
    assert names == [("zeta", "line", "5", "35"), ("alpha", "line", "3", "10"),
                     ("cam", "grid 3x4", "3", "36"), ("pts", "points", "3", "7")], r.stdout
    assert "path: 21 poses" in r.stdout and "path_cov: yes, magnetometer: yes" in r.stdout
    info = run_carvemap("info", path).stdout
    assert "sensor cam: grid" in info and "R_s2c yaw -90.000°" in info, info


def test_written_file_read_with_h5py_alone(full):
    """The bytes follow §3 as h5py sees them: attributes, dtypes, shapes, values, order."""
    path, want = full
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "carvemap-scan"
        assert f.attrs.get_id("version").dtype.kind == "i" and f.attrs["version"] == 1
        p = f["path"]
        assert p.dtype == PATH_DTYPE and p.shape == (21,)
        assert_same(p["t"], want["t"])
        assert_same(np.stack([p["x"], p["y"], p["z"]], 1), want["position"])
        assert_same(np.stack([p["qw"], p["qx"], p["qy"], p["qz"]], 1), want["orientation"])
        assert f["path_cov"].dtype == np.float32 and f["path_cov"].shape == (21, 12)
        assert_same(f["path_cov"], want["cov"].astype(np.float32))
        s = f["sensors"]
        assert s.id.get_create_plist().get_link_creation_order() & h5py.h5p.CRT_ORDER_INDEXED
        order = []
        s.id.links.iterate(lambda n: order.append(n.decode()), idx_type=h5py.h5.INDEX_CRT_ORDER)
        assert order == ["zeta", "alpha", "cam", "pts"]
        alpha = s["alpha"]
        assert alpha.attrs["kind"] == "line" and "rows" not in alpha.attrs
        assert_same(alpha.attrs["R_s2c"], rot_z(30).reshape(9))  # row-major
        assert alpha.attrs["R_s2c"].dtype == np.float64 and alpha.attrs["R_s2c"].shape == (9,)
        assert_same(alpha.attrs["T_s2c"], [0, 0.2, 0.1])
        assert alpha.attrs["sigma_t"] == 0.0 and alpha.attrs["max_range"] == 20.0
        assert_same(alpha.attrs["range_sigma"], [0.02, 0.0])
        fr = alpha["frames"][...]
        assert alpha["frames"].dtype == FRAME_DTYPE
        bulk_t, counts, pts = want["bulk"]
        assert_same(fr["t"], bulk_t)
        assert_same(fr["count"], counts)
        assert_same(fr["first"], [0, 4, 4])
        assert alpha["points"].dtype == np.float32 and alpha["points"].shape == (10, 3)
        assert_same(alpha["points"], pts.astype(np.float32))
        cam = s["cam"]
        assert (cam.attrs["rows"], cam.attrs["cols"]) == (3, 4)
        assert_same(cam["frames"]["count"], [12, 12, 12])
        assert_same(cam["points"][24:], want["grid"][2][1].reshape(12, 3).astype(np.float32))
        zeta = s["zeta"]["points"][...]
        assert np.isnan(zeta[7 + 2]).all() and np.isnan(zeta[7 + 5]).all()
        m = f["magnetometer"][...]
        assert_same(m["t"], want["mag"][0])
        assert_same(np.stack([m["mx"], m["my"], m["mz"]], 1), want["mag"][1])
        # No object carries time stamps, so equal content gives equal bytes (below).
        modification_time = 1 << 0x12  # the object header message holding the times
        for obj in (f, p, s, alpha, alpha["points"], f["magnetometer"]):
            assert not h5py.h5o.get_info(obj.id).hdr.mesg.present & modification_time, obj.name


def test_written_file_passes_the_independent_reader(tmp_path):
    """tests/tools/independent_reader.py (h5py and numpy, no carvemap code) on a walk written
    from numpy arrays; it also asks for a sensor and returns within max_range."""
    from box_room import write_box_room
    path = write_box_room(tmp_path / "room.h5", seconds=3.0, no_return_every=17)
    r = subprocess.run([sys.executable, INDEPENDENT_READER, "--scan", str(path)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all checks hold" in r.stdout


def test_equal_content_gives_equal_bytes(tmp_path):
    write_full(tmp_path / "a.h5")
    write_full(tmp_path / "b.h5")
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


# ---- reading back -----------------------------------------------------------------------------

def test_reader_round_trip(full):
    path, want = full
    scan = read_scan(path)
    assert_same(scan.path.t, want["t"])
    assert_same(scan.path.position, want["position"])
    assert_same(scan.path.orientation, want["orientation"])
    assert_same(scan.path.covariance, want["cov"].astype(np.float32))
    assert [s.name for s in scan.sensors] == ["zeta", "alpha", "cam", "pts"]
    zeta = scan.sensor("zeta")
    assert zeta.kind == "line" and zeta.rows is None and zeta.max_range == 30.0
    assert_same(zeta.T_s2c, [0.1, 0, 0.2])
    assert_same(zeta.range_sigma, [0.01, 0.001])
    for i, (ft, p) in enumerate(want["line"]):
        t, got = zeta.frame(i)
        assert t == ft and got.dtype == np.float32
        assert_same(got, p.astype(np.float32))
    cam = scan.sensor("cam")
    assert (cam.kind, cam.rows, cam.cols) == ("grid", 3, 4)
    assert_same(cam.R_s2c, rot_z(-90))
    for i, (ft, p) in enumerate(want["grid"]):
        assert_same(cam.frame(i)[1], p.reshape(-1, 3).astype(np.float32))
    pts = scan.sensor("pts")
    assert_same(pts.frame_rays, [5, 0, 2])
    assert pts.frame(1)[1].shape == (0, 3)
    assert_same(scan.magnetometer.t, want["mag"][0])
    assert_same(scan.magnetometer.field, want["mag"][1])
    with ScanReader(path) as r:
        assert [(s.name, s.frame_count, s.point_count) for s in r.sensors] == \
            [("zeta", 5, 35), ("alpha", 3, 10), ("cam", 3, 36), ("pts", 3, 7)]
        t, first, count = r.frames("alpha")
        assert_same(first, [0, 4, 4])
        frames = list(r.iter_frames("zeta"))
        assert [f[0] for f in frames] == [ft for ft, _ in want["line"]]
        assert_same(frames[3][1], want["line"][3][1].astype(np.float32))
        assert_same(r.frame("alpha", 2)[1], want["bulk"][2][4:].astype(np.float32))
    # Written again from what was read: the same bytes.
    write_scan(path.parent / "again.h5", scan)
    assert (path.parent / "again.h5").read_bytes() == path.read_bytes()


def test_cpp_written_scan_round_trip(simulated_room, tmp_path):
    """A scan the C++ writer made (the simulator) read, written again, read by C++."""
    src = simulated_room / "scan.h5"
    scan = read_scan(src)
    with h5py.File(src, "r") as f:
        assert_same(scan.path.t, f["path"]["t"])
        assert_same(scan.sensor("v_left").points, f["sensors/v_left/points"])
        assert [s.name for s in scan.sensors] == ["h_level", "v_left", "v_right"]
    copy = tmp_path / "copy.h5"
    write_scan(copy, scan)
    a = run_carvemap("info", src).stdout.splitlines()[1:]
    b = run_carvemap("info", copy).stdout.splitlines()[1:]
    assert a == b
    assert run_carvemap("validate", copy).stdout.strip().endswith("valid")
    again = read_scan(copy)
    for s, t in zip(scan.sensors, again.sensors):
        assert_same(s.points, t.points)
        assert_same(s.frame_t, t.frame_t)


# ---- what the writer refuses ------------------------------------------------------------------

def _with_path(w, n=21):
    t, position, orientation, cov = path_arrays(n)
    w.add_path(t, position, orientation, cov)


def _sensors(w):
    _with_path(w)
    w.add_sensor("l", "line", R_s2c=np.eye(3), T_s2c=[0, 0, 0], sigma_t=1e-3,
                 range_sigma=(0.01, 0.0), max_range=30)
    w.add_sensor("g", "grid", rows=2, cols=3, R_s2c=np.eye(3), T_s2c=[0, 0, 0], sigma_t=1e-3,
                 range_sigma=(0.01, 0.0), max_range=30)


def _sensor(w, **kw):
    args = dict(name="s", kind="line", R_s2c=np.eye(3), T_s2c=[0, 0, 0], sigma_t=1e-3,
                range_sigma=(0.01, 0.0), max_range=30.0)
    args.update(kw)
    w.add_sensor(**args)


_DEFAULT = object()


def _path(w, t=None, position=None, orientation=None, cov=_DEFAULT, n=4):
    t0, p0, q0, c0 = path_arrays(n)
    w.add_path(t0 if t is None else t, p0 if position is None else position,
               q0 if orientation is None else orientation, c0 if cov is _DEFAULT else cov)


def _bad(arr, row, col, value):
    arr = np.array(arr, dtype=np.float64)
    arr[row, col] = value
    return arr


P = path_arrays(4)
REFUSED = [
    # /path
    ("path t not finite", lambda w: _path(w, t=[0, np.nan, 1, 2]),
     r"^/path t row 1: not finite \(nan\)"),
    ("path t not increasing", lambda w: _path(w, t=[0, 1, 1, 2]),
     r"^/path t row 2: 1 is not after row 1's 1 \(times must increase strictly\)"),
    ("path t not increasing across calls",
     lambda w: (_path(w), _path(w, t=[2, 3, 4, 5])),
     r"^/path t row 4: 2 is not after row 3's 2"),
    ("path position not finite", lambda w: _path(w, position=_bad(P[1], 2, 1, np.inf)),
     r"^/path x, y, z row 2: not finite"),
    ("path position shape", lambda w: _path(w, position=P[1][:, :2]),
     r"^/path x, y, z: shape \(4, 2\), expected \(4, 3\)"),
    ("path orientation shape", lambda w: _path(w, orientation=P[2][:3]),
     r"^/path qw, qx, qy, qz: shape \(3, 4\), expected \(4, 4\)"),
    ("path quaternion not unit", lambda w: _path(w, orientation=_bad(P[2], 3, 0, 0.5)),
     r"^/path qw, qx, qy, qz row 3: quaternion .* has norm 0\.5.*, not within 0\.001 of 1"),
    ("path quaternion not finite", lambda w: _path(w, orientation=_bad(P[2], 0, 2, np.nan)),
     r"^/path qw, qx, qy, qz row 0: not finite"),
    ("path as text", lambda w: _path(w, t=["a", "b", "c", "d"]), r"^/path t: not numbers"),
    ("path_cov shape", lambda w: _path(w, cov=P[3][:, :6]),
     r"^/path_cov: shape \(4, 6\), expected \(4, 12\)"),
    ("path_cov not finite", lambda w: _path(w, cov=_bad(P[3], 1, 4, np.nan)),
     r"^/path_cov row 1: not finite"),
    ("path_cov overflows float32", lambda w: _path(w, cov=_bad(P[3], 2, 1, 1e300)),
     r"^/path_cov row 2: not finite"),
    ("path_cov negative variance", lambda w: _path(w, cov=_bad(P[3], 1, 9, -1.0)),
     r"^/path_cov row 1: negative variance -1 in column 9"),
    ("path_cov on some poses only", lambda w: (_path(w), _path(w, t=[3, 4, 5, 6], cov=None)),
     r"^/path_cov row 4: every pose has a covariance or none does"),
    ("path_cov added later", lambda w: (_path(w, cov=None), _path(w, t=[3, 4, 5, 6])),
     r"^/path_cov row 4: every pose has a covariance or none does"),
    ("no path", lambda w: w.close(), r"^/path: no poses \(a scan has at least one\)"),
    # sensors
    ("sensor name with /", lambda w: _sensor(w, name="a/b"),
     r"^/sensors: sensor name 'a/b' is not a valid HDF5 name"),
    ("sensor name empty", lambda w: _sensor(w, name=""), r"^/sensors: sensor name ''"),
    ("sensor name .", lambda w: _sensor(w, name="."), r"^/sensors: sensor name '\.'"),
    ("sensor name twice", lambda w: (_sensor(w), _sensor(w)),
     r"^/sensors/s: a sensor of that name was already added"),
    ("sensor kind", lambda w: _sensor(w, kind="lidar"),
     r"^/sensors/s attribute kind: 'lidar', expected one of line, grid, points"),
    ("grid without rows", lambda w: _sensor(w, kind="grid", cols=3),
     r"^/sensors/s attributes rows, cols: a grid sensor needs both"),
    ("grid rows 0", lambda w: _sensor(w, kind="grid", rows=0, cols=3),
     r"^/sensors/s attribute rows: 0 is not a positive integer"),
    ("grid cols not an integer", lambda w: _sensor(w, kind="grid", rows=2, cols=2.5),
     r"^/sensors/s attribute cols: 2\.5 is not an integer"),
    ("rows on a line sensor", lambda w: _sensor(w, rows=2, cols=3),
     r"^/sensors/s attributes rows, cols: only a grid sensor has them \(kind is 'line'\)"),
    ("R_s2c scaled", lambda w: _sensor(w, R_s2c=2 * np.eye(3)),
     r"^/sensors/s attribute R_s2c: not a rotation"),
    ("R_s2c a reflection", lambda w: _sensor(w, R_s2c=np.diag([1.0, 1.0, -1.0])),
     r"^/sensors/s attribute R_s2c: not a rotation"),
    ("R_s2c size", lambda w: _sensor(w, R_s2c=[1, 0, 0, 0, 1, 0]),
     r"^/sensors/s attribute R_s2c: 6 values, expected a 3×3 rotation"),
    ("R_s2c not finite", lambda w: _sensor(w, R_s2c=_bad(np.eye(3), 0, 0, np.nan)),
     r"^/sensors/s attribute R_s2c: not finite"),
    ("T_s2c size", lambda w: _sensor(w, T_s2c=[0, 0]),
     r"^/sensors/s attribute T_s2c: 2 values, expected 3"),
    ("T_s2c not finite", lambda w: _sensor(w, T_s2c=[0, np.inf, 0]),
     r"^/sensors/s attribute T_s2c: not finite"),
    ("sigma_t negative", lambda w: _sensor(w, sigma_t=-1e-3),
     r"^/sensors/s attribute sigma_t: -0\.001 must be ≥ 0"),
    ("sigma_t not finite", lambda w: _sensor(w, sigma_t=np.nan),
     r"^/sensors/s attribute sigma_t: nan is not finite"),
    ("range_sigma negative", lambda w: _sensor(w, range_sigma=(0.01, -0.1)),
     r"^/sensors/s attribute range_sigma: .* must be finite and ≥ 0"),
    ("range_sigma size", lambda w: _sensor(w, range_sigma=(0.01, 0, 0)),
     r"^/sensors/s attribute range_sigma: 3 values, expected 2"),
    ("max_range zero", lambda w: _sensor(w, max_range=0),
     r"^/sensors/s attribute max_range: 0 must be > 0"),
    ("max_range infinite", lambda w: _sensor(w, max_range=np.inf),
     r"^/sensors/s attribute max_range: inf is not finite"),
    # frames and points
    ("frame of an unknown sensor", lambda w: (_sensors(w), w.add_frame("x", 0.5, np.ones((2, 3)))),
     r"^/sensors/x: no such sensor \(add_sensor first\)"),
    ("frame of an unknown index", lambda w: (_sensors(w), w.add_frame(5, 0.5, np.ones((2, 3)))),
     r"^/sensors: no sensor with index 5 \(2 added\)"),
    ("frame t not finite", lambda w: (_sensors(w), w.add_frame("l", np.nan, np.ones((2, 3)))),
     r"^/sensors/l/frames t row 0: not finite"),
    ("frame t not increasing",
     lambda w: (_sensors(w), w.add_frame("l", 0.5, np.ones((2, 3))),
                w.add_frame("l", 0.5, np.ones((2, 3)))),
     r"^/sensors/l/frames t row 1: 0\.5 is not after row 0's 0\.5"),
    ("frame before the path",
     lambda w: (_sensors(w), w.add_frame("l", -1.0, np.ones((2, 3)))),
     r"^/sensors/l/frames t row 0: -1 is before the path's first time 0 \(no pose"),
    ("frame before a path written later",
     lambda w: (_sensor(w, name="l"), w.add_frame("l", -1.0, np.ones((2, 3))), _with_path(w)),
     r"^/sensors/l/frames t row 0: -1 is before the path's first time 0"),
    ("frame after the path",
     lambda w: (_sensors(w), w.add_frame("l", 2.5, np.ones((2, 3))), w.close()),
     r"^/sensors/l/frames t row 0: 2\.5 is after the path's last time 2 \(no pose"),
    ("grid frame size", lambda w: (_sensors(w), w.add_frame("g", 0.5, np.ones((5, 3)))),
     r"^/sensors/g/frames count row 0: a grid frame has 5 rays, expected rows × cols = 2 × 3"),
    ("grid frames in bulk",
     lambda w: (_sensors(w), w.add_frames("g", [0.5, 0.6], [6, 3], np.ones((9, 3)))),
     r"^/sensors/g/frames count row 1: a grid frame has 3 rays"),
    ("points partly NaN",
     lambda w: (_sensors(w), w.add_frame("l", 0.5, _bad(np.ones((3, 3)), 1, 2, np.nan))),
     r"^/sensors/l/points row 1: point 1, 1, nan is partly non-finite \(a ray with no return "
     r"is a row of three NaN"),
    ("points infinite",
     lambda w: (_sensors(w), w.add_frame("l", 0.5, np.ones((2, 3))),
                w.add_frame("l", 0.6, _bad(np.ones((3, 3)), 2, 0, -np.inf))),
     r"^/sensors/l/points row 4: point -inf, 1, 1 is partly non-finite"),
    ("points overflow float32",
     lambda w: (_sensors(w), w.add_frame("l", 0.5, _bad(np.ones((3, 3)), 0, 0, 1e39))),
     r"^/sensors/l/points row 0: point inf, 1, 1 is partly non-finite"),
    ("points shape", lambda w: (_sensors(w), w.add_frame("l", 0.5, np.ones((3, 2)))),
     r"^/sensors/l/points: shape \(3, 2\), expected \(3, 3\)"),
    ("frames counts and times", lambda w: (_sensors(w), w.add_frames("l", [0.5, 0.6, 0.7],
                                                                      [1, 1], np.ones((2, 3)))),
     r"^/sensors/l/frames count: 2 counts for 3 times"),
    ("frames counts negative", lambda w: (_sensors(w), w.add_frames("l", [0.5, 0.6], [2, -1],
                                                                     np.ones((1, 3)))),
     r"^/sensors/l/frames count: .* must be integers"),
    ("frames points and counts", lambda w: (_sensors(w), w.add_frames("l", [0.5, 0.6], [2, 2],
                                                                       np.ones((3, 3)))),
     r"^/sensors/l/points: shape \(3, 3\), expected \(4, 3\)"),
    # magnetometer
    ("magnetometer not finite", lambda w: w.add_magnetometer([0, 1], [[1, 0, 0], [0, np.nan, 0]]),
     r"^/magnetometer mx, my, mz row 1: not finite"),
    ("magnetometer t not finite", lambda w: w.add_magnetometer([np.inf], [[1, 0, 0]]),
     r"^/magnetometer t row 0: not finite"),
    ("magnetometer shape", lambda w: w.add_magnetometer([0, 1], [[1, 0, 0]]),
     r"^/magnetometer mx, my, mz: shape \(1, 3\), expected \(2, 3\)"),
]


@pytest.mark.parametrize("what,call,message", REFUSED, ids=[r[0] for r in REFUSED])
def test_writer_refuses(tmp_path, what, call, message):
    path = tmp_path / "bad.h5"
    with pytest.raises(ValueError) as e:
        with ScanWriter(path) as w:
            call(w)
            w.close()
    assert re.search(message, str(e.value)), f"{what}: {e.value}"
    # Nothing is left, under the final name or the partial one.
    assert os.listdir(tmp_path) == []


def test_writer_accepts_the_limits(tmp_path, carvemap_bin):
    """The edges §3 allows: a quaternion norm 0.0009 off 1, negative covariances off the
    diagonal, zero variances, one pose, frames at the path's first and last times, a frame
    without rays, a scan without sensors."""
    path = tmp_path / "edge.h5"
    with ScanWriter(path) as w:
        c = np.zeros((1, 12))
        c[0, 1] = -1e-3
        w.add_path([5.0], [[1, 2, 3]], [[1.0009, 0, 0, 0]], c)
        _sensor(w, kind="points")
        w.add_frame("s", 5.0, np.zeros((0, 3)))
    assert run_carvemap("validate", path).stdout.strip().endswith("valid")
    assert read_scan(path).sensor("s").frame_count == 1
    path2 = tmp_path / "path_only.h5"
    with ScanWriter(path2) as w:
        t, position, orientation, _ = path_arrays()
        w.add_path(t, position, orientation)
        w.add_sensor("first", "line", np.eye(3), [0, 0, 0], 0, (0, 0), 1)
        w.add_frame("first", 0.0, np.ones((1, 3)))
        w.add_frame("first", 2.0, np.ones((1, 3)))
    assert run_carvemap("validate", path2).stdout.strip().endswith("valid")
    assert read_scan(path2).path.covariance is None


def test_a_refused_call_changes_nothing(tmp_path, carvemap_bin):
    """A caller may catch the ValueError and go on: the refused rows were not written."""
    path = tmp_path / "go_on.h5"
    with ScanWriter(path) as w:
        _sensors(w)
        w.add_frame("l", 0.5, np.ones((2, 3)))
        with pytest.raises(ValueError):
            w.add_frame("l", 0.4, np.ones((2, 3)))
        with pytest.raises(ValueError):
            w.add_frame("l", 0.6, [[1, np.nan, 1]])
        w.add_frame("l", 0.6, np.ones((4, 3)))
    scan = read_scan(path)
    assert_same(scan.sensor("l").frame_t, [0.5, 0.6])
    assert_same(scan.sensor("l").frame_first, [0, 2])
    assert len(scan.sensor("l").points) == 6
    assert run_carvemap("validate", path).stdout.strip().endswith("valid")


# ---- what the reader refuses ------------------------------------------------------------------

def _rows(f, name, edit):
    rows = f[name][...]
    edit(rows)
    f[name][...] = rows


def _replace(f, name, data):
    del f[name]
    f.create_dataset(name, data=data)


def _set(arr_name, field, row, value):
    def edit(rows):
        rows[field][row] = value
    return lambda f: _rows(f, arr_name, edit)


def _set_cell(name, row, col, value):
    def edit(rows):
        rows[row, col] = value
    return lambda f: _rows(f, name, edit)


def _rename_path_field(f):
    rows = f["path"][...]
    names = list(rows.dtype.names)
    names[names.index("qw")] = "w"
    rows.dtype.names = names
    _replace(f, "path", rows)


# (what, change, our message, the C++ validator's message or None where it does not check).
BROKEN = [
    ("format", lambda f: f.attrs.__setitem__("format", "other"),
     r"/: format is 'other', expected 'carvemap-scan'", r"format is 'other'"),
    ("version 2", lambda f: f.attrs.__setitem__("version", 2),
     r"unknown format version 2", r"unknown format version 2"),
    ("version as a float", lambda f: f.attrs.__setitem__("version", 1.0),
     r"/: attribute 'version' is not a single integer", r"'version' is not a single integer"),
    ("no path", lambda f: f.__delitem__("path"), r"/path: missing", r"/path: missing"),
    ("path field missing", _rename_path_field, r"/path: missing field 'qw'",
     r"/path: missing field 'qw'"),
    ("path t not increasing", _set("path", "t", 3, 0.1),
     r"/path t row 3: 0\.1.* is not after row 2's", r"/path row 3: time 0\.1 is not after"),
    ("path not finite", _set("path", "y", 2, np.nan), r"/path row 2: not finite",
     r"/path row 2: non-finite value"),
    ("path quaternion", _set("path", "qx", 4, 0.5), r"/path qw, qx, qy, qz row 4: quaternion",
     r"/path row 4: non-unit quaternion"),
    ("path_cov negative variance", _set_cell("path_cov", 1, 0, -1.0),
     r"/path_cov row 1: negative variance -1 in column 0", r"/path_cov row 1: negative variance"),
    ("path_cov not finite", _set_cell("path_cov", 6, 11, np.inf), r"/path_cov row 6: not finite",
     r"/path_cov row 6: non-finite value"),
    ("path_cov rows", lambda f: _replace(f, "path_cov", f["path_cov"][:-1]),
     r"/path_cov: 20 rows, but /path has 21", r"/path_cov: 20 rows, but /path has 21"),
    ("magnetometer not finite", _set("magnetometer", "my", 0, np.nan),
     r"/magnetometer row 0: not finite", r"/magnetometer row 0: non-finite value"),
    ("sensor kind", lambda f: f["sensors/zeta"].attrs.__setitem__("kind", "lidar"),
     r"/sensors/zeta attribute kind: 'lidar'", r"/sensors/zeta: kind is 'lidar'"),
    ("grid rows 0", lambda f: f["sensors/cam"].attrs.__setitem__("rows", 0),
     r"/sensors/cam attribute rows: 0 is not a positive integer",
     r"/sensors/cam: attribute 'rows' is 0"),
    ("grid frame size", _set("sensors/cam/frames", "count", 0, 5),
     r"/sensors/cam/frames count row 0: a grid frame has 5 rays",
     r"/sensors/cam/frames row 0: grid frame has 5 rays"),
    ("frame outside the path", _set("sensors/zeta/frames", "t", 4, 2.5),
     r"/sensors/zeta/frames t row 4: 2\.5 is outside the path's time span \[0, 2\]",
     r"/sensors/zeta/frames row 4: time 2\.5 is outside the path's time span"),
    ("frame t not increasing", _set("sensors/zeta/frames", "t", 2, 0.2),
     r"/sensors/zeta/frames t row 2: 0\.2.* is not after row 1's",
     r"/sensors/zeta/frames row 2: time 0\.2 is not after"),
    ("frame beyond the points", _set("sensors/alpha/frames", "first", 2, 8),
     r"/sensors/alpha/frames row 2: rays \[8, 14\) outside /sensors/alpha/points \(10 rows\)",
     r"/sensors/alpha/frames row 2: rays \[8, 14\) outside /sensors/alpha/points"),
    ("point partly NaN", _set_cell("sensors/pts/points", 3, 1, np.nan),
     r"/sensors/pts/points row 3: point .* is partly non-finite",
     r"/sensors/pts/points row 3: point .* is partly non-finite"),
    ("points with 2 columns", lambda f: _replace(f, "sensors/pts/points",
                                                 f["sensors/pts/points"][:, :2]),
     r"/sensors/pts/points: shape \(7, 2\), expected \[N\]\[3\]",
     r"/sensors/pts/points: shape \[7\]\[2\], expected \[N\]\[3\]"),
    # §3's rules that `carvemap validate` does not check (storage/scan_reader.cc): None.
    ("R_s2c not a rotation",
     lambda f: f["sensors/zeta"].attrs.__setitem__("R_s2c", 2 * np.eye(3).reshape(9)),
     r"/sensors/zeta attribute R_s2c: not a rotation", None),
    ("sigma_t negative", lambda f: f["sensors/zeta"].attrs.__setitem__("sigma_t", -1.0),
     r"/sensors/zeta attribute sigma_t: -1 must be ≥ 0", None),
    ("range_sigma negative",
     lambda f: f["sensors/zeta"].attrs.__setitem__("range_sigma", [-0.01, 0.0]),
     r"/sensors/zeta attribute range_sigma: .* must be finite and ≥ 0", None),
    ("max_range zero", lambda f: f["sensors/zeta"].attrs.__setitem__("max_range", 0.0),
     r"/sensors/zeta attribute max_range: 0 must be > 0", None),
    ("R_s2c not finite", lambda f: f["sensors/zeta"].attrs.__setitem__("R_s2c", np.full(9, np.nan)),
     r"/sensors/zeta attribute R_s2c: not finite", None),
    ("T_s2c not finite", lambda f: f["sensors/zeta"].attrs.__setitem__("T_s2c", [0, np.nan, 0]),
     r"/sensors/zeta attribute T_s2c: not finite", None),
    ("sigma_t not finite", lambda f: f["sensors/zeta"].attrs.__setitem__("sigma_t", np.inf),
     r"/sensors/zeta attribute sigma_t: inf is not finite", None),
]


@pytest.mark.parametrize("what,change,ours,cpp", BROKEN, ids=[b[0] for b in BROKEN])
def test_reader_refuses(full, carvemap_bin, what, change, ours, cpp):
    path, _ = full
    with h5py.File(path, "r+") as f:
        change(f)
    with pytest.raises(ValueError) as e:
        ScanReader(path)
    assert str(e.value).startswith(f"{path}: "), e.value
    assert re.search(ours, str(e.value)), f"{what}: {e.value}"
    r = run_carvemap("validate", path, check=False)
    if cpp is not None:
        assert r.returncode != 0, f"{what}: carvemap validate accepted it:\n{r.stdout}"
        assert re.search(cpp, r.stdout + r.stderr), f"{what}: {r.stdout}{r.stderr}"


def test_reader_reads_what_a_foreign_writer_may_write(tmp_path, carvemap_bin):
    """§3 lets a writer reorder and pad compound fields, use fixed-length strings, other
    numeric types, and not track the sensors' creation order (then: names in order)."""
    path = tmp_path / "foreign.h5"
    t, position, orientation, cov = path_arrays()
    with h5py.File(path, "w") as f:
        f.attrs["format"] = np.bytes_(b"carvemap-scan")  # fixed-length
        f.attrs["version"] = np.int32(1)
        padded = np.dtype({"names": ["qz", "qy", "qx", "qw", "z", "y", "x", "t"],
                           "formats": ["<f8"] * 8, "offsets": [8 * i for i in range(8)],
                           "itemsize": 72})
        rows = np.zeros(len(t), padded)
        rows["t"] = t
        for i, n in enumerate("xyz"):
            rows[n] = position[:, i]
        for i, n in enumerate(("qw", "qx", "qy", "qz")):
            rows[n] = orientation[:, i]
        f["path"] = rows
        f["path_cov"] = cov  # float64
        s = f.create_group("sensors")  # h5py's default: creation order not tracked
        for name, shift in (("zz", 0.0), ("aa", 0.5)):
            g = s.create_group(name)
            g.attrs["kind"] = np.bytes_(b"points")
            g.attrs["R_s2c"] = np.eye(3, dtype=np.float32).reshape(9)
            g.attrs["T_s2c"] = np.array([0, 0, 1], dtype=np.int32)
            g.attrs["sigma_t"] = np.array([0.001])
            g.attrs["range_sigma"] = [0.01, 0.0]
            g.attrs["max_range"] = 10
            fr = np.zeros(2, [("count", "<u2"), ("t", "<f4"), ("first", "<i8")])
            fr["t"] = [0.25 + shift, 1.25 + shift]
            fr["first"] = [0, 2]
            fr["count"] = [2, 1]
            g["frames"] = fr
            g["points"] = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    assert run_carvemap("validate", path).stdout.strip().endswith("valid")
    scan = read_scan(path)
    assert [s.name for s in scan.sensors] == ["aa", "zz"]
    assert_same(scan.path.orientation, orientation)
    aa = scan.sensor("aa")
    assert aa.kind == "points" and aa.max_range == 10.0
    assert_same(aa.frame_t, [0.75, 1.75])
    assert_same(aa.frame(1)[1], [[0, 0, 1]])
    assert_same(aa.T_s2c, [0, 0, 1])
    # And written back out in the format's own types.
    write_scan(tmp_path / "ours.h5", scan)
    assert run_carvemap("validate", tmp_path / "ours.h5").stdout.strip().endswith("valid")


def test_reader_refuses_what_is_not_a_scan(tmp_path):
    text = tmp_path / "scan.h5"
    text.write_text("not HDF5")
    with pytest.raises(ValueError, match="not an HDF5 file"):
        ScanReader(text)
    with pytest.raises(FileNotFoundError):
        ScanReader(tmp_path / "missing.h5")
    empty = tmp_path / "empty.h5"
    h5py.File(empty, "w").close()
    with pytest.raises(ValueError, match=r"/: attribute 'format' missing"):
        ScanReader(empty)


def test_partial_file_is_not_a_scan_until_closed(tmp_path):
    path = tmp_path / "scan.h5"
    w = ScanWriter(path)
    _with_path(w)
    assert not path.exists() and (tmp_path / "scan.h5.partial").exists()
    w.close()
    assert path.exists() and not (tmp_path / "scan.h5.partial").exists()
    with pytest.raises(ValueError, match="writer is closed"):
        _with_path(w)
    shutil.copy(path, tmp_path / "copy.h5")
    assert read_scan(tmp_path / "copy.h5").path.t[-1] == 2.0
