// Load one GLB with Babylon.js (@babylonjs/core + @babylonjs/loaders, NullEngine: no browser, no GPU)
// and print one JSON report: skeletons, meshes, materials (texture references), animation groups
// sampled at two frames (do bones move? does the loop close?), MSFT_lod levels the loader went
// through, and every console message Babylon printed (Logger writes to console), including the ones
// printed while the scene is made ready and rendered once (e.g. "Normals have been created").
// EXT_meshopt_compression: Babylon's MeshoptCompression loads its decoder as a <script> from
// MeshoptCompression.Configuration.decoder.url (a CDN by default), which Node cannot do; here its
// default instance is the meshoptimizer npm package's own decoder (synchronous, no workers).
// Usage: node tools/babylon_check.mjs [--container] FILE.glb
// Exit 0 when a report was printed (whatever it says), 2 on bad usage.
import { readFile } from "node:fs/promises";
import path from "node:path";

const EPS = 1e-4;
const args = process.argv.slice(2);
const useContainer = args.includes("--container");
if (useContainer) args.splice(args.indexOf("--container"), 1);
if (args.length !== 1) {
  console.error("usage: node babylon_check.mjs [--container] FILE.glb");
  process.exit(2);
}
const file = path.resolve(args[0]);

const messages = [];
for (const level of ["log", "info", "warn", "error", "debug"]) {
  console[level] = (...parts) => messages.push({ level, text: parts.map(String).join(" ") });
}

const BABYLON = await import("@babylonjs/core");
await import("@babylonjs/loaders/glTF/index.js");
const { MeshoptDecoder } = await import("meshoptimizer/decoder");
await MeshoptDecoder.ready;
BABYLON.MeshoptCompression._Default = {
  decodeGltfBufferAsync: async (source, count, stride, mode, filter) => {
    const target = new Uint8Array(count * stride);
    MeshoptDecoder.decodeGltfBuffer(target, count, stride, source, mode, filter);
    return target;
  },
  dispose() {},
};

function round(x) {
  return Math.round(x * 1e6) / 1e6;
}

function textureRef(tex) {
  if (!tex) return null;
  return { name: tex.name, class: tex.getClassName(), ready: tex.isReady() };
}

function materialInfo(m) {
  const info = { name: m.name, class: m.getClassName(), back_face_culling: m.backFaceCulling };
  info.base_color_texture = textureRef(m.albedoTexture ?? m.diffuseTexture ?? null);
  info.normal_texture = textureRef(m.bumpTexture ?? null);
  info.transparency_mode = m.transparencyMode ?? null; // 0 opaque, 1 alpha test, 2 blend, 3 both
  info.alpha_cutoff = m.alphaCutOff ?? null;
  return info;
}

function uvRange(mesh) {
  const uv = mesh.getVerticesData(BABYLON.VertexBuffer.UVKind); // float copy, normalized decoded
  if (!uv || uv.length === 0) return null;
  const lo = [Infinity, Infinity];
  const hi = [-Infinity, -Infinity];
  for (let i = 0; i < uv.length; i += 2) {
    lo[0] = Math.min(lo[0], uv[i]);
    lo[1] = Math.min(lo[1], uv[i + 1]);
    hi[0] = Math.max(hi[0], uv[i]);
    hi[1] = Math.max(hi[1], uv[i + 1]);
  }
  return { min: lo.map(round), max: hi.map(round) };
}

function computeWorld(roots) {
  const walk = (n) => {
    n.computeWorldMatrix(true);
    for (const c of n.getChildren()) walk(c);
  };
  for (const r of roots) walk(r);
}

function snapshot(nodes, roots) {
  computeWorld(roots);
  return nodes.map((n) => {
    const q = n.rotationQuaternion ?? BABYLON.Quaternion.FromEulerVector(n.rotation);
    return {
      local: [...n.position.asArray(), ...q.asArray(), ...n.scaling.asArray()],
      world: Array.from(n.getWorldMatrix().m),
    };
  });
}

function compare(a, b) {
  let moved = 0;
  let local = 0;
  let world = 0;
  for (let i = 0; i < a.length; i++) {
    let dl = 0;
    let dq = 0;
    for (let k = 0; k < 10; k++) {
      const d = Math.abs(a[i].local[k] - b[i].local[k]);
      dl = Math.max(dl, d);
      // q and -q are the same rotation
      dq = Math.max(dq, k >= 3 && k < 7 ? Math.abs(a[i].local[k] + b[i].local[k]) : d);
    }
    dl = Math.min(dl, dq);
    let dw = 0;
    for (let k = 0; k < 16; k++) dw = Math.max(dw, Math.abs(a[i].world[k] - b[i].world[k]));
    if (dl > EPS) moved++;
    local = Math.max(local, dl);
    world = Math.max(world, dw);
  }
  return { moved, local, world };
}

