"""glTF reader: a .glb/.gltf (ours, or any triangle glTF with at most one skin per LOD node) as a
Drawable, for the preview and the tests. LOD k is the k-th node of the first mesh node's
MSFT_lod chain; animation samplers are played with glTF's own interpolation rules.

Materials as core glTF 2.0 defines them, so any engine-bound file previews textured: the
baseColorTexture (PNG/JPEG, or WebP through EXT_texture_webp, decoded by Pillow) with its
TEXCOORD_n (float, or normalized unsigned byte/short), sampler wrap modes, normalTexture
(+ scale, when it shares the base texture's UV set), alphaMode MASK + alphaCutoff (BLEND is
previewed as a cut-out at 0.5: no sorting in a preview), doubleSided. Images come from a
bufferView, a data: URI, or a relative URI beside the file. `--compress` files too:
KHR_mesh_quantization's integers are dequantized as the spec says (normalized / through the
skin's inverse binds) and EXT_meshopt_compression's views are decoded by meshoptimizer's own
decoder (npm, through Node: compress.decode), the library that encoded them. Read only for
the base texture's UV set: KHR_texture_transform offset and scale. Not read:
occlusion/emissive/metallic-roughness maps (the preview's lighting has no use for them).
"""

from __future__ import annotations

import base64
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from ..drawable import (
    Channel,
    Drawable,
    Part,
    PoseRig,
    check_lod,
    decode_image,
    forest_error,
    is_impostor,
    lit_through,
    vertex_normals,
)
from ..errors import TreegenError
from ..skeleton import forward, trs
from .compress import MESHOPT, decode
from .gltf_container import read_accessor, read_gltf

WRAP = {10497: "REPEAT", 33071: "CLAMP", 33648: "MIRROR"}  # sampler wrapS / wrapT


def _node_world(gltf: dict) -> tuple[np.ndarray, np.ndarray]:
    """(parent per node, rest world matrix per node) from the node hierarchy."""
    nodes = gltf.get("nodes", [])
    n = len(nodes)
    parent = np.full(n, -1, dtype=np.int64)
    for i, node in enumerate(nodes):  # JSON nodes: one Python step each
        for c in node.get("children", []):
            parent[c] = i
    local = np.empty((n, 4, 4))
    for i, node in enumerate(nodes):
        if "matrix" in node:
            local[i] = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
        else:
            local[i] = trs(
                np.asarray(node.get("translation", [0, 0, 0]), float),
                np.asarray(node.get("rotation", [0, 0, 0, 1]), float),
                np.asarray(node.get("scale", [1, 1, 1]), float),
            )
    return parent, forward(parent, local)


def read_drawable(path: Path, lod: int = 0, refuse_forest: bool = False) -> Drawable:
    """A .glb/.gltf (ours, or any triangle glTF with at most one skin per LOD node): the first
    mesh root of the scene, so a forest reads as its first tree, or with `refuse_forest` raises
    the one line saying it is a forest."""
    try:
        gltf, blob = read_gltf(path)
        trees = forest_instances(gltf)
        if refuse_forest and trees:
            raise forest_error(path, trees)
        if MESHOPT in gltf.get("extensionsUsed", []):
            gltf, blob = unpack_meshopt(gltf, blob, path)
        return _gltf_scene(gltf, blob, read_strided, lod, path)
    except TreegenError:
        raise
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as e:
        raise TreegenError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None


def forest_instances(gltf: dict) -> int:
    """Trees in a treegen forest file (the count forest_gltf.py records in the asset's
    extras), or 0. Only treegen's own mark counts: another tool's file with several skinned
    roots (a body and its clothes) is not a forest."""
    extras = gltf.get("asset", {}).get("extras", {})
    if isinstance(extras, dict) and "forest" in extras:
        return int(extras.get("instances", 0))
    return 0


