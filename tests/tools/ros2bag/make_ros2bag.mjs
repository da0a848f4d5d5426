#!/usr/bin/env node
// Writes the ROS 2 bag fixtures of tests/data/ros2/ with implementations that share no code with
// carvemap's readers: the MCAP files with @mcap/core (the MCAP project's TypeScript library), the
// messages as CDR with @foxglove/cdr. The .db3 (sqlite3) files are written by make_db3.py from
// the JSON lines this script prints on stdout (one line per topic, one per message with its CDR
// bytes in hex, and a closing line), so that both containers hold byte-identical messages.
//
// The scenario is tests/tools/make_rosbag.py's, number for number: the same room, path, sensors,
// frames, stamps, record times and ray casting (that file's functions are the truth for these
// bags too). Differences are only those of ROS 2: std_msgs/Header has no seq, type names are
// "pkg/msg/Type", messages are CDR (little-endian, encapsulation header 00 01 00 00).
//
//   node make_ros2bag.mjs OUT_DIR | python3 make_db3.py OUT_DIR
//
// writes OUT_DIR/robot.mcap (chunks uncompressed), robot_zstd.mcap (zstd, small chunks),
// robot_lz4.mcap (lz4 frames, small chunks), robot_unorganized.mcap (/cloud as 1 x 15).

import { mkdirSync, writeFileSync } from "node:fs";
import { join } from "node:path";

import { CdrWriter, EncapsulationKind } from "@foxglove/cdr";
import * as zstd from "@foxglove/wasm-zstd";
import { LIBRARY_IDENTIFIER, McapWriter, TempBuffer } from "@mcap/core";
import lz4 from "lz4js";

// ---- the scenario (tests/tools/make_rosbag.py) ----

const ROOM = [6.0, 4.0, 2.5];
const T0 = 1700000000.0;
const DURATION = 4.0;
const RECEIVE_LATENCY = 0.02;
const radians = (deg) => deg * (Math.PI / 180.0); // CPython's math.radians
const LASER_IN_BASE = [[0.2, 0.0, 0.3], 0.0]; // translation, yaw
const CAMERA_IN_BASE = [[0.0, 0.1, 1.2], radians(30)];
const CAMERA_PITCH = radians(20);

function basePose(t) {
  const s = t / DURATION;
  return [[1.0 + 3.5 * s, 1.0 + 2.0 * s, 0.0], -0.3 + 1.2 * s];
}

function rotZ(a) {
  const c = Math.cos(a);
  const s = Math.sin(a);
  return [[c, -s, 0], [s, c, 0], [0, 0, 1]];
}

function rotY(a) {
  const c = Math.cos(a);
  const s = Math.sin(a);
  return [[c, 0, s], [0, 1, 0], [-s, 0, c]];
}

const EYE = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];

function matMul(a, b) {
  const r = [[0, 0, 0], [0, 0, 0], [0, 0, 0]];
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) {
      r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
    }
  }
  return r;
}

function matVec(a, v) {
  return a.map((row) => row[0] * v[0] + row[1] * v[1] + row[2] * v[2]);
}

function cameraRotation() {
  return matMul(rotZ(CAMERA_IN_BASE[1]), rotY(CAMERA_PITCH));
}

function copysign(mag, sgn) {
  const negative = sgn < 0 || Object.is(sgn, -0);
  return negative ? -Math.abs(mag) : Math.abs(mag);
}

/** [x, y, z, w] of a rotation matrix: make_rosbag.py's quat_of. */
function quatOf(r) {
  const w = Math.sqrt(Math.max(0.0, 1 + r[0][0] + r[1][1] + r[2][2])) / 2;
  const x = copysign(Math.sqrt(Math.max(0.0, 1 + r[0][0] - r[1][1] - r[2][2])) / 2, r[2][1] - r[1][2]);
  const y = copysign(Math.sqrt(Math.max(0.0, 1 - r[0][0] + r[1][1] - r[2][2])) / 2, r[0][2] - r[2][0]);
  const z = copysign(Math.sqrt(Math.max(0.0, 1 - r[0][0] - r[1][1] + r[2][2])) / 2, r[1][0] - r[0][1]);
  return [x, y, z, w];
}

