"""glTF 2.0 writer: Asset → .glb (binary, default) or .gltf + sibling .bin.

A lean writer of our own: every array goes to the binary buffer as a byte view of a numpy
array (no per-vertex Python, no tobytes/join copies: a GLB is streamed to disk part by part),
the JSON is built from plain dicts and dumped with sorted keys, so the same Asset always gives
the same bytes. Vertex data stays float32 end to end (the Y-up swap is an exact shuffle).
WEIGHTS_0 is normalized UNSIGNED_BYTE for rigid primitives (leaves: exact) and normalized
UNSIGNED_SHORT for blended ones (bark), each row summing exactly to 255 / 65535 — a quarter /
half of float32's bytes; JOINTS_0 is UNSIGNED_BYTE up to 256 joints. NORMAL and float TEXCOORD_0 are always written:
Godot reads neither normalized integer UVs nor computes missing normals. Textures are PNGs in
the buffer. All core glTF 2.0 (MSFT_lod only as an optional extension).

Axes: the generator is Z up, glTF is Y up (right-handed), so every vector goes through
C: (x, y, z) → (x, z, −y); quaternion vector parts likewise; matrices become C·M·Cᵀ.

Node layout: the skinned mesh node of LOD0 and each LOD's rig node (holding that skeleton's
root joint; `skin.skeleton` = the joint) are scene roots, side by side. A mesh node that
parents its own joints hangs Godot 3's importer; a tree node wrapping mesh and joints draws
glTF-Validator's NODE_SKINNED_MESH_NON_ROOT warning; side by side at the root every client
takes them. One rig node per LOD keeps skeletons apart in importers that merge sibling roots
(Godot 3 would make one 444-bone skeleton of four).

    "<name>_LOD0"           mesh + skin, no transform, MSFT_lod → "<name>_LOD1", …
    "<name>_LOD0_rig"       identity
        └── trunk_0 …       LOD0's skeleton (local TRS), joints named by what they are
    "<name>_LOD1_rig"       LOD1's skeleton, …

Lower LODs' mesh nodes are reached only through LOD0's MSFT_lod ids, so clients without
MSFT_lod draw just the full-detail tree; their skeletons stay in the scene so every clip finds
its joints. Each LOD node's extras carry its index, distance and screen coverage.
"""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path

import numpy as np

from .. import __version__
from ..asset import Asset, Clip, Material, Primitive, Skeleton, Texture
from ..axes import Z_UP_TO_Y_UP, matrix_to_y_up, quat_to_y_up, to_y_up  # noqa: F401  (re-exported)
from ..quat import continuous as _continuous
from . import key_plan
from .impostor_meta import describe, impostor_lod, write_sidecar
from .compress import (
    GLTF_DEFAULTS,
    MESHOPT,
    QUANTIZATION,
    TEXTURE_TRANSFORM,
    GltfOptions,
    Grid,
    MeshoptView,
    UvRange,
    encode,
    meshopt_step,
    position_grid,
    quantize_positions,
    quantize_uvs,
    snorm8,
    snorm16,
    uv_range,
)

# glTF enums
FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5121, 5123, 5125
BYTE, SHORT = 5120, 5122
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_COMPONENT = {
    np.dtype(np.float32): FLOAT,
    np.dtype(np.uint8): UNSIGNED_BYTE,
    np.dtype(np.uint16): UNSIGNED_SHORT,
    np.dtype(np.uint32): UNSIGNED_INT,
    np.dtype(np.int8): BYTE,
    np.dtype(np.int16): SHORT,
}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


