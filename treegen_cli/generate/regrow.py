"""Geometric LODs' leaves: the same tree with fewer leaves or levels, without regrowing it.

Stems of the kept levels come from the same random streams whatever the leaves are, so a LOD
that changes only Leaves, LeafQuality or lowers Levels takes them from the grown tree as they
are and grows only its leaves again (placement.LevelContext rebuilt from the Tree's arrays).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..params import Params
from ..tree import Tree
from .bounds import DEFAULTS, GenerateOptions, apply_options
from .grow import generate
from .leaves import grow_leaves, leaf_fields
from .placement import LevelContext


def regrow_leaves(tree: Tree, p: Params, options: GenerateOptions = DEFAULTS) -> Tree:
    """What `generate(p, tree.seed, options)` grows, for a `p`/`options` that differ from the
    tree's only in its leaves (Leaves, LeafQuality) and a lower or equal Levels — the geometric
    LODs. Stems of the kept levels come from the same random streams, so they are taken from
    `tree` as they are and only the leaves grow again: same arrays, a fraction of the time."""
    p, n_levels = apply_options(p, options)
    if (
        n_levels > tree.params.levels
        or replace(
            p, leaves=tree.params.leaves, leaf_quality=tree.params.leaf_quality, levels=tree.params.levels
        )
        != tree.params
    ):
        return generate(p, tree.seed, options)
    present = int(tree.stem_level.max()) if tree.n_stems else 0
    last = min(max(n_levels, 1) - 1, present)
    n_stems = int(np.searchsorted(tree.stem_level, last, side="right"))
    n_nodes = int(tree.stem_node_start[n_stems]) if n_stems < tree.n_stems else tree.n_nodes
    g0 = int(np.searchsorted(tree.stem_level, last, side="left"))
    n0 = int(tree.stem_node_start[g0])
    lvl = np.arange(g0, n_stems)
    clone = tree.stem_clone[lvl]
    origin = np.where(clone, tree.stem_parent[lvl] - g0, np.arange(lvl.shape[0]))
    while True:  # clones of clones: jump to the original
        nxt = np.where(clone[origin], origin[origin], origin)
        if np.array_equal(nxt, origin):
            break
        origin = nxt
    res = max(1, int(p.level[last].curve_res))
    length = tree.stem_length[lvl]
    seg_len = length / res
    first_seg = np.rint(tree.node_z[tree.stem_node_start[lvl]] / np.maximum(seg_len, 1e-300)).astype(np.int64)
    orig_parent = tree.stem_parent[g0 + origin]
    parent_length = np.where(orig_parent >= 0, tree.stem_length[np.maximum(orig_parent, 0)], 1.0)
    ctx = LevelContext(
        level=last,
        g0=g0,
        node_start=tree.stem_node_start[lvl].astype(np.int64),
        counts=tree.stem_node_count[lvl].astype(np.int64),
        first_seg=first_seg,
        origin=origin,
        length=length,
        seg_len=seg_len,
        radius=tree.stem_radius[lvl],
        offset_on_parent=tree.stem_offset[g0 + origin],
        parent_length=parent_length,
        node_pos=tree.node_pos[n0:n_nodes],
        node_frame=tree.node_frame[n0:n_nodes],
        node_radius=tree.node_radius[n0:n_nodes],
        node_z=tree.node_z[n0:n_nodes],
        n_originals=int(np.count_nonzero(~clone)),
    )
    leaves = grow_leaves(p, ctx, tree.seed, n_levels, options, tree.scale) if n_levels >= 1 else None
    s, n = slice(0, n_stems), slice(0, n_nodes)
    return replace(
        tree,
        params=p,
        stem_level=tree.stem_level[s],
        stem_parent=tree.stem_parent[s],
        stem_parent_node=tree.stem_parent_node[s],
        stem_offset=tree.stem_offset[s],
        stem_length=tree.stem_length[s],
        stem_radius=tree.stem_radius[s],
        stem_clone=tree.stem_clone[s],
        stem_node_start=tree.stem_node_start[s],
        stem_node_count=tree.stem_node_count[s],
        node_stem=tree.node_stem[n],
        node_pos=tree.node_pos[n],
        node_frame=tree.node_frame[n],
        node_radius=tree.node_radius[n],
        node_z=tree.node_z[n],
        **leaf_fields(leaves),
    )
