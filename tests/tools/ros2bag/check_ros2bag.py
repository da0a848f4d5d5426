#!/usr/bin/env python3
"""Checks the ROS 2 fixtures of tests/data/ros2/ against the ROS 1 bags of the same scenario:

  /usr/bin/python3 check_ros2bag.py DIR

It runs `node check_ros2bag.mjs DIR` (which reads the MCAP files back and prints every message of
robot.mcap and robot_unorganized.mcap, decoded), and it writes the two ROS 1 bags with tests/tools/make_rosbag.py (Debian's
python3-rosbag), reads them back with rosbag, and checks that each ROS 2 message carries the same
values (stamps, frames, ranges and points bit for bit as float32) with the same record time; then
that robot.db3 and robot_db3/ hold robot.mcap's messages byte for byte, with rosbag2's tables
and metadata. It needs Debian's python3 (for rosbag and numpy).
"""
import json
import math
import os
import sqlite3
import struct
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))  # tests/tools
import make_rosbag  # noqa: E402
import numpy as np  # noqa: E402
import rosbag  # noqa: E402

failures = 0


def check(ok, what):
    global failures
    if not ok:
        failures += 1
        print(f"FAIL: {what}", file=sys.stderr)


def f32(values):
    return struct.pack(f"<{len(values)}f", *values)


def ros1_messages(unorganized):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "robot.bag")
        make_rosbag.write(path, "none", unorganized)
        with rosbag.Bag(path) as bag:
            return [(topic, msg, t.to_nsec()) for topic, msg, t in bag.read_messages()]


def same_stamp(ros1_stamp, ros2_stamp):
    return ros1_stamp.secs == ros2_stamp["sec"] and ros1_stamp.nsecs == ros2_stamp["nanosec"]


def compare(file, ros1, ros2, stats):
    check(len(ros1) == len(ros2) == 260, f"{file}: {len(ros1)} ROS 1 and {len(ros2)} ROS 2 messages")
    for i, ((topic, m1, t1), r2) in enumerate(zip(ros1, ros2)):
        where = f"{file} #{i} {topic}"
        check(topic == r2["topic"], f"{where}: topic {r2['topic']}")
        check(t1 == r2["log_time"], f"{where}: record time {t1} != log time {r2['log_time']}")
        m2 = r2["msg"]
        if topic in ("/tf", "/tf_static"):
            check(len(m1.transforms) == len(m2["transforms"]), f"{where}: transform count")
            for a, b in zip(m1.transforms, m2["transforms"]):
                check(same_stamp(a.header.stamp, b["header"]["stamp"]), f"{where}: stamp")
                check(a.header.frame_id == b["header"]["frame_id"], f"{where}: frame_id")
                check(a.child_frame_id == b["child_frame_id"], f"{where}: child_frame_id")
                va = [a.transform.translation.x, a.transform.translation.y,
                      a.transform.translation.z, a.transform.rotation.x, a.transform.rotation.y,
                      a.transform.rotation.z, a.transform.rotation.w]
                tb, rb = b["transform"]["translation"], b["transform"]["rotation"]
                vb = [tb["x"], tb["y"], tb["z"], rb["x"], rb["y"], rb["z"], rb["w"]]
                for x, y in zip(va, vb):
                    stats["f64"] += 1
                    stats["f64_exact"] += x == y
                    check(abs(x - y) <= 1e-12, f"{where}: {x} != {y}")
        elif topic == "/scan":
            check(same_stamp(m1.header.stamp, m2["header"]["stamp"]), f"{where}: stamp")
            check(m1.header.frame_id == m2["header"]["frame_id"], f"{where}: frame_id")
            for k in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
                      "range_min", "range_max"):
                check(getattr(m1, k) == m2[k], f"{where}: {k} {getattr(m1, k)} != {m2[k]}")
            a = np.frombuffer(f32(m1.ranges), "<f4")
            b = np.frombuffer(bytes.fromhex(m2["ranges"]["f32le"]), "<f4")
            check(len(a) == len(b) == 181, f"{where}: {len(b)} ranges")
            if len(a) == len(b):
                stats["ranges"] += len(a)
                stats["ranges_exact"] += int(np.sum(a.view("<u4") == b.view("<u4")))
                check(np.array_equal(np.isinf(a), np.isinf(b)), f"{where}: inf beams differ")
                fin = np.isfinite(a) & np.isfinite(b)
                ulps = np.abs(a[fin].view("<i4").astype(np.int64) - b[fin].view("<i4").astype(np.int64))
                stats["ranges_max_ulp"] = max(stats["ranges_max_ulp"], int(ulps.max(initial=0)))
                check(ulps.max(initial=0) <= 1, f"{where}: ranges differ by {ulps.max()} ulp")
            check(list(m1.intensities) == [] and m2["intensities"]["f32le"] == "",
                  f"{where}: intensities")
        elif topic == "/cloud":
            check(same_stamp(m1.header.stamp, m2["header"]["stamp"]), f"{where}: stamp")
            check(m1.header.frame_id == m2["header"]["frame_id"], f"{where}: frame_id")
            for k in ("height", "width", "is_bigendian", "point_step", "row_step", "is_dense"):
                check(getattr(m1, k) == m2[k], f"{where}: {k} {getattr(m1, k)} != {m2[k]}")
            f1 = [(f.name, f.offset, f.datatype, f.count) for f in m1.fields]
            f2 = [(f["name"], f["offset"], f["datatype"], f["count"]) for f in m2["fields"]]
            check(f1 == f2, f"{where}: fields {f2}")
            a = np.frombuffer(bytes(m1.data), "<f4")
            b = np.frombuffer(bytes.fromhex(m2["data"]["hex"]), "<f4")
            check(len(a) == len(b) == 45, f"{where}: {len(b)} floats")
            if len(a) == len(b):
                stats["points"] += len(a)
                stats["points_exact"] += int(np.sum(a.view("<u4") == b.view("<u4")))
                check(np.array_equal(np.isnan(a), np.isnan(b)), f"{where}: NaN pixels differ")
                fin = np.isfinite(a)
                ulps = np.abs(a[fin].view("<i4").astype(np.int64) - b[fin].view("<i4").astype(np.int64))
                stats["points_max_ulp"] = max(stats["points_max_ulp"], int(ulps.max(initial=0)))
                check(ulps.max(initial=0) <= 1, f"{where}: points differ by {ulps.max()} ulp")
        else:
            check(False, f"{where}: unexpected topic")


