"""Triangle budgets of the geometric LODs: LOD k may draw at most `triangles[k]` × LOD0's
triangles (`--lod-triangles`, default 1, 0.5, 0.15, 0.05), and never more than LOD k−1.

Each LOD is cut from LOD0's tree (lod_leaves.py), in this order:
  1. sides: the LOD table's sides per level, never more than LOD0's (`--sides 5,3` caps them);
  2. bark: stems kept thickest first (their ancestors always) while their bark, counted from the
     mesh's own ring and side formulas, fits the bark share of the budget — LOD0's share of bark
     in its triangles, so bark and leaves shrink together;
  3. leaves: as many stratified leaves as the rest of the budget holds, their blades scaled so
     the LOD covers what LOD0 covers (`leaf_factor`; kept stems thicken where bark shows most: `radius_factor`).

    plan = plan_lod(tree, lod0_counts, budget=0.15 * lod0_total, mesh=mesh_k)
    # Result: plan.tree (pruned, thinned), plan.bark_estimate + plan.leaf_triangles <= budget
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .limits import bark_triangles
from .lod_leaves import prune_stems, stem_closure, thin_leaves
from .mesh import MeshOptions
from .tree import Tree


CELL = 1.0               # Boolean-model cell, in enlarged leaves (projected_cover)
BARK_SHOWS = 0.9         # bark's share of the shown area above which dropped stems thicken kept ones
MIN_RADIUS_PX = 0.5      # stems thinner than this many pixels at the LOD's distance are dropped


@dataclass(frozen=True, eq=False)
class LodPlan:
    tree: Tree
    bark_estimate: int          # upper bound on the bark triangles the mesh will have
    leaf_triangles: int
    area_factor: float          # each kept leaf's blade area × this
    mesh: MeshOptions | None = None   # the mesh options to draw it with


def capped_sides(table: tuple[int, ...], cap: tuple[int, ...]) -> tuple[int, ...]:
    """Per level the smaller of two side tables (each one's last entry repeats)."""
    n = max(len(table), len(cap))
    return tuple(min(table[min(i, len(table) - 1)], cap[min(i, len(cap) - 1)]) for i in range(n))


def keep_stems(tree: Tree, per_stem: np.ndarray, budget: float, min_radius: float = 0.0) -> np.ndarray:
    """Stems kept thickest first (trunks always) while their triangles fit `budget` and their
    base radius is at least `min_radius`; closed under ancestors."""
    order = np.lexsort((np.arange(tree.n_stems), -tree.stem_radius,
                        (tree.stem_level != 0).astype(np.int8)))
    total = np.cumsum(per_stem[order])
    keep = np.zeros(tree.n_stems, dtype=bool)
    keep[order[total <= budget]] = True
    keep &= tree.stem_radius >= min_radius
    return stem_closure(tree, keep)


def plan_lod(tree: Tree, bark0: int, leaf0: int, budget: float, mesh: MeshOptions,
             min_radius: float = 0.0) -> LodPlan:
    """LOD `tree` within `budget` triangles for `mesh` (see the module doc). `bark0`, `leaf0`:
    LOD0's bark and leaf triangles."""
    total0 = bark0 + leaf0
    p = tree.params
    if p.lobes > 0 and p.lobe_depth != 0 and tree.n_stems and \
            abs(p.lobe_depth) * float(tree.stem_radius[0]) < min_radius:
        tree = replace(tree, params=replace(p, lobe_depth=0.0))   # lobes under a pixel: round
    per_stem = bark_triangles(tree, mesh)
    if budget >= total0 and per_stem.sum() <= bark0:
        return LodPlan(tree, int(per_stem.sum()), leaf0, 1.0)
    share = bark0 / total0 if total0 else 1.0
    keep = keep_stems(tree, per_stem, budget * share, min_radius if leaf0 else 0.0)
    pruned = prune_stems(tree, keep)
    L = tree.n_leaves
    per_leaf = leaf0 / L if L else 0.0
    n_keep = int(min(L, max(1, math.floor((budget - per_stem[keep].sum()) / per_leaf)))) if L else 0
    leaf = leaf_factor(tree, thin_leaves(pruned, n_keep, 1.0))
    radius = radius_factor(tree, keep)
    if radius != 1.0:     # thicker stems draw the same rings; sides cut to the bark table's
        pruned = replace(pruned, stem_radius=pruned.stem_radius * radius,
                         node_radius=pruned.node_radius * radius)
        mesh_thin = replace(mesh, thin_radius=mesh.thin_radius * radius)
    else:
        mesh_thin = mesh
    bark = int(bark_triangles(pruned, mesh_thin).sum())
    return LodPlan(thin_leaves(pruned, n_keep, leaf), bark, int(round(n_keep * per_leaf)), leaf,
                   mesh_thin)


def _splats(tree: Tree, leaf_factor: float = 1.0):
    """Leaf blades as what covers the view: centres, areas, normals (seen × |n·v|)."""
    if not tree.n_leaves:
        return None
    F = tree.leaf_frame
    return (tree.leaf_pos + (0.5 * tree.leaf_size[:, 0])[:, None] * F[:, :, 1],
            tree.leaf_area * leaf_factor, F[:, :, 2])


def projected_cover(splats, cell: float) -> float:
    """Cover (m²) seen from four sides, by the Boolean model per cell of a `cell`-metre grid:
    1 − exp(−projected area in the cell / cell area), summed. Leaves that clump together (on
    one twig) overlap and cover less than their area, which is why thinning and enlarging
    them changes the cover unless the factor is solved for."""
    if splats is None:
        return 0.0
    pts, area, normal = splats
    total = 0.0
    for view in ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)):
        v = np.array([view[0], view[1], 0.0])
        side = np.array([-view[1], view[0], 0.0])
        seen = area * np.abs(normal @ v)
        u = np.floor(pts @ side / cell).astype(np.int64)
        w = np.floor(pts[:, 2] / cell).astype(np.int64)
        key = (u - u.min()) * (int(w.max() - w.min()) + 1) + (w - w.min())
        a = np.bincount(key, weights=seen)
        total += float(np.sum(1.0 - np.exp(-a[a > 0] / (cell * cell)))) * cell * cell
    return total / 4.0


