// Khronos glTF validator on GLB files: `node validate_glb.mjs a.glb b.glb` prints one JSON object
// {path: {numErrors, numWarnings, numInfos, errors: [...]}}; exit status 0 even with errors (the
// Python test reads the counts and shows the messages).
import { readFileSync } from "node:fs";
import validator from "gltf-validator";

const out = {};
for (const path of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(path)), {
    maxIssues: 50,
    externalResourceFunction: () => Promise.reject(new Error("a GLB must be self-contained")),
  });
  const { numErrors, numWarnings, numInfos, messages } = report.issues;
  out[path] = {
    numErrors, numWarnings, numInfos,
    errors: messages.filter((m) => m.severity === 0),
    warnings: messages.filter((m) => m.severity === 1),
  };
}
process.stdout.write(JSON.stringify(out));