/** Distance from origin (inside the room) along a unit direction to the room's faces. */
function rayToRoom(origin, direction) {
  let best = Infinity;
  for (let d = 0; d < 3; d++) {
    if (Math.abs(direction[d]) < 1e-12) {
      continue;
    }
    for (const wall of [0.0, ROOM[d]]) {
      const s = (wall - origin[d]) / direction[d];
      if (s > 1e-9) {
        best = Math.min(best, s);
      }
    }
  }
  return best;
}

/** rospy.Time.from_sec(T0 + t) (genpy: secs = int(x), nsecs = int((x - secs) * 1e9)). */
function stamp(t) {
  const x = T0 + t;
  const sec = Math.trunc(x);
  const nanosec = Math.trunc((x - sec) * 1000000000);
  return { sec, nanosec };
}

const stampNs = ({ sec, nanosec }) => BigInt(sec) * 1000000000n + BigInt(nanosec);

function sensorInWorld(t, inBase, extra = EYE) {
  const [p, yaw] = basePose(t);
  const rb = rotZ(yaw);
  const r = matMul(matMul(rb, rotZ(inBase[1])), extra);
  const o = matVec(rb, inBase[0]);
  return [[p[0] + o[0], p[1] + o[1], p[2] + o[2]], r];
}

function transform(parent, child, t, translation, rotation) {
  return { stamp: stamp(t), frameId: parent, childFrameId: child, translation, rotation: quatOf(rotation) };
}

// ---- CDR (field order of the ROS 2 .msg files) ----

function newWriter() {
  return new CdrWriter({ kind: EncapsulationKind.CDR_LE });
}

function writeHeader(w, st, frameId) {
  w.int32(st.sec); // builtin_interfaces/Time: int32 sec, uint32 nanosec
  w.uint32(st.nanosec);
  w.string(frameId);
}

function encodeTFMessage(transforms) {
  const w = newWriter();
  w.sequenceLength(transforms.length);
  for (const tf of transforms) {
    writeHeader(w, tf.stamp, tf.frameId);
    w.string(tf.childFrameId);
    for (const v of tf.translation) w.float64(v);
    for (const v of tf.rotation) w.float64(v); // x, y, z, w
  }
  return w.data.slice();
}

function encodeLaserScan(m) {
  const w = newWriter();
  writeHeader(w, m.stamp, m.frameId);
  w.float32(m.angleMin);
  w.float32(m.angleMax);
  w.float32(m.angleIncrement);
  w.float32(m.timeIncrement);
  w.float32(m.scanTime);
  w.float32(m.rangeMin);
  w.float32(m.rangeMax);
  w.float32Array(m.ranges, true);
  w.float32Array(m.intensities, true);
  return w.data.slice();
}

function encodePointCloud2(m) {
  const w = newWriter();
  writeHeader(w, m.stamp, m.frameId);
  w.uint32(m.height);
  w.uint32(m.width);
  w.sequenceLength(m.fields.length);
  for (const f of m.fields) {
    w.string(f.name);
    w.uint32(f.offset);
    w.uint8(f.datatype);
    w.uint32(f.count);
  }
  w.uint8(m.isBigendian ? 1 : 0);
  w.uint32(m.pointStep);
  w.uint32(m.rowStep);
  w.uint8Array(m.data, true);
  w.uint8(m.isDense ? 1 : 0);
  return w.data.slice();
}

const FLOAT32 = 7; // sensor_msgs/msg/PointField.FLOAT32

// ---- the messages, in the order a recorder receives them ----

