// Reads the LAS fixtures of tests/data/las/ with LAS readers from the npm registry that share
// no code with tests/tools/make_las.py or with carvemap, and compares everything they report
// with the values make_las.py says it wrote (its --expected JSON):
//
//   node check_las.mjs DATA_DIR EXPECTED_JSON
//
// - @loaders.gl/las: LASLoader (the package's default, laz-perf based; LAS <= 1.3, formats
//   0-3) for the 1.2 and 1.3 files, LAZRsLoader (LAS <= 1.4, formats 0-10) for all four:
//   header (point count, record format and length, offset to points, scale, offset, bounds),
//   every point's X/Y/Z, intensity, classification and (format 3) colour.
// - copc (copc.js): Las.Header.parse for every header field, Las.Vlr.parse for the VLR, and
//   Las.View for every point's dimensions, GPS time and return numbers included.
// - Then, with copc's values and corridor_truth.json only: every point lies on the room's box,
//   in the sensor's y-z plane at the trajectory's pose interpolated at its GPS time, at its
//   beam's angle; GPS times follow the scanner's clock.
//
// Ends with "N passed, M failed"; exits 1 if anything failed.
import crypto from 'node:crypto';
import fs from 'node:fs';
import path from 'node:path';

import { parse } from '@loaders.gl/core';
import { LASLoader, LAZRsLoader } from '@loaders.gl/las';
import copc from 'copc';

const { Las } = copc;

if (process.argv.length !== 4) {
  console.error('usage: node check_las.mjs DATA_DIR EXPECTED_JSON');
  process.exit(2);
}
const [dataDir, expectedPath] = process.argv.slice(2);
const expected = JSON.parse(fs.readFileSync(expectedPath, 'utf8'));
const truth = JSON.parse(fs.readFileSync(path.join(dataDir, 'corridor_truth.json'), 'utf8'));

let passed = 0;
let failed = 0;
const readersOf = {};
function check(ok, what) {
  if (ok) {
    passed++;
  } else {
    failed++;
    console.log(`FAIL ${what}`);
  }
}
const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);
function checkEqual(actual, want, what) {
  check(same(actual, want), `${what}: got ${JSON.stringify(actual)}, want ${JSON.stringify(want)}`);
}
// Compares arrays element by element, reporting at most a few mismatches.
function checkEach(n, get, want, what, equal = (a, b) => a === b) {
  let bad = 0;
  for (let i = 0; i < n; i++) {
    const a = get(i);
    const b = want(i);
    if (!equal(a, b)) {
      if (bad < 3) console.log(`  ${what}[${i}]: got ${a}, want ${b}`);
      bad++;
    }
  }
  check(bad === 0, `${what}: ${bad} of ${n} points differ`);
}

// LAZRsLoader's wasm-bindgen glue would fetch() its .wasm by file URL, which Node's fetch
// cannot: hand it the bytes once (the same module instance that the loader imports).
const lasEntry = import.meta.resolve('@loaders.gl/las');
const initLazRs = (await import(new URL('./libs/laz-rs-wasm/laz_rs_wasm.js', lasEntry))).default;
await initLazRs({
  module_or_path: fs.readFileSync(new URL('./libs/laz-rs-wasm/laz_rs_wasm_bg.wasm', lasEntry)),
});

const arrayBufferOf = (buf) => buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);

function quantizedWorld(exp, i, j) {
  const h = exp.header;
  return exp.points.stored[i][j] * h.scale[j] + h.offset[j];
}

