"""glTF mesh primitives: a Primitive's vertex attributes and indices as accessors.

Vertex data stays float32 end to end (the Y-up swap is an exact shuffle, `y_up32`). WEIGHTS_0
is normalized UNSIGNED_BYTE for rigid primitives (leaves: exact) and normalized UNSIGNED_SHORT
for blended ones (bark), each row summing exactly to 255 / 65535 — a quarter / half of
float32's bytes; JOINTS_0 is UNSIGNED_BYTE up to 256 joints. NORMAL and float TEXCOORD_0 are
always written: Godot reads neither normalized integer UVs nor computes missing normals. With
--compress, KHR_mesh_quantization's integer attributes instead (`Quantization`).
"""

from __future__ import annotations

import numpy as np

from ..asset import Asset, Primitive
from ..axes import to_y_up
from .compress import Grid, UvRange, position_grid, quantize_positions, quantize_uvs, snorm8, uv_range
from .gltf_buffer import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, Buffer


def unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


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


def y_up32(v: np.ndarray) -> np.ndarray:
    """float32 (V, 3) → new float32 (V, 3) in Y up: an exact shuffle, no float64 detour.
    Contiguous first: numpy 2.4's strided `negative(..., out=)` reads the wrong elements."""
    v = np.ascontiguousarray(v, dtype=np.float32)
    out = np.empty(v.shape, dtype=np.float32)
    out[:, 0] = v[:, 0]
    out[:, 1] = v[:, 2]
    np.negative(v[:, 1], out=out[:, 2])
    return out


def gltf_uvs(p: Primitive) -> np.ndarray:
    """Asset UVs have their origin bottom-left (OpenGL/USD); glTF's is top-left."""
    uv = np.array(p.uvs, dtype=np.float32)
    np.subtract(np.float32(1.0), uv[:, 1], out=uv[:, 1])
    return uv


class Quantization:
    """--compress quantize/meshopt state of one LOD: its skin's position grid and each
    material's UV box (shared by every LOD, as the material is)."""

    def __init__(self, grid: Grid, uvs: dict[str, UvRange]):
        self.grid, self.uvs = grid, uvs


def primitive_dict(
    buf: Buffer, p: Primitive, n_joints: int, material: int, quant: Quantization | None = None
) -> dict:
    if quant is not None:
        return _quantized_primitive(buf, p, n_joints, material, quant)
    pos = y_up32(p.positions)
    # Always float UVs here: Godot 3.2 ignores `normalized` on integer UVs, and every client
    # reads float32.
    uv = gltf_uvs(p)
    joints, weights = _weights(p.joints, p.weights)
    joints = joints.astype(np.uint8 if n_joints <= 256 else np.uint16, copy=False)
    V = len(p.positions)
    indices = np.asarray(p.indices).astype(np.uint16 if V < 65535 else np.uint32, copy=False)
    # NORMAL always: Godot does not compute missing normals and Babylon/three.js regenerate
    # them with a warning or flat shading
    nrm = y_up32(p.normals)
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
    buf: Buffer, p: Primitive, n_joints: int, material: int, quant: Quantization
) -> dict:
    """KHR_mesh_quantization (compress.py): grid positions, int8 normals and tangents,
    uint16 UVs in the material's box; joints, weights and indices as in `primitive_dict`."""
    pos = quantize_positions(y_up32(p.positions), quant.grid)
    nrm = unit(y_up32(p.normals).astype(np.float64))
    uv = quantize_uvs(gltf_uvs(p), quant.uvs[p.material])
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
        tan = np.column_stack([unit(to_y_up(t[:, :3])), np.sign(t[:, 3]) + (t[:, 3] == 0)])
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
            by_material.setdefault(p.material, []).append(gltf_uvs(p))
    grid = position_grid([y_up32(p.positions) for p in asset.lods[lod_index].primitives], min_step)
    return Quantization(grid, {m: uv_range(u) for m, u in by_material.items()})


def _tangent(buf: Buffer, p: Primitive) -> dict:
    """TANGENT (xyz + handedness w) where the primitive has them (normal-mapped bark), so no
    client generates its own tangent space (the validator warns about that)."""
    if p.tangents is None:
        return {}
    t = np.asarray(p.tangents, dtype=np.float32)
    xyz = y_up32(t[:, :3])  # a rotation: handedness w is unchanged
    return {"TANGENT": buf.accessor(np.column_stack([xyz, t[:, 3]]).astype(np.float32), ARRAY_BUFFER)}