const report = { client: "babylon.js", version: BABYLON.Engine.Version, file, loaded: false };
try {
  const engine = new BABYLON.NullEngine();
  report.engine_caps = { standardDerivatives: engine.getCaps().standardDerivatives };
  const scene = new BABYLON.Scene(engine);
  new BABYLON.FreeCamera("camera", new BABYLON.Vector3(0, 5, -30), scene);

  const lodEvents = [];
  let complete = null;
  const activated = BABYLON.SceneLoader.OnPluginActivatedObservable.add((loader) => {
    if (loader.name !== "gltf") return;
    complete = loader.whenCompleteAsync();
    loader.onExtensionLoadedObservable.add((ext) => {
      if (ext.name === "MSFT_lod" && ext.onNodeLODsLoadedObservable) {
        ext.onNodeLODsLoadedObservable.add((i) => lodEvents.push(i));
      }
    });
  });

  const bytes = new Uint8Array(await readFile(file));
  const options = {
    pluginExtension: ".glb",
    pluginOptions: { gltf: { animationStartMode: BABYLON.GLTFLoaderAnimationStartMode?.NONE ?? 0 } },
  };
  const t0 = performance.now();
  // What gets inspected: the scene itself (AppendSceneAsync) or, with --container, an AssetContainer
  // (LoadAssetContainerAsync, then addAllToScene): the two paths differ for MSFT_lod files.
  let from = scene;
  if (useContainer) {
    from = await BABYLON.LoadAssetContainerAsync(bytes, scene, options);
  } else {
    await BABYLON.AppendSceneAsync(bytes, scene, options);
  }
  if (complete) await complete; // MSFT_lod: finer LODs keep loading after the first one is ready
  report.load_ms = Math.round(performance.now() - t0);
  BABYLON.SceneLoader.OnPluginActivatedObservable.remove(activated);
  if (useContainer) from.addAllToScene();
  report.loaded = true;
  report.load_path = useContainer ? "LoadAssetContainerAsync" : "AppendSceneAsync";
  report.msft_lod_levels_loaded = lodEvents;

  const live = (x) => !(typeof x.isDisposed === "function" ? x.isDisposed() : x._isDisposed);
  const meshes = from.meshes.filter(live).filter((m) => m.getTotalVertices() > 0);
  report.nodes = from.transformNodes.filter(live).length + from.meshes.filter(live).length;
  report.skeletons = from.skeletons.map((s) => ({
    name: s.name,
    bones: s.bones.length,
    meshes: meshes.filter((m) => m.skeleton === s).map((m) => m.name),
  }));
  report.meshes = meshes.map((m) => ({
    name: m.name,
    vertices: m.getTotalVertices(),
    has_normal: m.isVerticesDataPresent(BABYLON.VertexBuffer.NormalKind),
    uv: uvRange(m),
    skinned: !!m.skeleton,
    material: m.material ? m.material.name : null,
  }));

  // Make the scene ready and render one frame: materials check their meshes here, and this is
  // where Babylon adds missing normals (and says so) on devices without standard derivatives.
  const before = messages.length;
  await scene.whenReadyAsync();
  scene.render();
  report.messages_at_first_render = messages.length - before;
  report.meshes_after_render = meshes.map((m) => ({
    name: m.name,
    has_normal: m.isVerticesDataPresent(BABYLON.VertexBuffer.NormalKind),
  }));
  report.materials = from.materials.filter(live).map(materialInfo);

  const roots = (useContainer ? from.rootNodes : scene.rootNodes).filter(live);
  const boneNodes = [
    ...new Set(from.skeletons.flatMap((s) => s.bones.map((b) => b.getTransformNode() ?? b))),
  ];
  report.animations = [];
  for (const g of from.animationGroups) {
    const ta = g.targetedAnimations;
    const fps = ta.length ? ta[0].animation.framePerSecond : 60;
    const info = {
      name: g.name,
      from_frame: g.from,
      to_frame: g.to,
      fps,
      duration: round((g.to - g.from) / fps),
      targeted_animations: ta.length,
      targets_disposed: ta.filter((t) => t.target && t.target.isDisposed && t.target.isDisposed()).length,
    };
    for (const other of from.animationGroups) other.stop();
    g.start(false);
    g.pause();
    g.goToFrame(g.from);
    const p0 = snapshot(boneNodes, roots);
    const f1 = g.from + (g.to - g.from) * 0.37;
    g.goToFrame(f1);
    const p1 = snapshot(boneNodes, roots);
    g.goToFrame(g.to);
    const p2 = snapshot(boneNodes, roots);
    g.stop();
    const mv = compare(p0, p1);
    const lp = compare(p0, p2);
    info.sample_times = [0, round((f1 - g.from) / fps)];
    info.bones_moved = mv.moved;
    info.max_local_change = round(mv.local);
    info.max_world_change = round(mv.world);
    info.loop_max_diff = Math.max(lp.local, lp.world);
    info.loop_closes = lp.local <= EPS && lp.world <= EPS;
    report.animations.push(info);
  }
  scene.dispose();
  engine.dispose();
} catch (err) {
  report.error = String(err && err.stack ? err.stack : err);
}
report.messages = messages;
process.stdout.write(JSON.stringify(report) + "\n");
