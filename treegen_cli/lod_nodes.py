"""Coarser branches for far LODs: nodes a branch does not need at the LOD's pixel size dropped.

A branch's bark costs two triangles per side per ring, one ring per node; at a far switch a
gently curving twig drawn with five nodes looks the same with two. Dropping such nodes leaves
room in the bark budget for more branches, so fewer are cut and the crown's twigs, which the
silhouette shows, stay (a whorled horsetail kept its lower whorls whole and lost the top ones).

A node goes when the chord between its kept neighbours passes within `tol` metres of every
original node it replaces (and their radii within `tol` of the interpolated ones), so the
coarse branch stays within `tol` of the full one; every other node at most per pass, so a
curve is never flattened by removing neighbours together. Trunks keep their nodes (their flare and
bends carry the silhouette) unless `trunks` says (per stem, or all: a leafless tree's, whose
budget goes to its twigs; a trunk under a pixel wide, a grass's stalk, draws as a twig does).
Leaves and child stems on a dropped node move to the kept node below it, where the skin binds
them; their positions do not change.

    coarse = coarsen_nodes(tree, tol=0.5 * px)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .lod_leaves import stratified_keys
from .tree import Tree

PASSES = 3  # halving passes, at most: a stem keeps at least 1/8 of its interior nodes' spans


def _droppable(tree: Tree, keep: np.ndarray, tol: float, trunks=False) -> np.ndarray:
    """Nodes (N,) that one pass may drop: interior kept nodes of branches at odd places among
    their stem's kept nodes, where the chord between their kept neighbours passes within `tol`
    of every original node between those neighbours (radii likewise), so the error does not
    build up over passes."""
    idx = np.flatnonzero(keep)
    stem = tree.node_stem[idx]
    head = np.r_[True, stem[1:] != stem[:-1]]
    tail = np.r_[stem[1:] != stem[:-1], True]
    start = np.maximum.accumulate(np.where(head, np.arange(idx.size), 0))
    rank = np.arange(idx.size) - start
    coarse = (tree.stem_level > 0) | np.broadcast_to(np.asarray(trunks, dtype=bool), (tree.n_stems,))
    j = np.flatnonzero(~head & ~tail & (rank % 2 == 1) & coarse[stem])
    a, c = idx[j - 1], idx[j + 1]
    span = c - a - 1  # original nodes strictly between the neighbours (>= 1)
    which = np.repeat(np.arange(j.size), span)
    node = a[which] + 1 + np.arange(which.size) - np.repeat(np.cumsum(span) - span, span)
    p0, d = tree.node_pos[a][which], (tree.node_pos[c] - tree.node_pos[a])[which]
    t = np.clip(
        np.einsum("ij,ij->i", tree.node_pos[node] - p0, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-30),
        0.0,
        1.0,
    )
    off = np.linalg.norm(p0 + t[:, None] * d - tree.node_pos[node], axis=1)
    r = tree.node_radius
    dr = np.abs(r[a][which] + t * (r[c] - r[a])[which] - r[node])
    worst = np.maximum.reduceat(np.maximum(off, dr), np.cumsum(span) - span) if j.size else np.zeros(0)
    out = np.zeros(tree.n_nodes, dtype=bool)
    out[idx[j][worst <= tol]] = True
    return out


def coarsen_nodes(
    tree: Tree, tol: float, trunks=False, stems: np.ndarray | None = None, passes: int = PASSES
) -> Tree:
    """`tree` with the branch nodes (and the trunks' too where `trunks`, one bool or one per
    stem (S,); only those of `stems`
    (S,) if given) within `tol` metres of their kept neighbours' chord dropped, in at most
    `passes` passes (see the module doc); the same tree when none is."""
    if tol <= 0 or tree.n_nodes < 3:
        return tree
    keep = np.ones(tree.n_nodes, dtype=bool)
    mine = None if stems is None else stems[tree.node_stem]
    for _ in range(passes):
        drop = _droppable(tree, keep, tol, trunks)
        if mine is not None:
            drop &= mine
        if not drop.any():
            break
        keep &= ~drop
    return drop_nodes(tree, keep)


def drop_nodes(tree: Tree, keep: np.ndarray) -> Tree:
    """`tree` with only the nodes `keep` (N,) (every stem's first and last among them); leaves
    and child stems on a dropped node move to the kept node below it; kept nodes remember
    which of LOD0's they are (Tree.lod0_nodes)."""
    if keep.all():
        return tree
    new_node = np.cumsum(keep) - 1  # a dropped node maps to the kept node below it
    pnode = tree.stem_parent_node
    return replace(
        tree,
        stem_parent_node=np.where(pnode >= 0, new_node[np.maximum(pnode, 0)], -1).astype(np.int32),
        stem_node_start=new_node[tree.stem_node_start].astype(np.int32),
        stem_node_count=np.bincount(tree.node_stem[keep], minlength=tree.n_stems).astype(np.int32),
        node_stem=tree.node_stem[keep],
        node_pos=tree.node_pos[keep],
        node_frame=_frames(tree, keep),
        node_radius=tree.node_radius[keep],
        node_z=tree.node_z[keep],
        leaf_node=new_node[tree.leaf_node].astype(np.int32),
        node_lod0=tree.lod0_nodes[keep],
    )


def _frames(tree: Tree, keep: np.ndarray) -> np.ndarray:
    """Kept nodes' frames, each turned so its column 2 follows its new segment (to the next
    kept node of its stem); a stem's last node keeps its own."""
    idx = np.flatnonzero(keep)
    F = tree.node_frame[idx].copy()
    same = tree.node_stem[idx[:-1]] == tree.node_stem[idx[1:]]
    i = np.flatnonzero(same)
    d = tree.node_pos[idx[i + 1]] - tree.node_pos[idx[i]]
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-30)[:, None]
    z = F[i, :, 2]
    # the smallest rotation taking z to d (Rodrigues), applied to the whole frame
    v = np.cross(z, d)
    c = np.einsum("ij,ij->i", z, d)
    k = 1.0 / np.maximum(1.0 + c, 1e-12)
    vx = np.zeros((i.size, 3, 3))
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx[:, 1, 0], vx[:, 2, 0], vx[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    R = np.eye(3)[None] + vx + k[:, None, None] * (vx @ vx)
    ok = c > -0.999  # a reversed segment (never on a smooth branch): leave the frame
    F[i[ok]] = R[ok] @ F[i[ok]]
    return F


def point_tips(tree: Tree, stems: np.ndarray | None = None) -> Tree:
    """`tree` with every branch (or those of `stems` (S,)) ending in a point (its last node's
    radius 0): the mesh closes a pointed tip on its apex instead of a last ring and a cap, so a
    one-segment twig costs a third of its triangles (a cone) and a far leafless LOD keeps three
    times the twigs; the area the cones lose is made up by thickening (lod_factors.cover_factors)."""
    tip = tree.stem_node_start.astype(np.int64) + tree.stem_node_count - 1
    tip = tip[(tree.stem_level > 0 if stems is None else stems) & (tree.stem_node_count > 1)]
    if not tip.size:
        return tree
    radius = tree.node_radius.copy()
    radius[tip] = 0.0
    return replace(tree, node_radius=radius)


def stub_stems(tree: Tree, which: np.ndarray, tol: float) -> Tree:
    """`tree` with the stems `which` (S,) coarsened to within `tol` metres of their nodes
    (every interior node the chord test allows, not one pass in two) and ending in a point:
    a leafy stem a far LOD cannot afford whole, drawn as a cone of a segment or a few, still
    reaches its leaves (the fan palm's petioles) along where it was."""
    if not which.any():
        return tree
    return point_tips(coarsen_nodes(tree, tol, stems=which, passes=2 * PASSES), which)


TWIGS_PER_CELL = 4  # twig_keys: stems per (azimuth, height) cell, about


def twig_keys(tree: Tree) -> np.ndarray:
    """(S,) keys whose smallest k pick k stems spread over the heights and the directions
    (azimuths, base to tip) of all of them, nested (stratified_keys on a grid of about
    TWIGS_PER_CELL stems per cell): each whorl keeps twigs on every side, so the crown covers
    alike from every side (a 3-D grid of a cell per stem picks at random, and a whorl kept
    on one side shows more from one view than another)."""
    start = tree.stem_node_start.astype(np.int64)
    last = start + tree.stem_node_count - 1
    d = tree.node_pos[last] - tree.node_pos[start]
    z = 0.5 * (tree.node_pos[start, 2] + tree.node_pos[last, 2])
    az = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi)  # a side view sees az and az + π alike
    pts = np.stack([az, z, np.zeros(tree.n_stems)], axis=1)
    grid = max(1, int(round(np.sqrt(tree.n_stems / TWIGS_PER_CELL))))
    return stratified_keys(pts, tree.seed, grid)
