"""The grown tree as a struct of numpy arrays (no object per stem or leaf).

Generator space: metres, Z up, trunk base at the origin. Writers convert to their format's axes.

Stems are ordered so that a parent always comes before its children (level by level), which
lets later stages walk the hierarchy with vectorised passes. Nodes are the segment boundaries
of each stem (`curve_res + 1` per full stem), stored contiguously per stem, base to tip.
They are the candidate skeleton joints.

A split ("clone") is a stem of the same level whose parent is the stem it split from; its
first node sits on the parent's split node and its `node_z` continues the parent's, so radius
and taper carry on seamlessly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .params import Params


@dataclass(frozen=True, eq=False)
class Tree:
    params: Params
    seed: int
    scale: float  # scale_tree = Scale ± ScaleV, metres

    # stems, shape (S,)
    stem_level: np.ndarray  # int8, 0 = trunk
    stem_parent: np.ndarray  # int32, -1 for a trunk
    stem_parent_node: np.ndarray  # int32, global index of the parent's node at the start of the
    # parent segment the stem grows from (-1 for a trunk)
    stem_offset: np.ndarray  # float64, metres along the parent from its base (node_z units)
    stem_length: np.ndarray  # float64, metres (a clone carries its original's length)
    stem_radius: np.ndarray  # float64, base radius in metres (before flare)
    stem_clone: np.ndarray  # bool, True for a split clone
    stem_node_start: np.ndarray  # int32, first node of the stem
    stem_node_count: np.ndarray  # int32, number of nodes (>= 2)

    # nodes, shape (N,)
    node_stem: np.ndarray  # int32
    node_pos: np.ndarray  # float64 (N, 3)
    node_frame: np.ndarray  # float64 (N, 3, 3) rotation; column 2 = direction of the segment
    # leaving the node (the last node repeats the last segment's)
    node_radius: np.ndarray  # float64, radius at the node (taper and trunk flare applied)
    node_z: np.ndarray  # float64, metres from the stem's (original's) base

    # leaves, shape (L,)
    leaf_stem: np.ndarray  # int32, stem the leaf grows on
    leaf_node: np.ndarray  # int32, node the leaf is fixed to (segment start below it)
    leaf_pos: np.ndarray  # float64 (L, 3), base of the leaf blade
    leaf_frame: np.ndarray  # float64 (L, 3, 3); column 0 = blade width axis, column 1 =
    # blade length axis (base to tip), column 2 = blade normal
    leaf_size: np.ndarray  # float64 (L, 2): (length, width) in metres

    # A LOD cut from LOD0's tree (lod_leaves.prune_stems, lod_nodes.drop_nodes renumber stems
    # and nodes): LOD0's index of each stem (S,) and node (N,), so the LOD's joints take LOD0's
    # names and only LOD0's joints (rig.build_rig). None: a grown tree, each its own.
    stem_lod0: np.ndarray | None = None
    node_lod0: np.ndarray | None = None

    @property
    def n_stems(self) -> int:
        return int(self.stem_level.shape[0])

    @property
    def n_nodes(self) -> int:
        return int(self.node_pos.shape[0])

    @property
    def n_leaves(self) -> int:
        return int(self.leaf_pos.shape[0])

    @property
    def lod0_stems(self) -> np.ndarray:
        """(S,) LOD0's index of each stem (`stem_lod0`, or 0..S-1 in a grown tree)."""
        return np.arange(self.n_stems) if self.stem_lod0 is None else self.stem_lod0

    @property
    def lod0_nodes(self) -> np.ndarray:
        """(N,) LOD0's index of each node (`node_lod0`, or 0..N-1 in a grown tree)."""
        return np.arange(self.n_nodes) if self.node_lod0 is None else self.node_lod0

    @property
    def segments(self) -> np.ndarray:
        """(G,) the first node of every segment: consecutive nodes of one stem (node g to g + 1)."""
        return np.flatnonzero(self.node_stem[:-1] == self.node_stem[1:])

    @property
    def leaf_area(self) -> np.ndarray:
        """Blade area per leaf (m²), from the leaf shape's fill factor."""
        from .leafshapes import fill_factor

        return self.leaf_size[:, 0] * self.leaf_size[:, 1] * fill_factor(self.params.leaf_shape)

    @property
    def leaf_middle(self) -> np.ndarray:
        """(L, 3) middle of each blade, half its length out along the frame's column 1: where
        its area and its load sit."""
        return self.leaf_pos + (0.5 * self.leaf_size[:, 0])[:, None] * self.leaf_frame[:, :, 1]

    @property
    def leaf_reach(self) -> np.ndarray:
        """(L, 3) how far each blade's card reaches from its middle along each axis: half its
        length and half its width along the frame's columns 1 and 0, by absolute components."""
        F, size = self.leaf_frame, 0.5 * self.leaf_size
        return np.abs(size[:, 0, None] * F[:, :, 1]) + np.abs(size[:, 1, None] * F[:, :, 0])


def tree_height(tree: Tree) -> float:
    """Top of the tree (m): the highest node or leaf."""
    top = tree.node_pos[:, 2].max() if tree.n_nodes else 0.0
    if tree.n_leaves:
        top = max(top, tree.leaf_pos[:, 2].max())
    return float(top)


def tree_box(tree: Tree) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of the box around `tree`'s stems (nodes ± radius) and blades (each its
    middle ± Tree.leaf_reach: no corner arrays)."""
    r = tree.node_radius[:, None]
    lo, hi = (tree.node_pos - r).min(0), (tree.node_pos + r).max(0)
    if tree.n_leaves:
        mid, reach = tree.leaf_middle, tree.leaf_reach
        lo, hi = np.minimum(lo, (mid - reach).min(0)), np.maximum(hi, (mid + reach).max(0))
    return lo, hi


def tree_stats(tree: Tree) -> dict:
    """The figures `treegen info` reports: counts per level, leaf area, height, crown width."""
    levels = np.bincount(tree.stem_level.astype(np.int64), minlength=1) if tree.n_stems else []
    pts = np.concatenate([tree.node_pos, tree.leaf_pos]) if tree.n_leaves else tree.node_pos
    horizontal = pts[:, :2]
    width = float(np.max(np.ptp(horizontal, axis=0))) if len(pts) else 0.0
    return {
        "species": tree.params.name,
        "seed": tree.seed,
        "scale_m": round(tree.scale, 4),
        "stems": tree.n_stems,
        "stems_per_level": [int(n) for n in levels],
        "clones": int(np.count_nonzero(tree.stem_clone)),
        "nodes": tree.n_nodes,
        "leaves": tree.n_leaves,
        "leaf_area_m2": round(float(tree.leaf_area.sum()), 4),
        "height_m": round(tree_height(tree), 4),
        "crown_width_m": round(width, 4),
        "trunk_radius_m": round(float(tree.node_radius[0]) if tree.n_nodes else 0.0, 4),
    }
