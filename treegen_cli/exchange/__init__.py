"""Output formats: one table from file suffix to writer; `export` dispatches on the suffix.

A writer is `writer(asset, path, **opts)` that simply writes `path` (plus any sibling files,
like a .gltf's .bin). `export` makes it atomic: the writer writes into a hidden staging folder
inside the target folder, then every file it produced is moved into place with os.replace
(siblings first, the main file last), so an interrupted run never leaves a half-written asset.

To add a format, add one entry to WRITERS (import heavy modules lazily inside the function).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..asset import Asset
from ..errors import TreegenError


@contextmanager
def staged(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a path named like `path` inside a fresh staging folder next to it; on success move
    everything written there into place (main file last), on failure leave nothing behind."""
    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise TreegenError(f"{path}: is a folder; give an output file name such as tree.glb")
    try:
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder))
    except FileNotFoundError:
        raise TreegenError(f"{path}: output folder '{folder}' does not exist") from None
    except OSError as e:
        raise TreegenError(f"{path}: cannot write into folder '{folder}' ({e.strerror})") from None
    try:
        yield tmpdir / path.name
        produced = sorted(os.listdir(tmpdir), key=lambda n: (n == path.name, n))
        if path.name not in produced:
            raise RuntimeError(f"writer for {path.suffix} did not write {path.name}")
        for name in produced:
            os.replace(tmpdir / name, folder / name)
    except OSError as e:
        raise TreegenError(f"{path}: cannot write ({e.strerror or e})") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def _gltf(asset: Asset, path: Path, **opts) -> None:
    from .gltf import write_gltf_files
    write_gltf_files(asset, path, **opts)


def _usd(asset: Asset, path: Path, **opts) -> None:
    from .usd import write_usd   # lazy: pxr is slow to import and usd.py is optional
    write_usd(asset, path, **opts)


def write_static(asset: Asset, path: Path, lod: int = 0, **_opts) -> None:
    """Rest-pose geometry of one LOD, no skin or animation, via trimesh (format from the
    suffix). Converted to Y up like glTF, since OBJ consumers mostly assume Y up."""
    import trimesh

    from .gltf import to_y_up

    prims = asset.lods[lod].primitives
    counts = np.array([len(p.positions) for p in prims])
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vertices = to_y_up(np.concatenate([np.asarray(p.positions, np.float64) for p in prims]))
    normals = to_y_up(np.concatenate([np.asarray(p.normals, np.float64) for p in prims]))
    faces = np.concatenate([np.asarray(p.indices, np.int64).reshape(-1, 3) + o
                            for p, o in zip(prims, offsets)])
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_normals=normals, process=False)
    mesh.export(path)


WRITERS: dict[str, Callable[..., None]] = {
    ".glb": _gltf,
    ".gltf": _gltf,
    ".usda": _usd,
    ".usdc": _usd,
    ".usdz": _usd,
    ".obj": write_static,
    ".ply": write_static,
}


def supported_suffixes() -> list[str]:
    return sorted(WRITERS)


def export(asset: Asset, path: str | os.PathLike, **opts) -> list[Path]:
    """Write `asset` in the format named by `path`'s suffix, atomically. Returns the files
    written, main file first (a .gltf also writes its .bin)."""
    path = Path(path)
    suffix = path.suffix.lower()
    writer = WRITERS.get(suffix)
    if writer is None:
        raise TreegenError(f"{path}: unknown output extension '{suffix or '(none)'}'; "
                           f"supported: {', '.join(supported_suffixes())}")
    with staged(path) as tmp:
        writer(asset, tmp, **opts)
        files = written(tmp, path)
    return files


def written(tmp: Path, path: Path) -> list[Path]:
    """Where the files a writer put beside `tmp` (in its staging folder) land: `path`'s
    folder, main file first (a .gltf also writes its .bin)."""
    names = sorted(os.listdir(tmp.parent), key=lambda n: (n != path.name, n))
    return [path.parent / n for n in names]