async function checkLoadersGl(name, buf, exp, loader, loaderName) {
  const h = exp.header;
  const n = exp.points.gps_time.length;
  // fp64: the default Float32Array positions lose up to 0.25 m at UTM northings.
  const mesh = await parse(arrayBufferOf(buf), loader, {
    worker: false,
    las: { fp64: true, colorDepth: 16, skip: 1 },
  });
  const d = mesh.loaderData;
  const tag = `${name} ${loaderName}`;
  checkEqual(mesh.header.vertexCount, n, `${tag} vertexCount`);
  checkEqual(d.pointsCount, n, `${tag} point count`);
  checkEqual(d.pointsFormatId, h.point_data_format, `${tag} point data format`);
  checkEqual(d.pointsStructSize, h.point_data_record_length, `${tag} record length`);
  checkEqual(d.pointsOffset, h.offset_to_point_data, `${tag} offset to point data`);
  checkEqual(d.scale, h.scale, `${tag} scale`);
  checkEqual(d.offset, h.offset, `${tag} offset`);
  checkEqual(d.mins, h.min, `${tag} min`);
  checkEqual(d.maxs, h.max, `${tag} max`);
  if (d.versionAsString !== undefined) {
    checkEqual(d.versionAsString, `${h.version_major}.${h.version_minor}`, `${tag} version`);
  }
  const pos = mesh.attributes.POSITION.value;
  check(pos instanceof Float64Array && pos.length === 3 * n, `${tag} POSITION Float64 x ${n}`);
  for (let j = 0; j < 3; j++) {
    const axis = 'XYZ'[j];
    checkEach(n, (i) => pos[3 * i + j], (i) => quantizedWorld(exp, i, j), `${tag} ${axis}`);
    checkEach(n, (i) => pos[3 * i + j], (i) => exp.points.world[i][j],
      `${tag} ${axis} within 0.0005 m of the ray-cast point`,
      (a, b) => Math.abs(a - b) <= 0.0005 + 1e-9);
  }
  const bbox = mesh.header.boundingBox;
  checkEqual(bbox, [h.min, h.max], `${tag} bounding box of the points = header bounds`);
  checkEach(n, (i) => mesh.attributes.intensity.value[i], (i) => exp.points.intensity[i],
    `${tag} intensity`);
  checkEach(n, (i) => mesh.attributes.classification.value[i],
    (i) => exp.points.classification[i], `${tag} classification`);
  const color = mesh.attributes.COLOR_0;
  if (h.point_data_format === 3) {
    // colorDepth 16: the loader keeps the high byte of each 16-bit channel.
    check(color !== undefined, `${tag} has COLOR_0`);
    for (let c = 0; c < 3; c++) {
      checkEach(n, (i) => color.value[4 * i + c], (i) => exp.points.rgb[i][c] >> 8,
        `${tag} colour ${'RGB'[c]} (high byte)`);
    }
  } else {
    check(color === undefined, `${tag} has no COLOR_0`);
  }
  (readersOf[name] ??= []).push(`@loaders.gl/las ${loaderName}`);
}

