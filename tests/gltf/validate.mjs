// Validate a glTF/GLB with the Khronos glTF Validator; print its report as JSON.
// Usage: node validate.mjs FILE.glb   (gltf-validator must be installed beside this script or in NODE_PATH)
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const validator = require("gltf-validator");
const data = new Uint8Array(readFileSync(process.argv[2]));
const report = await validator.validateBytes(data, { maxIssues: 200 });
console.log(JSON.stringify(report));