class _Buffer:
    """Accumulates bufferViews (each 4-byte aligned) and accessors into one binary blob.

    Parts are kept as byte views of the arrays themselves (no tobytes copy); `write_to` streams
    them into a file, so a 300 MB buffer is never joined in memory on the way to disk."""

    def __init__(self, meshopt: bool = False, pooled: bool = False) -> None:
        self.parts: list[memoryview] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []
        self.view_parts: list[memoryview] = []
        # --compress meshopt: how each accessor's view is encoded (compress.meshopt_views)
        self.meshopt: dict[int, MeshoptView] | None = {} if meshopt else None
        # (index accessor, vertex accessors) per primitive: reordered together under meshopt
        self.groups: list[tuple[int, list[int]]] = []
        # --compress: data pooled into one view per (target, element type, filter), as gltfpack
        # does: meshopt's codec sees long streams instead of hundreds of 301-key tracks, and the
        # JSON lists a few views instead of one per track and vertex attribute
        self.pooled = pooled or meshopt
        self.pools: dict[tuple, list[tuple[int, np.ndarray, np.ndarray | None]]] = {}
        # meshopt: a pooled view's members (accessor, data, filter source), encoded as one stream
        self.members: dict[int, list[tuple[int, np.ndarray, np.ndarray | None]]] = {}
        self.bits: dict[int, int] = {}  # accessor → its filter's bits, where not the default

    def view(self, data, target: int | None) -> int:
        data = memoryview(data).cast("B")
        pad = -self.size % 4
        if pad:
            self.parts.append(memoryview(b"\0" * pad))
            self.size += pad
        v = {"buffer": 0, "byteOffset": self.size, "byteLength": data.nbytes}
        if target is not None:
            v["target"] = target
        self.parts.append(data)
        self.view_parts.append(data)
        self.size += data.nbytes
        self.views.append(v)
        return len(self.views) - 1

    def accessor(
        self,
        a: np.ndarray,
        target: int | None = None,
        bounds: bool = False,
        normalized: bool = False,
        padded: bool = False,
        filter: str = "NONE",
        source: np.ndarray | None = None,
        bits: int | None = None,
    ) -> int:
        """`padded`: a's last component is alignment padding, not data (the view's byteStride
        keeps it, the accessor type drops it). `filter`/`source`/`bits`: the meshopt filter
        for this view, the float32 (count, 4) data it encodes and its bits (a pooled
        QUATERNION view's members may differ: each key states its own)."""
        a = np.ascontiguousarray(a)
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)  # no copy on little-endian hosts
        stored = 1 if a.ndim == 1 else math.prod(a.shape[1:])
        comps = stored - 1 if padded else stored
        if self.pooled:
            if bits is not None:
                self.bits[len(self.accessors)] = bits
            self.accessors.append(self._fields(a, comps, stored, normalized, bounds))
            key = (target, a.dtype.str, stored, filter)
            self.pools.setdefault(key, []).append((len(self.accessors) - 1, a, source))
            return len(self.accessors) - 1
        view = self.view(a.reshape(-1).view(np.uint8), target)
        if padded:
            self.views[view]["byteStride"] = stored * a.itemsize
        if self.meshopt is not None:
            self.meshopt[view] = MeshoptView(
                mode="TRIANGLES" if target == ELEMENT_ARRAY_BUFFER else "ATTRIBUTES",
                stride=stored * a.itemsize,
                count=int(a.size // stored),
                filter=filter,
                source=source,
            )
        acc = {"bufferView": view, **self._fields(a, comps, stored, normalized, bounds)}
        self.accessors.append(acc)
        return len(self.accessors) - 1

    @staticmethod
    def _fields(a: np.ndarray, comps: int, stored: int, normalized: bool, bounds: bool) -> dict:
        acc = {
            "componentType": _COMPONENT[a.dtype.newbyteorder("=")],
            "count": int(a.shape[0]),
            "type": _TYPE[comps],
        }
        if normalized:
            acc["normalized"] = True
        if bounds:  # column by column: numpy's axis-0 reduce over (V, 3) is 20× slower
            flat = a.reshape(len(a), stored)
            acc["min"] = [_num(flat[:, c].min()) for c in range(comps)]
            acc["max"] = [_num(flat[:, c].max()) for c in range(comps)]
        return acc

    def flush_pools(self) -> None:
        """One view per pool, each accessor at its offset in it (meshopt: with its encoding).
        A vertex pool states its byteStride (several accessors share the view); every element
        is 4 bytes or a multiple, so each accessor stays 4-byte aligned."""
        for (target, _, stored, filter), members in self.pools.items():
            data = np.concatenate([a.reshape(-1).view(np.uint8) for _, a, _ in members])
            view = self.view(data, target)
            size = members[0][1].itemsize * stored
            if target == ARRAY_BUFFER:
                self.views[view]["byteStride"] = size
            offset = 0
            for acc, a, _ in members:
                self.accessors[acc]["bufferView"] = view
                if offset:
                    self.accessors[acc]["byteOffset"] = offset
                offset += a.nbytes
            if self.meshopt is None:
                continue
            self.meshopt[view] = MeshoptView(
                mode={ARRAY_BUFFER: "ATTRIBUTES", ELEMENT_ARRAY_BUFFER: "TRIANGLES"}.get(
                    target, "ATTRIBUTES"
                ),
                stride=size,
                count=len(data) // size,
                filter=filter,
            )
            self.members[view] = members
        self.pools = {}

    def padding(self) -> bytes:
        return b"\0" * (-self.size % 4)

    def blob(self) -> bytes:
        return b"".join([*self.parts, self.padding()])

    def write_to(self, f) -> None:
        for part in self.parts:
            f.write(part)
        f.write(self.padding())


def _num(x) -> int | float:
    return int(x) if np.issubdtype(type(x), np.integer) else float(x)


def _weights(
    joints: np.ndarray, weights: np.ndarray, blended: type = np.uint16
) -> tuple[np.ndarray, np.ndarray]:
    """Normalised integer weights whose rows sum exactly to the type's maximum; zero-weight
    slots index joint 0.

    Rigid rows (every weight 0 or 1, like leaves on their carrier) are exact as UNSIGNED_BYTE;
    blended rows (bark) take UNSIGNED_SHORT, steps of 1/65535, the rounding residual put on
    each row's largest weight. Result: [.7, .3, 0, 0] → [45875, 19660, 0, 0] (sum 65535).
    `blended=np.uint8` (--compress): bark in steps of 1/255 too, as gltfpack stores weights.
    Row sums and maxima go column by column: numpy's axis-1 reductions over (V, 4) are slow."""
    w = np.asarray(weights)
    if w.dtype != np.float64:
        w = w.astype(np.float32, copy=False)
    cols = range(w.shape[1])
    flat = w.reshape(-1)
    if bool(np.all((flat == 0) | (flat == 1))) and bool(np.all(sum(w[:, k] for k in cols) == 1)):
        q = w.astype(np.uint8) * np.uint8(255)
    else:
        full = int(np.iinfo(blended).max)
        w = w.astype(np.float64)
        s = sum(w[:, k] for k in cols)
        w *= (full / np.where(s > 0, s, 1.0))[:, None]
        top = np.zeros(len(w), dtype=np.int64)
        for k in cols[1:]:
            top[w[:, k] > w[np.arange(len(w)), top]] = k
        qi = np.rint(w).astype(np.int64)
        qi[np.arange(len(qi)), top] += full - sum(qi[:, k] for k in cols)
        q = qi.astype(blended)
    j = np.where(q > 0, joints, 0)
    return j, q


def _y_up32(v: np.ndarray) -> np.ndarray:
    """float32 (V, 3) → new float32 (V, 3) in Y up: an exact shuffle, no float64 detour.
    Contiguous first: numpy 2.4's strided `negative(..., out=)` reads the wrong elements."""
    v = np.ascontiguousarray(v, dtype=np.float32)
    out = np.empty(v.shape, dtype=np.float32)
    out[:, 0] = v[:, 0]
    out[:, 1] = v[:, 2]
    np.negative(v[:, 1], out=out[:, 2])
    return out


def _gltf_uvs(p: Primitive) -> np.ndarray:
    """Asset UVs have their origin bottom-left (OpenGL/USD); glTF's is top-left."""
    uv = np.array(p.uvs, dtype=np.float32)
    np.subtract(np.float32(1.0), uv[:, 1], out=uv[:, 1])
    return uv


class Quantization:
    """--compress quantize/meshopt state of one LOD: its skin's position grid and each
    material's UV box (shared by every LOD, as the material is)."""

    def __init__(self, grid: Grid, uvs: dict[str, UvRange]):
        self.grid, self.uvs = grid, uvs


def _primitive(
    buf: _Buffer, p: Primitive, n_joints: int, material: int, quant: Quantization | None = None
) -> dict:
    if quant is not None:
        return _quantized_primitive(buf, p, n_joints, material, quant)
    pos = _y_up32(p.positions)
    # Always float UVs here: Godot 3.2 ignores `normalized` on integer UVs, and every client
    # reads float32.
    uv = _gltf_uvs(p)
    joints, weights = _weights(p.joints, p.weights)
    joints = joints.astype(np.uint8 if n_joints <= 256 else np.uint16, copy=False)
    V = len(p.positions)
    indices = np.asarray(p.indices).astype(np.uint16 if V < 65535 else np.uint32, copy=False)
    # NORMAL always: Godot does not compute missing normals and Babylon/three.js regenerate
    # them with a warning or flat shading
    nrm = _y_up32(p.normals)
    length = np.sqrt(np.einsum("ij,ij->i", nrm, nrm))
    nrm /= np.where(length > 0, length, np.float32(1.0))[:, None]
    attrs = {
        "POSITION": buf.accessor(pos, ARRAY_BUFFER, bounds=True),
        "NORMAL": buf.accessor(nrm, ARRAY_BUFFER),
        "TEXCOORD_0": buf.accessor(uv, ARRAY_BUFFER),
        **_tangent(buf, p),
        "JOINTS_0": buf.accessor(joints, ARRAY_BUFFER),
        "WEIGHTS_0": buf.accessor(weights, ARRAY_BUFFER, normalized=True),
    }
    return {
        "attributes": attrs,
        "indices": buf.accessor(indices, ELEMENT_ARRAY_BUFFER),
        "material": material,
        "mode": 4,
    }


def _quantized_primitive(
    buf: _Buffer, p: Primitive, n_joints: int, material: int, quant: Quantization
) -> dict:
    """KHR_mesh_quantization (compress.py): grid positions, int8 normals and tangents,
    uint16 UVs in the material's box; joints, weights and indices as in `_primitive`."""
    pos = quantize_positions(_y_up32(p.positions), quant.grid)
    nrm = _unit(_y_up32(p.normals).astype(np.float64))
    uv = quantize_uvs(_gltf_uvs(p), quant.uvs[p.material])
    joints, weights = _weights(p.joints, p.weights, np.uint8)
    joints = joints.astype(np.uint8 if n_joints <= 256 else np.uint16, copy=False)
    V = len(p.positions)
    indices = np.asarray(p.indices).astype(np.uint16 if V < 65535 else np.uint32, copy=False)
    attrs = {
        "POSITION": buf.accessor(pos, ARRAY_BUFFER, bounds=True, padded=True),
        "NORMAL": buf.accessor(
            snorm8(nrm, pad=True),
            ARRAY_BUFFER,
            normalized=True,
            padded=True,
            filter="OCTAHEDRAL",
            source=_pad4(nrm, 0.0),
        ),
        "TEXCOORD_0": buf.accessor(uv, ARRAY_BUFFER, normalized=True),
    }
    if p.tangents is not None:
        t = np.asarray(p.tangents, dtype=np.float64)
        tan = np.column_stack([_unit(to_y_up(t[:, :3])), np.sign(t[:, 3]) + (t[:, 3] == 0)])
        attrs["TANGENT"] = buf.accessor(
            snorm8(tan, pad=False),
            ARRAY_BUFFER,
            normalized=True,
            filter="OCTAHEDRAL",
            source=tan.astype(np.float32),
        )
    attrs |= {
        "JOINTS_0": buf.accessor(joints, ARRAY_BUFFER),
        "WEIGHTS_0": buf.accessor(weights, ARRAY_BUFFER, normalized=True),
    }
    prim = {
        "attributes": attrs,
        "indices": buf.accessor(indices, ELEMENT_ARRAY_BUFFER),
        "material": material,
        "mode": 4,
    }
    if buf.meshopt is not None:  # one vertex order for all of the primitive's attributes
        buf.groups.append((prim["indices"], list(attrs.values())))
    return prim


def _pad4(v: np.ndarray, w: float) -> np.ndarray:
    return np.column_stack([v, np.full(len(v), w)]).astype(np.float32)


def quantization(asset: Asset, lod_index: int, min_step: float = 0.0) -> Quantization:
    """The grid of one LOD's skin and every material's UV box over all LODs."""
    by_material: dict[str, list[np.ndarray]] = {}
    for lod in asset.lods:
        for p in lod.primitives:
            by_material.setdefault(p.material, []).append(_gltf_uvs(p))
    grid = position_grid([_y_up32(p.positions) for p in asset.lods[lod_index].primitives], min_step)
    return Quantization(grid, {m: uv_range(u) for m, u in by_material.items()})


def _tangent(buf: _Buffer, p: Primitive) -> dict:
    """TANGENT (xyz + handedness w) where the primitive has them (normal-mapped bark), so no
    client generates its own tangent space (the validator warns about that)."""
    if p.tangents is None:
        return {}
    t = np.asarray(p.tangents, dtype=np.float32)
    xyz = _y_up32(t[:, :3])  # a rotation: handedness w is unchanged
    return {"TANGENT": buf.accessor(np.column_stack([xyz, t[:, 3]]).astype(np.float32), ARRAY_BUFFER)}


def moving_joints(clip: Clip) -> np.ndarray:
    """Joints that get a channel (prepared in Clip.animated)."""
    if clip.animated is None:
        raise ValueError(f"clip {clip.name!r} is not prepared (prepare.prepare before export)")
    return np.flatnonzero(clip.animated)


def rotation_samplers(
    buf: _Buffer,
    clip: Clip,
    joints: np.ndarray,
    inputs: dict,
    quantized: bool = False,
    wide: np.ndarray | None = None,
    bits: np.ndarray | None = None,
) -> list[tuple[int, dict]]:
    """[(joint, sampler)] for the rotation tracks of `joints`, each with only its kept keys
    (Y up, sign-continuous). `inputs` caches input accessors by (times, key set), so tracks
    with the same schedule share one. `quantized`: outputs as normalized int16 (core glTF),
    QUATERNION-filtered under meshopt (at `bits` per joint when given), but float32 for the
    `wide` joints (key_plan.py); a
    track whose stored keys are all equal is stored as its first key (the first track keeps
    its span, so the clip keeps its length)."""
    K = len(clip.times)
    rot = _unit(quat_to_y_up(clip.rotations))
    times = np.asarray(clip.times, dtype=np.float32)
    out = []
    for j in joints:  # loop over joints (a few hundred), not keys or vertices
        keys = np.arange(K) if clip.keys is None else np.asarray(clip.keys[j], dtype=np.int64)
        q = _continuous(rot[keys, j])
        if not quantized:
            values, fields = q.astype(np.float32), {}
        elif wide is not None and wide[j]:  # meshopt: EXPONENTIAL-filtered
            values = q.astype(np.float32)
            fields = {"filter": "EXPONENTIAL", "source": values}
            if bits is not None:
                fields["bits"] = int(bits[j])
        else:
            values = snorm16(q)
            fields = {"normalized": True, "filter": "QUATERNION", "source": q.astype(np.float32)}
            if bits is not None:
                fields["bits"] = int(bits[j])
        if quantized and out and len(keys) > 1 and not np.any(values != values[:1]):
            keys, values = keys[:1], values[:1]
            if "source" in fields:
                fields["source"] = fields["source"][:1]
        ident = (times.tobytes(), keys.tobytes())
        if ident not in inputs:
            inputs[ident] = buf.accessor(times[keys], bounds=True)
        sampler = {"input": inputs[ident], "output": buf.accessor(values, **fields)}
        if not (quantized and clip.interpolation == "LINEAR"):  # (LINEAR is glTF's default)
            sampler["interpolation"] = clip.interpolation
        out.append((int(j), sampler))
    return out


def _animation(
    buf: _Buffer,
    clip: Clip,
    skeleton: Skeleton,
    joint_nodes: np.ndarray,
    quantized: bool = False,
    plan: key_plan.KeyPlan | None = None,
) -> dict | None:
    joints = moving_joints(clip)
    if len(joints) == 0:
        return None
    if plan is not None:
        clip = plan.clip
    wide, bits = (plan.wide, plan.bits) if plan is not None else (None, None)
    samplers, channels = [], []
    for j, sampler in rotation_samplers(buf, clip, joints, {}, quantized, wide, bits):
        samplers.append(sampler)
        channels.append(
            {"sampler": len(samplers) - 1, "target": {"node": int(joint_nodes[j]), "path": "rotation"}}
        )
    return {"name": clip.name, "samplers": samplers, "channels": channels}


def joint_fields(skeleton: Skeleton, short: bool = False) -> list[dict]:
    """Per joint, its glTF node's rest TRS fields (Y up; defaults left out). `short`
    (--compress): each number as the shortest text of its float32, which every client reads
    it as anyway (a third of the JSON of full float64 digits)."""
    t = to_y_up(np.asarray(skeleton.rest_translation, dtype=np.float64))
    q = _unit(quat_to_y_up(skeleton.rest_rotation))
    num = _short if short else float
    out = []
    for j in range(len(skeleton.names)):  # one JSON node per joint
        n = {}
        if not _is_default(t[j], [0, 0, 0]):
            n["translation"] = [num(x) for x in t[j]]
        if not _is_default(q[j], [0, 0, 0, 1]):
            n["rotation"] = [num(x) for x in q[j]]
        out.append(n)
    return out


def _short(x) -> float:
    """The float64 whose shortest text is float32(x)'s: 0.1 for 0.10000000149011612."""
    return float(str(np.float32(x)))


def inverse_bind_accessor(buf: _Buffer, skeleton: Skeleton, grid: Grid | None = None) -> int:
    """Accessor of the skin's inverse bind matrices (Y up, column-major float32); with a
    quantization `grid`, each times the grid's dequantization (a skinned mesh's node transform
    is ignored, so this is where integer positions become metres)."""
    ibm = matrix_to_y_up(skeleton.inverse_bind())
    ibm[:, 3, :] = (0.0, 0.0, 0.0, 1.0)
    if grid is not None:
        ibm = ibm @ grid.dequantize()
    return buf.accessor(ibm.transpose(0, 2, 1).reshape(len(ibm), 16).astype(np.float32))


def set_msft_lod(node: dict, lower: list[int], lods: list) -> None:
    """Make `node` the LOD0 of an MSFT_lod chain: lower LOD node ids and screen coverages."""
    node["extensions"] = {"MSFT_lod": {"ids": lower}}
    node["extras"] = node.get("extras", {}) | {
        "MSFT_screencoverage": [float(lod.screen_coverage) for lod in lods]
    }


def _is_default(v: np.ndarray, default) -> bool:
    return bool(np.array_equal(v, default))


def build(asset: Asset, options: GltfOptions = GLTF_DEFAULTS) -> tuple[dict, bytes]:
    """Asset → (glTF JSON dict without buffer uri, binary buffer)."""
    gltf, buf = _build(asset, options)
    return gltf, buf.blob()


REPEAT, CLAMP_TO_EDGE, LINEAR, LINEAR_MIPMAP_LINEAR = 10497, 33071, 9729, 9987
_WRAP = {"REPEAT": REPEAT, "CLAMP": CLAMP_TO_EDGE}


class Textures:
    """Images (PNG bytes in the buffer), samplers (one per wrap mode) and textures, each
    written once however many materials use them."""

    def __init__(self, buf: _Buffer):
        self.buf = buf
        self.images: list[dict] = []
        self.samplers: list[dict] = []
        self.textures: list[dict] = []
        self._tex: dict = {}
        self._sampler: dict = {}
        self._image: dict = {}

    def index(self, t: Texture) -> int:
        if t not in self._tex:
            if t.wrap not in self._sampler:
                self._sampler[t.wrap] = len(self.samplers)
                self.samplers.append(
                    {
                        "magFilter": LINEAR,
                        "minFilter": LINEAR_MIPMAP_LINEAR,
                        "wrapS": _WRAP[t.wrap],
                        "wrapT": _WRAP[t.wrap],
                    }
                )
            if t not in self._image:
                view = self.buf.view(np.frombuffer(t.png, dtype=np.uint8), None)
                self.images.append({"name": t.name, "bufferView": view, "mimeType": "image/png"})
                self._image[t] = len(self.images) - 1
            self._tex[t] = len(self.textures)
            self.textures.append({"sampler": self._sampler[t.wrap], "source": self._image[t]})
        return self._tex[t]

    def image(self, t: Texture) -> int:
        """Index of `t`'s image, written once; an image no material samples (the impostor's
        normal + depth atlas) gets no texture."""
        if t in self._tex:
            return self.textures[self._tex[t]]["source"]
        if t not in self._image:
            view = self.buf.view(np.frombuffer(t.png, dtype=np.uint8), None)
            self.images.append({"name": t.name, "bufferView": view, "mimeType": "image/png"})
            self._image[t] = len(self.images) - 1
        return self._image[t]

    def fields(self, gltf: dict) -> None:
        if self.textures:
            gltf |= {"images": self.images, "samplers": self.samplers, "textures": self.textures}


def material_dict(m: Material, textures: Textures, uvs: UvRange | None = None) -> dict:
    """A Material as a glTF metallic-roughness material: base colour (and texture), normal map,
    MASK with its cutoff for alpha-tested leaves, double-sided leaves. `uvs`: the box of
    quantized UVs, undone by KHR_texture_transform on each texture reference."""
    pbr: dict = {
        "baseColorFactor": [float(c) for c in m.base_color],
        "metallicFactor": float(m.metallic),
        "roughnessFactor": float(m.roughness),
    }
    d: dict = {"name": m.name, "pbrMetallicRoughness": pbr}
    ext = {} if uvs is None or uvs.identity else {"extensions": uvs.transform()}
    if m.base_texture is not None:
        pbr["baseColorTexture"] = {"index": textures.index(m.base_texture), **ext}
    if m.normal_texture is not None:
        d["normalTexture"] = {"index": textures.index(m.normal_texture), **ext}
    if m.double_sided:
        d["doubleSided"] = True
    if m.alpha_cutoff is not None:
        d["alphaMode"] = "MASK"
        d["alphaCutoff"] = float(m.alpha_cutoff)
    return d


def _build(asset: Asset, options: GltfOptions = GLTF_DEFAULTS) -> tuple[dict, _Buffer]:
    """Asset → (glTF JSON dict without buffer uri, the unjoined buffer)."""
    buf = _Buffer(meshopt=options.compress == "meshopt", pooled=options.quantized)
    textures = Textures(buf)
    mat_index = {m.name: i for i, m in enumerate(asset.materials)}
    steps = [
        meshopt_step(options, lod.distance) if options.compress == "meshopt" else 0.0 for lod in asset.lods
    ]
    quants = (
        [quantization(asset, k, steps[k]) for k in range(len(asset.lods))]
        if options.quantized
        else [None] * len(asset.lods)
    )
    uv_boxes = quants[0].uvs if quants and quants[0] is not None else {}
    materials = [material_dict(m, textures, uv_boxes.get(m.name)) for m in asset.materials]

    nodes: list[dict] = []
    meshes, skins, animations, lod_nodes, rig_nodes = [], [], [], [], []
    for k, lod in enumerate(asset.lods):
        sk = lod.skeleton
        J = len(sk.names)
        mesh_node = len(nodes)
        rig_node = mesh_node + 1
        joint_nodes = rig_node + 1 + np.arange(J)
        lod_nodes.append(mesh_node)
        nodes.append({})  # filled below
        parent = np.asarray(sk.parent)
        roots = np.flatnonzero(parent < 0)
        rig_nodes.append(rig_node)
        nodes.append(
            {
                "name": f"{asset.name}_LOD{asset.extras.get('lod_index', k)}_rig",
                "children": [int(x) for x in joint_nodes[roots]],
            }
        )
        for j, fields in enumerate(joint_fields(sk, options.quantized)):
            n = {"name": sk.names[j], **fields}
            kids = np.flatnonzero(parent == j)
            if len(kids):
                n["children"] = [int(x) for x in joint_nodes[kids]]
            nodes.append(n)
        skin = {
            "name": f"{asset.name}_LOD{asset.extras.get('lod_index', k)}_skin",
            "joints": [int(x) for x in joint_nodes],
            "inverseBindMatrices": inverse_bind_accessor(
                buf, sk, quants[k].grid if quants[k] is not None else None
            ),
        }
        if len(roots) == 1:
            skin["skeleton"] = int(joint_nodes[roots[0]])
        skins.append(skin)
        missing = {p.material for p in lod.primitives} - set(mat_index)
        if missing:
            raise ValueError(f"primitives use materials {sorted(missing)} not in asset.materials")
        prims = [_primitive(buf, p, J, mat_index[p.material], quants[k]) for p in lod.primitives]
        name = f"{asset.name}_LOD{asset.extras.get('lod_index', k)}"
        meshes.append({"name": name, "primitives": prims})
        nodes[mesh_node] = {
            "name": name,
            "mesh": len(meshes) - 1,
            "skin": len(skins) - 1,
            "extras": lod_extras(asset, k),
        }
        for clip in lod.clips:
            kp = None
            if options.quantized and clip.keys is None and len(clip.times) > 2:
                kp = key_plan.plan(lod, clip, options.compress == "meshopt")  # within 1 mm
            anim = _animation(buf, clip, sk, joint_nodes, options.quantized, kp)
            if anim is not None:
                animations.append(anim)

    gltf: dict = {
        "asset": {"version": "2.0", "generator": f"treegen {__version__}"},
        "scene": 0,
        # the skinned mesh and each skeleton's rig node are scene roots, side by side (see the
        # module docstring); a lower LOD's mesh is reached only through MSFT_lod, its skeleton
        # is in the scene so its clip always finds its joints
        "scenes": [{"name": asset.name, "nodes": [lod_nodes[0], *rig_nodes]}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": skins,
        "materials": materials,
    }
    k = impostor_lod(asset)
    extras = dict(asset.extras)
    if k is not None:
        imp = asset.lods[k].impostor
        extras["treegen_impostor"] = describe(
            asset,
            k,
            Z_UP_TO_Y_UP,
            {"albedo": textures.image(imp.albedo), "normal_depth": textures.image(imp.normal_depth)},
        )
    textures.fields(gltf)
    if extras:
        gltf["asset"]["extras"] = extras
    if animations:
        gltf["animations"] = animations
    if len(asset.lods) > 1:
        set_msft_lod(nodes[lod_nodes[0]], lod_nodes[1:], asset.lods)
        gltf["extensionsUsed"] = ["MSFT_lod"]
    return gltf, finish(gltf, buf, options.quantized, uv_boxes.values())


def finish(gltf: dict, buf: _Buffer, quantized: bool, uv_boxes) -> _Buffer:
    """Accessors, views and buffers into `gltf`; with --compress, the extensions it uses
    (KHR_texture_transform when a material's UV box is not the identity) and the meshopt
    encoding. Returns the buffer to write (tree and forest writers alike)."""
    if buf.pooled:
        buf.flush_pools()
    gltf["accessors"] = buf.accessors
    gltf["bufferViews"] = buf.views
    gltf["buffers"] = [{"byteLength": buf.size + len(buf.padding())}]
    if quantized:
        used = [QUANTIZATION]
        if any(not box.identity for box in uv_boxes):
            used.append(TEXTURE_TRANSFORM)
        if buf.meshopt is not None:
            used.append(MESHOPT)
            buf = _meshopt(gltf, buf)
        gltf["extensionsUsed"] = sorted(gltf.get("extensionsUsed", []) + used)
        gltf["extensionsRequired"] = sorted(used)
    return buf


def _meshopt(gltf: dict, buf: _Buffer) -> _Buffer:
    """EXT_meshopt_compression: every view with an encoding (buf.meshopt) is encoded by
    meshoptimizer into buffer 0; its uncompressed layout moves to buffer 1, a fallback buffer
    with no data (the extension is required, so no client reads it). Images stay as they are.
    A pooled view goes to the encoder as one job per member (a primitive's index and vertex
    members are reordered together), joined into one stream before encoding."""
    assert buf.meshopt is not None
    order = sorted(buf.meshopt)
    jobs: list[tuple[MeshoptView, memoryview]] = []
    joins: list[int] = []
    job_of: dict[int, int] = {}  # accessor → job
    for k, v in enumerate(order):
        spec = buf.meshopt[v]
        for acc, a, source in buf.members.get(v, [(None, None, None)]):
            if acc is None:  # a view of its own
                jobs.append((spec, buf.view_parts[v]))
            else:
                job_of[acc] = len(jobs)
                part = MeshoptView(spec.mode, spec.stride, len(a), spec.filter, source, buf.bits.get(acc))
                jobs.append((part, memoryview(a.reshape(-1).view(np.uint8))))
            joins.append(k)
    groups = [(job_of[i], [job_of[v] for v in vs]) for i, vs in buf.groups]
    encoded = dict(zip(order, encode(jobs, groups, joins)))
    out = _Buffer()
    for i, view in enumerate(buf.views):
        if i not in encoded:
            view["byteOffset"] = out.size + (-out.size % 4)
            out.view(buf.view_parts[i], None)
            continue
        spec = buf.meshopt[i]
        data = encoded[i]
        offset = out.size + (-out.size % 4)
        out.view(np.frombuffer(data, dtype=np.uint8), None)
        view["buffer"] = 1
        view["extensions"] = {
            MESHOPT: {
                "buffer": 0,
                "byteOffset": offset,
                "byteLength": len(data),
                "byteStride": spec.stride,
                "count": spec.count,
                "mode": spec.mode,
                **({"filter": spec.filter} if spec.filter != "NONE" else {}),
            }
        }
    out.views, out.accessors = buf.views, buf.accessors
    fallback = {"byteLength": buf.size + len(buf.padding()), "extensions": {MESHOPT: {"fallback": True}}}
    gltf["buffers"] = [{"byteLength": out.size + len(out.padding())}, fallback]
    return out


def lod_extras(asset: Asset, k: int) -> dict:
    """What an engine needs to switch LODs itself (Godot 4 visibility ranges, Unity LODGroup):
    this LOD's index, the distance from which it is used and the screen coverage below which
    the next one takes over."""
    lod = asset.lods[k]
    return {
        "treegen_lod": {
            "index": int(asset.extras.get("lod_index", k)),
            "count": int(asset.extras.get("lod_count", len(asset.lods))),
            "distance_m": float(lod.distance),
            "screen_coverage": float(lod.screen_coverage),
        }
    }


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o).__name__} into glTF JSON")