function checkCopc(name, buf, exp) {
  const h = exp.header;
  const n = exp.points.gps_time.length;
  const minor = h.version_minor;
  // copc.js parses headers of LAS 1.2 and 1.4 only, and of 1.4 only the 64-bit counts. The
  // first 227 bytes of a 1.3 or 1.4 header are laid out as 1.2's, so a copy whose minor
  // version byte says 2 gives the legacy fields through the same parser.
  let header;
  if (minor === 3) {
    let refused = false;
    try {
      Las.Header.parse(buf);
    } catch (e) {
      refused = /only 1\.2 and 1\.4/.test(e.message);
    }
    check(refused, `${name} copc refuses LAS 1.3 headers (as documented in its source)`);
  }
  const as12 = Buffer.from(buf);
  as12[25] = 2;
  const legacy = Las.Header.parse(as12);
  header = minor === 4 ? Las.Header.parse(buf) : legacy;
  const tag = `${name} copc`;
  checkEqual(header.fileSignature, h.file_signature, `${tag} file signature`);
  checkEqual(header.fileSourceId, h.file_source_id, `${tag} file source ID`);
  checkEqual(header.globalEncoding, h.global_encoding, `${tag} global encoding`);
  // copc prints the GUID as four little-endian uint32 in hex, grouped 8-4-4-16
  checkEqual(header.projectId.replace(/-/g, ''), h.project_id_hex, `${tag} project ID (zero)`);
  checkEqual([header.majorVersion, minor === 4 ? header.minorVersion : buf[25]],
    [h.version_major, h.version_minor], `${tag} version`);
  checkEqual(header.systemIdentifier, h.system_identifier, `${tag} system identifier`);
  checkEqual(header.generatingSoftware, h.generating_software, `${tag} generating software`);
  checkEqual([header.fileCreationDayOfYear, header.fileCreationYear],
    [h.file_creation_day_of_year, h.file_creation_year], `${tag} creation day/year`);
  checkEqual(header.headerLength, h.header_size, `${tag} header size`);
  checkEqual(header.pointDataOffset, h.offset_to_point_data, `${tag} offset to point data`);
  checkEqual(header.vlrCount, h.number_of_vlrs, `${tag} number of VLRs`);
  checkEqual(header.pointDataRecordFormat, h.point_data_format, `${tag} point data format`);
  checkEqual(buf[104], h.point_data_format, `${tag} format byte has no compression bits`);
  checkEqual(header.pointDataRecordLength, h.point_data_record_length, `${tag} record length`);
  checkEqual(legacy.pointCount, h.legacy_point_count, `${tag} legacy point count`);
  checkEqual(legacy.pointCountByReturn, h.legacy_points_by_return,
    `${tag} legacy points by return`);
  checkEqual(header.scale, h.scale, `${tag} scale`);
  checkEqual(header.offset, h.offset, `${tag} offset`);
  checkEqual(header.min, h.min, `${tag} min`);
  checkEqual(header.max, h.max, `${tag} max`);
  if (minor === 4) {
    checkEqual(header.pointCount, h.point_count, `${tag} point count (64-bit)`);
    checkEqual(header.pointCountByReturn, h.points_by_return, `${tag} points by return (64-bit)`);
    checkEqual(header.waveformDataOffset, h.start_of_waveform_data, `${tag} waveform start`);
    checkEqual(header.evlrOffset, h.start_of_first_evlr, `${tag} first EVLR`);
    checkEqual(header.evlrCount, h.number_of_evlrs, `${tag} number of EVLRs`);
  } else if (minor === 3) {
    // not parsed by copc: the one 1.3 field, read here
    checkEqual(Number(buf.readBigUInt64LE(227)), h.start_of_waveform_data,
      `${name} (own DataView) 1.3 start of waveform data`);
  }

  // VLRs: copc's parser for each 54-byte VLR header, then the payload.
  let at = h.header_size;
  for (let v = 0; v < h.number_of_vlrs; v++) {
    const vlr = Las.Vlr.parse(buf.subarray(at, at + Las.Constants.vlrHeaderLength), false);
    const want = h.vlrs[v];
    checkEqual([vlr.userId, vlr.recordId, vlr.contentLength, vlr.description],
      [want.user_id, want.record_id, want.length, want.description], `${tag} VLR ${v}`);
    at += Las.Constants.vlrHeaderLength;
    const payload = buf.subarray(at, at + vlr.contentLength).toString('latin1');
    if (want.user_id === 'LASF_Projection' && want.record_id === 2112) {
      checkEqual(payload, `${exp.wkt}\0`, `${tag} WKT payload (null-terminated)`);
      check((header.globalEncoding & 16) !== 0, `${tag} WKT global encoding bit set`);
    }
    at += vlr.contentLength;
  }
  checkEqual(at, h.offset_to_point_data, `${tag} VLRs end where the points start`);
  checkEqual(buf.length, h.offset_to_point_data + n * h.point_data_record_length,
    `${tag} file size = offset + count x record length`);

  const points = buf.subarray(h.offset_to_point_data, h.offset_to_point_data +
    n * h.point_data_record_length);
  const view = Las.View.create(points, header);
  checkEqual(view.pointCount, n, `${tag} view point count`);
  const g = (dim) => view.getter(dim);
  const P = exp.points;
  for (const [j, dim] of ['X', 'Y', 'Z'].entries()) {
    const get = g(dim);
    checkEach(n, get, (i) => quantizedWorld(exp, i, j), `${tag} ${dim}`);
    checkEach(n, get, (i) => P.world[i][j], `${tag} ${dim} within 0.0005 m of the ray-cast point`,
      (a, b) => Math.abs(a - b) <= 0.0005 + 1e-9);
  }
  const dims = [
    ['Intensity', 'intensity'], ['ReturnNumber', 'return_number'],
    ['NumberOfReturns', 'number_of_returns'], ['ScanDirectionFlag', 'scan_direction'],
    ['EdgeOfFlightLine', 'edge'], ['Classification', 'classification'],
    ['UserData', 'user_data'], ['PointSourceId', 'point_source_id'],
  ];
  for (const [dim, key] of dims) checkEach(n, g(dim), (i) => P[key][i], `${tag} ${dim}`);
  for (const dim of ['Synthetic', 'KeyPoint', 'Withheld', 'Overlap']) {
    checkEach(n, g(dim), () => 0, `${tag} ${dim}`);
  }
  if (h.point_data_format === 6) {
    checkEach(n, g('ScannerChannel'), () => 0, `${tag} ScannerChannel`);
    // copc multiplies the i16 by 0.006 (degrees)
    checkEach(n, g('ScanAngle'), (i) => P.scan_angle_i16[i], `${tag} ScanAngle (0.006 deg units)`,
      (a, b) => Math.round(a / 0.006) === b);
  } else {
    checkEach(n, g('ScanAngle'), (i) => P.scan_angle_rank[i], `${tag} ScanAngle rank`);
  }
  if (h.point_data_format === 0) {
    check(!view.dimensions.GpsTime, `${tag} format 0 has no GpsTime dimension`);
  } else {
    checkEach(n, g('GpsTime'), (i) => P.gps_time[i], `${tag} GpsTime (exact)`);
  }
  if (h.point_data_format === 3) {
    for (const [c, dim] of ['Red', 'Green', 'Blue'].entries()) {
      checkEach(n, g(dim), (i) => P.rgb[i][c], `${tag} ${dim}`);
    }
  }
  (readersOf[name] ??= []).push('copc Las.Header/Vlr/View');
  return view;
}

