#!/usr/bin/env node
// Reads the MCAP fixtures of tests/data/ros2/ back and checks them, with other code than wrote
// them where there is any: the chunks are decompressed with @foxglove/wasm-zstd and
// @foxglove/wasm-lz4 (liblz4 compiled to WebAssembly; lz4js compressed them), every message is
// decoded twice, by hand with @foxglove/cdr's CdrReader and by @foxglove/rosmsg2-serialization's
// MessageReader from the schema text in the file (parsed by @foxglove/rosmsg), and the CRCs of
// the data section and the summary are recomputed here.
//
//   node check_ros2bag.mjs DIR > decoded.jsonl
//
// prints one JSON line per message of robot.mcap and robot_unorganized.mcap (its CDR bytes and
// its decoded fields), which check_ros2bag.py (which runs this script) compares with the ROS 1
// bags that tests/tools/make_rosbag.py writes, and with the .db3 files. Its findings, and a
// summary of each file's records, go to stderr.

import { readFileSync } from "node:fs";
import { join } from "node:path";

import { CdrReader } from "@foxglove/cdr";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import lz4Decompress from "@foxglove/wasm-lz4";
import * as zstd from "@foxglove/wasm-zstd";
import { McapIndexedReader, McapStreamReader, TempBuffer } from "@mcap/core";

const FILES = {
  "robot.mcap": { compression: "", unorganized: false, minChunks: 1 },
  "robot_zstd.mcap": { compression: "zstd", unorganized: false, minChunks: 5 },
  "robot_lz4.mcap": { compression: "lz4", unorganized: false, minChunks: 5 },
  "robot_unorganized.mcap": { compression: "", unorganized: true, minChunks: 1 },
};
const COUNTS = { "/tf_static": 1, "/tf": 201, "/scan": 39, "/cloud": 19 };
const TYPES = {
  "/tf_static": "tf2_msgs/msg/TFMessage",
  "/tf": "tf2_msgs/msg/TFMessage",
  "/scan": "sensor_msgs/msg/LaserScan",
  "/cloud": "sensor_msgs/msg/PointCloud2",
};

const decompressHandlers = {
  zstd: (data, size) => zstd.decompress(data, Number(size)),
  lz4: (data, size) => lz4Decompress(data, Number(size)),
};

