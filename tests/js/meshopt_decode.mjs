// meshoptimizer's official decoder (npm meshoptimizer, pinned in package.json) on GLB files:
//   node meshopt_decode.mjs a.glb
// prints one JSON object {byteOffset of the compressed data: base64 of the decoded bufferView} for
// every bufferView of the GLB with EXT_meshopt_compression (service.pipeline.gltf_read reads it).
import { readFileSync } from "node:fs";
import { MeshoptDecoder } from "meshoptimizer/decoder";

const data = readFileSync(process.argv[2]);
if (data.toString("latin1", 0, 4) !== "glTF") throw new Error("not a GLB");
const jsonLength = data.readUInt32LE(12);
const doc = JSON.parse(data.toString("utf8", 20, 20 + jsonLength));
const binStart = 20 + jsonLength + 8;
await MeshoptDecoder.ready;
const out = {};
for (const view of doc.bufferViews) {
  const ext = view.extensions?.EXT_meshopt_compression;
  if (!ext) continue;
  const offset = ext.byteOffset || 0;
  const source = new Uint8Array(data.buffer, data.byteOffset + binStart + offset, ext.byteLength);
  const target = new Uint8Array(ext.count * ext.byteStride);
  MeshoptDecoder.decodeGltfBuffer(target, ext.count, ext.byteStride, source, ext.mode, ext.filter || "NONE");
  out[offset] = Buffer.from(target).toString("base64");
}
process.stdout.write(JSON.stringify(out));
