"""Pruning (PruneRatio): stems that leave the envelope are shortened or removed.

Each stem's length is bisected with the level's same random draws (stems.grow_level is
deterministic in seed and level), so a pruned stem keeps its shape, only shorter.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shapes import ENVELOPE, shape_ratio
from .stems import Grown, Level, grow_level


def inside_envelope(p: Params, scale_tree: float, pts: np.ndarray) -> np.ndarray:
    """True where points (n, 3) lie inside the pruning envelope (tree coordinates)."""
    r = np.hypot(pts[:, 0], pts[:, 1]) / scale_tree
    rel = (scale_tree - pts[:, 2]) / (scale_tree * max(1.0 - p.base_size, 1e-6))
    env = p.prune_width * shape_ratio(
        ENVELOPE, rel, p.prune_width_peak, p.prune_power_low, p.prune_power_high
    )
    return (r <= env) & (rel >= 0.0) & (rel <= 1.0)


def grow_pruned(
    p: Params, level: int, batch: Level, scale_tree: float, seed: int, steps: int
) -> tuple[Level, Grown, np.ndarray]:
    """Grow a level; with PruneRatio > 0 shorten stems that leave the envelope (bisection on
    each stem's length with the same random draws), final L0 − (L0 − L_fit)·PruneRatio.
    Stems pruned away entirely (no length fits) are removed, as in the paper."""
    length = batch.length.copy()
    grown = grow_level(p, level, batch, length, seed)
    if p.prune_ratio <= 0.0 or level == 0:
        return batch, grown, length

    def outside_by_stem(g: Grown) -> np.ndarray:
        bad = ~inside_envelope(p, scale_tree, g.node_pos)
        out = np.zeros(batch.pos.shape[0], dtype=bool)
        np.logical_or.at(out, g.stem_origin[g.node_stem], bad)
        return out

    out = outside_by_stem(grown)
    if not out.any():
        return batch, grown, length
    lo = np.zeros_like(length)
    hi = np.ones_like(length)
    hi[~out] = 1.0
    lo[~out] = 1.0
    for _ in range(steps):
        mid = np.where(out, 0.5 * (lo + hi), 1.0)
        g = grow_level(p, level, batch, batch.length * mid, seed)
        bad = outside_by_stem(g)
        hi = np.where(out & bad, mid, hi)
        lo = np.where(out & ~bad, mid, lo)
    fit = batch.length * lo
    final = batch.length - (batch.length - fit) * p.prune_ratio
    final = np.maximum(final, 1e-3 * batch.length)
    grown = grow_level(p, level, batch, final, seed)
    keep = (lo > 0.0) | (p.prune_ratio < 1.0)
    if keep.all() or not keep.any():
        return batch, grown, final
    return _keep_originals(batch, grown, final, keep)


def _keep_originals(batch: Level, grown: Grown, length: np.ndarray, keep: np.ndarray):
    """The level without the original stems `~keep` and their split members."""
    new_origin = np.cumsum(keep) - 1
    stem_keep = keep[grown.stem_origin]
    local = np.full(stem_keep.shape[0], -1)
    local[stem_keep] = np.arange(int(stem_keep.sum()))
    node_keep = stem_keep[grown.node_stem]
    parent = grown.stem_parent[stem_keep]
    kept = Grown(
        stem_parent=np.where(parent >= 0, local[np.maximum(parent, 0)], -1),
        stem_origin=new_origin[grown.stem_origin[stem_keep]],
        stem_first_seg=grown.stem_first_seg[stem_keep],
        node_stem=local[grown.node_stem[node_keep]],
        node_seg=grown.node_seg[node_keep],
        node_pos=grown.node_pos[node_keep],
        node_frame=grown.node_frame[node_keep],
    )
    trimmed = Level(
        **{
            f: getattr(batch, f)[keep]
            for f in ("pos", "frame", "length", "radius", "parent", "parent_node", "offset")
        }
    )
    return trimmed, kept, length[keep]