def _solve(cover_at, target: float, lo: float, hi: float) -> float:
    """The factor in [lo, hi] (log-bisection) at which the increasing `cover_at` meets `target`."""
    lo, hi = math.log(lo), math.log(hi)
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cover_at(math.exp(mid)) < target else (lo, mid)
    return math.exp(0.5 * (lo + hi))


def leaf_factor(full: Tree, kept: Tree) -> float:
    """Blade area factor for `kept` (thinned leaves of `full`) so its leaves cover what
    `full`'s cover (`projected_cover`, cells the size of the enlarged leaves)."""
    if not kept.n_leaves or not full.n_leaves:
        return 1.0
    base = float(full.leaf_area.sum() / max(kept.leaf_area.sum(), 1e-30))
    cell = CELL * float(np.sqrt(np.mean(full.leaf_size[:, 0] * full.leaf_size[:, 1]) * base))
    target = projected_cover(_splats(full), cell)
    return _solve(lambda f: projected_cover(_splats(kept, f), cell), target,
                  base / 4.0, base * 4.0)


def _stem_area(tree: Tree) -> np.ndarray:
    """Side-on area of each stem (S,): length × twice its mean node radius."""
    r = np.bincount(tree.node_stem, weights=tree.node_radius, minlength=tree.n_stems)
    return 2.0 * tree.stem_length * r / np.maximum(tree.stem_node_count, 1)


def radius_factor(full: Tree, keep: np.ndarray) -> float:
    """Radius factor for the stems `keep` of `full` so they show the bark area the dropped
    ones showed, when bark is nearly all the tree shows (a share of at least BARK_SHOWS, leaves
    seen at random angles showing half their area): a bush of bare twigs or a horsetail keeps
    its cover. In a leafy crown the leaves hid the twigs and make up for them (`leaf_factor`)."""
    area = _stem_area(full)
    kept = float(area[keep].sum())
    dropped = float(area.sum()) - kept
    if dropped <= 0 or kept <= 0:
        return 1.0
    share = float(area.sum()) / (float(area.sum()) + 0.5 * float(full.leaf_area.sum()))
    return 1.0 + share * dropped / kept if share >= BARK_SHOWS else 1.0


def _triangles(lod, name: str | None = None) -> int:
    return sum(len(p.indices) // 3 for p in lod.primitives if name is None or p.name == name)


def lod_budget(k: int, lod0, previous, options) -> float:
    """Triangles LOD `k` may have: its fraction of LOD0's, never above the LOD before it."""
    frac = min(options.triangles[min(i, len(options.triangles) - 1)] for i in range(k + 1))
    return min(frac * _triangles(lod0), _triangles(previous))


def lod_tree(tree: Tree, k: int, lod0, previous, rig_options, mesh_options, options):
    """(Tree, RigOptions, MeshOptions) of LOD `k` > 0, cut from LOD0's `tree` within its
    triangle budget (`lod0`, `previous`: the LODs built so far, first and last)."""
    table = options.sides[min(k, len(options.sides) - 1)]
    mesh = replace(mesh_options, sides=capped_sides(table, mesh_options.sides))
    frac = options.joint_fraction[min(k, len(options.joint_fraction) - 1)]
    rig = replace(rig_options, max_joints=max(1, int(round(rig_options.max_joints * frac)))) \
        if frac < 1.0 else rig_options
    from .lod import pixel_size

    px = pixel_size(options.distances[k], options)
    plan = plan_lod(tree, _triangles(lod0, "bark"), _triangles(lod0, "leaves"),
                    lod_budget(k, lod0, previous, options), mesh, MIN_RADIUS_PX * px)
    return plan.tree, rig, plan.mesh or mesh
