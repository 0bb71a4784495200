"""The glTF document on disk, both ways: a .glb (12-byte header, JSON chunk, BIN chunk, the
buffer streamed, never joined) or a .gltf with its sibling .bin, and reading either back as
(JSON, buffer) with accessors as numpy arrays (exchange/read_gltf.py, the tests). The JSON is
dumped with sorted keys, so the same document always gives the same bytes."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from urllib.parse import quote, unquote

import numpy as np

from ..errors import TreegenError
from .gltf_buffer import BYTE, FLOAT, SHORT, UNSIGNED_BYTE, UNSIGNED_INT, UNSIGNED_SHORT, Buffer


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


# RFC 3986 sub-delimiters and '@' stay as they are in a relative path: Godot 3.2 reads URIs
# without decoding them, so "r(1).bin" as r%281%29.bin was a file it could not find
URI_SAFE = "/!$&'()*+,;=@"


def file_uri(name: str) -> str:
    """A sibling file's relative URI: "my tree#1.bin" → my%20tree%231.bin, "r(1).bin" as is."""
    return quote(name, safe=URI_SAFE)


def write_document(
    gltf: dict, buf: Buffer, path: Path, binary: bool, files: dict[str, bytes] | None = None
) -> None:
    """A built glTF: .glb streamed (the buffer is never joined), or JSON + `<stem>.bin` and
    `files` (name relative to `path` → bytes: the PNGs its images name)."""
    blob_len = gltf["buffers"][0]["byteLength"]
    if binary:
        with open(path, "wb") as f:  # streamed: the buffer is never joined
            f.write(_glb_head(gltf, blob_len))
            if blob_len:
                buf.write_to(f)
        return
    bin_path = path.with_suffix(".bin")
    gltf["buffers"][0]["uri"] = file_uri(bin_path.name)
    with open(bin_path, "wb") as f:
        buf.write_to(f)
    for name, data in sorted((files or {}).items()):
        (path.parent / name).write_bytes(data)
    path.write_bytes(dumps(gltf))


# reading back (exchange/read_gltf.py, the tests)
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
        if total > len(data):
            raise TreegenError(
                f"{path}: not a whole GLB file (its header says {total:,} bytes, the file has "
                f"{len(data):,}: cut short in a copy or download?)"
            )
        jlen, _ = struct.unpack_from("<I4s", data, 12)
        gltf = json.loads(data[20 : 20 + jlen])
        blob = b""
        if 20 + jlen < total:
            blen, _ = struct.unpack_from("<I4s", data, 20 + jlen)
            blob = data[28 + jlen : 28 + jlen + blen]
        return gltf, blob
    gltf = json.loads(data)
    uri = gltf["buffers"][0].get("uri") if gltf.get("buffers") else None
    return gltf, (path.parent / unquote(uri)).read_bytes() if uri else b""


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