def check_first_scan(ros2):
    """The first /scan against make_rosbag.py's ray casting, computed here directly."""
    first = next(r for r in ros2 if r["topic"] == "/scan")
    t = 1 / 10.0 + 0.003
    origin, r = make_rosbag.sensor_in_world(t, make_rosbag.LASER_IN_BASE)
    truth = []
    for k in range(181):
        a = -math.pi / 2 + k * (math.pi / 180)
        rng = make_rosbag.ray_to_room(origin, r @ np.array([math.cos(a), math.sin(a), 0.0]))
        truth.append(rng if rng <= 5.0 else math.inf)
    got = np.frombuffer(bytes.fromhex(first["msg"]["ranges"]["f32le"]), "<f4")
    want = np.array(truth, dtype=np.float32)
    check(np.array_equal(np.isinf(got), np.isinf(want)), "first scan: inf beams")
    fin = np.isfinite(want)
    err = np.abs(got[fin].astype(np.float64) - np.array(truth)[fin])
    check(err.max() <= 1e-6 * 5, f"first scan: off by {err.max()} m")
    stamp = make_rosbag.stamp(t + make_rosbag.RECEIVE_LATENCY)
    check(first["log_time"] == stamp.to_nsec(), "first scan: log time")
    return {"first_scan_log_time": first["log_time"], "first_scan_inf_beams": int(np.sum(~fin)),
            "first_scan_max_err_m": float(err.max()),
            "first_scan_ranges_0_3": [float(x) for x in got[:3]]}


QOS_KEYS = ("- history: 3\n", "  avoid_ros_namespace_conventions: false")


