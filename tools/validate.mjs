// Validate one glTF/GLB file with the Khronos glTF-Validator and print the JSON report.
// Usage: node tools/validate.mjs FILE [--max-issues N]
// Exit 0 when a report was produced (whatever it says), 2 when the file could not be validated.
import { readFile } from "node:fs/promises";
import path from "node:path";
import validator from "gltf-validator";

const args = process.argv.slice(2);
if (args.length < 1) {
  console.error("usage: node validate.mjs FILE [--max-issues N]");
  process.exit(2);
}
const file = path.resolve(args[0]);
const mi = args.indexOf("--max-issues");
const maxIssues = mi >= 0 ? Number(args[mi + 1]) : 0;

try {
  const bytes = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    format: file.toLowerCase().endsWith(".glb") ? "glb" : "gltf",
    maxIssues,
    writeTimestamp: false,
    // .gltf: resolve the sibling .bin (and any other relative URI) next to the file
    externalResourceFunction: async (uri) =>
      new Uint8Array(await readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)))),
  });
  process.stdout.write(JSON.stringify(report, null, 1) + "\n");
} catch (err) {
  console.error(`validate.mjs: cannot validate ${file}: ${err}`);
  process.exit(2);
}
