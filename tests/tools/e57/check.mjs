// Cross-checks the E57 fixtures in tests/data/e57/ against the scene geometry.
//
//   node check.mjs DATA_DIR EXPECTED.json
//
// EXPECTED.json comes from `make_e57.py --expected` (geometry only, no E57 bytes).
// Two readers are used:
//  1. web-e57 (npm; the Rust crate "e57" 0.10.5 compiled to WebAssembly): the independent
//     reader. Its convertE57() gives the XML (read through its CRC-checked page layer) and the
//     points in file coordinates (pose applied, spherical converted, invalid points skipped).
//     It does not expose row/column indices, invalid states or raw values.
//  2. miniDecode() below: a small decoder written separately from make_e57.py, from the
//     format facts in README.md. Used for the fields web-e57 does not expose.
import { readFileSync, readdirSync } from "fs";
import { join } from "path";

const [dataDir, expectedPath] = process.argv.slice(2);
if (!dataDir || !expectedPath) {
  console.error("usage: node check.mjs DATA_DIR EXPECTED.json");
  process.exit(2);
}
const expected = JSON.parse(readFileSync(expectedPath, "utf8"));
const truth = JSON.parse(readFileSync(join(dataDir, "truth.json"), "utf8"));

let passed = 0, failed = 0;
function check(ok, what) {
  if (ok) passed++;
  else { failed++; console.log("FAIL " + what); }
  return ok;
}

// ---------------------------------------------------------------- web-e57 loader
// The package is a wasm-bindgen "bundler" build; node cannot import its .wasm directly, so
// instantiate it by hand with the package's own JS glue.
const bg = await import(new URL("./node_modules/web-e57/e57_bg.js", import.meta.url));
const wasmBytes = readFileSync(new URL("./node_modules/web-e57/e57_bg.wasm", import.meta.url));
const inst = new WebAssembly.Instance(new WebAssembly.Module(wasmBytes), { "./e57_bg.js": bg });
bg.__wbg_set_wasm(inst.exports);
const webe57Version = JSON.parse(
  readFileSync(new URL("./node_modules/web-e57/package.json", import.meta.url), "utf8")).version;
function webE57(bytes, fmt) {
  return bg.convertE57(new Uint8Array(bytes), fmt);
}

// ---------------------------------------------------------------- tiny XML helpers
function scanBlocks(xml) {
  const d = xml.slice(xml.indexOf("<data3D"), xml.indexOf("</data3D>"));
  return d.split("<vectorChild").slice(1);
}
function cdata(block, tag) {
  const m = block.match(new RegExp(`<${tag} type="String"><!\\[CDATA\\[(.*?)\\]\\]></${tag}>`));
  return m ? m[1] : null;
}
function floatIn(block, outer, tag) {
  const o = block.slice(block.indexOf(`<${outer} `), block.indexOf(`</${outer}>`));
  const m = o.match(new RegExp(`<${tag} type="Float">([^<]*)</${tag}>`));
  return m ? Number(m[1]) : NaN;
}
function attrs(s) {
  const a = {};
  for (const m of s.matchAll(/(\w+)="([^"]*)"/g)) a[m[1]] = m[2];
  return a;
}
function parseScans(xml) {
  return scanBlocks(xml).map((b) => {
    const pts = attrs(b.match(/<points ([^>]*)>/)[1]);
    const proto = b.slice(b.indexOf("<prototype"), b.indexOf("</prototype>"));
    const fields = [...proto.matchAll(/<(\w+) (type="(?:Integer|ScaledInteger|Float)"[^>]*)\/>/g)]
      .map((m) => ({ name: m[1], ...attrs(m[2]) }));
    return {
      guid: cdata(b, "guid"), name: cdata(b, "name"),
      t: ["x", "y", "z"].map((k) => floatIn(b, "translation", k)),
      q: ["w", "x", "y", "z"].map((k) => floatIn(b, "rotation", k)),
      fileOffset: Number(pts.fileOffset), recordCount: Number(pts.recordCount), fields,
      hasIndexBounds: b.includes("<indexBounds"),
    };
  });
}

