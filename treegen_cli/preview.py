"""`treegen preview`: a picture (or a looping GIF) of a tree, rendered headless.

Input is a species file (grown in-process), or a file `treegen make` wrote (.glb/.gltf read back
with our own glTF reader, .usda/.usdc/.usdz through pxr's UsdSkel). Each becomes a render.Scene:
parts in Y-up world space plus `skinning(t)`, the per-joint matrices S_j(t) = W_j(t)·B_j⁻¹ that
an engine would upload — joint world matrices posed from the clip, times inverse bind. The
renderer applies them per vertex, so what you see is what the file's skin and animation do.
"""
from __future__ import annotations

import json

import os
import re
import struct
from dataclasses import dataclass, field, replace
from pathlib import Path

import click
import numpy as np

from .clip import loop_times, sample_track
from .errors import TreegenError
from .render import Part, Scene, frame_points, skin_points
from .skeleton import forward, trs

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
ANIMATION_SUFFIXES = (".gif",)
GLTF_SUFFIXES = (".glb", ".gltf")
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
SPECIES_SUFFIXES = (".txt", ".xml")


@dataclass(frozen=True)
class PreviewOptions:
    """Camera and output; angles in degrees, size in pixels."""

    azimuth: float = -90.0      # camera bearing, counter-clockwise from +X (Z up): −90 looks
                                # along +Y, so the default wind (towards +X) blows left → right
    elevation: float = 8.0      # camera height angle above the horizon
    width: int = 512
    height: int = 512
    lod: int = 0
    seed: int = 0               # species input only
    fps: float = 15.0           # GIF frames per second of the wind loop
    sun_azimuth: float | None = None   # None: 50° left of the camera
    sun_elevation: float = 50.0


DEFAULTS = PreviewOptions()


# ------------------------------------------------------------------------------ math helpers

def _z_up_to_y_up() -> np.ndarray:
    """4×4 Z-up → Y-up change of axes, the glTF writer's convention (imported lazily: the CLI
    loads this module for every command)."""
    from .exchange.gltf import Z_UP_TO_Y_UP

    c = np.eye(4)
    c[:3, :3] = Z_UP_TO_Y_UP
    return c


@dataclass(frozen=True, eq=False)
class Channel:
    """One animated property of some joints, all on the same key times."""

    joints: np.ndarray          # (M,) joint indices
    path: str                   # "rotation" | "translation" | "scale"
    times: np.ndarray           # (K,) seconds
    values: np.ndarray          # (K, M, 4 or 3)
    interpolation: str = "LINEAR"


