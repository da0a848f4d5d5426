#!/usr/bin/env python3
"""Writes the rosbag2 sqlite3 fixtures of tests/data/ros2/ with Python's sqlite3, from the JSON
lines that make_ros2bag.mjs prints (its topics and the CDR bytes of robot.mcap's messages), so that
the .db3 holds byte for byte the messages of robot.mcap:

  node make_ros2bag.mjs OUT_DIR | python3 make_db3.py OUT_DIR

writes OUT_DIR/robot.db3 (the storage file alone) and OUT_DIR/robot_db3/ (a bag directory as
`ros2 bag record -s sqlite3` lays it out: metadata.yaml and robot_db3_0.db3, a copy of robot.db3).

The database has the tables of rosbag2's sqlite3 storage in ROS 2 Humble (schema version 3). Its
bytes depend only on the input and on the SQLite library's version, which SQLite writes into the
file's header (bytes 96-99).
"""
import json
import os
import shutil
import sqlite3
import sys

BAG_DIR = "robot_db3"
BAG_FILE = "robot_db3_0.db3"

SCHEMA = [
    "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);",
    "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
    "metadata TEXT NOT NULL);",
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
    "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);",
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
    "timestamp INTEGER NOT NULL, data BLOB NOT NULL);",
    "CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
]


def read_input(stream):
    topics, messages, end = [], [], None
    for line in stream:
        if not line.strip():
            continue
        rec = json.loads(line)
        if end is not None:
            raise SystemExit("make_db3.py: input goes on after its end line")
        if rec["kind"] == "topic":
            topics.append(rec)
        elif rec["kind"] == "message":
            messages.append(rec)
        elif rec["kind"] == "end":
            end = rec
        else:
            raise SystemExit(f"make_db3.py: unknown record kind {rec['kind']!r}")
    # A failed or cut-short generator must not leave a plausible bag behind.
    if end is None or end["topics"] != len(topics) or end["messages"] != len(messages):
        raise SystemExit("make_db3.py: input is incomplete (did make_ros2bag.mjs fail?)")
    return topics, messages


def yaml_str(s):
    # A YAML double-quoted scalar; the strings here are ASCII, for which JSON's escapes are YAML's.
    return json.dumps(s)


def metadata_yaml(topics, messages):
    """metadata.yaml as rosbag2 (Humble, metadata version 5) writes it."""
    start = min(m["timestamp"] for m in messages)
    duration = max(m["timestamp"] for m in messages) - start
    counts = {t["name"]: 0 for t in topics}
    for m in messages:
        counts[m["topic"]] += 1
    out = [
        "rosbag2_bagfile_information:",
        "  version: 5",
        "  storage_identifier: sqlite3",
        "  duration:",
        f"    nanoseconds: {duration}",
        "  starting_time:",
        f"    nanoseconds_since_epoch: {start}",
        f"  message_count: {len(messages)}",
        "  topics_with_message_count:",
    ]
    for t in topics:
        out += [
            "    - topic_metadata:",
            f"        name: {t['name']}",
            f"        type: {t['type']}",
            f"        serialization_format: {t['serialization_format']}",
            f"        offered_qos_profiles: {yaml_str(t['offered_qos_profiles'])}",
            f"      message_count: {counts[t['name']]}",
        ]
    out += [
        '  compression_format: ""',
        '  compression_mode: ""',
        "  relative_file_paths:",
        f"    - {BAG_FILE}",
        "  files:",
        f"    - path: {BAG_FILE}",
        "      starting_time:",
        f"        nanoseconds_since_epoch: {start}",
        "      duration:",
        f"        nanoseconds: {duration}",
        f"      message_count: {len(messages)}",
    ]
    return "\n".join(out)


def write_db3(path, topics, messages, metadata):
    tmp = path + ".tmp"
    for p in (tmp, tmp + "-journal"):
        if os.path.exists(p):
            os.remove(p)
    con = sqlite3.connect(tmp, isolation_level=None)
    try:
        con.execute("BEGIN")
        for stmt in SCHEMA:
            con.execute(stmt)
        con.execute("INSERT INTO schema (schema_version, ros_distro) VALUES (3, 'humble')")
        con.execute("INSERT INTO metadata (id, metadata_version, metadata) VALUES (1, 5, ?)",
                    (metadata,))
        ids = {}
        for t in topics:
            ids[t["name"]] = t["id"]
            con.execute("INSERT INTO topics (id, name, type, serialization_format, "
                        "offered_qos_profiles) VALUES (?, ?, ?, ?, ?)",
                        (t["id"], t["name"], t["type"], t["serialization_format"],
                         t["offered_qos_profiles"]))
        for i, m in enumerate(messages, start=1):
            con.execute("INSERT INTO messages (id, topic_id, timestamp, data) VALUES (?, ?, ?, ?)",
                        (i, ids[m["topic"]], m["timestamp"], bytes.fromhex(m["data"])))
        con.execute("COMMIT")
        con.execute("VACUUM")
    finally:
        con.close()
    if os.path.exists(tmp + "-journal"):
        raise SystemExit(f"make_db3.py: {tmp}-journal was left behind")
    os.replace(tmp, path)


def main():
    if len(sys.argv) != 2:
        raise SystemExit("usage: node make_ros2bag.mjs OUT_DIR | python3 make_db3.py OUT_DIR")
    out_dir = sys.argv[1]
    topics, messages = read_input(sys.stdin)
    meta = metadata_yaml(topics, messages)
    db3 = os.path.join(out_dir, "robot.db3")
    write_db3(db3, topics, messages, meta)
    bag_dir = os.path.join(out_dir, BAG_DIR)
    os.makedirs(bag_dir, exist_ok=True)
    shutil.copyfile(db3, os.path.join(bag_dir, BAG_FILE))
    with open(os.path.join(bag_dir, "metadata.yaml"), "w", encoding="ascii", newline="\n") as f:
        f.write(meta + "\n")


if __name__ == "__main__":
    main()
