// Reads building.ifc with web-ifc (IFC parser and geometry kernel of That Open Company) and
// checks it against the job: usage `node check.mjs OUT` (OUT/building.ifc with OUT/job.json and
// OUT/levels.json) or `node check.mjs FILE.ifc` (the file against its own quantities). Prints
// the counts; exits non-zero on any problem.
import { existsSync, readFileSync, statSync } from 'node:fs';
import path from 'node:path';
import * as WebIFC from 'web-ifc';

const arg = process.argv[2];
if (!arg) {
  console.error('usage: node check.mjs OUT_DIR | FILE.ifc');
  process.exit(2);
}
const isDir = statSync(arg).isDirectory();
const file = isDir ? path.join(arg, 'building.ifc') : arg;
const job = isDir && existsSync(path.join(arg, 'job.json'))
  ? JSON.parse(readFileSync(path.join(arg, 'job.json'), 'utf8')) : null;
const levels = isDir && existsSync(path.join(arg, 'levels.json'))
  ? JSON.parse(readFileSync(path.join(arg, 'levels.json'), 'utf8')) : null;

const problems = [];
const api = new WebIFC.IfcAPI();
await api.Init();
const model = api.OpenModel(new Uint8Array(readFileSync(file)));
const schema = api.GetModelSchema(model);
if (schema !== 'IFC4') problems.push(`schema ${schema}, not IFC4`);

const ids = (type) => {
  const v = api.GetLineIDsWithType(model, type);
  const out = [];
  for (let i = 0; i < v.size(); ++i) out.push(v.get(i));
  return out;
};
const line = (id) => api.GetLine(model, id);
const value = (x) => (x && typeof x === 'object' && 'value' in x ? x.value : x);

const counts = {};
for (const [name, type] of [['IfcProject', WebIFC.IFCPROJECT], ['IfcSite', WebIFC.IFCSITE],
  ['IfcBuilding', WebIFC.IFCBUILDING], ['IfcBuildingStorey', WebIFC.IFCBUILDINGSTOREY],
  ['IfcSpace', WebIFC.IFCSPACE], ['IfcWall', WebIFC.IFCWALL], ['IfcDoor', WebIFC.IFCDOOR],
  ['IfcRelSpaceBoundary', WebIFC.IFCRELSPACEBOUNDARY]]) {
  counts[name] = ids(type).length;
}

// The hierarchy: IfcRelAggregates parent ➜ children, IfcRelContainedInSpatialStructure.
const children = new Map();
for (const id of ids(WebIFC.IFCRELAGGREGATES)) {
  const rel = line(id);
  const parent = value(rel.RelatingObject);
  children.set(parent, (children.get(parent) || []).concat(rel.RelatedObjects.map(value)));
}
const contained = new Map();
for (const id of ids(WebIFC.IFCRELCONTAINEDINSPATIALSTRUCTURE)) {
  const rel = line(id);
  contained.set(value(rel.RelatingStructure), rel.RelatedElements.map(value));
}
const typeOf = (id) => api.GetLineType(model, id);
const [project] = ids(WebIFC.IFCPROJECT);
const sites = children.get(project) || [];
const buildings = sites.flatMap((s) => children.get(s) || []);
const storeys = buildings.flatMap((b) => children.get(b) || []);
if (counts.IfcProject !== 1 || sites.length !== 1 || buildings.length !== 1 ||
    typeOf(sites[0]) !== WebIFC.IFCSITE || typeOf(buildings[0]) !== WebIFC.IFCBUILDING) {
  problems.push('not one project ➜ site ➜ building');
}
if (storeys.length !== counts.IfcBuildingStorey ||
    storeys.some((s) => typeOf(s) !== WebIFC.IFCBUILDINGSTOREY)) {
  problems.push(`${storeys.length} storeys under the building, ${counts.IfcBuildingStorey} in the file`);
}
if (levels && storeys.length !== levels.length) {
  problems.push(`${storeys.length} storeys, levels.json ${levels.length} levels`);
}
const spaces = storeys.flatMap((s) => children.get(s) || []);
if (spaces.length !== counts.IfcSpace || spaces.some((s) => typeOf(s) !== WebIFC.IFCSPACE)) {
  problems.push(`${spaces.length} spaces under the storeys, ${counts.IfcSpace} in the file`);
}
const elements = storeys.flatMap((s) => contained.get(s) || []);
const inStoreys = (type) => elements.filter((e) => typeOf(e) === type).length;
if (inStoreys(WebIFC.IFCWALL) !== counts.IfcWall || inStoreys(WebIFC.IFCDOOR) !== counts.IfcDoor) {
  problems.push('walls or doors not contained in a storey');
}