@dataclass(frozen=True, eq=False)
class PoseRig:
    """Enough of a skeleton to pose it: rest TRS per joint, the world matrix above each root
    joint, inverse binds and channels. `to_world` maps the source's axes to Y up."""

    parent: np.ndarray          # (J,) −1 where the parent is not a joint
    translation: np.ndarray     # (J, 3)
    rotation: np.ndarray        # (J, 4) xyzw
    scale: np.ndarray           # (J, 3)
    root_world: np.ndarray      # (J, 4, 4): world of the non-joint parent (identity if none)
    inverse_bind: np.ndarray    # (J, 4, 4)
    channels: list[Channel] = field(default_factory=list)
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def duration(self) -> float:
        return max((float(c.times[-1]) for c in self.channels if len(c.times)), default=0.0)

    def skinning(self, t: np.ndarray) -> np.ndarray:
        """(T, J, 4, 4) skinning matrices in Y-up world space at times t."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        T, J = len(t), len(self.parent)
        pose = {"translation": np.broadcast_to(self.translation, (T, J, 3)).copy(),
                "rotation": np.broadcast_to(self.rotation, (T, J, 4)).copy(),
                "scale": np.broadcast_to(self.scale, (T, J, 3)).copy()}
        for c in self.channels:
            pose[c.path][:, c.joints] = sample_track(c.times, c.values, t, c.interpolation,
                                                     rotation=c.path == "rotation")
        local = trs(pose["translation"], pose["rotation"], pose["scale"])
        world = forward(self.parent, local, self.root_world)
        skin = world @ self.inverse_bind
        return self.to_world @ skin @ self.to_world.T


# ------------------------------------------------------------------------------ from an Asset

def scene_from_asset(asset, lod: int = 0, label: str = "") -> Scene:
    """An in-memory Asset (generator space, Z up) as a Scene."""
    from .exchange.gltf import to_y_up

    _check_lod(lod, len(asset.lods), label or asset.name)
    L = asset.lods[lod]
    mats = {m.name: m for m in asset.materials}
    parts = []
    for p in L.primitives:
        m = mats.get(p.material)
        parts.append(Part(
            name=p.name, positions=to_y_up(p.positions).astype(np.float32),
            normals=to_y_up(p.normals).astype(np.float32),
            indices=np.asarray(p.indices, np.uint32), joints=np.asarray(p.joints),
            weights=np.asarray(p.weights, np.float32),
            color=tuple(m.base_color[:3]) if m else (0.6, 0.6, 0.6),
            double_sided=bool(m and m.double_sided)))
    sk = L.skeleton
    J = len(sk.names)
    channels = []
    if L.clips:
        clip = L.clips[0]
        rot = np.asarray(clip.rotations, dtype=np.float64)
        if clip.keys is None:
            channels.append(Channel(np.arange(J), "rotation", np.asarray(clip.times), rot,
                                    clip.interpolation))
        else:
            for j, keys in enumerate(clip.keys):     # joints (hundreds), each its own schedule
                keys = np.asarray(keys, dtype=np.int64)
                channels.append(Channel(np.array([j]), "rotation", np.asarray(clip.times)[keys],
                                        rot[keys, j:j + 1], clip.interpolation))
    rig = PoseRig(parent=np.asarray(sk.parent), translation=np.asarray(sk.rest_translation),
                  rotation=np.asarray(sk.rest_rotation), scale=np.ones((J, 3)),
                  root_world=np.broadcast_to(np.eye(4), (J, 4, 4)),
                  inverse_bind=np.linalg.inv(np.asarray(sk.bind_world, dtype=np.float64)),
                  channels=channels, to_world=_z_up_to_y_up())
    return Scene(parts=parts, n_joints=J, duration=rig.duration,
                 skinning=rig.skinning if channels else None, label=label or asset.name)


def _check_lod(lod: int, n: int, what) -> None:
    if not 0 <= lod < n:
        have = f"LODs 0..{n - 1}" if n > 1 else "only LOD 0"
        raise TreegenError(f"{what}: --lod {lod} is out of range; this asset has {have}")


# ------------------------------------------------------------------------------ from glTF

def _node_world(gltf: dict) -> tuple[np.ndarray, np.ndarray]:
    """(parent per node, rest world matrix per node) from the node hierarchy."""
    nodes = gltf.get("nodes", [])
    n = len(nodes)
    parent = np.full(n, -1, dtype=np.int64)
    for i, node in enumerate(nodes):              # JSON nodes: one Python step each
        for c in node.get("children", []):
            parent[c] = i
    local = np.empty((n, 4, 4))
    for i, node in enumerate(nodes):
        if "matrix" in node:
            local[i] = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
        else:
            local[i] = trs(np.asarray(node.get("translation", [0, 0, 0]), float),
                           np.asarray(node.get("rotation", [0, 0, 0, 1]), float),
                           np.asarray(node.get("scale", [1, 1, 1]), float))
    return parent, forward(parent, local)


def scene_from_gltf(path: Path, lod: int = 0) -> Scene:
    """A .glb/.gltf (ours, or any triangle glTF with at most one skin per LOD node)."""
    from .exchange.gltf import read_accessor, read_gltf

    try:
        gltf, blob = read_gltf(path)
        return _gltf_scene(gltf, blob, read_accessor, lod, path)
    except TreegenError:
        raise
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as e:
        raise TreegenError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None


def _gltf_scene(gltf, blob, read_accessor, lod, path) -> Scene:
    nodes = gltf.get("nodes", [])
    scene = gltf.get("scenes", [{}])[gltf.get("scene", 0)]
    roots = [i for i in scene.get("nodes", []) if "mesh" in nodes[i]] or \
            [i for i, nd in enumerate(nodes) if "mesh" in nd][:1]
    if not roots:
        raise TreegenError(f"{path}: no mesh in the glTF scene")
    lod_nodes = [roots[0]] + list(nodes[roots[0]].get("extensions", {}).get("MSFT_lod", {}).get("ids", []))
    _check_lod(lod, len(lod_nodes), path)
    node_index = lod_nodes[lod]
    node = nodes[node_index]
    parent, world = _node_world(gltf)
    materials = gltf.get("materials", [])

    skin = gltf["skins"][node["skin"]] if "skin" in node else None
    if skin is not None:
        joints = np.asarray(skin["joints"], dtype=np.int64)
        J = len(joints)
        ibm = (read_accessor(gltf, blob, skin["inverseBindMatrices"]).astype(np.float64)
               if "inverseBindMatrices" in skin else np.broadcast_to(np.eye(4), (J, 4, 4)))
    else:
        joints, J = np.array([node_index]), 1      # static: S = world of the mesh node
        ibm = np.eye(4)[None]

    parts = []
    for k, prim in enumerate(gltf["meshes"][node["mesh"]]["primitives"]):
        if prim.get("mode", 4) != 4:
            continue
        a = prim["attributes"]
        pos = read_accessor(gltf, blob, a["POSITION"]).astype(np.float32)
        idx = (read_accessor(gltf, blob, prim["indices"]).astype(np.uint32) if "indices" in prim
               else np.arange(len(pos), dtype=np.uint32))
        nrm = (read_accessor(gltf, blob, a["NORMAL"]).astype(np.float32) if "NORMAL" in a
               else vertex_normals(pos, idx))
        if skin is not None and "JOINTS_0" in a:
            jnt = read_accessor(gltf, blob, a["JOINTS_0"]).astype(np.int64)
            wgt = read_accessor(gltf, blob, a["WEIGHTS_0"]).astype(np.float32)
        else:
            jnt = np.zeros((len(pos), 4), np.int64)
            wgt = np.tile(np.float32([1, 0, 0, 0]), (len(pos), 1))
        mat = materials[prim["material"]] if "material" in prim else {}
        color = mat.get("pbrMetallicRoughness", {}).get("baseColorFactor", [0.6, 0.6, 0.6, 1])
        parts.append(Part(name=mat.get("name", f"primitive{k}"), positions=pos, normals=nrm,
                          indices=idx, joints=jnt, weights=wgt, color=tuple(color[:3]),
                          double_sided=bool(mat.get("doubleSided", False))))

    jparent = np.full(J, -1, dtype=np.int64)
    slot = {int(n): j for j, n in enumerate(joints)}
    for j, n in enumerate(joints):                # joints: hundreds at most
        jparent[j] = slot.get(int(parent[n]), -1)
    above = parent[joints]
    root_world = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    outside = (jparent < 0) & (above >= 0)           # a root joint under a non-joint node
    root_world[outside] = world[above[outside]]
    rest = [nodes[n] for n in joints]
    rig = PoseRig(
        parent=jparent,
        translation=np.array([n.get("translation", [0, 0, 0]) for n in rest], float).reshape(J, 3),
        rotation=np.array([n.get("rotation", [0, 0, 0, 1]) for n in rest], float).reshape(J, 4),
        scale=np.array([n.get("scale", [1, 1, 1]) for n in rest], float).reshape(J, 3),
        root_world=root_world, inverse_bind=ibm,
        channels=_gltf_channels(gltf, blob, read_accessor, slot) if skin is not None else [])
    if any("matrix" in n for n in rest):
        raise TreegenError(f"{path}: joint nodes with 'matrix' transforms are not supported")
    return Scene(parts=parts, n_joints=J, duration=rig.duration,
                 skinning=rig.skinning, label=str(path))


def _gltf_channels(gltf, blob, read_accessor, slot: dict[int, int]) -> list[Channel]:
    """Channels of the first animation that moves any of this skin's joints."""
    for anim in gltf.get("animations", []):
        out = []
        for ch in anim["channels"]:            # one per animated joint (hundreds)
            node, path = ch["target"].get("node"), ch["target"]["path"]
            if node not in slot or path not in ("rotation", "translation", "scale"):
                continue
            s = anim["samplers"][ch["sampler"]]
            times = read_accessor(gltf, blob, s["input"]).astype(np.float64)
            values = read_accessor(gltf, blob, s["output"]).astype(np.float64)
            out.append(Channel(np.array([slot[node]]), path, times, values[:, None, :],
                               s.get("interpolation", "LINEAR")))
        if out:
            return out
    return []


