"""Asset → .obj / .ply: the rest pose of one LOD, no skin or animation, via trimesh (the format
from the suffix). Converted to Y up like glTF, since OBJ consumers mostly assume Y up."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..asset import Asset
from ..axes import to_y_up


def write_static(asset: Asset, path: Path, lod: int = 0) -> None:
    """Rest-pose geometry of LOD `lod`, bark and leaves in one mesh."""
    import trimesh   # lazy: trimesh is slow to import and only static formats need it

    prims = asset.lods[lod].primitives
    counts = np.array([len(p.positions) for p in prims])
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vertices = to_y_up(np.concatenate([np.asarray(p.positions, np.float64) for p in prims]))
    normals = to_y_up(np.concatenate([np.asarray(p.normals, np.float64) for p in prims]))
    faces = np.concatenate([np.asarray(p.indices, np.int64).reshape(-1, 3) + o
                            for p, o in zip(prims, offsets)])
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_normals=normals, process=False)
    mesh.export(path)
