"""scan.h5, carvemap's input (format "carvemap-scan", version 1; docs/DESIGN.md §3).

ScanWriter writes the format from numpy arrays (the path, then per sensor its frames) and
refuses what §3 forbids with a ValueError naming the dataset, the field and the row, before
anything wrong reaches the file. ScanReader reads a file back into numpy arrays and checks the
same rules. Convert LAS, E57, bags or anything else in your own script: read it with the
library of your choice and hand the arrays to ScanWriter.

Units: metres, seconds, radians. The world frame is right-handed with z up (east, north, up);
the system (the backpack) has x forward, y left, z up. Orientations are quaternions
(qw, qx, qy, qz), system ➜ world.
"""
import dataclasses
import math
import os
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

try:
    import h5py
except ImportError as e:  # h5py is not declared to pip: see pyproject.toml
    raise ImportError(f"{e}: carvemap.scan needs h5py (Debian: python3-h5py)") from e

FORMAT = "carvemap-scan"
VERSION = 1
KINDS = ("line", "grid", "points")

PATH_DTYPE = np.dtype([(n, "<f8") for n in ("t", "x", "y", "z", "qw", "qx", "qy", "qz")])
FRAME_DTYPE = np.dtype([("t", "<f8"), ("first", "<u8"), ("count", "<u4")])
MAGNETOMETER_DTYPE = np.dtype([(n, "<f8") for n in ("t", "mx", "my", "mz")])

# §3: |q| within 1e-3 of 1.
QUATERNION_TOLERANCE = 1e-3
# §3 only says "a rotation"; tests/tools/independent_reader.py holds R·Rᵀ to the identity and
# det R to 1 within 1e-6, so the writer does too (a file it writes passes both readers).
ROTATION_TOLERANCE = 1e-6
# The variances of /path_cov: xx yy zz of the position block, then of the rotation block.
COVARIANCE_DIAGONAL = (0, 3, 5, 6, 9, 11)
POSITION_FIELDS = ("x", "y", "z")
QUATERNION_FIELDS = ("qw", "qx", "qy", "qz")
MAX_FRAME_RAYS = 2**32 - 1  # frames.count is a u32

# Rows per chunk of each dataset, as the C++ writer (storage/scan_writer.cc): ~100-200 KiB.
_PATH_CHUNK = 2048
_FRAME_CHUNK = 4096
_POINT_CHUNK = 16384
# Appends are buffered up to this many bytes per dataset, then written in one piece.
_BUFFER_BYTES = 1 << 20
# Rows per block when a file is validated: memory stays bounded whatever its size.
_BLOCK_ROWS = 1 << 18


# ---- the rules, shared by the writer (on its arguments) and the reader (on a file) ----------

def _rows(mask):
    return np.flatnonzero(mask)


def _first(mask):
    """Index of the first True in a 1-D mask, or None."""
    rows = _rows(mask)
    return int(rows[0]) if len(rows) else None


def _check_grid_counts(counts, sensor, where, first_row):
    """A grid sensor's frames each hold rows × cols rays (§3), as writer and reader check."""
    if sensor.kind != "grid":
        return
    row = _first(counts != sensor.rows * sensor.cols)
    if row is not None:
        raise ValueError(f"{where} count row {first_row + row}: a grid frame has "
                         f"{int(counts[row])} rays, expected rows × cols = {sensor.rows} × "
                         f"{sensor.cols}")


def _as_float(value, where, dtype=np.float64):
    try:
        with np.errstate(over="ignore"):  # an overflow becomes inf, refused by the checks
            return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: not numbers ({e})") from None


def _check_finite(values, where, first_row=0):
    """values: (N,) or (N, k); the first row holding a NaN or an infinity is refused."""
    bad = ~np.isfinite(values)
    if bad.ndim > 1:
        bad = bad.any(axis=tuple(range(1, bad.ndim)))
    row = _first(bad)
    if row is not None:
        raise ValueError(f"{where} row {first_row + row}: not finite ({_show(values[row])})")


def _check_increasing(t, where, previous=None, first_row=0):
    """t strictly increasing, and after `previous` (the last time of earlier rows)."""
    if previous is not None and len(t) and not t[0] > previous:
        raise ValueError(f"{where} row {first_row}: {_num(t[0])} is not after row "
                         f"{first_row - 1}'s {_num(previous)} (times must increase strictly)")
    row = _first(~(np.diff(t) > 0))
    if row is not None:
        raise ValueError(f"{where} row {first_row + row + 1}: {_num(t[row + 1])} is not after "
                         f"row {first_row + row}'s {_num(t[row])} (times must increase strictly)")


def _check_quaternions(q, where, first_row=0):
    norm = np.sqrt(np.sum(q * q, axis=1))
    row = _first(~(np.abs(norm - 1.0) <= QUATERNION_TOLERANCE))
    if row is not None:
        raise ValueError(f"{where} row {first_row + row}: quaternion {_show(q[row])} has norm "
                         f"{norm[row]:.6g}, not within {QUATERNION_TOLERANCE:g} of 1 (a unit "
                         "quaternion, system ➜ world)")


