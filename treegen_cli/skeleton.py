"""Kinematics of a joint hierarchy: depth levels, local TRS matrices, forward kinematics.

One home for the rules wind, LOD, the forest, the preview and the writers' preparation all
need. Everything is batched one depth level at a time, so the cost is a few numpy operations
per level of the hierarchy, never per joint or per key.
"""

from __future__ import annotations

import numpy as np

from .asset import Skeleton
from .quat import to_matrix


def joint_depth(parent: np.ndarray) -> np.ndarray:
    """Depth of each joint (root 0), by repeated parent look-ups (one pass per level)."""
    parent = np.asarray(parent, dtype=np.int64)
    depth = np.zeros(parent.shape[0], dtype=np.int64)
    has_parent = parent >= 0
    safe = np.where(has_parent, parent, 0)
    for _ in range(parent.shape[0] + 1):
        new = np.where(has_parent, depth[safe] + 1, 0)
        if np.array_equal(new, depth):
            return depth
        depth = new
    raise ValueError("joint parents contain a cycle")


def depth_levels(parent: np.ndarray) -> list[np.ndarray]:
    """Joint indices grouped by depth, root level first (empty list for no joints)."""
    if len(parent) == 0:
        return []
    depth = joint_depth(parent)
    order = np.argsort(depth, kind="stable")
    bounds = np.searchsorted(depth[order], np.arange(depth.max() + 2))
    return [order[bounds[d] : bounds[d + 1]] for d in range(depth.max() + 1)]


def trs(t: np.ndarray, q: np.ndarray, s: np.ndarray | None = None) -> np.ndarray:
    """Local matrices T·R·S (…, 4, 4), column vectors, from (…, 3), (…, 4) xyzw, (…, 3)."""
    q = np.asarray(q, dtype=np.float64)
    m = np.zeros(q.shape[:-1] + (4, 4))
    r = to_matrix(q) if q.size else np.zeros(q.shape[:-1] + (3, 3))
    m[..., :3, :3] = r if s is None else r * np.asarray(s, dtype=np.float64)[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def forward(parent: np.ndarray, local: np.ndarray, root_world: np.ndarray | None = None) -> np.ndarray:
    """World matrices (…, J, 4, 4) from local ones, parents before children; root joints sit
    under `root_world` (J, 4, 4) when given (the world of a non-joint parent node)."""
    parent = np.asarray(parent)
    world = np.empty_like(local)
    for idx in depth_levels(parent):
        roots, kids = idx[parent[idx] < 0], idx[parent[idx] >= 0]
        world[..., roots, :, :] = (
            local[..., roots, :, :] if root_world is None else root_world[roots] @ local[..., roots, :, :]
        )
        if kids.size:
            world[..., kids, :, :] = world[..., parent[kids], :, :] @ local[..., kids, :, :]
    return world


def pose_world(skeleton: Skeleton, rotations: np.ndarray) -> np.ndarray:
    """World matrices (K, J, 4, 4) of every joint in every frame of `rotations` (K, J, 4)
    xyzw; translations stay at rest."""
    rotations = np.asarray(rotations, dtype=np.float64)
    local = trs(np.broadcast_to(skeleton.rest_translation, rotations.shape[:-1] + (3,)), rotations)
    return forward(skeleton.parent, local)