def vertex_normals(pos: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, for meshes that come without any."""
    tri = np.asarray(idx, np.int64).reshape(-1, 3)
    p = np.asarray(pos, np.float64)
    fn = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, tri[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


# ------------------------------------------------------------------------------ from USD

def scene_from_usd(path: Path, lod: int = 0) -> Scene:
    """A UsdSkel file: LOD k is the k-th SkelRoot; skinning from UsdSkel's own query."""
    try:
        from pxr import Usd, UsdGeom, UsdShade, UsdSkel
    except ImportError as e:
        raise TreegenError(f"{path}: reading USD needs usd-core ({e})") from None
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as e:
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise TreegenError(f"{path}: not a readable USD file ({msg[:200]})") from None
    if stage is None:
        raise TreegenError(f"{path}: not a readable USD file")
    to_world = _z_up_to_y_up() if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else np.eye(4)
    skel_roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    if not skel_roots:
        raise TreegenError(f"{path}: no UsdSkel SkelRoot (treegen preview reads skinned trees)")
    _check_lod(lod, len(skel_roots), path)
    root = skel_roots[lod]
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(root), Usd.PrimDefaultPredicate)
    bindings = cache.ComputeSkelBindings(UsdSkel.Root(root), Usd.PrimDefaultPredicate)
    if not bindings:
        raise TreegenError(f"{path}: SkelRoot {root.GetPath()} binds no meshes to a skeleton")
    binding = bindings[0]
    skel_query = cache.GetSkelQuery(binding.GetSkeleton())
    J = len(skel_query.GetJointOrder())
    tcps = stage.GetTimeCodesPerSecond() or 24.0
    parts = []
    for sq in binding.GetSkinningTargets():
        prim = sq.GetPrim()
        mesh = UsdGeom.Mesh(prim)
        if sq.GetJointMapper() is not None and not sq.GetJointMapper().IsIdentity():
            raise TreegenError(f"{path}: {prim.GetPath()} has its own joint order (not supported)")
        pos = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
        geom_bind = np.asarray(sq.GetGeomBindTransform(), dtype=np.float64).T
        pos = pos @ geom_bind[:3, :3].T + geom_bind[:3, 3]
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
        fvi = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
        idx = _triangulate(counts, fvi)
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            idx = idx.reshape(-1, 3)[:, ::-1].reshape(-1)
        nrm = mesh.GetNormalsAttr().Get()
        nrm = (np.asarray(nrm, np.float64) @ geom_bind[:3, :3].T if nrm is not None and len(nrm) == len(pos)
               else vertex_normals(pos, idx))
        ji, jw = sq.ComputeJointInfluences()
        n_inf = sq.GetNumInfluencesPerComponent()
        ji = np.asarray(ji, np.int64).reshape(-1, n_inf)
        jw = np.asarray(jw, np.float32).reshape(-1, n_inf)
        if len(ji) == 1 and len(pos) > 1:                          # constant interpolation
            ji, jw = np.repeat(ji, len(pos), 0), np.repeat(jw, len(pos), 0)
        ji, jw = _four_influences(ji, jw)
        color, double = (0.6, 0.6, 0.6), bool(mesh.GetDoubleSidedAttr().Get())
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        if material:
            shader = material.ComputeSurfaceSource()[0]
            inp = shader.GetInput("diffuseColor") if shader else None
            if inp and inp.Get() is not None:
                color = tuple(float(c) for c in inp.Get())
        parts.append(Part(name=prim.GetName(), positions=_apply(to_world, pos).astype(np.float32),
                          normals=_apply(to_world, nrm, vector=True).astype(np.float32),
                          indices=idx.astype(np.uint32), joints=ji, weights=jw, color=color,
                          double_sided=double))
    anim = skel_query.GetAnimQuery()
    duration = 0.0
    if anim:
        codes = anim.GetJointTransformTimeSamples()
        if len(codes) > 1:
            duration = (max(codes) - min(codes)) / tcps
    start = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else 0.0

    def skinning(t: np.ndarray, _keep=(stage, cache)) -> np.ndarray:   # the query needs both alive
        out = np.empty((len(t), J, 4, 4))
        for i, ti in enumerate(np.atleast_1d(t)):     # frames (tens), not vertices
            xf = skel_query.ComputeSkinningTransforms(Usd.TimeCode(start + float(ti) * tcps))
            out[i] = np.asarray(xf, dtype=np.float64).transpose(0, 2, 1)
        return to_world @ out @ to_world.T

    return Scene(parts=parts, n_joints=J, duration=duration, skinning=skinning, label=str(path))


