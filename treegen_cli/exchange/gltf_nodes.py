"""glTF nodes and skins: a skeleton's joints as nodes with their rest TRS, the skin's inverse
bind matrices, and the LOD nodes' MSFT_lod chain and extras (gltf.py lays the nodes out)."""

from __future__ import annotations

import numpy as np

from ..asset import Asset, Skeleton
from ..axes import matrix_to_y_up, quat_to_y_up, to_y_up
from .compress import Grid
from .gltf_buffer import Buffer
from .gltf_mesh import unit


def joint_fields(skeleton: Skeleton, short: bool = False) -> list[dict]:
    """Per joint, its glTF node's rest TRS fields (Y up; defaults left out). `short`
    (--compress): each number as the shortest text of its float32, which every client reads
    it as anyway (a third of the JSON of full float64 digits)."""
    t = to_y_up(np.asarray(skeleton.rest_translation, dtype=np.float64))
    q = unit(quat_to_y_up(skeleton.rest_rotation))
    num = float
    if short:
        t, q, num = _flush(t), _flush(q), _short
    out = []
    for j in range(len(skeleton.names)):  # one JSON node per joint
        n = {}
        if not is_default(t[j], [0, 0, 0]):
            n["translation"] = [num(x) for x in t[j]]
        if not is_default(q[j], [0, 0, 0, 1]):
            n["rotation"] = [num(x) for x in q[j]]
        out.append(n)
    return out


def _short(x) -> float | int:
    """The float64 whose shortest text is float32(x)'s: 0.1 for 0.10000000149011612; 0 as
    the integer 0 (no "-0.0")."""
    return float(str(np.float32(x))) if x != 0 else 0


def _flush(v: np.ndarray) -> np.ndarray:
    """Rows (N, n) with every component below half a float32 step of the row's largest one
    set to 0: arithmetic noise such as 4.9e-17 beside 2.48 m, which float32 cannot hold
    beside it anyway, and which costs ~14 bytes of JSON a number."""
    return np.where(np.abs(v) < np.abs(v).max(axis=1, keepdims=True) * 2.0**-25, 0.0, v)


def is_default(v: np.ndarray, default) -> bool:
    return bool(np.array_equal(v, default))


def inverse_bind_accessor(buf: Buffer, skeleton: Skeleton, grid: Grid | None = None) -> int:
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


def lod_extras(asset: Asset, k: int, scale: float = 1.0) -> dict:
    """What an engine needs to switch LODs itself (Godot 4 visibility ranges, Unity LODGroup):
    this LOD's index, the distance from which it is used and the screen coverage below which
    the next one takes over. `scale`: a forest tree's; a tree 1.2× as tall switches 1.2× as
    far, at the same size on screen (the screen coverage is a share of its own bounds)."""
    lod = asset.lods[k]
    return {
        "treegen_lod": {
            "index": int(asset.extras.get("lod_index", k)),
            "count": int(asset.extras.get("lod_count", len(asset.lods))),
            "distance_m": float(lod.distance) * float(scale),
            "screen_coverage": float(lod.screen_coverage),
        }
    }