def dumps(gltf: dict) -> bytes:
    return json.dumps(
        gltf, sort_keys=True, separators=(",", ":"), allow_nan=False, default=_json_default
    ).encode("utf-8")


def _glb_head(gltf: dict, blob_len: int) -> bytes:
    """Everything of a GLB before the binary payload: 12-byte header, JSON chunk
    (space-padded), and the BIN chunk header when there is a payload."""
    js = dumps(gltf)
    js += b" " * (-len(js) % 4)
    bin_head = struct.pack("<I4s", blob_len, b"BIN\0") if blob_len else b""
    total = 12 + 8 + len(js) + len(bin_head) + blob_len
    return b"".join(
        [struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(js), b"JSON"), js, bin_head]
    )


def glb_bytes(gltf: dict, blob: bytes) -> bytes:
    """GLB container: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    return _glb_head(gltf, len(blob)) + blob


def write_gltf(
    asset: Asset, path: str | os.PathLike, binary: bool | None = None, options: GltfOptions = GLTF_DEFAULTS
) -> None:
    """Write straight to `path` (and `<stem>.bin` beside a .gltf); not atomic on its own —
    `exchange.export` stages it."""
    path = Path(path)
    if binary is None:
        binary = path.suffix.lower() != ".gltf"
    gltf, buf = _build(asset, options)
    write_document(gltf, buf, path, binary)
    meta = gltf["asset"].get("extras", {}).get("treegen_impostor")
    if meta is not None:  # for engines' impostor shaders: images are in the file
        write_sidecar(meta | {"file": path.name}, path)


def write_document(gltf: dict, buf: _Buffer, path: Path, binary: bool) -> None:
    """A built glTF: .glb streamed (the buffer is never joined), or JSON + `<stem>.bin`."""
    blob_len = gltf["buffers"][0]["byteLength"]
    if binary:
        with open(path, "wb") as f:  # streamed: the buffer is never joined
            f.write(_glb_head(gltf, blob_len))
            if blob_len:
                buf.write_to(f)
        return
    bin_path = path.with_suffix(".bin")
    gltf["buffers"][0]["uri"] = bin_path.name
    with open(bin_path, "wb") as f:
        buf.write_to(f)
    path.write_bytes(dumps(gltf))


# ---- reading back (tests, `treegen preview`, cross-format checks) ----

_DTYPE = {
    FLOAT: np.float32,
    UNSIGNED_BYTE: np.uint8,
    UNSIGNED_SHORT: np.uint16,
    UNSIGNED_INT: np.uint32,
    BYTE: np.int8,
    SHORT: np.int16,
}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_gltf(path: str | os.PathLike) -> tuple[dict, bytes]:
    """(JSON dict, buffer 0 bytes) of a .glb, or of a .gltf with its external .bin."""
    path = Path(path)
    data = path.read_bytes()
    if data[:4] == b"glTF":
        _, _, total = struct.unpack_from("<4sII", data, 0)
        jlen, _ = struct.unpack_from("<I4s", data, 12)
        gltf = json.loads(data[20 : 20 + jlen])
        blob = b""
        if 20 + jlen < total:
            blen, _ = struct.unpack_from("<I4s", data, 20 + jlen)
            blob = data[28 + jlen : 28 + jlen + blen]
        return gltf, blob
    gltf = json.loads(data)
    uri = gltf["buffers"][0].get("uri") if gltf.get("buffers") else None
    return gltf, (path.parent / uri).read_bytes() if uri else b""


def read_accessor(gltf: dict, blob: bytes, index: int) -> np.ndarray:
    """An accessor as a numpy array (count, components), or (count,) for scalars, (count, 4, 4)
    row-major for MAT4. Tightly packed views only (what this writer produces). Normalized
    integer accessors (WEIGHTS_0) come back dequantized as float64 c / type max, per the spec."""
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    n = _NCOMP[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    a = np.frombuffer(
        blob,
        dtype=np.dtype(_DTYPE[acc["componentType"]]).newbyteorder("<"),
        count=acc["count"] * n,
        offset=start,
    )
    if acc.get("normalized"):
        a = a / float(np.iinfo(a.dtype).max)
    if acc["type"] == "MAT4":
        return a.reshape(-1, 4, 4).transpose(0, 2, 1)
    return a if n == 1 else a.reshape(-1, n)
