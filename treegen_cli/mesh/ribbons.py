"""A far LOD's thin branches as two crossed ribbons ("twigs": the bark's texture on both
faces): 4 triangles a segment where a 3-sided tube takes 6, and the outline of a square tube
through the circle from any side (MeshOptions.ribbon_radius, lod_budget.RIBBON_PX).

    twigs = ribbons(tree, rig, pointed, rings...)      # called by bark.bark_primitives
    tubes = ribbons_as_tubes(twigs)                     # the same vertices as square tubes

Layout: rings of 4 vertices (x−, x+, y−, y+ along the ring frame's x and y axes), stem by stem,
then 2 apex vertices (one a ribbon) per pointed stem; triangles: 4 per pair of consecutive
rings (ribbon x's strip, then y's), then 2 per pointed tip.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..asset import TWIGS, Primitive
from .influences import merge_influences


def ribbons(tree, rig, pointed, rs, centre, frame, radius, v_ring, a, b, t, off_u, v_tip) -> Primitive:
    """The "twigs" primitive: per ribbon stem (its rings `rs`, centres, frames, drawn radii,
    v, and node binding a, b, t), two ribbons crossed along the ring frame's x and y axes, 4
    vertices a ring and 4 triangles between rings; a pointed stem (`pointed` (S,), read at
    `rs`) closes each ribbon on one apex. u spans half the bark tile across a ribbon (what a tube shows
    of it), v runs as on a tube."""
    R = rs.size
    x, y = frame[:, :, 0], frame[:, :, 1]
    rad = radius[:, None]
    pos = np.stack([centre - rad * x, centre + rad * x, centre - rad * y, centre + rad * y], axis=1)
    # each ribbon's plane normal, on the side its triangles' winding makes the front (x × z =
    # −y, y × z = x): a renderer lighting the face it sees flips it there (glTF doubleSided)
    nrm = np.stack([-y, -y, x, x], axis=1)
    uv = np.empty((R, 4, 2))
    uv[:, :, 0] = off_u[rs][:, None] + np.array([0.0, 0.5, 0.25, 0.75])
    uv[:, :, 1] = v_ring[:, None]
    J = np.concatenate([rig.node_joints[a], rig.node_joints[b]], axis=1)
    W = np.concatenate([rig.node_weights[a] * (1 - t)[:, None], rig.node_weights[b] * t[:, None]], axis=1)
    J, W = merge_influences(J, W)
    # per pair of consecutive rings of a stem: ribbon x's strip (corners 0 1), then y's (2 3)
    pair = np.flatnonzero(rs[1:] == rs[:-1])
    lo, hi = 4 * pair, 4 * (pair + 1)
    quads = np.stack(
        [
            np.stack([lo + e0, lo + e1, hi + e1, lo + e0, hi + e1, hi + e0], axis=1)
            for e0, e1 in ((0, 1), (2, 3))
        ],
        axis=1,
    )  # (P, 2 ribbons, 6)
    # pointed stems: each ribbon's last ring closes on its own vertex at the stem's apex
    ends = np.flatnonzero(np.r_[rs[1:] != rs[:-1], True] & pointed[rs])
    tip = tree.stem_node_start[rs[ends]].astype(np.int64) + tree.stem_node_count[rs[ends]] - 1
    apex = 4 * R + 2 * np.arange(ends.size)
    fans = np.stack(
        [
            np.stack([4 * ends + e0, 4 * ends + e1, apex + i], axis=1)
            for i, (e0, e1) in enumerate(((0, 1), (2, 3)))
        ],
        axis=1,
    )
    tri = np.concatenate([quads.reshape(-1, 3), fans.reshape(-1, 3)])
    aJ, aW = merge_influences(rig.node_joints[tip], rig.node_weights[tip])
    fx, fy = tree.node_frame[tip][:, :, 0], tree.node_frame[tip][:, :, 1]
    # each apex at the middle of its ribbon's u span (x: 0 to 0.5, y: 0.25 to 0.75)
    uv_apex = np.stack(
        [np.column_stack([off_u[rs[ends]] + m, v_tip[rs[ends]]]) for m in (0.25, 0.5)], axis=1
    ).reshape(-1, 2)
    return Primitive(
        name=TWIGS,
        material=TWIGS,
        positions=np.concatenate([pos.reshape(-1, 3), np.repeat(tree.node_pos[tip], 2, axis=0)]).astype(
            np.float32
        ),
        normals=np.concatenate([nrm.reshape(-1, 3), np.stack([-fy, fx], axis=1).reshape(-1, 3)]).astype(
            np.float32
        ),
        uvs=np.concatenate([uv.reshape(-1, 2), uv_apex]).astype(np.float32),
        indices=tri.astype(np.uint32).ravel(),
        joints=np.concatenate([np.repeat(J, 4, axis=0), np.repeat(aJ, 2, axis=0)]),
        weights=np.concatenate([np.repeat(W, 4, axis=0), np.repeat(aW, 2, axis=0)]),
    )


TUBE_CORNERS = np.array([1, 3, 0, 2])  # a ribbon ring's vertices (x−, x+, y−, y+) around its axis


def ribbons_as_tubes(prim: Primitive) -> Primitive:
    """A "twigs" primitive's crossed ribbons as the closed square tubes through the same
    vertices (material "bark", normals radial), for a renderer that widens and thins bark by
    its tubes (the impostor's atlas: impostor_atlas._bark_at_least). Read as `ribbons` writes
    it: rings of 4 vertices, then a pointed stem's 2 apex vertices; 4 triangles per pair of
    rings (each starting at its lower ring's first vertex), then 2 per pointed tip."""
    tri = np.asarray(prim.indices, np.int64).reshape(-1, 3)
    k = np.arange(0, max(len(tri) - 1, 0), 4)
    fan_at = k[tri[k + 1, 0] != tri[k, 0]]  # a tip's two triangles start on two vertices
    n_quads = int(fan_at[0] if fan_at.size else len(tri)) // 4
    quads, fans = tri[: 4 * n_quads].reshape(-1, 4, 3), tri[4 * n_quads :].reshape(-1, 2, 3)
    n_ring = len(prim.positions) - 2 * len(fans)
    p = np.asarray(prim.positions, np.float64)
    ring = p[:n_ring].reshape(-1, 4, 3)
    radial = ring - ring.mean(axis=1, keepdims=True)
    normals = np.array(prim.normals, np.float64)
    normals[:n_ring] = (radial / np.maximum(np.linalg.norm(radial, axis=2, keepdims=True), 1e-30)).reshape(
        -1, 3
    )
    apex, base = fans[:, 0, 2], fans[:, 0, 0] // 4
    axis = p[apex] - ring[base].mean(axis=1)
    normals[apex] = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-30)
    lo, hi = quads[:, 0, 0] // 4, quads[:, 1, 2] // 4
    a, b = TUBE_CORNERS, np.roll(TUBE_CORNERS, -1)
    l0, l1, h0, h1 = 4 * lo[:, None] + a, 4 * lo[:, None] + b, 4 * hi[:, None] + a, 4 * hi[:, None] + b
    sides = np.stack([l0, l1, h1, l0, h1, h0], axis=2).reshape(-1, 3)
    e0, e1 = 4 * base[:, None] + a, 4 * base[:, None] + b
    cones = np.stack([e0, e1, np.broadcast_to(apex[:, None], e0.shape)], axis=2).reshape(-1, 3)
    return replace(
        prim,
        name="bark",
        material="bark",
        normals=normals.astype(np.float32),
        indices=np.concatenate([sides, cones]).astype(np.uint32).ravel(),
    )