/** [{topic, logTime (bigint ns), data (CDR bytes)}], sorted by log time. */
function makeMessages(unorganized, duration = DURATION) {
  const out = [];
  const staticTfs = [
    transform("map", "odom", 0.0, [0, 0, 0], EYE),
    transform("base_link", "laser", 0.0, LASER_IN_BASE[0], rotZ(LASER_IN_BASE[1])),
    transform("base_link", "camera", 0.0, CAMERA_IN_BASE[0], cameraRotation()),
  ];
  out.push({ topic: "/tf_static", logTime: stampNs(stamp(0.0)), data: encodeTFMessage(staticTfs) });

  const events = [];
  for (let i = 0; i < Math.trunc(duration * 50) + 1; i++) events.push([i / 50.0, "tf"]);
  for (let i = 1; i < Math.trunc(duration * 10); i++) events.push([i / 10.0 + 0.003, "scan"]);
  for (let i = 1; i < Math.trunc(duration * 5); i++) events.push([i / 5.0 + 0.011, "cloud"]);
  // Python's sort of (t, kind) tuples.
  events.sort((a, b) => (a[0] !== b[0] ? a[0] - b[0] : a[1] < b[1] ? -1 : a[1] > b[1] ? 1 : 0));

  for (const [t, kind] of events) {
    if (kind === "tf") {
      const [p, yaw] = basePose(t);
      const data = encodeTFMessage([transform("odom", "base_link", t, p, rotZ(yaw))]);
      out.push({ topic: "/tf", logTime: stampNs(stamp(t)), data });
    } else if (kind === "scan") {
      const [origin, r] = sensorInWorld(t, LASER_IN_BASE);
      const m = {
        stamp: stamp(t),
        frameId: "laser",
        angleMin: -Math.PI / 2,
        angleMax: Math.PI / 2,
        angleIncrement: Math.PI / 180,
        timeIncrement: 0.0,
        scanTime: 0.1,
        rangeMin: 0.05,
        rangeMax: 5.0,
        ranges: [],
        intensities: [],
      };
      for (let k = 0; k < 181; k++) {
        const a = m.angleMin + k * m.angleIncrement;
        const d = matVec(r, [Math.cos(a), Math.sin(a), 0.0]);
        const rng = rayToRoom(origin, d);
        m.ranges.push(rng <= m.rangeMax ? rng : Infinity);
      }
      out.push({ topic: "/scan", logTime: stampNs(stamp(t + RECEIVE_LATENCY)), data: encodeLaserScan(m) });
    } else {
      const [origin, r] = sensorInWorld(t, CAMERA_IN_BASE, rotY(CAMERA_PITCH));
      const rows = 3;
      const cols = 5;
      const data = new Uint8Array(rows * cols * 12);
      const view = new DataView(data.buffer);
      let off = 0;
      for (let v = 0; v < rows; v++) {
        for (let u = 0; u < cols; u++) {
          let xyz;
          if (v === 1 && u === 2) {
            xyz = [NaN, NaN, NaN];
          } else {
            // The camera looks along its +x: pixels fan out in y and z.
            const d = [1.0, 0.25 * (u - 2), 0.2 * (1 - v)];
            const n = Math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (let i = 0; i < 3; i++) d[i] /= n;
            const rng = rayToRoom(origin, matVec(r, d));
            xyz = d.map((c) => c * rng);
          }
          for (const c of xyz) {
            view.setFloat32(off, c, true);
            off += 4;
          }
        }
      }
      const [height, width] = unorganized ? [1, rows * cols] : [rows, cols];
      const m = {
        stamp: stamp(t),
        frameId: "camera",
        height,
        width,
        fields: [
          { name: "x", offset: 0, datatype: FLOAT32, count: 1 },
          { name: "y", offset: 4, datatype: FLOAT32, count: 1 },
          { name: "z", offset: 8, datatype: FLOAT32, count: 1 },
        ],
        isBigendian: false,
        pointStep: 12,
        rowStep: 12 * width,
        data,
        isDense: false,
      };
      out.push({ topic: "/cloud", logTime: stampNs(stamp(t + RECEIVE_LATENCY)), data: encodePointCloud2(m) });
    }
  }
  // A recorder stores messages as they arrive: by record time (stable: /tf_static before the
  // /tf of the same instant). make_rosbag.py writes them in stamp order with these record times;
  // a ROS 1 bag reader returns them in this order too.
  return out
    .map((m, i) => [m, i])
    .sort((a, b) => (a[0].logTime < b[0].logTime ? -1 : a[0].logTime > b[0].logTime ? 1 : a[1] - b[1]))
    .map(([m]) => m);
}