def check_db3(path, mcap_messages):
    with open(path, "rb") as f:
        head = f.read(100)
    check(head[:16] == b"SQLite format 3\x00", f"{path}: not SQLite")
    check(head[18] == 1 and head[19] == 1, f"{path}: not in rollback-journal mode (WAL?)")
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        check(con.execute("PRAGMA integrity_check").fetchone()[0] == "ok", f"{path}: integrity")
        check(con.execute("SELECT schema_version, ros_distro FROM schema").fetchall() == [(3, "humble")],
              f"{path}: schema table")
        topics = con.execute("SELECT id, name, type, serialization_format, offered_qos_profiles "
                             "FROM topics ORDER BY id").fetchall()
        want = [(1, "/tf_static", "tf2_msgs/msg/TFMessage"), (2, "/tf", "tf2_msgs/msg/TFMessage"),
                (3, "/scan", "sensor_msgs/msg/LaserScan"), (4, "/cloud", "sensor_msgs/msg/PointCloud2")]
        check([t[:3] for t in topics] == want, f"{path}: topics {topics}")
        check(all(t[3] == "cdr" and t[4].startswith(QOS_KEYS[0]) and t[4].endswith(QOS_KEYS[1])
                  for t in topics), f"{path}: serialization format or QoS")
        check("durability: 1" in topics[0][4] and all("durability: 2" in t[4] for t in topics[1:]),
              f"{path}: /tf_static should be transient_local, the others volatile")
        names = {t[0]: t[1] for t in topics}
        rows = con.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
        got = [(names[tid], ts, bytes(data).hex()) for tid, ts, data in rows]
        want = [(m["topic"], m["log_time"], m["data"]) for m in mcap_messages]
        check(got == want, f"{path}: messages differ from robot.mcap's")
        check(rows == sorted(rows, key=lambda r: r[1]), f"{path}: ids not in timestamp order")
        idx = con.execute("SELECT sql FROM sqlite_master WHERE name = 'timestamp_idx'").fetchone()
        check(idx is not None and "timestamp ASC" in idx[0], f"{path}: timestamp_idx")
        meta = con.execute("SELECT metadata_version, metadata FROM metadata").fetchall()
        check(len(meta) == 1 and meta[0][0] == 5 and
              meta[0][1].startswith("rosbag2_bagfile_information:\n  version: 5\n"),
              f"{path}: metadata table")
        return meta[0][1] if meta else None
    finally:
        con.close()


def check_metadata_yaml(path, table_text, mcap_messages):
    with open(path, encoding="ascii") as f:
        text = f.read()
    check(text == table_text + "\n", f"{path}: differs from the .db3's metadata table")
    try:
        import yaml
    except ImportError:
        return
    info = yaml.safe_load(text)["rosbag2_bagfile_information"]
    times = [m["log_time"] for m in mcap_messages]
    check(info["version"] == 5 and info["storage_identifier"] == "sqlite3", f"{path}: version")
    check(info["starting_time"]["nanoseconds_since_epoch"] == min(times), f"{path}: start")
    check(info["duration"]["nanoseconds"] == max(times) - min(times), f"{path}: duration")
    check(info["message_count"] == 260, f"{path}: message_count")
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    check(counts == {"/tf_static": 1, "/tf": 201, "/scan": 39, "/cloud": 19}, f"{path}: counts")
    check(info["relative_file_paths"] == ["robot_db3_0.db3"], f"{path}: relative_file_paths")
    check(info["compression_format"] == "" and info["compression_mode"] == "", f"{path}: compression")
    check(info["files"][0]["path"] == "robot_db3_0.db3" and info["files"][0]["message_count"] == 260,
          f"{path}: files")
    qos = yaml.safe_load(info["topics_with_message_count"][0]["topic_metadata"]["offered_qos_profiles"])
    check(qos[0]["durability"] == 1, f"{path}: /tf_static QoS")


def main():
    if len(sys.argv) != 2:
        raise SystemExit("usage: /usr/bin/python3 check_ros2bag.py DIR")
    data_dir = sys.argv[1]
    node = subprocess.run(["node", os.path.join(HERE, "check_ros2bag.mjs"), data_dir],
                          stdout=subprocess.PIPE, check=False, text=True)
    if node.returncode != 0:
        raise SystemExit("check_ros2bag.py: check_ros2bag.mjs failed")
    by_file = {}
    for line in node.stdout.splitlines():
        r = json.loads(line)
        by_file.setdefault(r["file"], []).append(r)
    stats = {"f64": 0, "f64_exact": 0, "ranges": 0, "ranges_exact": 0, "ranges_max_ulp": 0,
             "points": 0, "points_exact": 0, "points_max_ulp": 0}
    compare("robot.mcap", ros1_messages(False), by_file.get("robot.mcap", []), stats)
    compare("robot_unorganized.mcap", ros1_messages(True), by_file.get("robot_unorganized.mcap", []),
            stats)
    stats.update(check_first_scan(by_file["robot.mcap"]))
    mcap = by_file["robot.mcap"]
    table = check_db3(os.path.join(data_dir, "robot.db3"), mcap)
    table2 = check_db3(os.path.join(data_dir, "robot_db3", "robot_db3_0.db3"), mcap)
    check(table == table2, "the two .db3 files' metadata differ")
    check_metadata_yaml(os.path.join(data_dir, "robot_db3", "metadata.yaml"), table, mcap)
    print(json.dumps(stats), file=sys.stderr)
    if failures:
        raise SystemExit(f"check_ros2bag.py: {failures} failures")
    print("check_ros2bag.py: ROS 2 fixtures match make_rosbag.py's ROS 1 bags", file=sys.stderr)


if __name__ == "__main__":
    main()
