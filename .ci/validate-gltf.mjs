// Validates glTF/glb files with the Khronos glTF-Validator (npm package `gltf-validator`).
// Usage: node .ci/validate-gltf.mjs FILE...   Exits 1 if any file has an error.
import { createRequire } from 'node:module';
import { readFileSync } from 'node:fs';
const require = createRequire(process.env.GLTF_VALIDATOR_DIR ? process.env.GLTF_VALIDATOR_DIR + '/' : import.meta.url);
const validator = require('gltf-validator');
let failed = false;
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)));
  const i = report.issues;
  console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos`);
  for (const m of i.messages.filter((m) => m.severity <= 1)) {
    console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer ?? ''}: ${m.message}`);
  }
  if (i.numErrors > 0) failed = true;
}
process.exit(failed ? 1 : 0);