// ---- message definitions (schema data, "ros2msg") ----
//
// Same fields, types, order, constants and defaults as the .msg files of ROS 2 Humble
// (sensor_msgs, std_msgs, builtin_interfaces, geometry_msgs, tf2_msgs); the comments are ours.

const MSG = {
  "builtin_interfaces/msg/Time":
    "# A point in time: seconds and nanoseconds since the epoch of its clock.\n" +
    "\n" +
    "int32 sec\n" +
    "\n" +
    "# Always in [0, 1e9).\n" +
    "uint32 nanosec\n",
  "std_msgs/msg/Header":
    "# Stamp and coordinate frame of data that has both.\n" +
    "\n" +
    "builtin_interfaces/Time stamp # when the data was taken\n" +
    "\n" +
    "string frame_id # the frame the data is expressed in\n",
  "geometry_msgs/msg/Vector3":
    "# A vector in free space.\n" +
    "\n" +
    "float64 x\n" +
    "float64 y\n" +
    "float64 z\n",
  "geometry_msgs/msg/Quaternion":
    "# An orientation as a unit quaternion (x, y, z, w).\n" +
    "\n" +
    "float64 x 0\n" +
    "float64 y 0\n" +
    "float64 z 0\n" +
    "float64 w 1\n",
  "geometry_msgs/msg/Transform":
    "# A rigid transform: first rotate, then translate.\n" +
    "\n" +
    "Vector3 translation\n" +
    "Quaternion rotation\n",
  "geometry_msgs/msg/TransformStamped":
    "# The pose of frame child_frame_id in frame header.frame_id at time header.stamp.\n" +
    "\n" +
    "std_msgs/Header header\n" +
    "\n" +
    "string child_frame_id # the frame this transform moves points from\n" +
    "\n" +
    "Transform transform\n",
  "tf2_msgs/msg/TFMessage":
    "# A batch of transforms, as published on /tf and /tf_static.\n" +
    "geometry_msgs/TransformStamped[] transforms\n",
  "sensor_msgs/msg/LaserScan":
    "# One sweep of a planar laser range finder.\n" +
    "#\n" +
    "# Angles are measured counter-clockwise about the frame's z axis, 0 along x.\n" +
    "\n" +
    "std_msgs/Header header # stamp: when the first ray was taken\n" +
    "\n" +
    "float32 angle_min        # angle of the first ray [rad]\n" +
    "float32 angle_max        # angle of the last ray [rad]\n" +
    "float32 angle_increment  # angle between rays [rad]\n" +
    "\n" +
    "float32 time_increment   # time between rays [s]\n" +
    "float32 scan_time        # time between sweeps [s]\n" +
    "\n" +
    "float32 range_min        # shortest valid range [m]\n" +
    "float32 range_max        # longest valid range [m]\n" +
    "\n" +
    "float32[] ranges         # [m]; outside [range_min, range_max] means no valid return\n" +
    "float32[] intensities    # in the device's units; may be empty\n",
  "sensor_msgs/msg/PointField":
    "# One field of the points of a PointCloud2.\n" +
    "uint8 INT8    = 1\n" +
    "uint8 UINT8   = 2\n" +
    "uint8 INT16   = 3\n" +
    "uint8 UINT16  = 4\n" +
    "uint8 INT32   = 5\n" +
    "uint8 UINT32  = 6\n" +
    "uint8 FLOAT32 = 7\n" +
    "uint8 FLOAT64 = 8\n" +
    "\n" +
    "string name      # e.g. x, y, z, intensity, rgb\n" +
    "uint32 offset    # bytes from the start of a point\n" +
    "uint8  datatype  # one of the constants above\n" +
    "uint32 count     # number of elements\n",
  "sensor_msgs/msg/PointCloud2":
    "# A set of points, each a record of the fields listed in fields. An organized cloud has\n" +
    "# height > 1 and is laid out row by row like an image; an unorganized one has height 1.\n" +
    "\n" +
    "std_msgs/Header header\n" +
    "\n" +
    "uint32 height\n" +
    "uint32 width\n" +
    "\n" +
    "PointField[] fields\n" +
    "\n" +
    "bool    is_bigendian # byte order of data\n" +
    "uint32  point_step   # bytes per point\n" +
    "uint32  row_step     # bytes per row\n" +
    "uint8[] data         # height * row_step bytes\n" +
    "\n" +
    "bool is_dense        # true when no point is invalid\n",
};

