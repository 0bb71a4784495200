"""How much a LOD's kept leaves grow and its kept branches thicken so that, at its switch
distance, it covers on screen what LOD0 covers (lod_cover measures the cover).

    leaf, radius = cover_factors(full, thin, px, sides)
    # Result: (per-leaf area factors, e.g. 2.1-3.4, 1.0): grow_leaves(thin, leaf), thicken(thin, radius)

Each kept leaf grows by what its region (cells of REGION_PX pixels) lost in leaves and dropped
twigs, within REGION_CLIP of the crown's growth; one factor then matches the whole. A leafless
tree thickens its kept branches instead.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .leafshapes import triangle_share
from .lod_cover import Blades, Grid, solve_factor, stem_area, tree_area, tree_cover
from .lod_leaves import LENGTH_SHARE
from .tree import Tree

REGION_PX = 4.0  # cells (pixels at the switch) over which a LOD keeps LOD0's area
REGION_CLIP = 2.0  # a region's leaves grow at most this much more (or less) than the crown's
STEM_STANDIN = 2.0  # leaves stand in for the dropped stems while those showed at most this ×
# the leaves' own area; past it (a grass's awns, a twiggy bush's far LODs) each kind keeps its
# own cover, or a barley ear's brown awns came back as green grains grown ninefold
STEMS_REACH = 0.95  # ... unless the kept branches, thickened as far as they go, cover less than
# this share of what LOD0's did: the leaves then cover the rest (barley's LOD3 keeps 19 cones
# for its 665 awns and lost a third of its cover, IoU 0.558 at its switch; 0.748, −9 %)


def cover_factors(
    full: Tree, thin: Tree, px: float, sides=(None, None), triangle: bool = False, widen=None
) -> tuple[np.ndarray | float, float]:
    """(leaf area factors (L,), stem radius factor) so that `thin` (pruned and thinned from
    `full`) covers on screen what `full` covers, at `px` metres per pixel (lod_cover): each
    kept leaf grows by what its region (cells of REGION_PX pixels) lost in leaves and stems,
    times one factor solved so the whole covers as `full` does (`triangle`: `thin`'s blades
    are drawn as triangle cards; `widen`: `thin`'s mesh.girth). A leafless tree thickens its
    kept branches instead."""
    if full.n_leaves and not thin.n_leaves:
        return 1.0, 1.0  # the budget holds no leaf: nothing to grow, and no branch stands in
    grid = Grid.around(full, px)
    if not (thin.n_leaves and full.n_leaves):  # leafless: the kept branches thicken
        return 1.0, _thickening(thin, grid, sides, widen, tree_cover(full, grid, sides[0]), 0.5)
    if _lost_stems(full, thin) > STEM_STANDIN * _seen(full, True)[1].sum():
        return _by_kind(full, thin, grid, px, sides, triangle, widen)
    stems = stem_area(thin, grid, sides=sides[1], girth=widen)
    target = tree_cover(full, grid, sides[0])
    return _leaf_growth(full, thin, grid, px, stems, target, triangle, True), 1.0


def _lost_stems(full: Tree, thin: Tree) -> float:
    """Stem area (seen from the side) `thin` dropped from `full`."""
    return float(_seen(full, False)[1].sum() - _seen(thin, False)[1].sum())


def _by_kind(full: Tree, thin: Tree, grid: Grid, px: float, sides, triangle: bool, widen):
    """cover_factors where the dropped stems outweigh the leaves: kept branches thicken to
    cover what `full`'s stems covered, then the leaves grow to cover what its leaves covered
    over them (their regions by the leaves they lost only), so bark stays bark-coloured; where
    the branches cannot (STEMS_REACH), the leaves grow to cover what all of `full` covered."""
    full_stems = stem_area(full, grid, sides=sides[0])
    covered = grid.cover(full_stems)
    r = 1.0
    if np.any(thin.stem_level > 0):
        r = _thickening(thin, grid, sides, widen, covered, 1.0)
    stems = stem_area(thicken(thin, r), grid, sides=sides[1], girth=widen)
    if grid.cover(stems) >= STEMS_REACH * covered:
        target = grid.cover(stems + tree_area(full, grid, sides[0], full_stems) - full_stems)
    else:  # thickened as far as they go, the kept branches fall short: leaves cover the rest
        target = tree_cover(full, grid, sides[0])
    return _leaf_growth(full, thin, grid, px, stems, target, triangle, False), r


def _thickening(thin: Tree, grid: Grid, sides, widen, target: float, lo: float) -> float:
    """The factor (in [lo, 32]) on `thin`'s branch radii at which its stems cover `target`."""
    return solve_factor(
        lambda r: grid.cover(stem_area(thicken(thin, r), grid, sides=sides[1], girth=widen)), target, lo, 32.0
    )


def _leaf_growth(
    full: Tree, thin: Tree, grid: Grid, px: float, stems, target: float, triangle: bool, for_stems: bool
):
    """Per kept leaf, the area factor at which `thin`'s blades over `stems` cover `target`: the
    regions' factors (regional_factors; `for_stems`: standing in for dropped twigs too) times
    one solved factor."""
    drawn = triangle_share(int(thin.params.leaf_shape))[0] if triangle else 1.0
    local = regional_factors(full, thin, REGION_PX * px, drawn, stems=for_stems)
    blades = Blades(thin, grid.px, LENGTH_SHARE, float(np.median(local)), triangle)
    f = solve_factor(lambda f: grid.cover(stems + blades.area(grid, f * local)), target, 0.25, 4.0)
    return f * local


def thicken(tree: Tree, factor: float) -> Tree:
    """`tree` with its branches' radii (not the trunks') × `factor`."""
    if factor == 1.0:
        return tree
    f = np.where(tree.stem_level > 0, factor, 1.0)
    return replace(tree, stem_radius=tree.stem_radius * f, node_radius=tree.node_radius * f[tree.node_stem])


def _seen(tree: Tree, leaves: bool) -> tuple[np.ndarray, np.ndarray]:
    """(points, area seen from the side, mean over directions): blade middles or stem
    segment middles."""
    if leaves:
        return tree.leaf_middle, tree.leaf_area * (1.0 - 0.5 * np.abs(tree.leaf_frame[:, 2, 2]))
    seg = tree.segments
    d = tree.node_pos[seg + 1] - tree.node_pos[seg]
    length = np.linalg.norm(d, axis=1)
    width = tree.node_radius[seg] + tree.node_radius[seg + 1]
    return tree.node_pos[seg] + 0.5 * d, width * length * np.sqrt(
        1.0 - 0.5 * (d[:, 2] / np.maximum(length, 1e-12)) ** 2
    )


def regional_factors(
    full: Tree, thin: Tree, cell: float, drawn: float = 1.0, stems: bool = True
) -> np.ndarray:
    """Per kept leaf (L,), the area factor that gives its cell (of `cell` metres) the area
    `full` showed there (leaves and stems) less the kept stems', relative to the whole crown's
    (clipped to [1/REGION_CLIP, REGION_CLIP] of it): where the dropped twigs were, leaves grow
    more (`stems=False`: its leaves' area only). `drawn`: the share of a kept blade's area its
    leaf draws (triangle cards draw part)."""
    mid, seen = _seen(thin, True)
    pts = [_seen(full, True), _seen(full, False), _seen(thin, False), (mid, drawn * seen)]
    lo = np.min([p.min(0) for p, _ in pts if len(p)], axis=0)
    ijk = np.concatenate([np.floor((p - lo) / cell).astype(np.int64) for p, _ in pts])
    span = ijk.max(axis=0) + 1 if len(ijk) else np.ones(3, dtype=np.int64)
    keys = (ijk[:, 0] * span[1] + ijk[:, 1]) * span[2] + ijk[:, 2]  # (a 1-D unique: 10× faster)
    _, flat = np.unique(keys, return_inverse=True)  # occupied cells only
    flat = flat.reshape(-1)
    n = int(flat.max()) + 1 if flat.size else 1
    ends = np.cumsum([len(p) for p, _ in pts])
    flat = np.split(flat, ends[:-1])
    sums = [np.bincount(f, weights=a, minlength=n) for f, (_, a) in zip(flat, pts)]
    want = np.maximum(sums[0] + sums[1] - sums[2], 0.0) if stems else sums[0]
    ratio = want.sum() / max(sums[3].sum(), 1e-30)
    g = np.where(sums[3] > 0, want / np.maximum(sums[3], 1e-30), ratio)[flat[3]] / ratio
    return ratio * np.clip(g, 1.0 / REGION_CLIP, REGION_CLIP)
