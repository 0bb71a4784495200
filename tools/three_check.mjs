// Load one GLB with three.js's GLTFLoader (in Node, no browser) and print one JSON report:
// skeletons, meshes, materials (texture references), animation clips played through an
// AnimationMixer (do bones move between two times? does the loop close?) and every console message
// three.js printed while loading and playing.
// EXT_meshopt_compression is decoded by three's own MeshoptDecoder (examples/jsm/libs), as a web
// page would set it up; KHR_mesh_quantization needs nothing.
// --positions: each mesh's POSITION values as three.js decoded them (meshes[i].positions, flat).
// Usage: node tools/three_check.mjs [--poses K] [--positions] FILE.glb
// --poses K: per clip, the world position of every scene node (traversal order) at K evenly
// spaced times (animations[i].poses: K × nodes × 3), to compare two encodings of one tree.
// Exit 0 when a report was printed (whatever it says), 2 on bad usage or an unreadable file.
import { readFile } from "node:fs/promises";
import path from "node:path";
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";
import { MeshoptDecoder } from "three/examples/jsm/libs/meshopt_decoder.module.js";

const EPS = 1e-4;
const args = process.argv.slice(2);
let poses = 0;
if (args[0] === "--poses") {
  poses = Number(args[1]);
  args.splice(0, 2);
}
const withPositions = args[0] === "--positions";
if (withPositions) args.shift();
if (args.length !== 1 || !(poses >= 0)) {
  console.error("usage: node three_check.mjs [--poses K] [--positions] FILE.glb");
  process.exit(2);
}
const file = path.resolve(args[0]);

// Everything three.js says goes into the report; our own output goes straight to stdout.
const messages = [];
for (const level of ["log", "info", "warn", "error", "debug"]) {
  console[level] = (...parts) => messages.push({ level, text: parts.map(String).join(" ") });
}

// Node has no DOM, so images cannot be decoded: a stub plug-in answers every texture request with
// an empty THREE.Texture that remembers which glTF image it stands for. The material then shows
// whether the file *references* a texture, which is all a headless check can say.
class StubTextures {
  constructor(parser) {
    this.parser = parser;
    this.name = "treegen_stub_textures";
  }
  loadTexture(index) {
    const json = this.parser.json;
    const def = json.textures[index];
    const source = def.source ?? null;
    const image = source !== null && json.images ? json.images[source] : null;
    const tex = new THREE.Texture();
    tex.name = def.name || (image && image.name) || "";
    tex.userData.stub = {
      texture: index,
      image: source,
      mimeType: image ? image.mimeType ?? null : null,
      bufferView: image ? image.bufferView ?? null : null,
      uri: image && image.uri && !image.uri.startsWith("data:") ? image.uri : null,
    };
    return Promise.resolve(tex);
  }
}

function round(x) {
  return Math.round(x * 1e6) / 1e6;
}

function uvRange(attr) {
  if (!attr || attr.count === 0) return null;
  const lo = [Infinity, Infinity];
  const hi = [-Infinity, -Infinity];
  for (let i = 0; i < attr.count; i++) {
    const u = attr.getX(i); // getX/getY undo the normalized-integer encoding
    const v = attr.getY(i);
    if (u < lo[0]) lo[0] = u;
    if (v < lo[1]) lo[1] = v;
    if (u > hi[0]) hi[0] = u;
    if (v > hi[1]) hi[1] = v;
  }
  return { min: lo.map(round), max: hi.map(round), normalized: attr.normalized, array: attr.array.constructor.name };
}

function positionsOf(attr) {
  const out = new Array(attr.count * 3);
  for (let i = 0; i < attr.count; i++) {
    out[3 * i] = attr.getX(i);
    out[3 * i + 1] = attr.getY(i);
    out[3 * i + 2] = attr.getZ(i);
  }
  return out;
}

function textureRef(tex) {
  if (!tex) return null;
  return { name: tex.name, ...(tex.userData.stub || { decoded: tex.image != null }) };
}

function materialInfo(m) {
  return {
    name: m.name,
    type: m.type,
    base_color_texture: textureRef(m.map),
    normal_texture: textureRef(m.normalMap),
    color: m.color ? m.color.toArray().map(round) : null,
    transparent: m.transparent,
    alpha_test: m.alphaTest,
    double_sided: m.side === THREE.DoubleSide,
    flat_shading: m.flatShading,
  };
}

function snapshot(bones, root) {
  root.updateMatrixWorld(true);
  return bones.map((b) => ({
    local: [...b.position.toArray(), ...b.quaternion.toArray(), ...b.scale.toArray()],
    world: b.matrixWorld.elements.slice(),
  }));
}