const PRIMITIVES = new Set([
  "bool", "byte", "char", "float32", "float64", "int8", "uint8",
  "int16", "uint16", "int32", "uint32", "int64", "uint64", "string",
]);

/** The text of a type's .msg file, for "pkg/Type" or "pkg/msg/Type". */
function msgText(name) {
  const parts = name.split("/");
  const full = parts.length === 2 ? `${parts[0]}/msg/${parts[1]}` : name;
  const text = MSG[full];
  if (text === undefined) throw new Error(`no definition for ${name}`);
  return [text, parts[0]];
}

/**
 * The complete "ros2msg" definition of a type, built as rosbag2 builds it
 * (rosbag2_cpp's LocalMessageDefinitionSource::get_full_text): the type's .msg text, then each
 * dependency not yet included, in sorted order and depth first, after a line of 80 '=' and a line
 * "MSG: <type as the field names it>".
 */
function fullDefinition(rootType) {
  const seen = new Set();
  const fieldType = /(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+/g;
  const appendRecursive = (name, depth) => {
    if (depth <= 0) throw new Error(`definition of ${rootType} nests too deep`);
    const [text, pkg] = msgText(name);
    const deps = new Set();
    for (const m of text.matchAll(fieldType)) {
      const type = m[1];
      if (PRIMITIVES.has(type)) continue;
      deps.add(type.includes("/") ? type : `${pkg}/${type}`);
    }
    let result = text;
    for (const dep of [...deps].sort()) {
      if (!seen.has(dep)) {
        seen.add(dep);
        result += "\n" + "=".repeat(80) + "\n" + `MSG: ${dep}\n` + appendRecursive(dep, depth - 1);
      }
    }
    return result;
  };
  return appendRecursive(rootType, 50);
}

// ---- topics: as `ros2 bag record` stores them (Humble) ----

function qos({ reliability, durability }) {
  // rmw_qos_profile_t as rosbag2 (Humble) serializes a publisher's offered QoS: history 3
  // (unknown) with depth 0; reliability 1 reliable, 2 best effort; durability 1 transient
  // local, 2 volatile; infinite deadline, lifespan and lease; liveliness 1 automatic.
  const inf = "    sec: 9223372036\n    nsec: 854775807\n";
  return (
    "- history: 3\n" +
    "  depth: 0\n" +
    `  reliability: ${reliability}\n` +
    `  durability: ${durability}\n` +
    "  deadline:\n" + inf +
    "  lifespan:\n" + inf +
    "  liveliness: 1\n" +
    "  liveliness_lease_duration:\n" + inf +
    "  avoid_ros_namespace_conventions: false"
  );
}

const TOPICS = [
  { name: "/tf_static", type: "tf2_msgs/msg/TFMessage", qos: qos({ reliability: 1, durability: 1 }) },
  { name: "/tf", type: "tf2_msgs/msg/TFMessage", qos: qos({ reliability: 1, durability: 2 }) },
  { name: "/scan", type: "sensor_msgs/msg/LaserScan", qos: qos({ reliability: 2, durability: 2 }) },
  { name: "/cloud", type: "sensor_msgs/msg/PointCloud2", qos: qos({ reliability: 2, durability: 2 }) },
];

// ---- MCAP ----

async function writeMcap(path, messages, { chunkSize, compression }) {
  const buffer = new TempBuffer();
  const writer = new McapWriter({
    writable: buffer,
    chunkSize,
    startChannelId: 1, // as rosbag2's writer numbers them (0 is valid MCAP too)
    compressChunk:
      compression === "zstd"
        ? (data) => ({ compression: "zstd", compressedData: zstd.compress(data) })
        : compression === "lz4"
          ? (data) => ({ compression: "lz4", compressedData: Uint8Array.from(lz4.compress(data)) })
          : undefined,
  });
  await writer.start({ profile: "ros2", library: LIBRARY_IDENTIFIER });
  const encoder = new TextEncoder();
  const schemaIds = new Map();
  const channelIds = new Map();
  for (const topic of TOPICS) {
    if (!schemaIds.has(topic.type)) {
      schemaIds.set(
        topic.type,
        await writer.registerSchema({
          name: topic.type,
          encoding: "ros2msg",
          data: encoder.encode(fullDefinition(topic.type)),
        }),
      );
    }
    channelIds.set(
      topic.name,
      await writer.registerChannel({
        topic: topic.name,
        schemaId: schemaIds.get(topic.type),
        messageEncoding: "cdr",
        metadata: new Map([["offered_qos_profiles", topic.qos]]),
      }),
    );
  }
  const sequence = new Map();
  for (const m of messages) {
    const seq = (sequence.get(m.topic) ?? 0) + 1;
    sequence.set(m.topic, seq);
    await writer.addMessage({
      channelId: channelIds.get(m.topic),
      sequence: seq,
      logTime: m.logTime,
      publishTime: m.logTime,
      data: m.data,
    });
  }
  await writer.end();
  writeFileSync(path, buffer.get());
}

function hex(bytes) {
  return Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength).toString("hex");
}

