"""A scan made from numpy arrays alone: a walk across an empty 6 × 4 × 2.6 m box room with two
line scanners (one level, one scanning the plane across the walk), the rays cast analytically
against the box's walls, floor and ceiling."""
import numpy as np

from carvemap.scan import ScanWriter

LO = np.array([0.0, 0.0, 0.0])
HI = np.array([6.0, 4.0, 2.6])
BEAMS = np.radians(np.arange(-135.0, 135.01, 1.0))
RAYS = np.column_stack([np.cos(BEAMS), np.sin(BEAMS), np.zeros_like(BEAMS)])  # sensor frame
MOUNTS = {"level": np.eye(3),                                                 # the x-y plane
          "across": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])}  # y-z
T_S2C = np.array([0.1, 0.0, 0.2])
VELOCITY = np.array([0.5, 0.25, 0.0])
START = np.array([1.0, 1.0, 1.5])
YAW = np.arctan2(VELOCITY[1], VELOCITY[0])
R_WORLD = np.array([[np.cos(YAW), -np.sin(YAW), 0.0], [np.sin(YAW), np.cos(YAW), 0.0],
                    [0.0, 0.0, 1.0]])


def ranges(origin, directions):
    """Distance from `origin` inside the box to its faces along each direction."""
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(directions > 0, (HI - origin) / directions, (LO - origin) / directions)
    return np.min(np.where(directions != 0, d, np.inf), axis=1)


def frame_points(sensor, t):
    """The end points (n, 3) of a frame of `sensor` at time t, in the sensor frame."""
    R = MOUNTS[sensor]
    origin = START + VELOCITY * t + R_WORLD @ T_S2C
    return RAYS * ranges(origin, RAYS @ (R_WORLD @ R).T)[:, None]


def write_box_room(path, seconds=8.0, rate_hz=10.0, magnetometer=True, no_return_every=0):
    """Writes the walk to `path`; no_return_every=k makes every k-th beam a ray with no return
    (a row of NaN). Returns path."""
    t = np.linspace(0.0, seconds, int(round(seconds * 100)) + 1)  # poses at 100 Hz
    position = START + np.outer(t, VELOCITY)
    orientation = np.tile([np.cos(YAW / 2), 0.0, 0.0, np.sin(YAW / 2)], (len(t), 1))
    cov = np.tile([1e-4, 0, 0, 1e-4, 0, 1e-4, 1e-5, 0, 0, 1e-5, 0, 1e-5], (len(t), 1))
    with ScanWriter(path) as w:
        w.add_path(t, position, orientation, covariance=cov)
        for name, R in MOUNTS.items():
            w.add_sensor(name, "line", R_s2c=R, T_s2c=T_S2C, sigma_t=1e-3,
                         range_sigma=(0.01, 0.001), max_range=30.0)
            for ft in np.arange(0.5 / rate_hz, seconds - 0.5 / rate_hz, 1.0 / rate_hz):
                p = frame_points(name, ft)
                if no_return_every:
                    p[::no_return_every] = np.nan
                w.add_frame(name, ft, p)
        if magnetometer:
            # The field points north (+y) and down, seen from the system: turned by -yaw.
            field = R_WORLD.T @ np.array([0.0, 0.2, -0.4])
            w.add_magnetometer(t[::10], np.tile(field, (len(t[::10]), 1)))
    return path