def _check_covariance(c, where, first_row=0):
    _check_finite(c, where, first_row)
    diagonal = c[:, COVARIANCE_DIAGONAL]
    bad = diagonal < 0
    row = _first(bad.any(axis=1))
    if row is not None:
        col = COVARIANCE_DIAGONAL[int(np.argmax(bad[row]))]
        raise ValueError(f"{where} row {first_row + row}: negative variance {_num(c[row, col])} "
                         f"in column {col} (the variances, columns 0 3 5 6 9 11, may not be "
                         "negative)")


def _check_points(p, where, first_row=0):
    """A row is a return (three finite values) or a ray with no return (three NaN)."""
    finite = np.isfinite(p).all(axis=1)
    no_return = np.isnan(p).all(axis=1)
    row = _first(~(finite | no_return))
    if row is not None:
        raise ValueError(f"{where} row {first_row + row}: point {_show(p[row])} is partly "
                         "non-finite (a ray with no return is a row of three NaN; float32 "
                         "holds at most 3.4e38)")


def _check_sensor_name(name):
    if not isinstance(name, str) or not name or name in (".", "..") or "/" in name \
            or "\0" in name:
        raise ValueError(f"/sensors: sensor name {name!r} is not a valid HDF5 name (a "
                         "non-empty string without '/')")


def _check_int(value, where):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{where}: {value!r} is not an integer")
    if not 0 < int(value) <= MAX_FRAME_RAYS:
        raise ValueError(f"{where}: {value} is not a positive integer")
    return int(value)


def _check_scalar(value, where, minimum=None, strict=False):
    v = _as_float(value, where).reshape(-1)
    if v.shape != (1,):
        raise ValueError(f"{where}: {v.size} values, expected one number")
    v = float(v[0])
    if not math.isfinite(v):
        raise ValueError(f"{where}: {v} is not finite")
    if minimum is not None and (v <= minimum if strict else v < minimum):
        raise ValueError(f"{where}: {v:g} must be {'>' if strict else '≥'} {minimum:g}")
    return v


def check_sensor(name, kind, R_s2c, T_s2c, sigma_t, range_sigma, max_range, rows=None,
                 cols=None):
    """The sensor's attributes checked against §3 and normalized: (kind, rows, cols,
    R_s2c (3, 3), T_s2c (3,), sigma_t, range_sigma (2,), max_range). ValueError otherwise."""
    _check_sensor_name(name)
    g = f"/sensors/{name}"
    if kind not in KINDS:
        raise ValueError(f"{g} attribute kind: {kind!r}, expected one of {', '.join(KINDS)}")
    if kind == "grid":
        if rows is None or cols is None:
            raise ValueError(f"{g} attributes rows, cols: a grid sensor needs both (its frames "
                             "are rows × cols images)")
        rows = _check_int(rows, f"{g} attribute rows")
        cols = _check_int(cols, f"{g} attribute cols")
        if rows * cols > MAX_FRAME_RAYS:
            raise ValueError(f"{g} attributes rows, cols: {rows} × {cols} rays do not fit a "
                             "frame's u32 count")
    elif rows is not None or cols is not None:
        raise ValueError(f"{g} attributes rows, cols: only a grid sensor has them (kind is "
                         f"{kind!r})")
    R = _as_float(R_s2c, f"{g} attribute R_s2c")
    if R.size != 9:
        raise ValueError(f"{g} attribute R_s2c: {R.size} values, expected a 3×3 rotation "
                         "(9 values, row-major)")
    R = R.reshape(3, 3)
    if not np.isfinite(R).all():
        raise ValueError(f"{g} attribute R_s2c: not finite ({_show(R.reshape(-1))})")
    off = max(np.abs(R @ R.T - np.eye(3)).max(), abs(np.linalg.det(R) - 1.0))
    if not off <= ROTATION_TOLERANCE:
        raise ValueError(f"{g} attribute R_s2c: not a rotation (R·Rᵀ or det R off by "
                         f"{off:.3g}, more than {ROTATION_TOLERANCE:g}); row-major, sensor ➜ "
                         "system")
    T = _as_float(T_s2c, f"{g} attribute T_s2c").reshape(-1)
    if T.shape != (3,):
        raise ValueError(f"{g} attribute T_s2c: {T.size} values, expected 3 (the sensor's "
                         "origin in the system frame, m)")
    if not np.isfinite(T).all():
        raise ValueError(f"{g} attribute T_s2c: not finite ({_show(T)})")
    sigma_t = _check_scalar(sigma_t, f"{g} attribute sigma_t", minimum=0.0)
    rs = _as_float(range_sigma, f"{g} attribute range_sigma").reshape(-1)
    if rs.shape != (2,):
        raise ValueError(f"{g} attribute range_sigma: {rs.size} values, expected 2 (a, b: "
                         "the range noise a + b·range)")
    if not np.isfinite(rs).all() or (rs < 0).any():
        raise ValueError(f"{g} attribute range_sigma: {_show(rs)} must be finite and ≥ 0")
    max_range = _check_scalar(max_range, f"{g} attribute max_range", minimum=0.0, strict=True)
    return kind, rows, cols, R, T, sigma_t, rs, max_range


