#!/usr/bin/env python3
"""Writes ROS 1 bags of a robot driving through a known room, with Debian's rosbag library
(python3-rosbag, python3-sensor-msgs, python3-tf2-msgs): an implementation that shares no code
with carvemap's reader (storage/import/rosbag_reader.h).

The room is the box [0, 6] x [0, 4] x [0, 2.5] m. /tf_static holds map -> odom (identity),
base_link -> laser and base_link -> camera; /tf holds odom -> base_link at 50 Hz along a path
whose position is linear in time and whose yaw turns at a constant rate (so interpolating /tf
linearly and by SLERP is exact). /scan is a sensor_msgs/LaserScan at 10 Hz (181 beams over
180 deg, range_max 5 m: farther walls are inf), /cloud an organized sensor_msgs/PointCloud2
(3 x 5 pixels, one of them NaN) at 5 Hz. Every range is ray-cast against the room, so every
point that is not a no-return lies on one of its six faces.

  make_rosbag.py OUT.bag [--compression none|bz2|lz4] [--cloud-unorganized] [--duration S]

lz4 chunks come from ROS's roslz4 (Debian's python3-roslz4).
"""
import argparse
import math
import struct

import numpy as np
import rosbag
import rospy
from geometry_msgs.msg import TransformStamped
from sensor_msgs.msg import LaserScan, PointCloud2, PointField
from tf2_msgs.msg import TFMessage

ROOM = np.array([6.0, 4.0, 2.5])
T0 = 1700000000.0  # the bag's clock starts at a real epoch, as recorded bags do
DURATION = 4.0
# Scans reach the recorder after their stamps: a record's time is not its message's stamp.
RECEIVE_LATENCY = 0.02
LASER_IN_BASE = (np.array([0.2, 0.0, 0.3]), 0.0)           # translation, yaw
CAMERA_IN_BASE = (np.array([0.0, 0.1, 1.2]), math.radians(30))  # translation, yaw; then pitched
CAMERA_PITCH = math.radians(20)  # looking down a little


def base_pose(t):
    """base_link in odom (= map) at time t since T0: position and yaw."""
    s = t / DURATION
    p = np.array([1.0 + 3.5 * s, 1.0 + 2.0 * s, 0.0])
    return p, -0.3 + 1.2 * s


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def camera_rotation():
    return rot_z(CAMERA_IN_BASE[1]) @ rot_y(CAMERA_PITCH)


def quat_of(r):
    """(x, y, z, w) of a rotation matrix."""
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return x, y, z, w


def ray_to_room(origin, direction):
    """Distance from origin (inside the room) along a unit direction to the room's faces."""
    best = math.inf
    for d in range(3):
        if abs(direction[d]) < 1e-12:
            continue
        for wall in (0.0, ROOM[d]):
            s = (wall - origin[d]) / direction[d]
            if s > 1e-9:
                best = min(best, s)
    return best


def stamp(t):
    return rospy.Time.from_sec(T0 + t)


def transform(parent, child, t, translation, rotation):
    m = TransformStamped()
    m.header.stamp = stamp(t)
    m.header.frame_id = parent
    m.child_frame_id = child
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = translation
    q = quat_of(rotation)
    (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
     m.transform.rotation.w) = q
    return m


def sensor_in_world(t, in_base, extra=np.eye(3)):
    p, yaw = base_pose(t)
    rb = rot_z(yaw)
    r = rb @ rot_z(in_base[1]) @ extra
    return p + rb @ in_base[0], r


def write(path, compression, unorganized, duration=DURATION):
    bag = rosbag.Bag(path, "w", compression=compression)
    try:
        static = TFMessage()
        static.transforms = [
            transform("map", "odom", 0.0, (0, 0, 0), np.eye(3)),
            transform("base_link", "laser", 0.0, LASER_IN_BASE[0], rot_z(LASER_IN_BASE[1])),
            transform("base_link", "camera", 0.0, CAMERA_IN_BASE[0], camera_rotation()),
        ]
        bag.write("/tf_static", static, stamp(0.0))
        events = []
        for i in range(int(duration * 50) + 1):
            events.append((i / 50.0, "tf"))
        for i in range(1, int(duration * 10)):
            events.append((i / 10.0 + 0.003, "scan"))
        for i in range(1, int(duration * 5)):
            events.append((i / 5.0 + 0.011, "cloud"))
        events.sort()
        seq = 0
        for t, kind in events:
            seq += 1
            if kind == "tf":
                p, yaw = base_pose(t)
                m = TFMessage()
                m.transforms = [transform("odom", "base_link", t, p, rot_z(yaw))]
                bag.write("/tf", m, stamp(t))
            elif kind == "scan":
                origin, r = sensor_in_world(t, LASER_IN_BASE)
                m = LaserScan()
                m.header.seq = seq
                m.header.stamp = stamp(t)
                m.header.frame_id = "laser"
                m.angle_min = -math.pi / 2
                m.angle_max = math.pi / 2
                m.angle_increment = math.pi / 180
                m.time_increment = 0.0
                m.scan_time = 0.1
                m.range_min = 0.05
                m.range_max = 5.0
                ranges = []
                for k in range(181):
                    a = m.angle_min + k * m.angle_increment
                    d = r @ np.array([math.cos(a), math.sin(a), 0.0])
                    rng = ray_to_room(origin, d)
                    ranges.append(rng if rng <= m.range_max else math.inf)
                m.ranges = ranges
                m.intensities = []
                bag.write("/scan", m, stamp(t + RECEIVE_LATENCY))
            else:
                origin, r = sensor_in_world(t, CAMERA_IN_BASE, rot_y(CAMERA_PITCH))
                rows, cols = 3, 5
                data = bytearray()
                for v in range(rows):
                    for u in range(cols):
                        if (v, u) == (1, 2):
                            data += struct.pack("<fff", math.nan, math.nan, math.nan)
                            continue
                        # The camera looks along its +x: pixels fan out in y and z.
                        d = np.array([1.0, 0.25 * (u - 2), 0.2 * (1 - v)])
                        d /= np.linalg.norm(d)
                        rng = ray_to_room(origin, r @ d)
                        data += struct.pack("<fff", *(d * rng))
                m = PointCloud2()
                m.header.seq = seq
                m.header.stamp = stamp(t)
                m.header.frame_id = "camera"
                m.height, m.width = (1, rows * cols) if unorganized else (rows, cols)
                m.fields = [PointField("x", 0, PointField.FLOAT32, 1),
                            PointField("y", 4, PointField.FLOAT32, 1),
                            PointField("z", 8, PointField.FLOAT32, 1)]
                m.is_bigendian = False
                m.point_step = 12
                m.row_step = 12 * m.width
                m.data = bytes(data)
                m.is_dense = False
                bag.write("/cloud", m, stamp(t + RECEIVE_LATENCY))
    finally:
        bag.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--compression", default="none", choices=["none", "bz2", "lz4"])
    ap.add_argument("--cloud-unorganized", action="store_true")
    ap.add_argument("--duration", type=float, default=DURATION,
                    help="seconds of the path to record (it is the same path, cut short)")
    a = ap.parse_args()
    write(a.out, a.compression, a.cloud_unorganized, a.duration)


if __name__ == "__main__":
    main()
