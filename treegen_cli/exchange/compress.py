"""glTF compression (`--compress`): integer vertex data and meshoptimizer's codec.

    none      float32 positions, normals, tangents, UVs and rotations: every importer reads it.
    quantize  KHR_mesh_quantization: positions as unsigned 16-bit integers on one uniform grid
              per skin, normals and tangents as normalized int8, UVs as normalized uint16 (ranges
              beyond [0, 1], bark's, through KHR_texture_transform), rotation keys as normalized
              int16 (core glTF). A skinned mesh ignores its node's transform, so the grid's
              dequantization (offset + uniform scale: normals stay normals) is folded into the
              skin's inverse bind matrices, as gltfpack does. A dense clip's keys (LOD0's)
              follow key_plan.py: aimed through their parents, float32 for long levers,
              fewer keys, within 1 mm; lower LODs leave out tracks held near their rest.
              Joint nodes' TRS as float32 text, arithmetic noise (1e-17 m) as 0.
    meshopt   quantize, then EXT_meshopt_compression on every vertex, index, skin and animation
              view with the extension's filters (OCTAHEDRAL for normals and tangents, QUATERNION
              for rotations, EXPONENTIAL for float32 rotations); a fallback buffer without
              data. Encoded by meshoptimizer's own
              encoder (npm `meshoptimizer`, pinned in tools/) in one `node
              tools/meshopt_encode.mjs` call per file: the PyPI `meshoptimizer` package is an
              unofficial 0.x binding; the npm package is the library author's own build.

Grid error: half a step, extent / 131070 (0.23 mm for a 30 m tree). UV error: half a step of
the material's UV range over 65535 (≤ 0.001 for bark's ±64).
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from dataclasses import dataclass

import numpy as np

from ..asset import EXP_BITS
from ..errors import TreegenError

COMPRESS = ("none", "quantize", "meshopt")
QUANTIZATION = "KHR_mesh_quantization"
MESHOPT = "EXT_meshopt_compression"
TEXTURE_TRANSFORM = "KHR_texture_transform"
ENCODER = "meshopt_encode.mjs"
DECODER = "meshopt_decode.mjs"  # reading EXT_meshopt_compression back (preview)


@dataclass(frozen=True)
class GltfOptions:
    """How the glTF writer encodes vertex and key data; `none` is plain float32."""

    compress: str = "none"  # one of COMPRESS
    # meshopt: metres one pixel spans per metre of distance (lod.pixel_size(1)); a LOD shown
    # from distance d gets a position grid of step ≤ d · pixel_size / 2 (error ≤ ¼ pixel, on
    # top of the LOD's own error_px), never finer than MESHOPT_POSITION_STEP. 0: that step.
    pixel_size: float = 0.0

    @property
    def quantized(self) -> bool:
        return self.compress != "none"


GLTF_DEFAULTS = GltfOptions()

# bits of the meshopt filters: int8 octahedral normals/tangents as in quantize; 16-bit
# quaternions keep the rotation keys as exact as quantize's normalized int16
OCT_BITS, QUAT_BITS = 8, 16
# EXP_BITS (asset.py): mantissa bits of the EXPONENTIAL filter on float32 rotation keys
# (key_plan's `wide` joints, whose 16-bit keys would move a long lever by more than the bound)
FILTER_BITS = {"OCTAHEDRAL": OCT_BITS, "QUATERNION": QUAT_BITS, "EXPONENTIAL": EXP_BITS}
# metres: LOD0's grid (and any LOD's seen from nearer than 2 mm / pixel size); a step of 1.15 mm
# rounds each coordinate by ≤ 0.575 mm, a position by ≤ √3 · 0.575 = 0.996 mm
MESHOPT_POSITION_STEP = 0.00115


def meshopt_step(options: GltfOptions, distance: float) -> float:
    """Position grid step for a LOD first shown at `distance` metres (see GltfOptions)."""
    return max(MESHOPT_POSITION_STEP, 0.5 * distance * options.pixel_size)


@dataclass(frozen=True)
class Grid:
    """One skin's position grid: position = offset + step · q, q in [0, 65535]."""

    offset: np.ndarray  # (3,) float64, Y up
    step: float

    def dequantize(self) -> np.ndarray:
        """The 4×4 matrix taking grid coordinates to mesh coordinates."""
        m = np.eye(4)
        m[:3, :3] *= self.step
        m[:3, 3] = self.offset
        return m


