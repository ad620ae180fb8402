// Validates a .glb/.gltf with the Khronos glTF-Validator (npm: gltf-validator).
// usage: node tests/validate_glb.mjs FILE [--max-warnings N]
// Prints a one-line summary and every message; exits 1 on any error (or more warnings than
// allowed), 2 on usage/IO problems.
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const args = process.argv.slice(2);
let file = null, maxWarnings = Infinity;
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--max-warnings') maxWarnings = Number(args[++i]);
  else file = args[i];
}
if (!file || Number.isNaN(maxWarnings)) {
  console.error('usage: node validate_glb.mjs FILE [--max-warnings N]');
  process.exit(2);
}
let validator;
try {
  validator = require('gltf-validator');
} catch (e) {
  console.error('validate_glb: gltf-validator not installed (run scripts/setup.sh): ' + e.message);
  process.exit(2);
}
let data;
try {
  data = new Uint8Array(readFileSync(file));
} catch (e) {
  console.error(`validate_glb: ${file}: ${e.message}`);
  process.exit(2);
}
const report = await validator.validateBytes(data, { maxIssues: 100 });
const is = report.issues;
console.log(`${file}: glTF-Validator ${report.validatorVersion}: ${is.numErrors} errors, ` +
            `${is.numWarnings} warnings, ${is.numInfos} infos, ${is.numHints} hints`);
const sev = ['error', 'warning', 'info', 'hint'];
for (const m of is.messages) console.log(`  ${sev[m.severity]}: ${m.code} ${m.pointer || ''} ${m.message}`);
process.exit(is.numErrors > 0 || is.numWarnings > maxWarnings ? 1 : 0);
