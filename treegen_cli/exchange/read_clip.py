"""What a glTF file's clip plays for one skeleton's joints, read back from the file's bytes.

    played_rotations("tree_gp.glb", lod.skeleton.names, "wind_loop", clip.times)  # (K, J, 4)

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

import numpy as np

from ..clip import sample_track
from ..errors import TreegenError
from ..quat import unit
from .compress import MESHOPT
from .gltf_container import read_accessor, read_gltf
from .read_gltf import _unpack_meshopt


def played_rotations(
    path: str | os.PathLike, names: Sequence[str], clip: str, times: np.ndarray
) -> np.ndarray:
    """(K, J, 4) xyzw, Z up: the local rotation each joint `names[j]` of the skin with exactly
    these joints plays at `times` (K,) in the file's animation named `clip`."""
    gltf, blob = read_gltf(path)
    if MESHOPT in gltf.get("extensionsUsed", []):
        gltf, blob = _unpack_meshopt(gltf, blob, path)
    nodes = gltf.get("nodes", [])
    skin = next(
        (s for s in gltf.get("skins", []) if [nodes[j].get("name") for j in s["joints"]] == list(names)),
        None,
    )
    anim = next((a for a in gltf.get("animations", []) if a.get("name") == clip), None)
    if skin is None or anim is None:
        raise TreegenError(f"{path}: no skin with these {len(names)} joints, or no animation '{clip}'")
    slot = {node: j for j, node in enumerate(skin["joints"])}
    times = np.asarray(times, dtype=np.float64)
    rest = np.array([nodes[n].get("rotation", [0.0, 0.0, 0.0, 1.0]) for n in skin["joints"]], float)
    rot = np.broadcast_to(rest, (len(times),) + rest.shape).copy()
    for ch in anim["channels"]:  # one per animated joint (hundreds)
        node = ch["target"].get("node")
        if ch["target"]["path"] != "rotation" or node not in slot:
            continue
        s = anim["samplers"][ch["sampler"]]
        key_times = read_accessor(gltf, blob, s["input"]).astype(np.float64).ravel()
        # normalized signed integers: c / max, at least −1 (glTF's rule)
        values = np.maximum(read_accessor(gltf, blob, s["output"]).astype(np.float64), -1.0)
        track = sample_track(key_times, values[:, None, :], times, s.get("interpolation", "LINEAR"))
        rot[:, slot[node]] = track[:, 0]
    # Y up → Z up: the inverse of axes.quat_to_y_up, (x, y, z) ← (x, −z, y) on the vector part
    return unit(np.stack([rot[..., 0], -rot[..., 2], rot[..., 1], rot[..., 3]], axis=-1))
