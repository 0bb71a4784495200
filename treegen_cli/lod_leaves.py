"""Coverage-true leaf LODs: fewer leaves that cover the crown as the full set did.

A far LOD used to regrow the tree with fewer, larger leaves on fewer stem levels; with the twigs
gone, its leaves sat in rows along the bare main branches ("fern fronds") and the crown lost a
fifth of its cover. Here a LOD is cut from LOD0's own tree instead:

  * `prune_stems`: stems not kept are removed, and their leaves stay where they were, re-parented
    to the node where their nearest kept ancestor carries them (so they sway with it, skinned
    to a joint that exists in the LOD's rig);
  * `thin_leaves`: a spatially stratified subset of the leaves — every cell of a grid over the
    crown keeps its share, so the kept leaves fill the crown volume as the full set did — each
    kept leaf moved to the middle of the leaves it stands for (`gather_leaves`) and scaled so
    the LOD's projected leaf area matches LOD0's (`area_factor`).

    lod = thin_leaves(prune_stems(tree, keep), n_keep=len // 4, area_factor=...)
"""

from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np

from .tree import Tree

LENGTH_SHARE = 0.25  # of a kept leaf's growth in area (log), the share taken in length:
# blades widen more than they lengthen, so the crown's reach stays
GRID = 24  # cells per side of the stratification grid over the leaves' bounds
LEAF_FIELDS = ("leaf_stem", "leaf_node", "leaf_pos", "leaf_frame", "leaf_size")  # per leaf (L, ...)


def stem_closure(tree: Tree, keep: np.ndarray) -> np.ndarray:
    """`keep` (S,) with every stem whose ancestor is dropped dropped too (trunks kept)."""
    keep = np.asarray(keep, dtype=bool).copy()
    keep[tree.stem_level == 0] = True
    parent = tree.stem_parent
    has = parent >= 0
    while True:  # one pass per generation (levels, clone chains)
        nxt = keep & np.where(has, keep[np.maximum(parent, 0)], True)
        if np.array_equal(nxt, keep):
            return keep
        keep = nxt


def prune_stems(tree: Tree, keep: np.ndarray) -> Tree:
    """The tree without the stems `keep` (S,) drops (and their descendants); leaves of dropped
    stems keep their place and frame and hang from the node where their nearest kept ancestor
    carries the dropped branch (its `stem_parent_node`). Kept stems and nodes remember which
    of LOD0's they are (Tree.lod0_stems, lod0_nodes: a LOD's joints keep LOD0's names)."""
    keep = stem_closure(tree, keep)
    if keep.all():
        return tree
    new_stem = np.cumsum(keep) - 1
    node_keep = keep[tree.node_stem]
    new_node = np.cumsum(node_keep) - 1
    # leaves: climb dropped stems to the attach node on a kept one
    stem = tree.leaf_stem.astype(np.int64)
    node = tree.leaf_node.astype(np.int64)
    while (up := ~keep[stem]).any():
        node = np.where(up, tree.stem_parent_node[stem], node)
        stem = np.where(up, tree.stem_parent[stem], stem)
    s = np.flatnonzero(keep)
    parent = tree.stem_parent[s]
    pnode = tree.stem_parent_node[s]
    return replace(
        tree,
        stem_level=tree.stem_level[s],
        stem_parent=np.where(parent >= 0, new_stem[np.maximum(parent, 0)], -1).astype(np.int32),
        stem_parent_node=np.where(pnode >= 0, new_node[np.maximum(pnode, 0)], -1).astype(np.int32),
        stem_offset=tree.stem_offset[s],
        stem_length=tree.stem_length[s],
        stem_radius=tree.stem_radius[s],
        stem_clone=tree.stem_clone[s],
        stem_node_start=new_node[tree.stem_node_start[s]].astype(np.int32),
        stem_node_count=tree.stem_node_count[s],
        node_stem=new_stem[tree.node_stem[node_keep]].astype(np.int32),
        node_pos=tree.node_pos[node_keep],
        node_frame=tree.node_frame[node_keep],
        node_radius=tree.node_radius[node_keep],
        node_z=tree.node_z[node_keep],
        leaf_stem=new_stem[stem].astype(np.int32),
        leaf_node=new_node[node].astype(np.int32),
        stem_lod0=tree.lod0_stems[s],
        node_lod0=tree.lod0_nodes[node_keep],
    )


def stratified_keys(points: np.ndarray, seed: int, grid: int = GRID) -> np.ndarray:
    """(n,) keys in [0, 1) whose smallest k pick k of `points` (n, 3) spread like all of them,
    for every k (nested: fewer picks are a subset of more). A point's key is its place in its
    `grid`³ cell's seeded random order, (rank + phase) / count with a seeded phase per cell, so
    every cell gives its share k/n of its points, within one."""
    n = points.shape[0]
    if n == 0:
        return np.zeros(0)
    rng = np.random.default_rng([int(seed), 0x57EA7])
    lo, hi = points.min(0), points.max(0)
    cell = np.floor((points - lo) / np.maximum(hi - lo, 1e-12) * (grid - 1e-9)).astype(np.int64)
    cid = (cell[:, 0] * grid + cell[:, 1]) * grid + cell[:, 2]
    order = np.lexsort((rng.random(n), cid))  # by cell, random within a cell
    sc = cid[order]
    start = np.flatnonzero(np.r_[True, sc[1:] != sc[:-1]])
    count = np.diff(np.r_[start, n])
    which = np.repeat(np.arange(start.size), count)
    rank = np.arange(n) - start[which]
    key = np.empty(n)
    key[order] = (rank + rng.random(start.size)[which]) / count[which]
    return key