// The trajectory, read as a C++ importer would: '#' comment, then time x y z qx qy qz qw.
function readTrajectory(file) {
  const lines = fs.readFileSync(file, 'utf8').split('\n').filter((l) => l.length > 0);
  checkEqual(lines[0], '# time x y z qx qy qz qw', 'trajectory header line');
  const poses = lines.slice(1).map((l) => l.split(' ').map(Number));
  checkEqual(poses.length, truth.trajectory.poses, 'trajectory pose count');
  checkEqual(lines.length, expected.trajectory.lines, 'trajectory line count');
  let ok = true;
  for (let i = 0; i < poses.length; i++) {
    const [t, , , , qx, qy, qz, qw] = poses[i];
    ok &&= poses[i].length === 8 && poses[i].every(Number.isFinite);
    ok &&= Math.abs(Math.hypot(qx, qy, qz, qw) - 1) < 1e-8;
    if (i > 0) ok &&= Math.abs(t - poses[i - 1][0] - 1 / truth.trajectory.rate_hz) < 1e-6;
  }
  check(ok, 'trajectory: 8 finite columns, unit quaternions, evenly spaced times');
  return poses;
}

// Sensor position and yaw at GPS time t: linear interpolation (and of the yaw angle, which
// is the SLERP for rotations about one axis).
function poseAt(poses, t) {
  let lo = 0;
  let hi = poses.length - 1;
  if (t < poses[lo][0] || t > poses[hi][0]) return null;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (poses[mid][0] <= t) lo = mid; else hi = mid;
  }
  const [a, b] = [poses[lo], poses[hi]];
  const f = (t - a[0]) / (b[0] - a[0]);
  const yawOf = (p) => 2 * Math.atan2(p[6], p[7]);
  const p = [1, 2, 3].map((j) => a[j] + f * (b[j] - a[j]));
  return { p, yaw: yawOf(a) + f * (yawOf(b) - yawOf(a)) };
}

