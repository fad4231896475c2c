// Validate a .glb with the Khronos glTF validator; prints its JSON report on stdout.
// Usage: node validate_gltf.mjs FILE.glb
import { readFileSync } from "node:fs";
import { basename } from "node:path";
import validator from "gltf-validator";

const file = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
  uri: basename(file),
  maxIssues: 100,
});
process.stdout.write(JSON.stringify(report));