def stratified_pick(points: np.ndarray, n_keep: int, seed: int) -> np.ndarray:
    """Sorted indices of `n_keep` of `points` (n, 3) spread like all of them, nested: the
    picks for fewer points are a subset of the picks for more, so consecutive LODs keep the
    same leaves (stratified_keys); gather_leaves then places each LOD's kept leaves anew."""
    n = points.shape[0]
    if n_keep >= n:
        return np.arange(n)
    if n_keep <= 0:
        return np.zeros(0, dtype=np.int64)
    return np.sort(_stratified_order(points, seed)[:n_keep])


_ORDER: list = [None]  # (weakref to the points, seed, their stratified order): the last asked


def _stratified_order(points: np.ndarray, seed: int) -> np.ndarray:
    """All of `points` by stratified key, ties by index; the last points array's kept (by
    identity: a make's LODs all thin LOD0's leaf_pos, which pruning leaves alone, and keyed
    it again for each LOD, 10 ms each for the aspen)."""
    last = _ORDER[0]
    if last is not None and last[0]() is points and last[1] == seed:
        return last[2]
    order = np.lexsort((np.arange(points.shape[0]), stratified_keys(points, seed)))
    _ORDER[0] = (weakref.ref(points), seed, order)
    return order


def thin_leaves(tree: Tree, n_keep: int, area_factor, seed: int = 0) -> Tree:
    """`n_keep` stratified leaves of `tree`, each blade scaled by `area_factor` in area (one
    factor, or one per kept leaf; see grow_leaves)."""
    if tree.n_leaves == 0:
        return tree
    pick = stratified_pick(tree.leaf_pos, n_keep, tree.seed if seed == 0 else seed)
    kept = replace(tree, **{k: getattr(tree, k)[pick] for k in LEAF_FIELDS})
    if 0 < pick.size < tree.n_leaves:  # (none kept: nothing to gather to)
        kept = gather_leaves(tree, kept, pick)
    return grow_leaves(kept, area_factor)


def gather_leaves(full: Tree, kept: Tree, pick: np.ndarray) -> Tree:
    """`kept` (`full`'s leaves `pick`) with each blade moved (frame and size unchanged) so
    that its middle sits at the area-weighted middle of the blades it stands for: itself and
    the dropped ones nearest to it. Grown in place, a kept leaf puts their area where it
    happened to be, off to one side of them, and a far LOD's crown reads blotchy at a few
    pixels (the XOR of two LODs at their switch is speckle all over the crown, not at its
    edge or trunk); gathered, the worst switch's IoU moves by -0.006 to +0.032, median
    +0.008 over the bundled species (bench/lod_pop_bench.py)."""
    from scipy.spatial import cKDTree

    a, b = full.leaf_middle, kept.leaf_middle
    dropped = np.ones(full.n_leaves, dtype=bool)
    dropped[pick] = False
    near = np.empty(full.n_leaves, dtype=np.int64)
    near[pick] = np.arange(pick.size)
    near[dropped] = cKDTree(b).query(a[dropped])[1]
    w = full.leaf_area
    n = kept.n_leaves
    total = np.bincount(near, weights=w, minlength=n)
    mid = np.stack([np.bincount(near, weights=w * a[:, i], minlength=n) for i in range(3)], axis=1)
    mid = np.where(total[:, None] > 0, mid / np.maximum(total, 1e-30)[:, None], b)
    return replace(kept, leaf_pos=kept.leaf_pos + (mid - b))


def grow_leaves(tree: Tree, area_factor, length_share: float = LENGTH_SHARE) -> Tree:
    """`tree` with each blade scaled by `area_factor` (scalar or (L,)) in area about its
    middle: length × area_factor^length_share, width × the rest."""
    f = np.maximum(np.broadcast_to(np.asarray(area_factor, dtype=np.float64), (tree.n_leaves,)), 0.0)
    if not tree.n_leaves or np.all(f == 1.0):
        return tree
    grow = np.stack([f**length_share, f ** (1.0 - length_share)], axis=1)  # (length, width)
    size, frame = tree.leaf_size, tree.leaf_frame
    # grown about the blade's middle, not its base: the leaf stays where it was
    pos = tree.leaf_pos - (0.5 * (grow[:, 0] - 1.0) * size[:, 0])[:, None] * frame[:, :, 1]
    return replace(tree, leaf_pos=pos, leaf_size=size * grow)


def fit_blades(tree: Tree, lo: np.ndarray, hi: np.ndarray) -> Tree:
    """`tree` with each blade that reaches out of the box (lo, hi) shrunk about its middle
    until it fits (LOD0's box: a LOD's enlarged leaves must not make the tree bigger than it
    is, or the silhouette grows at the switch and a tiny budget's few leaves poke out of it)."""
    if not tree.n_leaves:
        return tree
    mid, F, reach = tree.leaf_middle, tree.leaf_frame, tree.leaf_reach
    room = np.minimum(hi - mid, mid - lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(reach > 0, np.maximum(room, 0.0) / reach, np.inf).min(axis=1)
    s = np.clip(s, 0.0, 1.0)
    if np.all(s >= 1.0):
        return tree
    size = tree.leaf_size * s[:, None]
    pos = mid - (0.5 * size[:, 0])[:, None] * F[:, :, 1]
    return replace(
        tree,
        leaf_pos=np.where((s < 1.0)[:, None], pos, tree.leaf_pos),
        leaf_size=np.where((s < 1.0)[:, None], size, tree.leaf_size),
    )