// Each space's quantities (Qto_SpaceBaseQuantities).
const quantities = new Map();
for (const id of ids(WebIFC.IFCRELDEFINESBYPROPERTIES)) {
  const rel = line(id);
  const set = line(value(rel.RelatingPropertyDefinition));
  if (value(set.Name) !== 'Qto_SpaceBaseQuantities') continue;
  const q = {};
  for (const h of set.Quantities) {
    const qty = line(value(h));
    q[value(qty.Name)] = value(qty.AreaValue ?? qty.LengthValue ?? qty.VolumeValue);
  }
  for (const o of rel.RelatedObjects) quantities.set(value(o), q);
}
const rooms = new Map();
if (job) {
  for (const r of job.rooms || []) {
    if (r.area_m2 > 0) rooms.set(`level ${r.level} room ${r.room}`, r);
  }
  if (rooms.size !== spaces.length) problems.push(`${spaces.length} spaces, job.json ${rooms.size} rooms`);
}

// web-ifc's own geometry of each space: a mesh whose vertical extent is the room's floor to
// ceiling and whose volume is its area times its height. web-ifc hands out meshes with y up
// (its flatTransformation turns IFC's z up to y up), so the height is the mesh's y.
let worstZ = 0, worstVolume = 0, triangles = 0;
for (const id of spaces) {
  const name = value(line(id).Name);
  const mesh = api.GetFlatMesh(model, id);
  let lo = Infinity, hi = -Infinity, volume = 0, tris = 0;
  for (let g = 0; g < mesh.geometries.size(); ++g) {
    const placed = mesh.geometries.get(g);
    const geom = api.GetGeometry(model, placed.geometryExpressID);
    const v = api.GetVertexArray(geom.GetVertexData(), geom.GetVertexDataSize());
    const ix = api.GetIndexArray(geom.GetIndexData(), geom.GetIndexDataSize());
    const m = placed.flatTransformation;
    const p = (i) => {  // vertex i, transformed (column-major 4 × 4), 6 floats a vertex
      const x = v[6 * i], y = v[6 * i + 1], z = v[6 * i + 2];
      return [m[0] * x + m[4] * y + m[8] * z + m[12], m[1] * x + m[5] * y + m[9] * z + m[13],
        m[2] * x + m[6] * y + m[10] * z + m[14]];
    };
    for (let i = 0; i < v.length / 6; ++i) {
      const y = p(i)[1];
      lo = Math.min(lo, y);
      hi = Math.max(hi, y);
    }
    for (let t = 0; t < ix.length; t += 3) {
      const a = p(ix[t]), b = p(ix[t + 1]), c = p(ix[t + 2]);
      volume += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
        a[2] * (b[0] * c[1] - b[1] * c[0])) / 6;
      ++tris;
    }
    geom.delete();
  }
  triangles += tris;
  if (tris === 0) {
    problems.push(`${name}: web-ifc made no mesh`);
    continue;
  }
  const q = quantities.get(id);
  if (!q) {
    problems.push(`${name}: no Qto_SpaceBaseQuantities`);
    continue;
  }
  const room = rooms.get(name);
  if (job && !room) problems.push(`${name}: not a room of job.json`);
  const floor = room ? room.floor_z : lo, ceiling = room ? room.ceiling_z : lo + q.Height;
  const area = room ? room.area_m2 : q.NetFloorArea;
  const dz = Math.max(Math.abs(lo - floor), Math.abs(hi - ceiling));
  const dv = Math.abs(Math.abs(volume) - area * (ceiling - floor)) / Math.max(area * (ceiling - floor), 1e-9);
  worstZ = Math.max(worstZ, dz);
  worstVolume = Math.max(worstVolume, dv);
  if (dz > 1e-3) problems.push(`${name}: mesh from ${lo} to ${hi} m, the room ${floor} to ${ceiling}`);
  if (dv > 1e-3) problems.push(`${name}: mesh volume ${Math.abs(volume)} m³, area × height ${area * (ceiling - floor)}`);
  if (Math.abs(q.NetFloorArea - area) > 1e-4 * Math.max(1, area)) {
    problems.push(`${name}: NetFloorArea ${q.NetFloorArea}, job.json ${area}`);
  }
}
// Walls and doors have meshes too.
let elementMeshes = 0;
api.StreamAllMeshesWithTypes(model, [WebIFC.IFCWALL, WebIFC.IFCDOOR], () => { ++elementMeshes; });
if (elementMeshes !== counts.IfcWall + counts.IfcDoor) {
  problems.push(`web-ifc meshed ${elementMeshes} of ${counts.IfcWall + counts.IfcDoor} walls and doors`);
}
api.CloseModel(model);

console.log(JSON.stringify({ file, bytes: statSync(file).size, webIfc: api.GetVersion?.() ?? null,
  schema, counts, spaceTriangles: triangles, wallAndDoorMeshes: elementMeshes,
  worstSpaceZErrorM: worstZ, worstSpaceVolumeRelError: worstVolume }, null, 1));
for (const p of problems.slice(0, 30)) console.log('PROBLEM', p);
process.exit(problems.length ? 1 : 0);