def position_grid(positions: list[np.ndarray], min_step: float = 0.0) -> Grid:
    """The finest uniform 16-bit grid holding every position of one skin's primitives, no
    finer than `min_step` metres (meshopt: 1 mm, error ≤ 0.5 mm; fewer significant bits
    compress better, while quantize's file is the same size at any step)."""
    lo = np.min([p.min(axis=0) for p in positions if len(p)], axis=0).astype(np.float64)
    hi = np.max([p.max(axis=0) for p in positions if len(p)], axis=0).astype(np.float64)
    extent = float((hi - lo).max())
    return Grid(offset=lo, step=max(extent / 65535.0, min_step) if extent > 0 else 1.0)


def quantize_positions(pos: np.ndarray, grid: Grid) -> np.ndarray:
    """(V, 3) → (V, 4) uint16 grid coordinates, the 4th a zero pad (vertex elements are 4-byte
    aligned)."""
    out = np.zeros((len(pos), 4), dtype=np.uint16)
    q = np.rint((pos.astype(np.float64) - grid.offset) / grid.step)
    out[:, :3] = np.clip(q, 0, 65535)
    return out


def snorm8(v: np.ndarray, pad: bool) -> np.ndarray:
    """Unit vectors → normalized int8 (c / 127), padded to 4 components when `pad`."""
    q = np.rint(np.clip(v, -1.0, 1.0) * 127.0).astype(np.int8)
    if pad:
        q = np.column_stack([q, np.zeros(len(q), np.int8)])
    return q


def snorm16(v: np.ndarray) -> np.ndarray:
    """Values in [-1, 1] → normalized int16 (c / 32767)."""
    return np.rint(np.clip(v, -1.0, 1.0) * 32767.0).astype(np.int16)


@dataclass(frozen=True)
class UvRange:
    """A material's UV box: stored u' = (u − offset) / scale in [0, 1]; identity when the UVs
    already fit [0, 1] (leaves in their atlas)."""

    offset: tuple[float, float]
    scale: tuple[float, float]

    @property
    def identity(self) -> bool:
        return self.offset == (0.0, 0.0) and self.scale == (1.0, 1.0)

    def transform(self) -> dict:
        """KHR_texture_transform for the material's texture references (uv = offset + scale·u')."""
        return {TEXTURE_TRANSFORM: {"offset": list(self.offset), "scale": list(self.scale)}}


def uv_range(uvs: list[np.ndarray]) -> UvRange:
    """The UV box of one material's primitives (glTF orientation), or identity within [0, 1]."""
    uvs = [u for u in uvs if len(u)]
    if not uvs:
        return UvRange((0.0, 0.0), (1.0, 1.0))
    lo = np.min([u.min(axis=0) for u in uvs], axis=0).astype(np.float64)
    hi = np.max([u.max(axis=0) for u in uvs], axis=0).astype(np.float64)
    if lo.min() >= 0.0 and hi.max() <= 1.0:
        return UvRange((0.0, 0.0), (1.0, 1.0))
    span = np.where(hi > lo, hi - lo, 1.0)
    return UvRange((float(lo[0]), float(lo[1])), (float(span[0]), float(span[1])))


def quantize_uvs(uv: np.ndarray, box: UvRange) -> np.ndarray:
    """(V, 2) UVs → normalized uint16 within the material's box."""
    u = (uv.astype(np.float64) - np.asarray(box.offset)) / np.asarray(box.scale)
    return np.rint(np.clip(u, 0.0, 1.0) * 65535.0).astype(np.uint16)


# ---- EXT_meshopt_compression ----


@dataclass(frozen=True)
class MeshoptView:
    """How one bufferView is encoded: mode ATTRIBUTES/TRIANGLES/INDICES, element stride, and
    for a filtered view the float32 (count, 4) source the filter encodes."""

    mode: str
    stride: int
    count: int
    filter: str = "NONE"
    source: np.ndarray | None = None
    bits: int | None = None  # the filter's bits (None: FILTER_BITS)


def _node(who: str = "--compress meshopt", what: str = "encoder") -> str:
    given = os.environ.get("TREEGEN_NODE")
    node = shutil.which(given) if given else shutil.which("node")
    if not node:
        where = (
            f"TREEGEN_NODE={given} is not an executable"
            if given
            else "`node` is not on PATH; set TREEGEN_NODE to its path"
        )
        raise TreegenError(f"{who} needs Node.js ({where}) to run meshoptimizer's {what}")
    return node