async function main() {
  const outDir = process.argv[2];
  if (!outDir || process.argv.length !== 3) {
    process.stderr.write("usage: node make_ros2bag.mjs OUT_DIR | python3 make_db3.py OUT_DIR\n");
    process.exit(2);
  }
  mkdirSync(outDir, { recursive: true });
  await zstd.isLoaded;
  const organized = makeMessages(false);
  const unorganized = makeMessages(true);
  await writeMcap(join(outDir, "robot.mcap"), organized, { chunkSize: 1024 * 1024 });
  await writeMcap(join(outDir, "robot_zstd.mcap"), organized, { chunkSize: 4096, compression: "zstd" });
  await writeMcap(join(outDir, "robot_lz4.mcap"), organized, { chunkSize: 4096, compression: "lz4" });
  await writeMcap(join(outDir, "robot_unorganized.mcap"), unorganized, { chunkSize: 1024 * 1024 });

  // For make_db3.py: the topics, then the messages of robot.mcap, then a count to check.
  const lines = [];
  TOPICS.forEach((t, i) => {
    lines.push(JSON.stringify({
      kind: "topic", id: i + 1, name: t.name, type: t.type, serialization_format: "cdr",
      offered_qos_profiles: t.qos,
    }));
  });
  for (const m of organized) {
    // timestamp as a bare JSON integer: it is past 2^53, and Python's json reads it exactly.
    lines.push(`{"kind":"message","topic":${JSON.stringify(m.topic)},"timestamp":${m.logTime},"data":"${hex(m.data)}"}`);
  }
  lines.push(JSON.stringify({ kind: "end", topics: TOPICS.length, messages: organized.length }));
  process.stdout.write(lines.join("\n") + "\n");
}

await main();