def unpack_meshopt(gltf: dict, blob: bytes, path: Path, simd: bool = True) -> tuple[dict, bytes]:
    """EXT_meshopt_compression → the plain layout: every compressed view decoded by
    meshoptimizer (compress.decode; `simd`: its SIMD build, else the scalar one) and appended
    to buffer 0, so the readers below see ordinary views (quantized integers, as
    KHR_mesh_quantization stores them). Views must live in buffer 0 or a fallback buffer
    (what gltfpack and treegen write)."""
    views = gltf.get("bufferViews", [])
    packed = [i for i, v in enumerate(views) if MESHOPT in v.get("extensions", {})]
    exts = [views[i]["extensions"][MESHOPT] for i in packed]
    if any(e.get("buffer", 0) != 0 for e in exts) or any(
        v.get("buffer", 0) != 0 for i, v in enumerate(views) if i not in set(packed)
    ):
        raise TreegenError(
            f"{path}: EXT_meshopt_compression data outside the GLB's own buffer is not read here"
        )
    encoded = [blob[e.get("byteOffset", 0) : e.get("byteOffset", 0) + e["byteLength"]] for e in exts]
    parts, size = [blob], len(blob)
    views = [dict(v) for v in views]
    for i, data in zip(packed, decode(list(zip(exts, encoded)), str(path), simd)):
        pad = -size % 4
        parts.append(b"\0" * pad)
        views[i] = {
            "buffer": 0,
            "byteOffset": size + pad,
            "byteLength": len(data),
            **({"byteStride": views[i]["byteStride"]} if "byteStride" in views[i] else {}),
        }
        parts.append(data)
        size += pad + len(data)
    return {**gltf, "bufferViews": views}, b"".join(parts)


def _gltf_scene(gltf, blob, read_accessor, lod, path) -> Drawable:
    nodes = gltf.get("nodes", [])
    scene = gltf.get("scenes", [{}])[gltf.get("scene", 0)]
    roots = [i for i in scene.get("nodes", []) if "mesh" in nodes[i]] or [
        i for i, nd in enumerate(nodes) if "mesh" in nd
    ][:1]
    if not roots:
        raise TreegenError(f"{path}: no mesh in the glTF scene")
    lod_nodes = [roots[0]] + list(nodes[roots[0]].get("extensions", {}).get("MSFT_lod", {}).get("ids", []))
    check_lod(lod, len(lod_nodes), path)
    node_index = lod_nodes[lod]
    node = nodes[node_index]
    parent, world = _node_world(gltf)
    materials = gltf.get("materials", [])

    skin = gltf["skins"][node["skin"]] if "skin" in node else None
    if skin is not None:
        joints = np.asarray(skin["joints"], dtype=np.int64)
        J = len(joints)
        ibm = (
            read_accessor(gltf, blob, skin["inverseBindMatrices"]).astype(np.float64)
            if "inverseBindMatrices" in skin
            else np.broadcast_to(np.eye(4), (J, 4, 4))
        )
    else:
        joints, J = np.array([node_index]), 1  # static: S = world of the mesh node
        ibm = np.eye(4)[None]

    parts = []
    images = _Images(gltf, blob, Path(path))
    for k, prim in enumerate(gltf["meshes"][node["mesh"]]["primitives"]):
        if prim.get("mode", 4) != 4:
            continue
        a = prim["attributes"]
        pos = read_accessor(gltf, blob, a["POSITION"]).astype(np.float32)
        idx = (
            read_accessor(gltf, blob, prim["indices"]).astype(np.uint32)
            if "indices" in prim
            else np.arange(len(pos), dtype=np.uint32)
        )
        nrm = (
            read_accessor(gltf, blob, a["NORMAL"]).astype(np.float32)
            if "NORMAL" in a
            else vertex_normals(pos, idx)
        )
        if skin is not None and "JOINTS_0" in a:
            jnt = read_accessor(gltf, blob, a["JOINTS_0"]).astype(np.int64)
            wgt = read_accessor(gltf, blob, a["WEIGHTS_0"]).astype(np.float32)
        else:
            jnt = np.zeros((len(pos), 4), np.int64)
            wgt = np.tile(np.float32([1, 0, 0, 0]), (len(pos), 1))
        mat = materials[prim["material"]] if "material" in prim else {}
        pbr = mat.get("pbrMetallicRoughness", {})
        looks = _surface(gltf, blob, a, mat, images)
        color = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0] if "texture" in looks else [0.6, 0.6, 0.6, 1])
        parts.append(
            Part(
                name=mat.get("name", f"primitive{k}"),
                positions=pos,
                normals=nrm,
                indices=idx,
                joints=jnt,
                weights=wgt,
                color=tuple(color[:3]),
                double_sided=lit_through(mat.get("name"), bool(mat.get("doubleSided", False))),
                opacity=float(color[3]) if len(color) > 3 else 1.0,
                impostor=is_impostor(mat.get("name")),
                **looks,
            )
        )

    jparent = np.full(J, -1, dtype=np.int64)
    slot = {int(n): j for j, n in enumerate(joints)}
    for j, n in enumerate(joints):  # joints: hundreds at most
        jparent[j] = slot.get(int(parent[n]), -1)
    above = parent[joints]
    root_world = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    outside = (jparent < 0) & (above >= 0)  # a root joint under a non-joint node
    root_world[outside] = world[above[outside]]
    rest = [nodes[n] for n in joints]
    rig = PoseRig(
        parent=jparent,
        translation=np.array([n.get("translation", [0, 0, 0]) for n in rest], float).reshape(J, 3),
        rotation=np.array([n.get("rotation", [0, 0, 0, 1]) for n in rest], float).reshape(J, 4),
        scale=np.array([n.get("scale", [1, 1, 1]) for n in rest], float).reshape(J, 3),
        root_world=root_world,
        inverse_bind=ibm,
        channels=gltf_channels(gltf, blob, read_accessor, slot) if skin is not None else [],
    )
    if any("matrix" in n for n in rest):
        raise TreegenError(f"{path}: joint nodes with 'matrix' transforms are not supported")
    return Drawable(parts=parts, n_joints=J, duration=rig.duration, skinning=rig.skinning, label=str(path))