let failures = 0;
function check(ok, what) {
  if (!ok) {
    failures++;
    process.stderr.write(`FAIL: ${what}\n`);
  }
}

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC_TABLE[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

const hex = (b) => Buffer.from(b.buffer, b.byteOffset, b.byteLength).toString("hex");

// ---- decoding by hand (ROS 2 field order) ----

function time(r) {
  return { sec: r.int32(), nanosec: r.uint32() };
}

function header(r) {
  return { stamp: time(r), frame_id: r.string() };
}

function decodeByHand(type, data) {
  const r = new CdrReader(data);
  check(r.kind === 1 && data[0] === 0 && data[1] === 1 && data[2] === 0 && data[3] === 0,
    `encapsulation header 00 01 00 00 (${hex(data.subarray(0, 4))})`);
  let m;
  if (type === "tf2_msgs/msg/TFMessage") {
    const n = r.sequenceLength();
    const transforms = [];
    for (let i = 0; i < n; i++) {
      transforms.push({
        header: header(r),
        child_frame_id: r.string(),
        transform: {
          translation: { x: r.float64(), y: r.float64(), z: r.float64() },
          rotation: { x: r.float64(), y: r.float64(), z: r.float64(), w: r.float64() },
        },
      });
    }
    m = { transforms };
  } else if (type === "sensor_msgs/msg/LaserScan") {
    m = {
      header: header(r),
      angle_min: r.float32(),
      angle_max: r.float32(),
      angle_increment: r.float32(),
      time_increment: r.float32(),
      scan_time: r.float32(),
      range_min: r.float32(),
      range_max: r.float32(),
      ranges: r.float32Array(),
      intensities: r.float32Array(),
    };
  } else if (type === "sensor_msgs/msg/PointCloud2") {
    m = { header: header(r), height: r.uint32(), width: r.uint32(), fields: [] };
    const n = r.sequenceLength();
    for (let i = 0; i < n; i++) {
      m.fields.push({ name: r.string(), offset: r.uint32(), datatype: r.uint8(), count: r.uint32() });
    }
    m.is_bigendian = r.uint8() !== 0;
    m.point_step = r.uint32();
    m.row_step = r.uint32();
    m.data = r.uint8Array();
    m.is_dense = r.uint8() !== 0;
  } else {
    throw new Error(`unexpected type ${type}`);
  }
  check(r.decodedBytes === data.byteLength, `${type}: ${data.byteLength - r.decodedBytes} bytes left over`);
  return m;
}

function sameValue(a, b, path) {
  if (ArrayBuffer.isView(a) || ArrayBuffer.isView(b) || Array.isArray(a)) {
    check(a.length === b.length, `${path}: length ${a.length} != ${b.length}`);
    for (let i = 0; i < Math.min(a.length, b.length); i++) sameValue(a[i], b[i], `${path}[${i}]`);
  } else if (typeof a === "object" && a !== null) {
    const keys = new Set([...Object.keys(a), ...Object.keys(b)]);
    for (const k of keys) sameValue(a[k], b[k], `${path}.${k}`);
  } else {
    check(Object.is(a, b), `${path}: ${a} != ${b}`);
  }
}

/** A decoded message as JSON: float32 arrays and bytes as little-endian hex (NaN, inf). */
function toJson(m) {
  return JSON.parse(JSON.stringify(m, (k, v) => {
    if (v instanceof Float32Array) return { f32le: hex(v) };
    if (v instanceof Uint8Array) return { hex: hex(v) };
    return v;
  }));
}

// ---- one file ----

async function checkFile(dir, name, spec, out) {
  const bytes = new Uint8Array(readFileSync(join(dir, name)));
  const summary = { file: name, bytes: bytes.byteLength };

  // Stream pass: every record in file order, chunk CRCs validated by the reader.
  const stream = new McapStreamReader({ includeChunks: true, decompressHandlers, validateCrcs: true });
  stream.append(bytes);
  const opcodes = [];
  const streamMessages = [];
  let rec;
  let chunks = 0;
  let dataEnd;
  let footer;
  const compressions = new Set();
  while ((rec = stream.nextRecord())) {
    opcodes.push(rec.type);
    if (rec.type === "Chunk") {
      chunks++;
      compressions.add(rec.compression);
      check(rec.uncompressedCrc !== 0, `${name}: chunk without CRC`);
    }
    if (rec.type === "Message") streamMessages.push(rec);
    if (rec.type === "DataEnd") dataEnd = rec;
    if (rec.type === "Footer") footer = rec;
  }
  check(stream.done(), `${name}: stream reader not done`);
  check(chunks >= spec.minChunks, `${name}: ${chunks} chunks`);
  check(compressions.size === 1 && compressions.has(spec.compression),
    `${name}: chunk compression ${[...compressions]}`);
  summary.chunks = chunks;
  // Opcode runs, for the report: e.g. Header, Chunk, MessageIndex x4, ..., DataEnd, ...
  const runs = [];
  for (const op of opcodes) {
    const last = runs[runs.length - 1];
    if (last && last[0] === op) last[1]++;
    else runs.push([op, 1]);
  }
  summary.records = runs.map(([op, n]) => (n > 1 ? `${op} x${n}` : op)).join(", ");

  // Indexed pass: the summary section, and the messages through the chunk indexes.
  const reader = await McapIndexedReader.Initialize({ readable: new TempBuffer(bytes), decompressHandlers });
  check(reader.header.profile === "ros2", `${name}: profile ${reader.header.profile}`);
  summary.library = reader.header.library;
  const dataEndOffset = Number(reader.dataEndOffset);
  check(dataEnd.dataSectionCrc !== 0, `${name}: DataEnd without CRC`);
  check(dataEnd.dataSectionCrc === crc32(bytes.subarray(0, dataEndOffset)),
    `${name}: data section CRC`);
  const summaryStart = Number(footer.summaryStart);
  check(footer.summaryCrc !== 0 && footer.summaryCrc === crc32(bytes.subarray(summaryStart, bytes.byteLength - 8 - 4)),
    `${name}: summary CRC`);
  summary.data_section_crc = dataEnd.dataSectionCrc.toString(16);
  summary.summary_crc = footer.summaryCrc.toString(16);
  const stats = reader.statistics;
  check(stats && stats.messageCount === 260n && stats.channelCount === 4 && stats.schemaCount === 3 &&
    Number(stats.chunkCount) === chunks, `${name}: statistics`);

  const channelTopic = new Map();
  const definitions = new Map();
  for (const [id, ch] of reader.channelsById) {
    channelTopic.set(id, ch.topic);
    const schema = reader.schemasById.get(ch.schemaId);
    check(ch.messageEncoding === "cdr", `${name}: ${ch.topic} encoding ${ch.messageEncoding}`);
    check(schema.encoding === "ros2msg" && schema.name === TYPES[ch.topic], `${name}: ${ch.topic} schema`);
    check(ch.metadata.get("offered_qos_profiles")?.startsWith("- history: "), `${name}: ${ch.topic} QoS`);
    check(stats.channelMessageCounts.get(id) === BigInt(COUNTS[ch.topic]), `${name}: ${ch.topic} count`);
    const text = new TextDecoder().decode(schema.data);
    definitions.set(id, { type: schema.name, reader: new MessageReader(parse(text, { ros2: true })) });
  }
  check(channelTopic.size === 4, `${name}: ${channelTopic.size} channels`);

  const messages = [];
  for await (const m of reader.readMessages({ validateCrcs: true })) messages.push(m);
  check(messages.length === 260 && streamMessages.length === 260, `${name}: message count`);
  const counts = {};
  let lastTime = -1n;
  for (let i = 0; i < messages.length; i++) {
    const m = messages[i];
    const s = streamMessages[i];
    const topic = channelTopic.get(m.channelId);
    counts[topic] = (counts[topic] ?? 0) + 1;
    // The data section is in log-time order, so both passes see the same sequence.
    check(s && s.channelId === m.channelId && s.logTime === m.logTime && hex(s.data) === hex(m.data),
      `${name}: message ${i} differs between stream and indexed reading`);
    check(m.logTime >= lastTime, `${name}: message ${i} out of log-time order`);
    check(m.publishTime === m.logTime, `${name}: message ${i} publish time`);
    lastTime = m.logTime;
    const def = definitions.get(m.channelId);
    const byHand = decodeByHand(def.type, m.data);
    const generic = def.reader.readMessage(m.data);
    sameValue(generic, byHand, `${name} #${i} ${topic}`);
    out.push({
      file: name, topic, log_time: m.logTime, publish_time: m.publishTime,
      sequence: m.sequence, data: hex(m.data), msg: toJson(byHand),
    });
  }
  sameValue(counts, COUNTS, `${name}: messages per topic`);
  summary.counts = counts;
  const firstScan = messages.find((m) => channelTopic.get(m.channelId) === "/scan");
  summary.first_scan = { log_time: String(firstScan.logTime), bytes: firstScan.data.byteLength, head64: hex(firstScan.data.subarray(0, 64)) };
  return summary;
}

async function main() {
  const dir = process.argv[2];
  if (!dir || process.argv.length !== 3) {
    process.stderr.write("usage: node check_ros2bag.mjs DIR > decoded.jsonl\n");
    process.exit(2);
  }
  await zstd.isLoaded;
  await lz4Decompress.isLoaded;
  const records = [];
  const summaries = [];
  const perFile = {};
  for (const [name, spec] of Object.entries(FILES)) {
    const out = [];
    summaries.push(await checkFile(dir, name, spec, out));
    perFile[name] = out;
    if (name === "robot.mcap" || name === "robot_unorganized.mcap") records.push(...out);
  }
  // The compressed files hold exactly robot.mcap's messages.
  for (const name of ["robot_zstd.mcap", "robot_lz4.mcap"]) {
    const a = perFile["robot.mcap"];
    const b = perFile[name];
    check(a.length === b.length && a.every((m, i) => m.topic === b[i].topic && m.log_time === b[i].log_time &&
      m.sequence === b[i].sequence && m.data === b[i].data), `${name}: messages differ from robot.mcap's`);
  }
  // The unorganized file differs only in /cloud.
  const a = perFile["robot.mcap"];
  const u = perFile["robot_unorganized.mcap"];
  check(a.every((m, i) => m.topic === u[i].topic && m.log_time === u[i].log_time &&
    (m.topic === "/cloud" || m.data === u[i].data)), "robot_unorganized.mcap: differs beyond /cloud");

  for (const s of summaries) process.stderr.write(`${JSON.stringify(s)}\n`);
  for (const r of records) {
    process.stdout.write(`${JSON.stringify(r, (k, v) => (typeof v === "bigint" ? `@${v}` : v)).replace(/"@(\d+)"/g, "$1")}\n`);
  }
  process.stderr.write(failures === 0 ? "check_ros2bag.mjs: all MCAP checks passed\n" : `check_ros2bag.mjs: ${failures} failures\n`);
  process.exitCode = failures === 0 ? 0 : 1; // not process.exit(): it would cut a piped stdout short
}

await main();