function compare(a, b) {
  let moved = 0;
  let local = 0;
  let world = 0;
  for (let i = 0; i < a.length; i++) {
    let dl = 0;
    for (let k = 0; k < a[i].local.length; k++) dl = Math.max(dl, Math.abs(a[i].local[k] - b[i].local[k]));
    // q and -q are the same rotation
    let dq = 0;
    for (let k = 3; k < 7; k++) dq = Math.max(dq, Math.abs(a[i].local[k] + b[i].local[k]));
    let dn = 0;
    for (const k of [0, 1, 2, 7, 8, 9]) dn = Math.max(dn, Math.abs(a[i].local[k] - b[i].local[k]));
    dl = Math.min(dl, Math.max(dq, dn));
    let dw = 0;
    for (let k = 0; k < 16; k++) dw = Math.max(dw, Math.abs(a[i].world[k] - b[i].world[k]));
    if (dl > EPS) moved++;
    local = Math.max(local, dl);
    world = Math.max(world, dw);
  }
  return { moved, local, world };
}

const report = { client: "three.js", version: THREE.REVISION, file, loaded: false };
try {
  const bytes = await readFile(file);
  const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  const loader = new GLTFLoader();
  loader.setMeshoptDecoder(MeshoptDecoder);
  loader.register((parser) => new StubTextures(parser));
  const isGlb = bytes.subarray(0, 4).toString("latin1") === "glTF";
  const json = isGlb ? bytes.subarray(20, 20 + bytes.readUInt32LE(12)) : bytes;
  report.extensions_required = JSON.parse(new TextDecoder().decode(json)).extensionsRequired ?? [];
  const t0 = performance.now();
  const gltf = await loader.parseAsync(buffer, "");
  report.load_ms = Math.round(performance.now() - t0);
  report.loaded = true;

  const scene = gltf.scene;
  let nodes = 0;
  const skeletons = new Map();
  const meshes = [];
  const materials = new Map();
  scene.traverse((o) => {
    nodes++;
    if (!o.isMesh) return;
    const g = o.geometry;
    const mats = Array.isArray(o.material) ? o.material : [o.material];
    for (const m of mats) if (!materials.has(m.uuid)) materials.set(m.uuid, materialInfo(m));
    const box = new THREE.Box3().setFromBufferAttribute(g.attributes.position);
    meshes.push({
      name: o.name,
      position_box: [...box.min.toArray(), ...box.max.toArray()].map(round),
      position_array: g.attributes.position.array.constructor.name,
      ...(withPositions ? { positions: positionsOf(g.attributes.position) } : {}),
      type: o.type,
      skinned: !!o.isSkinnedMesh,
      vertices: g.attributes.position ? g.attributes.position.count : 0,
      has_normal: !!g.attributes.normal,
      uv: uvRange(g.attributes.uv),
      material: mats.map((m) => m.name),
    });
    if (o.isSkinnedMesh) {
      const s = o.skeleton;
      if (!skeletons.has(s.uuid)) skeletons.set(s.uuid, { bones: s.bones.length, meshes: [], skeleton: s });
      skeletons.get(s.uuid).meshes.push(o.name);
    }
  });
  report.nodes = nodes;
  // bone_inverse_0: the first joint's inverse bind matrix (column-major), as the loader decoded it
  report.skeletons = [...skeletons.values()].map(({ bones, meshes, skeleton }) => ({
    bones,
    meshes,
    bone_inverse_0: skeleton.boneInverses[0].elements.slice(),
  }));
  report.meshes = meshes;
  report.materials = [...materials.values()];

  // bones of every skeleton, once each
  const bones = [...new Set([...skeletons.values()].flatMap((s) => s.skeleton.bones))];
  const mixer = new THREE.AnimationMixer(scene);
  report.animations = [];
  for (const clip of gltf.animations) {
    const before = messages.length;
    const info = { name: clip.name, duration: round(clip.duration), tracks: clip.tracks.length };
    mixer.stopAllAction();
    const action = mixer.clipAction(clip);
    action.setLoop(THREE.LoopOnce, 1);
    action.clampWhenFinished = true; // at t = duration hold the last key instead of wrapping to 0
    action.reset().play();
    mixer.setTime(0);
    const p0 = snapshot(bones, scene);
    const t1 = clip.duration * 0.37;
    mixer.setTime(t1);
    const p1 = snapshot(bones, scene);
    mixer.setTime(clip.duration);
    const p2 = snapshot(bones, scene);
    const mv = compare(p0, p1);
    const lp = compare(p0, p2);
    info.sample_times = [0, round(t1)];
    info.bones_moved = mv.moved;
    info.max_local_change = round(mv.local);
    info.max_world_change = round(mv.world);
    info.loop_max_diff = Math.max(lp.local, lp.world);
    info.loop_closes = lp.local <= EPS && lp.world <= EPS;
    info.messages_while_playing = messages.length - before;
    if (poses > 0) {
      const first = [];
      scene.traverse((o) => first.push(o));
      info.poses = [];
      for (let k = 0; k < poses; k++) {
        mixer.setTime((clip.duration * k) / poses);
        scene.updateMatrixWorld(true);
        info.poses.push(first.map((b) => new THREE.Vector3().setFromMatrixPosition(b.matrixWorld).toArray().map(round)));
      }
    }
    action.stop();
    mixer.uncacheClip(clip);
    report.animations.push(info);
  }
} catch (err) {
  report.error = String(err && err.stack ? err.stack : err);
}
report.messages = messages;
process.stdout.write(JSON.stringify(report) + "\n");