// ---------------------------------------------------------------- mini decoder
const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? (c >>> 1) ^ 0x82f63b78 : c >>> 1; // CRC-32C, reflected
    t[n] = c >>> 0;
  }
  return t;
})();
function crc32c(buf, start, end) {
  let c = 0xffffffff;
  for (let i = start; i < end; i++) c = CRC_TABLE[(c ^ buf[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

function miniDecode(file) {
  const dv = new DataView(file.buffer, file.byteOffset, file.byteLength);
  const sig = String.fromCharCode(...file.subarray(0, 8));
  if (sig !== "ASTM-E57") throw new Error(`bad signature '${sig}'`);
  const major = dv.getUint32(8, true), minor = dv.getUint32(12, true);
  const physLen = Number(dv.getBigUint64(16, true));
  const xmlPhys = Number(dv.getBigUint64(24, true));
  const xmlLen = Number(dv.getBigUint64(32, true));
  const page = Number(dv.getBigUint64(40, true));
  if (major !== 1 || minor !== 0) throw new Error(`version ${major}.${minor}`);
  if (page !== 1024) throw new Error(`page size ${page}`);
  if (physLen !== file.length) throw new Error(`header says ${physLen} bytes, file has ${file.length}`);
  if (file.length % page) throw new Error("file length is not a whole number of pages");
  const lpage = page - 4;
  const npages = file.length / page;
  const logical = new Uint8Array(npages * lpage);
  for (let p = 0; p < npages; p++) {
    const s = p * page;
    const stored = dv.getUint32(s + lpage, false); // big-endian
    const calc = crc32c(file, s, s + lpage);
    if (stored !== calc) throw new Error(`CRC mismatch on page ${p}`);
    logical.set(file.subarray(s, s + lpage), p * lpage);
  }
  const toLogical = (phys) => {
    if (phys >= file.length) throw new Error(`offset ${phys} is past the end (${file.length})`);
    if (phys % page >= lpage) throw new Error(`offset ${phys} points into a CRC`);
    return Math.floor(phys / page) * lpage + (phys % page);
  };
  const L = new DataView(logical.buffer);
  const xs = toLogical(xmlPhys);
  const xml = new TextDecoder().decode(logical.subarray(xs, xs + xmlLen));
  const scans = parseScans(xml);
  for (const sc of scans) {
    const s0 = toLogical(sc.fileOffset);
    if (logical[s0] !== 1) throw new Error("section id is not 1");
    const secLen = Number(L.getBigUint64(s0 + 8, true));
    let pos = toLogical(Number(L.getBigUint64(s0 + 16, true)));
    const secEnd = s0 + secLen;
    const n = sc.fields.length;
    const parts = sc.fields.map(() => []);
    const pkts = { data: 0, other: 0 };
    while (pos < secEnd) {
      const type = logical[pos];
      const plen = L.getUint16(pos + 2, true) + 1;
      if (type === 1) {
        if (L.getUint16(pos + 4, true) !== n) throw new Error("bytestream count");
        let q = pos + 6 + 2 * n;
        for (let i = 0; i < n; i++) {
          const bl = L.getUint16(pos + 6 + 2 * i, true);
          parts[i].push(logical.subarray(q, q + bl));
          q += bl;
        }
        if (q > pos + plen) throw new Error("buffers overrun the packet");
        pkts.data++;
      } else if (type === 0 || type === 2) pkts.other++;
      else throw new Error(`unknown packet type ${type}`);
      if (plen % 4) throw new Error("packet length not a multiple of 4");
      pos += plen;
    }
    sc.packets = pkts;
    // how many packet boundaries split a bit-packed value between two packets
    sc.straddles = 0;
    sc.fields.forEach((f, i) => {
      if (f.type === "Float") return;
      const b = Math.ceil(Math.log2(Number(f.maximum) - Number(f.minimum) + 1));
      let cum = 0;
      for (const part of parts[i].slice(0, -1)) {
        cum += part.length;
        if (b && (cum * 8) % b !== 0 && cum * 8 < b * sc.recordCount) sc.straddles++;
      }
    });
    sc.values = {};
    sc.fields.forEach((f, i) => {
      const total = parts[i].reduce((a, b) => a + b.length, 0);
      const bytes = new Uint8Array(total);
      let o = 0;
      for (const b of parts[i]) { bytes.set(b, o); o += b.length; }
      const out = new Float64Array(sc.recordCount);
      const bdv = new DataView(bytes.buffer);
      if (f.type === "Float") {
        const sz = f.precision === "single" ? 4 : 8;
        if (total < sz * sc.recordCount) throw new Error(`${f.name}: stream too short`);
        for (let k = 0; k < sc.recordCount; k++)
          out[k] = sz === 4 ? bdv.getFloat32(4 * k, true) : bdv.getFloat64(8 * k, true);
      } else {
        const min = Number(f.minimum), max = Number(f.maximum);
        const bits = Math.ceil(Math.log2(max - min + 1)); // 0 when min == max
        if (Math.ceil(bits * sc.recordCount / 8) > total) throw new Error(`${f.name}: stream too short`);
        const scale = f.type === "ScaledInteger" ? Number(f.scale) : 1;
        const offset = f.type === "ScaledInteger" ? Number(f.offset ?? 0) : 0;
        let bit = 0;
        for (let k = 0; k < sc.recordCount; k++) {
          let v = 0;
          for (let j = 0; j < bits; j++, bit++) // LSB first, little-endian bytes
            if (bytes[bit >> 3] & (1 << (bit & 7))) v += 2 ** j;
          const raw = v + min;
          if (raw > max) throw new Error(`${f.name}: value above maximum`);
          out[k] = f.type === "ScaledInteger" ? raw * scale + offset : raw;
        }
      }
      sc.values[f.name] = out;
    });
  }
  return { xml, scans };
}

// ---------------------------------------------------------------- checks of good files
function maxAbsDiff(a, b) {
  let m = 0;
  for (let i = 0; i < a.length; i++) m = Math.max(m, Math.abs(a[i] - b[i]));
  return m;
}

for (const [fname, exp] of Object.entries(expected.files)) {
  const bytes = readFileSync(join(dataDir, fname));
  const tr = truth.files[fname];
  console.log(`== ${fname} (${bytes.length} bytes)`);

  // -- 1. web-e57: XML (metadata) and JSON (points in file coordinates)
  let wxml = null, wpts = null;
  try {
    wxml = webE57(bytes, "XML");
    wpts = JSON.parse(webE57(bytes, "JSON"));
  } catch (e) {
    check(false, `${fname}: web-e57 failed: ${e}`);
    continue;
  }
  const ws = parseScans(wxml);
  check(ws.length === exp.scans.length, `${fname}: web-e57 scan count ${ws.length}`);
  check(wpts.length === exp.scans.length, `${fname}: web-e57 point-cloud count ${wpts.length}`);
  check(wxml.includes('xmlns="http://www.astm.org/COMMIT/E57/2010-e57-v1.0"'), `${fname}: xmlns`);
  exp.scans.forEach((e, i) => {
    const w = ws[i], p = wpts[i], t = tr.scans[i];
    const tag = `${fname} scan ${i} (${e.name})`;
    check(w.name === e.name && t.name === e.name, `${tag}: name ${w.name}`);
    check(w.guid === e.guid && t.guid === e.guid, `${tag}: guid ${w.guid}`);
    check(w.t.every((v, k) => v === e.pose.translation[k]), `${tag}: translation ${w.t}`);
    check(w.q.every((v, k) => v === e.pose.rotation[k]), `${tag}: rotation ${w.q}`);
    check(t.pose.translation.x === e.pose.translation[0] && t.pose.rotation.w === e.pose.rotation[0],
      `${tag}: truth.json pose`);
    check(w.recordCount === e.records && t.records === e.records, `${tag}: recordCount ${w.recordCount}`);
    check(JSON.stringify(w.fields.map((f) => f.name)) === JSON.stringify(e.fields),
      `${tag}: prototype ${w.fields.map((f) => f.name)}`);
    check(w.hasIndexBounds === (e.kind === "scaled"), `${tag}: indexBounds present iff scaled file`);
    const nret = e.world.length / 3;
    check(t.returns === nret, `${tag}: truth.json returns ${t.returns} vs ${nret}`);
    if (e.kind !== "points") check(t.returns + t.no_return === e.rows * e.cols, `${tag}: truth returns + no_return`);
    if (check(p.length === nret, `${tag}: web-e57 gives ${p.length} points, expected ${nret}`)) {
      const flat = new Float64Array(3 * p.length);
      p.forEach((q, k) => { flat[3 * k] = q.x; flat[3 * k + 1] = q.y; flat[3 * k + 2] = q.z; });
      const d = maxAbsDiff(flat, e.world);
      check(d <= e.tol, `${tag}: web-e57 points differ by ${d} > ${e.tol}`);
      console.log(`  ${e.name}: web-e57 ${p.length} points, max |diff| to geometry ${d.toExponential(2)} m (tol ${e.tol})`);
    }
  });

  // web-e57's XYZ output carries intensity as a grey level (r = g = b); check it against the
  // geometry's intensity (normalised by the 0..1 limits, so about intensity*255).
  if (exp.scans[0].kind === "scaled") {
    const lines = webE57(bytes, "XYZ").trim().split("\n");
    const want = exp.scans.flatMap((e) => e.intensity.filter((_, k) => e.state[k] !== 2));
    let worst = 0;
    lines.forEach((l, k) => { worst = Math.max(worst, Math.abs(Number(l.split(" ")[3]) - want[k] * 255)); });
    check(lines.length === want.length && worst < 1.001, `${fname}: web-e57 XYZ intensity grey off by ${worst}`);
    console.log(`  web-e57 XYZ: ${lines.length} lines, intensity grey level within ${worst.toFixed(4)} of intensity*255`);
  }

  // -- 2. mini decoder: every stored field per record
  let mine;
  try { mine = miniDecode(bytes); } catch (err) { check(false, `${fname}: mini decoder: ${err}`); continue; }
  check(mine.scans.length === exp.scans.length, `${fname}: mini scan count`);
  exp.scans.forEach((e, i) => {
    const s = mine.scans[i], v = s.values, tag = `${fname} scan ${i} (${e.name}) mini`;
    const n = e.records;
    check(s.recordCount === n, `${tag}: records`);
    const eq = (a, b) => a.length === b.length && a.every((x, k) => x === b[k]);
    let note = `${s.packets.data} data packets, ${s.straddles} packet cuts inside a bit-packed value`;
    if (e.kind !== "points") check(s.packets.data >= 3 && s.straddles > 0, `${tag}: spans several packets, values straddle`);
    if (e.kind === "scaled") {
      check(eq(Array.from(v.rowIndex), e.row), `${tag}: rowIndex`);
      check(eq(Array.from(v.columnIndex), e.col), `${tag}: columnIndex`);
      check(eq(Array.from(v.cartesianInvalidState), e.state), `${tag}: cartesianInvalidState`);
      check(eq(Array.from(v.intensity), e.intensity), `${tag}: intensity`);
      let d = 0, zeroOk = true;
      for (let k = 0; k < n; k++) {
        for (let a = 0; a < 3; a++) {
          const got = v[["cartesianX", "cartesianY", "cartesianZ"][a]][k];
          if (e.state[k] === 2) zeroOk &&= got === 0;
          else d = Math.max(d, Math.abs(got - e.local[3 * k + a]));
        }
      }
      check(d <= 0.5 * e.tol + 1e-12, `${tag}: local xyz differ by ${d}`);
      check(zeroOk, `${tag}: no-return pixels have coordinates 0`);
      note += `, local xyz max |diff| ${d.toExponential(2)} m (half-step ${0.5 * e.tol})`;
    } else if (e.kind === "spherical") {
      check(eq(Array.from(v.rowIndex), e.row), `${tag}: rowIndex`);
      check(eq(Array.from(v.columnIndex), e.col), `${tag}: columnIndex`);
      check(eq(Array.from(v.sphericalInvalidState), e.state), `${tag}: sphericalInvalidState`);
      check(eq(Array.from(v.sphericalAzimuth), e.az), `${tag}: azimuth (float32 exact)`);
      check(eq(Array.from(v.sphericalElevation), e.el), `${tag}: elevation (float32 exact)`);
      const d = maxAbsDiff(v.sphericalRange, e.range);
      check(d <= 1e-9, `${tag}: range differs by ${d}`);
      // each (row, col) at most once; absent pixels are exactly the no-return ones
      const seen = new Set(e.row.map((r, k) => r * e.cols + e.col[k]));
      check(seen.size === n && n + e.no_return === e.rows * e.cols, `${tag}: pixel coverage`);
      note += `, range max |diff| ${d.toExponential(2)}`;
    } else {
      const flat = new Float64Array(3 * n);
      for (let k = 0; k < n; k++) {
        flat[3 * k] = v.cartesianX[k]; flat[3 * k + 1] = v.cartesianY[k]; flat[3 * k + 2] = v.cartesianZ[k];
      }
      const d = maxAbsDiff(flat, e.local);
      check(d <= 1e-9, `${tag}: local xyz differ by ${d}`);
      note += `, local xyz max |diff| ${d.toExponential(2)}`;
    }
    console.log(`  ${e.name}: mini decoder ${n} records, ${note}`);
  });
}

// ---------------------------------------------------------------- bad files
for (const fname of Object.keys(truth.bad_files)) {
  const bytes = readFileSync(join(dataDir, fname));
  let webErr = null, miniErr = null;
  try { webE57(bytes, "JSON"); } catch (e) { webErr = String(e); }
  try { miniDecode(bytes); } catch (e) { miniErr = String(e); }
  check(webErr !== null, `${fname}: web-e57 accepted it`);
  check(miniErr !== null, `${fname}: mini decoder accepted it`);
  console.log(`== ${fname}: web-e57 -> ${webErr ?? "ACCEPTED"}`);
  console.log(`   ${" ".repeat(fname.length)}  mini   -> ${miniErr ?? "ACCEPTED"}`);
}
// Control for bad_crc.e57: repair only the CRC of the damaged page; web-e57 must then read
// it, which shows that it rejected the file because of the CRC, not the changed value.
{
  const bad = new Uint8Array(readFileSync(join(dataDir, "bad_crc.e57")));
  const pg = truth.bad_files["bad_crc.e57"].page;
  new DataView(bad.buffer).setUint32(pg * 1024 + 1020, crc32c(bad, pg * 1024, pg * 1024 + 1020), false);
  let err = null;
  try { webE57(bad, "JSON"); } catch (e) { err = String(e); }
  check(err === null, `bad_crc.e57 with its page CRC repaired: web-e57 still fails: ${err}`);
  console.log(`== bad_crc.e57 with page ${pg} CRC repaired: web-e57 -> ${err ?? "reads it (so the rejection was the CRC check)"}`);
}
const listed = new Set([...Object.keys(expected.files), ...Object.keys(truth.bad_files), "truth.json"]);
const extra = readdirSync(dataDir).filter((f) => !listed.has(f));
check(extra.length === 0, `unexpected files in ${dataDir}: ${extra}`);

console.log(`reader: web-e57 ${webe57Version} (Rust crate e57 0.10.5 in WebAssembly)`);
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
