"""The impostor's sway: its cards ride one joint at the trunk base, turning as the trunk
does at the crown's height, so a tree switched to its impostor keeps swaying as a whole.

    skeleton, clip = trunk_sway(coarse_lod, crown_height)
    # Result: a one-joint Skeleton (the root's name and bind) and its Clip (None: no wind)
"""

from __future__ import annotations

import numpy as np

from .asset import Clip, Lod, Skeleton
from .quat import mul as quat_mul, unit as unit_quat


def trunk_sway(lod: Lod, height: float) -> tuple[Skeleton, Clip | None]:
    """One joint at the trunk base (LOD `lod`'s root) whose rotation is the world rotation,
    relative to rest, of the highest trunk joint at or below `height` (the crown's centre)."""
    sk = lod.skeleton
    chain = [0]  # the trunk: trunk_* joints from the root
    names, parent = sk.names, np.asarray(sk.parent)
    while True:
        kids = [j for j in np.flatnonzero(parent == chain[-1]) if names[j].startswith("trunk")]
        if not kids:
            break
        chain.append(int(kids[0]))
    z = np.asarray(sk.bind_world)[chain, 2, 3]
    top = chain[int(np.flatnonzero(z <= height)[-1])] if (z <= height).any() else 0
    path = chain[: chain.index(top) + 1]
    one = Skeleton(
        names=[names[0]],
        parent=np.array([-1], np.int32),
        rest_translation=np.asarray(sk.rest_translation)[:1].copy(),
        rest_rotation=np.asarray(sk.rest_rotation)[:1].copy(),
        bind_world=np.asarray(sk.bind_world)[:1].copy(),
    )
    if not lod.clips:
        return one, None
    clip = lod.clips[0]
    rot = np.asarray(clip.rotations, np.float64)
    world, rest = rot[:, path[0]], np.asarray(sk.rest_rotation, np.float64)[path[0]]
    for j in path[1:]:  # world rotation = product down the chain
        world = quat_mul(world, rot[:, j])
        rest = quat_mul(rest, np.asarray(sk.rest_rotation, np.float64)[j])
    inv_rest = rest * np.array([-1, -1, -1, 1.0])
    delta = quat_mul(world, inv_rest[None])  # world swing relative to rest
    local = unit_quat(quat_mul(delta, np.asarray(sk.rest_rotation, np.float64)[0][None]))
    return one, Clip(
        name=clip.name,
        times=np.asarray(clip.times),
        rotations=local[:, None, :],
        interpolation=clip.interpolation,
    )