def _num(v):
    return f"{float(v):.17g}"


def _show(v):
    return ", ".join(f"{float(x):.9g}" for x in np.asarray(v).reshape(-1))


# ---- plain data -------------------------------------------------------------------------

@dataclass
class Path:
    """/path (and /path_cov): t (N,), position (N, 3) x y z, orientation (N, 4) qw qx qy qz
    (system ➜ world), covariance (N, 12) float32 or None."""
    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    covariance: Optional[np.ndarray] = None


@dataclass
class Sensor:
    """A sensor group: its attributes, and (when read whole) its frames and points. Frame i is
    points[first[i] : first[i] + count[i]], at time frame_t[i]; a row of NaN has no return."""
    name: str
    kind: str
    R_s2c: np.ndarray
    T_s2c: np.ndarray
    sigma_t: float
    range_sigma: np.ndarray
    max_range: float
    rows: Optional[int] = None
    cols: Optional[int] = None
    frame_count: int = 0
    point_count: int = 0
    frame_t: Optional[np.ndarray] = None
    frame_first: Optional[np.ndarray] = None
    frame_rays: Optional[np.ndarray] = None
    points: Optional[np.ndarray] = None

    def frame(self, i):
        """(t, points (count, 3) float32) of frame i of a sensor read whole."""
        first = int(self.frame_first[i])
        return float(self.frame_t[i]), self.points[first:first + int(self.frame_rays[i])]

    def attributes(self):
        """The keyword arguments of ScanWriter.add_sensor for this sensor."""
        return dict(name=self.name, kind=self.kind, R_s2c=self.R_s2c, T_s2c=self.T_s2c,
                    sigma_t=self.sigma_t, range_sigma=self.range_sigma,
                    max_range=self.max_range, rows=self.rows, cols=self.cols)


@dataclass
class Magnetometer:
    """/magnetometer: t (K,), field (K, 3) mx my mz in the system frame."""
    t: np.ndarray
    field: np.ndarray


@dataclass
class Scan:
    path: Path
    sensors: list = field(default_factory=list)
    magnetometer: Optional[Magnetometer] = None

    def sensor(self, name):
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(name)


# ---- writing ----------------------------------------------------------------------------

class _Appender:
    """Buffered appends to an extendible dataset of rows."""

    def __init__(self, dataset):
        self.dataset = dataset
        self.written = 0
        self.parts = []
        self.buffered = 0
        self.row_bytes = dataset.dtype.itemsize * int(np.prod(dataset.shape[1:], dtype=int))

    @property
    def rows(self):
        return self.written + self.buffered

    def append(self, rows):
        if len(rows) == 0:
            return
        self.parts.append(rows)
        self.buffered += len(rows)
        if self.buffered * self.row_bytes >= _BUFFER_BYTES:
            self.flush()

    def flush(self):
        if not self.buffered:
            return
        rows = self.parts[0] if len(self.parts) == 1 else np.concatenate(self.parts)
        self.dataset.resize(self.written + len(rows), axis=0)
        self.dataset[self.written:] = rows
        self.written += len(rows)
        self.parts, self.buffered = [], 0


class _SensorState:
    def __init__(self, name, kind, rows, cols, frames, points):
        self.name, self.kind, self.rows, self.cols = name, kind, rows, cols
        self.frames, self.points = frames, points
        self.first_t = None
        self.last_t = None


def _create_group(parent, name, track_order):
    """A group without time stamps (equal content, equal bytes); links in creation order when
    track_order (§3: sensors are indexed in the group's creation order)."""
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    gcpl.set_obj_track_times(False)
    if track_order:
        gcpl.set_link_creation_order(h5py.h5p.CRT_ORDER_TRACKED | h5py.h5p.CRT_ORDER_INDEXED)
    lcpl = h5py.h5p.create(h5py.h5p.LINK_CREATE)
    lcpl.set_char_encoding(h5py.h5t.CSET_UTF8)
    h5py.h5g.create(parent.id, name.encode(), lcpl=lcpl, gcpl=gcpl)
    return parent[name]


def _create_rows(parent, name, dtype, cols, chunk_rows):
    shape = (0,) if cols == 0 else (0, cols)
    maxshape = (None,) if cols == 0 else (None, cols)
    chunks = (chunk_rows,) if cols == 0 else (chunk_rows, cols)
    return parent.create_dataset(name, shape=shape, maxshape=maxshape, dtype=dtype,
                                 chunks=chunks, track_times=False)


