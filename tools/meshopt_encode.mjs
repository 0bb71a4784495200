// meshoptimizer's own encoder for treegen's `--compress meshopt` (EXT_meshopt_compression).
// One call per file. stdin: uint32 LE JSON length, JSON {jobs: [{mode, filter, stride, count,
// bytes, bits, join}], groups: [{indices, vertices}]}, then each job's bytes (the data, or for a
// filter its float32 (count, 4) source). stdout: uint32 LE JSON length, JSON [encoded lengths],
// then the encoded streams in order: consecutive jobs with the same `join` are one bufferView,
// filtered job by job, then joined and encoded once.
// A group is one primitive: its index job and its vertex jobs are first reordered together by
// reorderMesh (vertex cache order for size, then vertex fetch order), the same triangles and
// vertices in another order. Vertex codec version 0: the one EXT_meshopt_compression defines.
import { MeshoptEncoder } from "meshoptimizer";

const chunks = [];
for await (const c of process.stdin) chunks.push(c);
const input = Buffer.concat(chunks);
const n = input.readUInt32LE(0);
const { jobs, groups } = JSON.parse(input.subarray(4, 4 + n).toString("utf8"));
await MeshoptEncoder.ready;

// each job's bytes as an aligned copy (typed views of it must start 4-byte aligned)
let pos = 4 + n;
const data = jobs.map((job) => {
  const d = new Uint8Array(input.subarray(pos, pos + job.bytes));
  pos += job.bytes;
  return d;
});
if (pos !== input.length) throw new Error(`stdin has ${input.length - pos} unread bytes`);

for (const g of groups) {
  const ij = jobs[g.indices];
  const wide = ij.stride === 4;
  const indices = new Uint32Array(wide ? new Uint32Array(data[g.indices].buffer) : new Uint16Array(data[g.indices].buffer));
  const count = jobs[g.vertices[0]].count;
  const [remap, unique] = MeshoptEncoder.reorderMesh(indices, true, true);
  // vertices no triangle uses keep their place after the used ones, so counts do not change
  let next = unique;
  const full = new Uint32Array(count);
  for (let i = 0; i < count; i++) full[i] = i < remap.length && remap[i] !== 0xffffffff ? remap[i] : next++;
  data[g.indices] = new Uint8Array((wide ? indices : Uint16Array.from(indices)).buffer);
  for (const v of g.vertices) {
    const size = data[v].length / count; // element bytes (the filter's float32 source: 16)
    const out = new Uint8Array(data[v].length);
    for (let i = 0; i < count; i++) out.set(data[v].subarray(i * size, (i + 1) * size), full[i] * size);
    data[v] = out;
  }
}

// filters per job, then each stream's jobs (consecutive, same `join`) joined and encoded once
const filtered = jobs.map((job, k) => {
  let d = data[k];
  if (job.filter !== "NONE") {
    const fn = { OCTAHEDRAL: "encodeFilterOct", QUATERNION: "encodeFilterQuat", EXPONENTIAL: "encodeFilterExp" }[job.filter];
    if (!fn) throw new Error(`unknown filter ${job.filter}`);
    // EXPONENTIAL: one exponent per vector (SharedVector), `bits` of mantissa
    const extra = job.filter === "EXPONENTIAL" ? ["SharedVector"] : [];
    d = MeshoptEncoder[fn](new Float32Array(d.buffer), job.count, job.stride, job.bits, ...extra);
  }
  return d;
});
const encoded = [];
for (let k = 0; k < jobs.length; ) {
  let end = k + 1;
  while (end < jobs.length && jobs[end].join === jobs[k].join) end++;
  const parts = filtered.slice(k, end);
  const joined = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const p of parts) {
    joined.set(p, at);
    at += p.length;
  }
  const count = jobs.slice(k, end).reduce((n, j) => n + j.count, 0);
  encoded.push(MeshoptEncoder.encodeGltfBuffer(joined, count, jobs[k].stride, jobs[k].mode, 0));
  k = end;
}
const head = Buffer.from(JSON.stringify(encoded.map((o) => o.length)), "utf8");
const len = Buffer.alloc(4);
len.writeUInt32LE(head.length, 0);
process.stdout.write(Buffer.concat([len, head, ...encoded.map((o) => Buffer.from(o.buffer, o.byteOffset, o.length))]));
