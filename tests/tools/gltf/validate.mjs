// Validates a .glb with the Khronos glTF-Validator (npm gltf-validator); prints its summary.
import { readFileSync } from 'node:fs';
import validator from 'gltf-validator';
const path = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {maxIssues: 50});
const { numErrors, numWarnings, numInfos, numHints, messages } = report.issues;
console.log(JSON.stringify({validatorVersion: report.validatorVersion, numErrors, numWarnings, numInfos, numHints,
  info: report.info && {totalVertexCount: report.info.totalVertexCount, totalTriangleCount: report.info.totalTriangleCount, drawCallCount: report.info.drawCallCount, materialCount: report.info.materialCount}}, null, 1));
for (const m of messages.slice(0, 20)) console.log(m.severity, m.code, m.pointer, m.message);
process.exit(numErrors > 0 ? 1 : 0);