class _Images:
    """Decoded images by (index, channels), each read once per file."""

    def __init__(self, gltf: dict, blob: bytes, path: Path):
        self.gltf, self.blob, self.path = gltf, blob, path
        self.cache: dict[tuple[int, int], np.ndarray] = {}

    def get(self, index: int, channels: int) -> np.ndarray:
        if (index, channels) not in self.cache:
            img = self.gltf["images"][index]
            what = f"{self.path}: image {index} ({img.get('name') or img.get('uri', 'embedded')})"
            self.cache[index, channels] = decode_image(self._bytes(img), channels, what)
        return self.cache[index, channels]

    def _bytes(self, img: dict) -> bytes:
        if "bufferView" in img:
            view = self.gltf["bufferViews"][img["bufferView"]]
            data = (
                self.blob
                if view.get("buffer", 0) == 0
                else self._uri(self.gltf["buffers"][view["buffer"]]["uri"])
            )
            start = view.get("byteOffset", 0)
            return bytes(data[start : start + view["byteLength"]])
        return self._uri(img["uri"])

    def _uri(self, uri: str) -> bytes:
        """A data: URI or a file relative to the glTF (URI-encoded, per the spec)."""
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            return base64.b64decode(payload) if head.endswith(";base64") else unquote(payload).encode()
        f = self.path.parent / unquote(uri)
        if not f.is_file():
            raise TreegenError(f"{self.path}: texture file {uri!r} not found beside it ({f})")
        return f.read_bytes()


def _texture(gltf: dict, ref: dict, images: _Images, channels: int):
    """(image, (wrap u, wrap v)) of a textureInfo."""
    tex = gltf["textures"][ref["index"]]
    source = tex.get("source")
    if source is None:  # EXT_texture_webp and the like: own source
        source = next(
            (
                e["source"]
                for e in tex.get("extensions", {}).values()
                if isinstance(e, dict) and "source" in e
            ),
            None,
        )
    if source is None:
        return None, ("REPEAT", "REPEAT")
    sampler = gltf["samplers"][tex["sampler"]] if "sampler" in tex else {}
    wrap = (WRAP.get(sampler.get("wrapS", 10497), "REPEAT"), WRAP.get(sampler.get("wrapT", 10497), "REPEAT"))
    return images.get(source, channels), wrap


