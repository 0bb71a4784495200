"""What a glTF file's clip plays for one skeleton's joints, read back from the file's bytes.

    played_rotations("tree_gp.glb", lod.skeleton.names, "wind_loop", clip.times)  # (K, J, 4)
    played_error(lod, "tree_gp.glb")  # metres, LOD0's clip against the float one

For measuring a written clip against the float one it came from with key_plan.error: our
compressed files (the test that the stored keys, not only the plan, stay within the bound)
and other tools' output of the same tree (bench/size_bench.py: gltfpack's, which drops and
collapses tracks it finds nearly still). The skin is found by its joints' node names, so a
tool that reorders nodes or meshes is still read right; a joint without a rotation channel
plays its node's rotation. Rotations come back in the generator's axes (Z up).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .. import key_plan
from ..asset import KeyPlan, Lod
from ..axes import quat_from_y_up
from ..clip import sample_track
from ..errors import TreegenError
from ..quat import unit
from .compress import MESHOPT
from .gltf_container import read_gltf
from .read_gltf import gltf_channels, read_strided, unpack_meshopt


def played_rotations(
    path: str | os.PathLike, names: Sequence[str], clip: str, times: np.ndarray, simd: bool = True
) -> np.ndarray:
    """(K, J, 4) xyzw, Z up: the local rotation each joint `names[j]` of the skin with exactly
    these joints plays at `times` (K,) in the file's animation named `clip`, EXT_meshopt
    views decoded by meshoptimizer's SIMD build or (`simd` False) its scalar one."""
    gltf, blob = read_gltf(path)
    if MESHOPT in gltf.get("extensionsUsed", []):
        gltf, blob = unpack_meshopt(gltf, blob, path, simd)
    nodes = gltf.get("nodes", [])
    skin = next(
        (s for s in gltf.get("skins", []) if [nodes[j].get("name") for j in s["joints"]] == list(names)),
        None,
    )
    if skin is None or not any(a.get("name") == clip for a in gltf.get("animations", [])):
        raise TreegenError(f"{path}: no skin with these {len(names)} joints, or no animation '{clip}'")
    slot = {node: j for j, node in enumerate(skin["joints"])}
    times = np.asarray(times, dtype=np.float64)
    rest = np.array([nodes[n].get("rotation", [0.0, 0.0, 0.0, 1.0]) for n in skin["joints"]], float)
    rot = np.broadcast_to(rest, (len(times),) + rest.shape).copy()
    for ch in gltf_channels(gltf, blob, read_strided, slot, clip):  # one per animated joint
        if ch.path == "rotation":
            rot[:, ch.joints] = sample_track(ch.times.ravel(), ch.values, times, ch.interpolation)
    return unit(quat_from_y_up(rot))


def played_error(lod: Lod, path: str | os.PathLike) -> float:
    """Metres: how far `lod`'s skinned vertices (hull corners) stray from its first (dense,
    float) clip on any frame when played from `path`'s bytes, by key_plan.error's measure;
    an EXT_meshopt file by the worse of meshoptimizer's two decoders (SIMD, scalar)."""
    dense = lod.clips[0]
    K, J = len(dense.times), len(lod.skeleton.names)
    meshopt = MESHOPT in read_gltf(path)[0].get("extensionsUsed", [])
    worst = 0.0
    for simd in (True, False) if meshopt else (True,):
        rot = played_rotations(path, lod.skeleton.names, dense.name, dense.times, simd)
        kp = KeyPlan(replace(dense, rotations=rot, keys=[np.arange(K)] * J), np.ones(J, bool))
        worst = max(worst, key_plan.error(lod, dense, kp))
    return worst
