"""Probes: a few points per joint whose pose error bounds the error of every vertex the joint
moves, so the decimation checks a clip's playback on ~8 points per joint instead of every
vertex (`probes` says why a few suffice)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Primitive, Skeleton


@dataclass(frozen=True, eq=False)
class Probes:
    """Representative points: `local` (P, 3) in the bind frame of joint `joint` (P,); `rest`
    (P, 3) their rest positions; `reach` (J,) the farthest probe each joint's rotation moves."""

    joint: np.ndarray
    local: np.ndarray
    rest: np.ndarray
    reach: np.ndarray


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Indices of the convex hull's corners of `points` (n, 3); all points when they are too
    few or too flat for a 3-D hull."""
    from scipy.spatial import ConvexHull, QhullError

    n = points.shape[0]
    if n <= 8:
        return np.arange(n)
    try:
        return ConvexHull(points).vertices
    except (QhullError, ValueError):
        if n <= 4096:
            return np.arange(n)
        return ConvexHull(points, qhull_options="QJ").vertices  # flat: joggled corners


def _box_corners(x: np.ndarray, owner: np.ndarray, J: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the 8 corners of a box around its points, aligned with their principal axes
    (a tight box for a branch's elongated cloud). Returns (joint (P,), corner positions (P, 3)).
    All joints at once: segment sums and extremes over the points sorted by joint, one
    batched 3 × 3 eigensolve."""
    order = np.argsort(owner.astype(np.uint16), kind="stable")  # radix sort: joints < 65536
    count = np.bincount(owner, minlength=J)
    has = np.flatnonzero(count)  # joints with points, ascending
    start = np.cumsum(count[has]) - count[has]
    group = np.repeat(np.arange(has.size), count[has])  # (P,) each sorted point's joint slot
    xs = x[order].astype(np.float64)
    mean = np.add.reduceat(xs, start, axis=0) / count[has, None]
    d = xs - mean[group]
    cov = np.add.reduceat(d[:, :, None] * d[:, None, :], start, axis=0) + np.eye(3) * 1e-12
    _, axes = np.linalg.eigh(cov)  # (G, 3, 3), columns: principal axes
    u = np.einsum("pi,pik->pk", d, axes[group])
    signs = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
    ext = np.where(signs, np.maximum.reduceat(u, start)[:, None], np.minimum.reduceat(u, start)[:, None])
    corners = mean[:, None] + np.einsum("gck,gik->gci", ext, axes)  # (G, 8, 3)
    return np.repeat(has, 8), corners.reshape(-1, 3)


def probes(skeleton: Skeleton, primitives: list[Primitive], exact: bool = False) -> Probes:
    """Points whose pose error bounds the error of every vertex a joint moves.

    Why a few points suffice: a joint's pose error is a rigid-motion difference, affine in the
    vertex's position, so its size is a convex function of the position and peaks at a corner
    of any convex set holding the joint's vertices. A vertex blended between joints moves by
    the weighted mean of its joints' errors, never more than the largest of them, and it counts
    for each joint that moves it. `exact=False` (decimation): the 8 corners of a box around each
    joint's vertices — a guaranteed, slightly pessimistic bound that is cheap to evaluate on
    every frame. `exact=True` (measuring): the corners of each joint's convex hull, the true
    maximum over all vertices. Every joint also probes its own pivot and its children's, so a
    joint with no skinned vertex has a reach."""
    bind = np.asarray(skeleton.bind_world, dtype=np.float64)
    parent = np.asarray(skeleton.parent, dtype=np.int64)
    J = bind.shape[0]
    pivot = bind[:, :3, 3]
    pts, own = (
        [pivot.astype(np.float32), pivot[parent >= 0].astype(np.float32)],
        [np.arange(J), parent[parent >= 0]],
    )
    for prim in primitives:
        w = np.asarray(prim.weights)
        jn = np.asarray(prim.joints)
        for s in range(jn.shape[1]):  # ≤ 4 influence slots
            use = w[:, s] > 0
            if use.all():
                pts.append(np.asarray(prim.positions, dtype=np.float32))
                own.append(jn[:, s])
            elif use.any():
                pts.append(np.asarray(prim.positions, dtype=np.float32)[use])
                own.append(jn[use, s])
    x = np.concatenate(pts)
    owner = np.concatenate(own).astype(np.intp)
    if exact:
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(J + 1))
        picks = []
        for j in range(J):  # one qhull call per joint (≤ a few hundred)
            rows = order[bounds[j] : bounds[j + 1]]
            if rows.size:
                picks.append(rows[_hull_vertices(x[rows].astype(np.float64))])
        pick = np.concatenate(picks)
    else:
        joint_of, corners = _box_corners(x, owner, J)
        x = np.concatenate([x, corners.astype(np.float32)])
        owner = np.concatenate([owner, joint_of])
        pick = x.shape[0] - corners.shape[0] + np.arange(corners.shape[0])  # 8 per joint
    joint, rest = owner[pick], x[pick].astype(np.float64)
    inv = skeleton.inverse_bind()[joint]
    local = np.einsum("pij,pj->pi", inv[:, :3, :3], rest) + inv[:, :3, 3]

    # reach: farthest probe (own or descendant's) from each joint, walking probes up the chain
    reach = np.zeros(J)
    cur, at = joint.copy(), rest
    while cur.size:
        np.maximum.at(reach, cur, np.linalg.norm(at - pivot[cur], axis=1))
        up = parent[cur] >= 0
        cur, at = parent[cur[up]], at[up]
    return Probes(joint=joint, local=local, rest=rest, reach=reach)


def probe_world(world: np.ndarray, pr: Probes) -> np.ndarray:
    """World positions (K, P, 3) of the probes under joint world matrices (K, J, 4, 4)."""
    # each probe's joint axes and origin, (K, P, 4, 3), rather than its whole 4×4 matrix: a
    # fraction of the memory traffic; summed in the order einsum did (x + z, then y), so the
    # numbers are the same to the bit. Box corners (8 a joint, in joint order) broadcast
    # against their joint's columns instead of gathering them.
    K, J = world.shape[:2]
    cols = world[..., :3, :].swapaxes(-1, -2)  # (K, J, 4, 3)
    n = len(pr.joint) // J if J else 0
    if n and n * J == len(pr.joint) and np.array_equal(pr.joint, np.repeat(np.arange(J), n)):
        cols, local = cols[:, :, None], pr.local.reshape(J, n, 3)  # (K, J, 1, 4, 3), (J, n, 3)
    else:
        cols, local = cols[:, pr.joint], pr.local
    x, y, z = (local[..., i, None] for i in range(3))
    out = ((cols[..., 0, :] * x + cols[..., 2, :] * z) + cols[..., 1, :] * y) + cols[..., 3, :]
    return out.reshape(K, len(pr.joint), 3)