def _apply(m: np.ndarray, v: np.ndarray, vector: bool = False) -> np.ndarray:
    out = np.asarray(v, np.float64) @ m[:3, :3].T
    return out if vector else out + m[:3, 3]


def _triangulate(counts: np.ndarray, fvi: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons (vectorised over faces of each size)."""
    if len(counts) and np.all(counts == 3):
        return fvi
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = []
    for n in np.unique(counts[counts >= 3]):          # one pass per polygon size
        s = starts[counts == n]
        k = np.arange(1, n - 1)
        tris.append(np.stack([np.repeat(fvi[s], n - 2), fvi[(s[:, None] + k).ravel()],
                              fvi[(s[:, None] + k + 1).ravel()]], axis=1).ravel())
    return np.concatenate(tris) if tris else np.zeros(0, np.int64)


def _four_influences(ji: np.ndarray, jw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the 4 strongest influences per vertex (renormalised), padding with zero weights."""
    if ji.shape[1] < 4:
        pad = 4 - ji.shape[1]
        return (np.pad(ji, ((0, 0), (0, pad))), np.pad(jw, ((0, 0), (0, pad))))
    if ji.shape[1] > 4:
        top = np.argsort(-jw, axis=1)[:, :4]
        ji, jw = np.take_along_axis(ji, top, 1), np.take_along_axis(jw, top, 1)
        jw = jw / np.maximum(jw.sum(1, keepdims=True), 1e-12)
    return ji, jw


# ------------------------------------------------------------------------------ front door

def load_scene(path: str | os.PathLike, options: PreviewOptions = DEFAULTS) -> Scene:
    """Any preview input as a Scene, dispatched on the suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    known = SPECIES_SUFFIXES + GLTF_SUFFIXES + USD_SUFFIXES
    if suffix not in known:
        raise TreegenError(f"{path}: unknown input extension '{suffix or '(none)'}'; preview reads "
                           f"species files (.txt .xml) and written trees ({' '.join(known[2:])})")
    if not path.is_file():
        raise TreegenError(f"{path}: no such file")
    if suffix in GLTF_SUFFIXES:
        return scene_from_gltf(path, options.lod)
    if suffix in USD_SUFFIXES:
        return scene_from_usd(path, options.lod)
    from .params import load_params
    from .pipeline import build_asset

    params = load_params(path)
    try:
        asset, _ = build_asset(params, options.seed)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None
    return scene_from_asset(asset, options.lod, label=str(path))


def framing_points(scene: Scene, times: np.ndarray, max_points: int = 20000) -> np.ndarray:
    """Up to `max_points` vertices (evenly strided), skinned at each of `times`: the bounds the
    camera must fit over the whole loop."""
    out = []
    total = sum(len(p.positions) for p in scene.parts)
    step = max(1, total // max_points)
    poses = scene.pose(times)
    for p in scene.parts:
        sel = slice(0, len(p.positions), step)
        pts, jnt, wgt = p.positions[sel], np.asarray(p.joints)[sel], p.weights[sel]
        for pose in poses:                   # a dozen poses at most
            out.append(skin_points(pts, jnt, wgt, pose))
    return np.concatenate(out) if out else np.zeros((1, 3))


def camera_for(scene: Scene, options: PreviewOptions, times: np.ndarray):
    """One camera that fits the tree at every one of `times` (up to 12 sampled)."""
    sample = times if len(times) <= 12 else times[np.linspace(0, len(times) - 1, 12).astype(int)]
    return frame_points(framing_points(scene, sample), options.azimuth, options.elevation)


def sun_angles(options: PreviewOptions) -> tuple[float, float]:
    az = options.azimuth - 50.0 if options.sun_azimuth is None else options.sun_azimuth
    return az, options.sun_elevation


def _renderer(scene: Scene, options: PreviewOptions, renderer=None):
    """`renderer` as a no-op context, or a new Renderer for `scene` (an EGL context)."""
    from contextlib import nullcontext

    from .render import Renderer

    return nullcontext(renderer) if renderer is not None else \
        Renderer(scene, options.width, options.height)


def render_still(scene: Scene, options: PreviewOptions = DEFAULTS, renderer=None) -> np.ndarray:
    """The rest (bind) pose, no wind, as uint8 (height, width, 3); `renderer`: an open one to
    reuse. (The wind clip's t = 0 is a swayed pose, not the rest pose the help promises.)"""
    rest = replace(scene, skinning=None)
    times = np.zeros(1)
    camera = camera_for(rest, options, times)
    with _renderer(scene, options, renderer) as r:
        az, el = sun_angles(options)
        return r.render(camera, rest.pose(times)[0], az, el)


def render_loop(scene: Scene, options: PreviewOptions = DEFAULTS,
                renderer=None) -> list[np.ndarray]:
    """Frames over the whole wind loop, first and last at t = 0 and t = duration (equal poses
    for a looping clip); one fixed camera that fits every frame."""
    if scene.duration <= 0 or scene.skinning is None:
        raise TreegenError(f"{scene.label}: has no wind animation to render (made with --no-wind?)")
    times = loop_times(scene.duration, options.fps)
    camera = camera_for(scene, options, times)
    frames = []
    with _renderer(scene, options, renderer) as r:
        az, el = sun_angles(options)
        for pose in scene.pose(times):             # frames: tens
            frames.append(r.render(camera, pose, az, el))
    return frames


def _check_suffix(path, allowed: tuple[str, ...], kind: str) -> Path:
    """`path` as a Path, or a TreegenError naming the supported extensions."""
    path = Path(path)
    if path.suffix.lower() not in allowed:
        raise TreegenError(f"{path}: unknown {kind} extension '{path.suffix or '(none)'}'; "
                           f"supported: {' '.join(allowed)}")
    return path


def save_image(pixels: np.ndarray, path: str | os.PathLike, colors: int = 0) -> Path:
    """PNG (optimised; `colors` > 0 quantises to a palette, ~3× smaller) or JPEG, atomically."""
    from PIL import Image

    from .exchange import staged

    path = _check_suffix(path, IMAGE_SUFFIXES, "image")
    img = Image.fromarray(pixels)
    with staged(path) as tmp:
        if path.suffix.lower() == ".png":
            if colors:
                img = img.quantize(colors=colors, method=Image.Quantize.MEDIANCUT,
                                   dither=Image.Dither.FLOYDSTEINBERG)
            img.save(tmp, format="PNG", optimize=True)
        else:
            img.save(tmp, format="JPEG", quality=90)
    return path


def save_gif(frames: list[np.ndarray], path: str | os.PathLike, fps: float) -> Path:
    """Animated GIF looping forever; one palette for all frames, so equal frames stay equal."""
    from PIL import Image

    from .exchange import staged

    path = _check_suffix(path, ANIMATION_SUFFIXES, "animation")
    stack = np.concatenate(frames[:: max(1, len(frames) // 8)], axis=0)
    palette = Image.fromarray(stack).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    with staged(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(round(1000 / fps)), loop=0, optimize=False, disposal=1)
    return path


# ------------------------------------------------------------------------------ command

def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*(?:[xX×]\s*(\d+))?\s*", text or "")
    if not m:
        raise TreegenError(f"--size '{text}': expected pixels as N or WxH, e.g. 512 or 800x600")
    w = int(m.group(1))
    h = int(m.group(2)) if m.group(2) else w
    if not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise TreegenError(f"--size '{text}': each side must be in 8..8192 pixels")
    return w, h


@click.command("preview")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Still image of the rest pose: .png (optimised) or .jpg.")
@click.option("--animate", type=click.Path(dir_okay=False, path_type=Path),
              help="Animated GIF of the whole wind loop (first frame = last frame), skinned on "
                   "the GPU from the file's joints and keys, like an engine.")
@click.option("--azimuth", type=float, default=DEFAULTS.azimuth, show_default=True,
              help="Camera bearing, degrees counter-clockwise from +X seen from above "
                   "(Z-up tree space); -90 looks along +Y, so the default wind blows left → right.")
@click.option("--elevation", type=float, default=DEFAULTS.elevation, show_default=True,
              help="Camera height angle above the horizon, degrees (-89..89).")
@click.option("--size", "size", default=str(DEFAULTS.width), show_default=True, metavar="N|WxH",
              help="Image size in pixels (square N, or width x height).")
@click.option("--lod", type=int, default=0, show_default=True,
              help="Which LOD to render (0 = full detail).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed when INPUT is a species file.")
@click.option("--fps", type=float, default=DEFAULTS.fps, show_default=True,
              help="GIF frames per second of the wind loop (frames = duration × fps + 1).")
@click.option("--png-colors", type=click.IntRange(0, 256), default=0, show_default=True,
              help="Quantise the PNG to this many palette colours (smaller files, e.g. 256 "
                   "for a README); 0 keeps full colour.")
@click.option("--json", "as_json", is_flag=True, help="Print what was written as JSON.")
def preview_command(input_path, output, animate, azimuth, elevation, size, lod, seed, fps,
                    png_colors, as_json):
    """Render INPUT headless (OpenGL on EGL; no display needed): a species file (.txt .xml,
    grown in-process) or a tree written by `treegen make` (.glb .gltf .usda .usdc .usdz).
    Lit by a sun with shadows and sky light, bark and leaf colours from the materials, framed
    automatically from the bounds of the whole animation."""
    import time

    if output is None and animate is None:
        raise TreegenError("preview: give an image with -o out.png and/or --animate out.gif")
    if output is not None:                        # fail before anything is grown or rendered
        _check_suffix(output, IMAGE_SUFFIXES, "image")
    if animate is not None:
        _check_suffix(animate, ANIMATION_SUFFIXES, "animation")
    if not -89.0 <= elevation <= 89.0:
        raise TreegenError(f"--elevation {elevation:g}: allowed range -89..89 degrees")
    if not 0.5 <= fps <= 60.0:
        raise TreegenError(f"--fps {fps:g}: allowed range 0.5..60 frames per second")
    if lod < 0:
        raise TreegenError(f"--lod {lod}: must be 0 or more")
    width, height = _size(size)
    options = PreviewOptions(azimuth=azimuth, elevation=elevation, width=width, height=height,
                             lod=lod, seed=seed, fps=fps)
    t0 = time.perf_counter()
    scene = load_scene(input_path, options)
    lines, summary = [], {"input": str(input_path), "width": width, "height": height, "lod": lod}
    with _renderer(scene, options) as renderer:   # one GL context for the still and the loop
        if output is not None:
            save_image(render_still(scene, options, renderer), output, png_colors)
            lines.append(f"wrote {output}  ({width}×{height}, LOD {lod})")
            summary["image"] = str(output)
        if animate is not None:
            frames = render_loop(scene, options, renderer)
            save_gif(frames, animate, fps)
            lines.append(f"wrote {animate}  ({width}×{height}, {len(frames)} frames over "
                         f"{scene.duration:.2f} s, LOD {lod})")
            summary |= {"animation": str(animate), "frames": len(frames),
                        "duration_s": round(float(scene.duration), 4)}
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    for line in lines:
        click.echo(line)
    click.echo(f"  {summary['seconds']:.2f} s")