function checkGeometry(name, view, poses) {
  const n = view.pointCount;
  const [X, Y, Z, T, I] = ['X', 'Y', 'Z', 'GpsTime', 'Intensity'].map((d) => view.getter(d));
  const off = truth.scene_offset;
  const lo = truth.room_scene_frame.min.map((v, j) => v + off[j]);
  const hi = truth.room_scene_frame.max.map((v, j) => v + off[j]);
  const beams = 90;
  const tol = 0.0005 + 1e-6;
  let onBox = 0;
  let inPlane = 0;
  let atAngle = 0;
  let clock = 0;
  let covered = 0;
  for (let i = 0; i < n; i++) {
    const q = [X(i), Y(i), Z(i)];
    const t = T(i);
    const k = I(i) - 1000;   // intensity = 1000 + beam index
    const profile = Math.floor(i / beams);
    if (k === i % beams &&
        Math.abs(t - (truth.T0 + profile / 100 + k * (0.01 / beams))) < 1e-7) clock++;
    const inside = q.every((v, j) => v >= lo[j] - tol && v <= hi[j] + tol);
    const face = q.some((v, j) => Math.abs(v - lo[j]) <= tol || Math.abs(v - hi[j]) <= tol);
    if (inside && face) onBox++;
    const pose = poseAt(poses, t);
    if (!pose) continue;
    covered++;
    const v = q.map((c, j) => c - pose.p[j]);
    const [c, s] = [Math.cos(pose.yaw), Math.sin(pose.yaw)];
    const along = c * v[0] + s * v[1];          // sensor x
    const left = -s * v[0] + c * v[1];          // sensor y
    const range = Math.hypot(...v);
    // quantization: |along| <= 0.0005 (|cos yaw| + |sin yaw|) m
    if (Math.abs(along) <= 0.0008 && range <= 30) inPlane++;
    let da = Math.atan2(v[2], left) - 2 * Math.PI * k / beams;
    da = Math.atan2(Math.sin(da), Math.cos(da));
    // quantization moves a point by <= 0.0005 m per axis: <= 0.00072 m within the plane
    if (Math.abs(da) <= 0.001 / Math.hypot(left, v[2])) atAngle++;
  }
  checkEqual(clock, n, `${name} GPS time = T0 + profile/100 + k*0.01/90 (k from intensity)`);
  checkEqual(onBox, n, `${name} points on the room box's faces (world frame)`);
  checkEqual(covered, n, `${name} the trajectory covers every point's time`);
  checkEqual(inPlane, n, `${name} points in the sensor's y-z plane at their time, range <= 30 m`);
  checkEqual(atAngle, n, `${name} points at their beam's angle a_k in the sensor's y-z plane`);
}

const poses = readTrajectory(path.join(dataDir, truth.trajectory.file));
for (const [name, exp] of Object.entries(expected.files)) {
  const file = path.join(dataDir, name);
  const buf = fs.readFileSync(file);
  const digest = crypto.createHash('sha256').update(buf).digest('hex');
  checkEqual(digest, exp.sha256, `${name} sha256 = make_las.py's output now`);
  checkEqual(buf.subarray(0, 4).toString('latin1'), 'LASF', `${name} signature`);
  checkEqual(truth.files[name].points, exp.points.gps_time.length,
    `${name} point count in corridor_truth.json`);
  const h = exp.header;
  if (h.version_minor <= 3) {
    await checkLoadersGl(name, buf, exp, LASLoader, 'LASLoader (laz-perf)');
  } else {
    let refused = false;
    try {
      await parse(arrayBufferOf(buf), LASLoader, { worker: false });
    } catch (e) {
      refused = /versions <= 1\.3/.test(e.message);
    }
    check(refused, `${name} LASLoader (laz-perf) refuses LAS 1.4 (as documented)`);
  }
  await checkLoadersGl(name, buf, exp, LAZRsLoader, 'LAZRsLoader');
  const view = checkCopc(name, buf, exp);
  if (h.point_data_format !== 0) checkGeometry(name, view, poses);
}

for (const [name, readers] of Object.entries(readersOf)) {
  console.log(`${name}: read by ${readers.join(', ')}`);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
