"""glTF buffer packing: bufferViews and accessors in one binary buffer, and their entry in the
JSON (`finish`), shared by the tree and forest writers.

Every array goes to the buffer as a byte view of a numpy array (no per-vertex Python, no
tobytes/join copies: a GLB is streamed to disk part by part, `Buffer.write_to`). With
--compress, skin and key data are pooled into a few views and, under meshopt, every view with
an encoding is handed to meshoptimizer (compress.py).
"""

from __future__ import annotations

import math

import numpy as np

from .compress import MESHOPT, QUANTIZATION, TEXTURE_TRANSFORM, MeshoptView, encode

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


class Buffer:
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


def finish(gltf: dict, buf: Buffer, quantized: bool, uv_boxes) -> Buffer:
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


def _meshopt(gltf: dict, buf: Buffer) -> Buffer:
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
    out = Buffer()
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