class ScanWriter:
    """Writes scan.h5 from numpy arrays, refusing what docs/DESIGN.md §3 forbids.

        with ScanWriter("scan.h5") as w:
            w.add_path(t, position, orientation, covariance=None)
            w.add_sensor("h0", "line", R_s2c=np.eye(3), T_s2c=[0, 0, 0.2], sigma_t=1e-3,
                         range_sigma=(0.01, 0.001), max_range=30.0)
            for t_i, points_i in frames:            # points in the sensor frame, (n, 3)
                w.add_frame("h0", t_i, points_i)

    Everything may be appended in any number of calls (times increasing across calls). The
    folder is made if missing. Data goes to "<path>.partial", renamed to `path` by close(): a
    file under the final name is complete and valid. Leaving the `with` block by an exception
    removes the partial file.
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self._partial = self.path + ".partial"
        os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)
        fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
        fcpl.set_obj_track_times(False)  # the root group too: no time stamps anywhere
        fid = h5py.h5f.create(self._partial.encode(), h5py.h5f.ACC_TRUNC, fcpl=fcpl)
        self._file = h5py.File(fid)
        self._file.attrs["format"] = FORMAT
        self._file.attrs["version"] = np.int64(VERSION)
        self._path = _Appender(_create_rows(self._file, "path", PATH_DTYPE, 0, _PATH_CHUNK))
        self._cov = None
        self._has_cov = None  # decided by the first add_path
        self._last_pose_t = None
        self._first_pose_t = None
        self._sensors_group = _create_group(self._file, "sensors", track_order=True)
        self._sensors = {}
        self._magnetometer = None
        self._closed = False

    # -- context
    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        if kind is None:
            self.close()
        else:
            self.abort()
        return False

    def _check_open(self):
        if self._closed:
            raise ValueError(f"{self.path}: the writer is closed")

    # -- path
    def add_path(self, t, position, orientation, covariance=None):
        """Appends poses to /path: t (N,) s, position (N, 3) m, orientation (N, 4) as
        (qw, qx, qy, qz), system ➜ world; covariance (N, 12) to /path_cov (position xx xy xz
        yy yz zz in m², then rotation in rad²; every pose has one or none does)."""
        self._check_open()
        first = self._path.rows
        t = _as_float(t, "/path t").reshape(-1)
        n = len(t)
        position = _as_float(position, "/path x, y, z")
        orientation = _as_float(orientation, "/path qw, qx, qy, qz")
        if position.shape != (n, 3):
            raise ValueError(f"/path x, y, z: shape {position.shape}, expected ({n}, 3) for "
                             f"{n} times")
        if orientation.shape != (n, 4):
            raise ValueError(f"/path qw, qx, qy, qz: shape {orientation.shape}, expected "
                             f"({n}, 4) for {n} times")
        _check_finite(t, "/path t", first)
        _check_finite(position, "/path x, y, z", first)
        _check_finite(orientation, "/path qw, qx, qy, qz", first)
        _check_increasing(t, "/path t", self._last_pose_t, first)
        _check_quaternions(orientation, "/path qw, qx, qy, qz", first)
        cov = None
        if covariance is not None:
            cov = _as_float(covariance, "/path_cov", np.float32)
            if cov.shape != (n, 12):
                raise ValueError(f"/path_cov: shape {cov.shape}, expected ({n}, 12): one row "
                                 "per pose")
            with np.errstate(over="ignore"):
                _check_covariance(cov, "/path_cov", first)
        if n == 0:
            return
        if self._has_cov is not None and self._has_cov != (cov is not None):
            raise ValueError(f"/path_cov row {first}: every pose has a covariance or none "
                             f"does (earlier poses {'had' if self._has_cov else 'had none'})")
        if self._first_pose_t is None:
            # A frame written before the path began can never lie in its span.
            for s in self._sensors.values():
                self._check_frame_after_path_start(s, s.first_t, 0, float(t[0]))
        rows = np.empty(n, PATH_DTYPE)
        rows["t"] = t
        for i, name in enumerate(POSITION_FIELDS):
            rows[name] = position[:, i]
        for i, name in enumerate(QUATERNION_FIELDS):
            rows[name] = orientation[:, i]
        if cov is not None and self._cov is None:
            self._cov = _Appender(_create_rows(self._file, "path_cov", "<f4", 12, _PATH_CHUNK))
        self._has_cov = cov is not None
        self._path.append(rows)
        if cov is not None:
            self._cov.append(cov)
        if self._first_pose_t is None:
            self._first_pose_t = float(t[0])
        self._last_pose_t = float(t[-1])

    # -- sensors
    def add_sensor(self, name, kind, R_s2c, T_s2c, sigma_t, range_sigma, max_range, rows=None,
                   cols=None):
        """Declares /sensors/<name>: kind "line" | "grid" | "points"; rows, cols for a grid
        (a frame is a rows × cols image, row-major); R_s2c a 3×3 rotation sensor ➜ system;
        T_s2c the sensor's origin in the system frame (m); sigma_t the frames' time stamp
        error (s); range_sigma (a, b): range noise a + b·range (m); max_range (m). Sensors are
        indexed in the order they are added. Returns the name."""
        self._check_open()
        kind, rows, cols, R, T, sigma_t, rs, max_range = check_sensor(
            name, kind, R_s2c, T_s2c, sigma_t, range_sigma, max_range, rows, cols)
        if name in self._sensors:
            raise ValueError(f"/sensors/{name}: a sensor of that name was already added")
        g = _create_group(self._sensors_group, name, track_order=False)
        g.attrs["kind"] = kind
        if kind == "grid":
            g.attrs["rows"] = np.int64(rows)
            g.attrs["cols"] = np.int64(cols)
        g.attrs["R_s2c"] = R.reshape(9).astype("<f8")  # row-major
        g.attrs["T_s2c"] = T.astype("<f8")
        g.attrs["sigma_t"] = np.float64(sigma_t)
        g.attrs["range_sigma"] = rs.astype("<f8")
        g.attrs["max_range"] = np.float64(max_range)
        frames = _Appender(_create_rows(g, "frames", FRAME_DTYPE, 0, _FRAME_CHUNK))
        points = _Appender(_create_rows(g, "points", "<f4", 3, _POINT_CHUNK))
        self._sensors[name] = _SensorState(name, kind, rows, cols, frames, points)
        return name

    def _sensor(self, sensor):
        if isinstance(sensor, (int, np.integer)) and not isinstance(sensor, bool):
            names = list(self._sensors)
            if not 0 <= sensor < len(names):
                raise ValueError(f"/sensors: no sensor with index {sensor} ({len(names)} added)")
            sensor = names[sensor]
        if sensor not in self._sensors:
            raise ValueError(f"/sensors/{sensor}: no such sensor (add_sensor first)")
        return self._sensors[sensor]

    def _check_frame_after_path_start(self, s, t, row, path_start=None):
        start = self._first_pose_t if path_start is None else path_start
        if t is not None and start is not None and t < start:
            raise ValueError(f"/sensors/{s.name}/frames t row {row}: {_num(t)} is before the "
                             f"path's first time {_num(start)} (no pose to interpolate)")

    def add_frame(self, sensor, t, points):
        """Appends one frame of `sensor` (its name or index) at time t: points (n, 3) in the
        sensor frame, m (a grid's may be (rows, cols, 3)); a row of three NaN is a ray with no
        return."""
        p = _as_float(points, f"/sensors/{sensor}/points")
        if p.ndim == 3:
            p = p.reshape(-1, 3)
        self.add_frames(sensor, [t], [len(p)] if p.ndim == 2 else [p.size // 3], p)

    def add_frames(self, sensor, t, counts, points):
        """Appends many frames of `sensor` at once: t (F,), counts (F,) rays per frame, and
        points (sum(counts), 3), the frames' rays one after another."""
        self._check_open()
        s = self._sensor(sensor)
        g = f"/sensors/{s.name}"
        first_row = s.frames.rows
        t = _as_float(t, f"{g}/frames t").reshape(-1)
        counts = np.asarray(counts).reshape(-1)
        if counts.shape != t.shape:
            raise ValueError(f"{g}/frames count: {counts.size} counts for {t.size} times")
        if counts.size and (counts.dtype.kind not in "iu" or (counts < 0).any()
                            or (counts > MAX_FRAME_RAYS).any()):
            raise ValueError(f"{g}/frames count: {_show(counts[:8])}… must be integers in "
                             f"[0, {MAX_FRAME_RAYS}]")
        counts = counts.astype(np.uint64)
        p = _as_float(points, f"{g}/points")
        if p.ndim == 3 and s.kind == "grid":
            p = p.reshape(-1, 3)
        total = int(counts.sum()) if counts.size else 0
        if p.ndim != 2 or p.shape[1] != 3 or len(p) != total:
            raise ValueError(f"{g}/points: shape {p.shape}, expected ({total}, 3): one row per "
                             "ray of the frames")
        _check_finite(t, f"{g}/frames t", first_row)
        _check_increasing(t, f"{g}/frames t", s.last_t, first_row)
        _check_grid_counts(counts, s, f"{g}/frames", first_row)
        with np.errstate(over="ignore", invalid="ignore"):
            p32 = p.astype(np.float32)
        _check_points(p32, f"{g}/points", s.points.rows)
        if len(t) == 0:
            return
        self._check_frame_after_path_start(s, float(t[0]), first_row)
        rows = np.empty(len(t), FRAME_DTYPE)
        rows["t"] = t
        rows["first"] = s.points.rows + np.concatenate(([0], np.cumsum(counts)[:-1]))
        rows["count"] = counts
        s.frames.append(rows)
        s.points.append(p32)
        if s.first_t is None:
            s.first_t = float(t[0])
        s.last_t = float(t[-1])

    # -- magnetometer
    def add_magnetometer(self, t, field):
        """Appends to /magnetometer: t (K,) s and the field (K, 3) mx my mz in the system
        frame (any unit: only its direction is used, §2.3)."""
        self._check_open()
        first = self._magnetometer.rows if self._magnetometer else 0
        t = _as_float(t, "/magnetometer t").reshape(-1)
        m = _as_float(field, "/magnetometer mx, my, mz")
        if m.shape != (len(t), 3):
            raise ValueError(f"/magnetometer mx, my, mz: shape {m.shape}, expected "
                             f"({len(t)}, 3) for {len(t)} times")
        _check_finite(t, "/magnetometer t", first)
        _check_finite(m, "/magnetometer mx, my, mz", first)
        if len(t) == 0:
            return
        if self._magnetometer is None:
            self._magnetometer = _Appender(
                _create_rows(self._file, "magnetometer", MAGNETOMETER_DTYPE, 0, _PATH_CHUNK))
        rows = np.empty(len(t), MAGNETOMETER_DTYPE)
        rows["t"] = t
        rows["mx"], rows["my"], rows["mz"] = m[:, 0], m[:, 1], m[:, 2]
        self._magnetometer.append(rows)

    # -- the end
    def close(self):
        """Checks what needs the whole file (a path; every frame within its time span),
        writes the rest and renames the file into place. On a ValueError nothing is left."""
        self._check_open()
        try:
            if self._path.rows == 0:
                raise ValueError("/path: no poses (a scan has at least one)")
            for s in self._sensors.values():
                if s.last_t is not None and s.last_t > self._last_pose_t:
                    raise ValueError(
                        f"/sensors/{s.name}/frames t row {s.frames.rows - 1}: {_num(s.last_t)} "
                        f"is after the path's last time {_num(self._last_pose_t)} (no pose to "
                        "interpolate)")
            for appender in [self._path, self._cov, self._magnetometer] + \
                    [a for s in self._sensors.values() for a in (s.frames, s.points)]:
                if appender is not None:
                    appender.flush()
            self._file.close()
            # Durable before it takes the final name: a job may read it at once.
            fd = os.open(self._partial, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(self._partial, self.path)
            dir_fd = os.open(os.path.dirname(os.path.abspath(self.path)), os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
        except BaseException:
            self.abort()
            raise
        self._closed = True

    def abort(self):
        """Closes and removes the partial file; nothing appears under the final name."""
        if self._closed:
            return
        self._closed = True
        try:
            self._file.close()
        finally:
            if os.path.exists(self._partial):
                os.remove(self._partial)


def write_scan(path, scan):
    """Writes a Scan (e.g. one read_scan returned, changed) to `path`."""
    with ScanWriter(path) as w:
        p = scan.path
        w.add_path(p.t, p.position, p.orientation, p.covariance)
        for s in scan.sensors:
            w.add_sensor(**s.attributes())
            if s.frame_t is not None and len(s.frame_t):
                # Frames as they lie in the file may skip or share rays: write each one's.
                if np.array_equal(s.frame_first, np.concatenate(
                        ([0], np.cumsum(s.frame_rays.astype(np.uint64))[:-1]))) \
                        and int(s.frame_rays.sum()) == len(s.points):
                    w.add_frames(s.name, s.frame_t, s.frame_rays, s.points)
                else:
                    for i in range(len(s.frame_t)):
                        w.add_frame(s.name, *s.frame(i))
        if scan.magnetometer is not None:
            w.add_magnetometer(scan.magnetometer.t, scan.magnetometer.field)


# ---- reading ----------------------------------------------------------------------------

def _attr(obj, name, where):
    if name not in obj.attrs:
        raise ValueError(f"{where}: attribute '{name}' missing")
    return obj.attrs[name], obj.attrs.get_id(name)


def _string_attr(obj, name, where):
    value, aid = _attr(obj, name, where)
    if h5py.check_string_dtype(aid.dtype) is None and aid.dtype.kind != "S":
        raise ValueError(f"{where}: attribute '{name}' is not a string")
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise ValueError(f"{where}: attribute '{name}' is not a single string")
        value = value.reshape(-1)[0]
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return str(value).rstrip("\0").rstrip(" ") if aid.dtype.kind == "S" else str(value)


def _int_attr(obj, name, where):
    value, aid = _attr(obj, name, where)
    if aid.dtype.kind not in "iu" or np.asarray(value).size != 1:
        raise ValueError(f"{where}: attribute '{name}' is not a single integer")
    return int(np.asarray(value).reshape(-1)[0])


def _numbers_attr(obj, name, where, n):
    value, aid = _attr(obj, name, where)
    v = np.asarray(value)
    if aid.dtype.kind not in "iuf" or v.size != n:
        raise ValueError(f"{where}: attribute '{name}' must hold {n} number{'s' if n > 1 else ''}")
    return v.astype(np.float64).reshape(-1)


def _dataset(f, name):
    if name not in f:
        raise ValueError(f"{name}: missing")
    d = f[name]
    if not isinstance(d, h5py.Dataset):
        raise ValueError(f"{name}: not a dataset")
    return d


def _table(f, name, fields):
    """A 1-D compound dataset with these numeric fields (matched by name, any order)."""
    d = _dataset(f, name)
    if d.dtype.names is None:
        raise ValueError(f"{name}: not a compound dataset")
    for n in fields:
        if n not in d.dtype.names:
            raise ValueError(f"{name}: missing field '{n}'")
        if d.dtype[n].kind not in "iuf":
            raise ValueError(f"{name}: field '{n}' is not numeric")
    if d.ndim != 1:
        raise ValueError(f"{name}: shape {d.shape}, expected a 1-D table")
    return d


def _matrix(f, name, cols):
    d = _dataset(f, name)
    if d.dtype.kind not in "iuf":
        raise ValueError(f"{name}: not a numeric dataset")
    if d.ndim != 2 or d.shape[1] != cols:
        raise ValueError(f"{name}: shape {d.shape}, expected [N][{cols}]")
    return d


def _sensor_names(group):
    """§3: creation order when the file tracks it, else ascending names."""
    flags = group.id.get_create_plist().get_link_creation_order()
    if flags & h5py.h5p.CRT_ORDER_INDEXED:
        names = []
        group.id.links.iterate(lambda n: names.append(n.decode()),
                               idx_type=h5py.h5.INDEX_CRT_ORDER)
        return names
    return sorted(group.keys(), key=lambda n: n.encode())


class ScanReader:
    """Reads scan.h5 into numpy arrays. Opening checks the structure (format, version,
    datasets, fields, attributes); with validate=True (the default) every row is checked too,
    in blocks, against the rules ScanWriter enforces. A violation is a ValueError naming the
    dataset and the row, prefixed with the file's name.

        with ScanReader("scan.h5") as r:
            path = r.path()                          # Path: t, position, orientation, covariance
            for s in r.sensors:                      # Sensor: attributes, frame/point counts
                t, first, count = r.frames(s.name)
                points = r.points(s.name)            # (M, 3) float32, NaN rows: no return
        scan = read_scan("scan.h5")                  # everything at once
    """

    def __init__(self, path, validate=True):
        self.file = os.fspath(path)
        if not os.path.isfile(self.file):
            raise FileNotFoundError(f"{self.file}: no such file")
        try:
            self._f = h5py.File(self.file, "r")
        except OSError as e:
            raise ValueError(f"{self.file}: not an HDF5 file ({e})") from None
        try:
            self._open()
            if validate:
                self.validate()
        except ValueError as e:
            self._f.close()
            raise ValueError(f"{self.file}: {e}") from None
        except BaseException:
            self._f.close()
            raise

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self):
        self._f.close()

    def _open(self):
        f = self._f
        fmt = _string_attr(f, "format", "/")
        if fmt != FORMAT:
            raise ValueError(f"/: format is '{fmt}', expected '{FORMAT}'")
        version = _int_attr(f, "version", "/")
        if version != VERSION:
            raise ValueError(f"/: unknown format version {version} (this reader knows {VERSION})")
        self._path_d = _table(f, "/path", PATH_DTYPE.names)
        self._cov_d = None
        if "path_cov" in f:
            self._cov_d = _matrix(f, "/path_cov", 12)
            if len(self._cov_d) != len(self._path_d):
                raise ValueError(f"/path_cov: {len(self._cov_d)} rows, but /path has "
                                 f"{len(self._path_d)}")
        self._mag_d = _table(f, "/magnetometer", MAGNETOMETER_DTYPE.names) \
            if "magnetometer" in f else None
        self.sensors = []
        self._data = {}
        if "sensors" not in f:
            return  # a scan with a path and no rays
        group = f["sensors"]
        if not isinstance(group, h5py.Group):
            raise ValueError("/sensors: not a group")
        for name in _sensor_names(group):
            where = f"/sensors/{name}"
            g = group[name]
            if not isinstance(g, h5py.Group):
                raise ValueError(f"{where}: not a group")
            kind = _string_attr(g, "kind", where)
            rows = cols = None
            if kind == "grid":
                rows = _int_attr(g, "rows", where)
                cols = _int_attr(g, "cols", where)
            kind, rows, cols, R, T, sigma_t, rs, max_range = check_sensor(
                name, kind, _numbers_attr(g, "R_s2c", where, 9),
                _numbers_attr(g, "T_s2c", where, 3), _numbers_attr(g, "sigma_t", where, 1),
                _numbers_attr(g, "range_sigma", where, 2),
                _numbers_attr(g, "max_range", where, 1), rows, cols)
            frames = _table(f, f"{where}/frames", FRAME_DTYPE.names)
            points = _matrix(f, f"{where}/points", 3)
            self.sensors.append(Sensor(name, kind, R, T, sigma_t, rs, max_range, rows, cols,
                                       frame_count=len(frames), point_count=len(points)))
            self._data[name] = (frames, points)

    def _sensor(self, sensor):
        if isinstance(sensor, (int, np.integer)) and not isinstance(sensor, bool):
            return self.sensors[sensor]
        for s in self.sensors:
            if s.name == sensor:
                return s
        raise KeyError(f"{self.file}: no sensor {sensor!r}")

    # -- whole tables
    def path(self):
        rows = self._path_d[...]
        cov = self._cov_d[...].astype(np.float32) if self._cov_d is not None else None
        return Path(rows["t"].astype(np.float64),
                    np.stack([rows[n] for n in POSITION_FIELDS], 1).astype(np.float64),
                    np.stack([rows[n] for n in QUATERNION_FIELDS], 1).astype(np.float64), cov)

    def magnetometer(self):
        if self._mag_d is None:
            return None
        rows = self._mag_d[...]
        return Magnetometer(rows["t"].astype(np.float64),
                            np.stack([rows["mx"], rows["my"], rows["mz"]], 1).astype(np.float64))

    def frames(self, sensor):
        """(t (F,) float64, first (F,) uint64, count (F,) uint32) of a sensor's frames."""
        rows = self._data[self._sensor(sensor).name][0][...]
        return (rows["t"].astype(np.float64), rows["first"].astype(np.uint64),
                rows["count"].astype(np.uint32))

    def points(self, sensor):
        """All of a sensor's rays' end points, (M, 3) float32 in the sensor frame."""
        return self._data[self._sensor(sensor).name][1][...].astype(np.float32)

    def frame(self, sensor, i):
        """(t, points (count, 3) float32) of frame i of a sensor, read alone."""
        frames, points = self._data[self._sensor(sensor).name]
        row = frames[i]
        first, count = int(row["first"]), int(row["count"])
        return float(row["t"]), points[first:first + count].astype(np.float32)

    def iter_frames(self, sensor):
        """Yields (t, points) for every frame of a sensor, reading the file in blocks."""
        frames, points = self._data[self._sensor(sensor).name]
        for start in range(0, len(frames), _BLOCK_ROWS):
            rows = frames[start:start + _BLOCK_ROWS]
            if not len(rows):
                break
            lo = int(rows["first"].min())
            hi = int((rows["first"].astype(np.uint64) + rows["count"]).max())
            block = points[lo:hi].astype(np.float32)
            for r in rows:
                first = int(r["first"]) - lo
                yield float(r["t"]), block[first:first + int(r["count"])]

    def read(self):
        """The whole scan as a Scan of numpy arrays."""
        sensors = []
        for s in self.sensors:
            t, first, count = self.frames(s.name)
            sensors.append(dataclasses.replace(s, frame_t=t, frame_first=first,
                                               frame_rays=count, points=self.points(s.name)))
        return Scan(self.path(), sensors, self.magnetometer())

    # -- every row
    def validate(self):
        """Checks every row of every dataset (§3); ValueError at the first violation."""
        n = len(self._path_d)
        if n == 0:
            raise ValueError("/path: no poses (a scan has at least one)")
        previous = None
        for start in range(0, n, _BLOCK_ROWS):
            rows = self._path_d[start:start + _BLOCK_ROWS]
            t = rows["t"].astype(np.float64)
            values = np.stack([rows[k].astype(np.float64) for k in PATH_DTYPE.names], 1)
            _check_finite(values, "/path", start)
            _check_increasing(t, "/path t", previous, start)
            _check_quaternions(np.stack([rows[k] for k in QUATERNION_FIELDS], 1)
                               .astype(np.float64), "/path qw, qx, qy, qz", start)
            previous = t[-1]
        t_begin = float(self._path_d[0]["t"])
        t_end = float(self._path_d[n - 1]["t"])
        if self._cov_d is not None:
            for start in range(0, n, _BLOCK_ROWS):
                _check_covariance(self._cov_d[start:start + _BLOCK_ROWS].astype(np.float64),
                                  "/path_cov", start)
        if self._mag_d is not None:
            for start in range(0, len(self._mag_d), _BLOCK_ROWS):
                rows = self._mag_d[start:start + _BLOCK_ROWS]
                _check_finite(np.stack([rows[k].astype(np.float64)
                                        for k in MAGNETOMETER_DTYPE.names], 1),
                              "/magnetometer", start)
        for s in self.sensors:
            self._validate_sensor(s, t_begin, t_end)

    def _validate_sensor(self, s, t_begin, t_end):
        frames, points = self._data[s.name]
        where = f"/sensors/{s.name}/frames"
        m = len(points)
        previous = None
        for start in range(0, len(frames), _BLOCK_ROWS):
            rows = frames[start:start + _BLOCK_ROWS]
            t = rows["t"].astype(np.float64)
            _check_finite(t, f"{where} t", start)
            _check_increasing(t, f"{where} t", previous, start)
            previous = t[-1]
            first = rows["first"]
            count = rows["count"]
            if first.dtype.kind == "f" or count.dtype.kind == "f":
                raise ValueError(f"{where}: fields 'first' and 'count' must be integers")
            first = first.astype(np.int64)
            count = count.astype(np.int64)
            row = _first((first < 0) | (count < 0) | (first > m) | (count > m - first))
            if row is not None:
                raise ValueError(f"{where} row {start + row}: rays [{first[row]}, "
                                 f"{first[row] + count[row]}) outside /sensors/{s.name}/points "
                                 f"({m} rows)")
            _check_grid_counts(count, s, where, start)
            row = _first((t < t_begin) | (t > t_end))
            if row is not None:
                raise ValueError(f"{where} t row {start + row}: {_num(t[row])} is outside the "
                                 f"path's time span [{_num(t_begin)}, {_num(t_end)}] (no pose "
                                 "to interpolate)")
        for start in range(0, m, _BLOCK_ROWS):
            with np.errstate(over="ignore", invalid="ignore"):
                block = points[start:start + _BLOCK_ROWS].astype(np.float32)
            _check_points(block, f"/sensors/{s.name}/points", start)


def read_scan(path, validate=True):
    """The whole of scan.h5 as a Scan of numpy arrays (see ScanReader)."""
    with ScanReader(path, validate=validate) as r:
        return r.read()