def _texcoords(
    gltf: dict, blob: bytes, attributes: dict, n: int, transform: dict | None = None
) -> np.ndarray | None:
    """TEXCOORD_n as float32 with the bottom-left origin (glTF's v runs down: v → 1 − v)."""
    key = f"TEXCOORD_{n}"
    if key not in attributes:
        return None
    uv = read_strided(gltf, blob, attributes[key]).astype(np.float32)
    if transform:  # KHR_texture_transform offset and scale (what --compress writes)
        uv = uv * np.float32(transform.get("scale", [1, 1])) + np.float32(transform.get("offset", [0, 0]))
    uv[:, 1] = 1.0 - uv[:, 1]
    return uv


def read_strided(gltf: dict, blob: bytes, index: int) -> np.ndarray:
    """read_accessor, plus interleaved views (byteStride) as other exporters write them."""
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    stride = view.get("byteStride")
    dtype = np.dtype(
        {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}[acc["componentType"]]
    )
    ncomp = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}.get(acc["type"])
    if not stride or ncomp is None or stride == ncomp * dtype.itemsize:
        a = read_accessor(gltf, blob, index)
        return np.maximum(a, -1.0) if acc.get("normalized") and dtype.kind == "i" else a
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    a = np.ndarray(
        (acc["count"], ncomp), dtype, buffer=blob, offset=start, strides=(stride, dtype.itemsize)
    ).copy()
    if acc.get("normalized"):  # signed: c / max, at least -1 (glTF's rule)
        a = np.maximum(a / float(np.iinfo(dtype).max), -1.0)
    return a


def _surface(gltf: dict, blob: bytes, attributes: dict, mat: dict, images: _Images) -> dict:
    """Part fields for a material's textures: uvs, texture, normal map, wrap, cut-out."""
    pbr = mat.get("pbrMetallicRoughness", {})
    base, normal = pbr.get("baseColorTexture"), mat.get("normalTexture")
    uv_set = (base or normal or {}).get("texCoord", 0)
    transform = (base or normal or {}).get("extensions", {}).get("KHR_texture_transform")
    out: dict = {"uvs": _texcoords(gltf, blob, attributes, uv_set, transform)}
    mode = mat.get("alphaMode", "OPAQUE")
    if mode in ("MASK", "BLEND"):
        out["alpha_cutoff"] = float(mat.get("alphaCutoff", 0.5)) if mode == "MASK" else 0.5
    if out["uvs"] is None:
        return out
    if base is not None:
        out["texture"], out["wrap"] = _texture(gltf, base, images, 4)
    if normal is not None and normal.get("texCoord", 0) == uv_set:
        out["normal_map"], out["normal_wrap"] = _texture(gltf, normal, images, 3)
        out["normal_scale"] = float(normal.get("scale", 1.0))
    return out


def gltf_channels(gltf, blob, read_accessor, slot: dict[int, int], name: str | None = None) -> list[Channel]:
    """Channels of the first animation that moves any of this skin's joints (`slot`: node →
    joint), or of the animation called `name`."""
    for anim in gltf.get("animations", []):
        if name is not None and anim.get("name") != name:
            continue
        out = []
        for ch in anim["channels"]:  # one per animated joint (hundreds)
            node, path = ch["target"].get("node"), ch["target"]["path"]
            if node not in slot or path not in ("rotation", "translation", "scale"):
                continue
            s = anim["samplers"][ch["sampler"]]
            times = read_accessor(gltf, blob, s["input"]).astype(np.float64)
            values = read_accessor(gltf, blob, s["output"]).astype(np.float64)
            out.append(
                Channel(
                    np.array([slot[node]]), path, times, values[:, None, :], s.get("interpolation", "LINEAR")
                )
            )
        if out:
            return out
    return []
