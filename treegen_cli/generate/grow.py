"""The generator: Params + seed → Tree, level by level.

Read top to bottom: the options and bounds (bounds.py), the tree's scale and its trunks
(placement.py), then per level: grow and prune its stems (stems.py, splits.py, prune.py),
their radii (radius.py), record them in the Tree's global arrays, and place the next level's
stems (placement.py) or, on the last level, the leaves (leaves.py).
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..tree import Tree
from .bounds import DEFAULTS, GenerateOptions, apply_options, check_size, refuse
from .draws import TREE, vary
from .leaves import grow_leaves, leaf_fields
from .placement import LevelContext, place_children, place_trunks
from .prune import grow_pruned
from .radius import node_radius


class _Builder:
    """Accumulates levels into the Tree's global arrays."""

    def __init__(self):
        self.parts: dict[str, list[np.ndarray]] = {}
        self.n_stems = 0
        self.n_nodes = 0

    def add(self, **arrays):
        for key, value in arrays.items():
            self.parts.setdefault(key, []).append(value)

    def cat(self, key, dtype, shape_tail=()):
        chunks = self.parts.get(key)
        if not chunks:
            return np.zeros((0,) + shape_tail, dtype=dtype)
        return np.concatenate(chunks).astype(dtype, copy=False)


def generate(p: Params, seed: int = 0, options: GenerateOptions = DEFAULTS) -> Tree:
    """Grow the whole Weber–Penn tree for `p` and `seed` as a struct of arrays."""
    p, n_levels = apply_options(p, options)

    rng = np.random.default_rng([seed, 0, TREE])
    scale_tree = float(vary(rng, p.scale, p.scale_v, 1)[0])
    batch = place_trunks(p, rng, scale_tree)

    out = _Builder()
    leaves = None
    total_stems = 0
    for level in range(max(n_levels, 1)):
        lp = p.level[level]
        batch, grown, length = grow_pruned(p, level, batch, scale_tree, seed, options.prune_steps)
        origin = grown.stem_origin
        res = max(1, int(lp.curve_res))
        n_local = origin.shape[0]
        total_stems += n_local
        if total_stems > options.max_stems:
            refuse("stems", total_stems, p, options)

        # global indices
        g0, n0 = out.n_stems, out.n_nodes
        counts = np.bincount(grown.node_stem, minlength=n_local)
        node_start = n0 + np.concatenate([[0], np.cumsum(counts)[:-1]])
        seg_len = (length / res)[origin]
        node_z = grown.node_seg * seg_len[grown.node_stem]
        s_len = length[origin]
        s_rad = batch.radius[origin]
        node_radii = node_radius(p, level, s_rad[grown.node_stem], s_len[grown.node_stem], node_z)
        # clones hang off the node of their split origin; originals off the batch's parent node
        clone = grown.stem_parent >= 0
        parent = np.where(clone, g0 + grown.stem_parent, batch.parent[origin])
        split_node = node_start[np.maximum(grown.stem_parent, 0)] + (
            grown.stem_first_seg - grown.stem_first_seg[np.maximum(grown.stem_parent, 0)]
        )
        parent_node = np.where(clone, split_node, batch.parent_node[origin])
        offset = np.where(clone, grown.stem_first_seg * seg_len, batch.offset[origin])
        out.add(
            stem_level=np.full(n_local, level),
            stem_parent=parent,
            stem_parent_node=parent_node,
            stem_offset=offset,
            stem_length=s_len,
            stem_radius=s_rad,
            stem_clone=clone,
            stem_node_start=node_start,
            stem_node_count=counts,
            node_stem=g0 + grown.node_stem,
            node_pos=grown.node_pos,
            node_frame=grown.node_frame,
            node_radius=node_radii,
            node_z=node_z,
        )
        out.n_stems += n_local
        out.n_nodes += grown.node_pos.shape[0]

        ctx = LevelContext(
            level=level,
            g0=g0,
            node_start=node_start,
            counts=counts,
            first_seg=grown.stem_first_seg,
            origin=origin,
            length=s_len,
            seg_len=seg_len,
            radius=s_rad,
            offset_on_parent=batch.offset[origin],
            parent_length=_parent_length(out, batch.parent[origin]),
            node_pos=grown.node_pos,
            node_frame=grown.node_frame,
            node_radius=node_radii,
            node_z=node_z,
            n_originals=batch.pos.shape[0],
        )
        last = level == max(n_levels, 1) - 1
        if not last:
            batch = place_children(p, ctx, seed, scale_tree, options, total_stems)
            if batch.pos.shape[0] == 0:
                last = True
        if last:
            if n_levels >= 1:
                leaves = grow_leaves(p, ctx, seed, n_levels, options, scale_tree)
            break

    tree = Tree(
        params=p,
        seed=seed,
        scale=float(scale_tree),
        stem_level=out.cat("stem_level", np.int8),
        stem_parent=out.cat("stem_parent", np.int32),
        stem_parent_node=out.cat("stem_parent_node", np.int32),
        stem_offset=out.cat("stem_offset", np.float64),
        stem_length=out.cat("stem_length", np.float64),
        stem_radius=out.cat("stem_radius", np.float64),
        stem_clone=out.cat("stem_clone", bool),
        stem_node_start=out.cat("stem_node_start", np.int32),
        stem_node_count=out.cat("stem_node_count", np.int32),
        node_stem=out.cat("node_stem", np.int32),
        node_pos=out.cat("node_pos", np.float64, (3,)),
        node_frame=out.cat("node_frame", np.float64, (3, 3)),
        node_radius=out.cat("node_radius", np.float64),
        node_z=out.cat("node_z", np.float64),
        **leaf_fields(leaves),
    )
    check_size(tree, options.max_size, options.max_size_flag)
    return tree


def _parent_length(out: _Builder, parent: np.ndarray) -> np.ndarray:
    """Length of each stem's parent stem (1 for the trunks, which have none)."""
    lengths = out.cat("stem_length", np.float64)
    return np.where(parent >= 0, lengths[np.maximum(parent, 0)] if lengths.size else 1.0, 1.0)