def check_encoder() -> None:
    """Refuse --compress meshopt up front when node or the npm package is missing."""
    _node()
    _tools()


def _tools(who: str = "--compress meshopt", script: str = ENCODER) -> str:
    from .validate import ValidatorUnavailable, tools_dir

    try:
        tools = tools_dir()
    except ValidatorUnavailable:
        tools = None
    if (
        tools is None
        or not (tools / "node_modules" / "meshoptimizer").is_dir()
        or not (tools / script).is_file()
    ):
        raise TreegenError(
            f"{who} needs the npm package meshoptimizer: run "
            "`make install` (npm ci in tools/) in a treegen checkout, or set "
            f"TREEGEN_TOOLS to a folder holding {script} and node_modules/"
        )
    return str(tools)


def decode(views: list[tuple[dict, bytes]], who: str, simd: bool = True) -> list[bytes]:
    """Decode EXT_meshopt_compression views with meshoptimizer's own decoder, in one node
    process (tools/meshopt_decode.mjs): each (the extension object, its encoded bytes) →
    byteStride × count bytes, filters undone into the stored integers (int8 normals, int16
    quaternions), as a client without the extension would have read the fallback. `who`
    names the reading file in messages; `simd`: False runs the decoder's scalar build (a
    client without WebAssembly SIMD), whose QUATERNION filter rounds differently."""
    jobs = [
        {
            "mode": ext["mode"],
            "filter": ext.get("filter", "NONE"),
            "stride": ext["byteStride"],
            "count": ext["count"],
            "bytes": len(data),
        }
        for ext, data in views
    ]
    head = json.dumps({"jobs": jobs, **({} if simd else {"simd": False})}).encode()
    tools = _tools(who, DECODER)
    proc = subprocess.run(
        [_node(who, "decoder"), os.path.join(tools, DECODER)],
        cwd=tools,
        capture_output=True,
        input=b"".join([struct.pack("<I", len(head)), head, *(data for _, data in views)]),
    )
    if proc.returncode != 0:
        raise TreegenError(
            f"{who}: meshoptimizer could not decode it: "
            f"{proc.stderr.decode(errors='replace').strip().splitlines()[-1:]}"
        )
    out, pos = [], 0
    for job in jobs:
        size = job["count"] * job["stride"]
        out.append(proc.stdout[pos : pos + size])
        pos += size
    return out


def encode(
    views: list[tuple[MeshoptView, memoryview]],
    groups: list[tuple[int, list[int]]] = (),  # type: ignore[assignment]
    joins: list[int] | None = None,
) -> list[bytes]:
    """Encode views with meshoptimizer in one node process: stdin is a little-endian uint32
    JSON length, the JSON {jobs, groups}, then each job's bytes (the data, or the float32
    filter source); stdout the same with the encoded streams. `groups` (index job, vertex
    jobs) are primitives the encoder first reorders with meshoptimizer's reorderMesh (vertex
    cache, then fetch order), as gltfpack does: the same triangles, in the order its codecs
    compress best. `joins[k]`: the stream job k belongs to (default: its own); consecutive
    jobs of one stream are filtered, joined and encoded as one view, one result per stream."""
    jobs, payloads = [], []
    for k, (spec, data) in enumerate(views):
        raw = memoryview(spec.source.astype("<f4", copy=False)).cast("B") if spec.source is not None else data
        jobs.append(
            {
                "mode": spec.mode,
                "filter": spec.filter,
                "stride": spec.stride,
                "count": spec.count,
                "bytes": raw.nbytes,
                "bits": spec.bits or FILTER_BITS.get(spec.filter, QUAT_BITS),
                "join": k if joins is None else joins[k],
            }
        )
        payloads.append(raw)
    head = json.dumps({"jobs": jobs, "groups": [{"indices": i, "vertices": v} for i, v in groups]}).encode()
    tools = _tools()
    proc = subprocess.run(
        [_node(), os.path.join(tools, ENCODER)],
        cwd=tools,
        capture_output=True,
        input=b"".join([struct.pack("<I", len(head)), head, *payloads]),
    )
    if proc.returncode != 0:
        raise RuntimeError(f"meshopt encoder failed: {proc.stderr.decode(errors='replace').strip()}")
    blob = proc.stdout
    (n,) = struct.unpack_from("<I", blob, 0)
    lengths = json.loads(blob[4 : 4 + n])
    pos, result = 4 + n, []
    for length in lengths:
        result.append(blob[pos : pos + length])
        pos += length
    return result
