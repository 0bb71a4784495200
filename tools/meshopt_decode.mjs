// meshoptimizer's own decoder for reading EXT_meshopt_compression files (`treegen preview`).
// One call per file. stdin: uint32 LE JSON length, JSON {jobs: [{mode, filter, stride, count,
// bytes}], simd}, then each job's encoded bytes. stdout: the decoded views (count × stride
// bytes each, filters undone into their stored integer form) in job order. simd: false picks
// the decoder's scalar build (what a client without WebAssembly SIMD runs), whose QUATERNION
// filter rounds differently (key_plan.quat_filter models both).

const chunks = [];
for await (const c of process.stdin) chunks.push(c);
const input = Buffer.concat(chunks);
const n = input.readUInt32LE(0);
const { jobs, simd = true } = JSON.parse(input.subarray(4, 4 + n).toString("utf8"));
const validate = WebAssembly.validate;
if (!simd) WebAssembly.validate = () => false; // the module picks its build on import
const { MeshoptDecoder } = await import("meshoptimizer");
WebAssembly.validate = validate;
await MeshoptDecoder.ready;

let pos = 4 + n;
const out = jobs.map((job) => {
  const source = new Uint8Array(input.subarray(pos, pos + job.bytes));
  pos += job.bytes;
  const target = new Uint8Array(job.count * job.stride);
  MeshoptDecoder.decodeGltfBuffer(target, job.count, job.stride, source, job.mode, job.filter);
  return target;
});
if (pos !== input.length) throw new Error(`stdin has ${input.length - pos} unread bytes`);
process.stdout.write(Buffer.concat(out.map((o) => Buffer.from(o.buffer, o.byteOffset, o.length))));
