"""Triangle budgets of the geometric LODs: LOD k may draw at most `triangles[k]` × LOD0's
triangles (`--lod-triangles`, default 1, 0.5, 0.15, 0.05), and never more than LOD k−1.

Each LOD is cut from LOD0's tree (lod_leaves.py), in this order:
  1. sides: the LOD table's sides per level, never more than LOD0's (`--sides 5,3` caps them),
     each stem widened to LOD0's mean width (mesh.girth, which lod_cover counts too); a
     branch of at most 4 sides under RIBBON_PX wide at the switch is drawn as two crossed
     ribbons instead (mesh "twigs", double-sided bark: a square tube's outline, 4 triangles
     a segment);
  2. nodes: branch nodes within NODE_TOL_PX pixels of the chord between their neighbours are
     dropped (lod_nodes.py): a far twig needs fewer rings, so more twigs fit the budget; a
     trunk's too where it is under THIN_TRUNK_PX wide, or the trunks alone exceed the bark's
     share (a grass's stalks, which otherwise left no room for its ears);
  3. bark: stems kept thickest first (their ancestors always) while their bark, counted from the
     mesh's own ring and side formulas, fits the bark share of the budget — LOD0's share of bark
     in its triangles, so bark and leaves shrink together; a leafy tree keeps stems under
     MIN_RADIUS_PX only if they show as much area per triangle as its leaves (`worth_keeping`),
     a leafless one spreads its kept branches over the crown (`keep_stems`), its trunks'
     nodes are coarsened too and its branches end in points (cones: a twig of one segment
     costs a third of its triangles, lod_nodes.point_tips); a leafy stem dropped whose
     leaves start GAP_PX pixels or more from its base is kept as a pointed cone of a few
     segments (`floating`, lod_nodes.stub_stems), within STUB_SHARE of what is left for
     leaves: its leaves would float (the fan palm's fronds);
  4. leaves: as many stratified leaves of LOD0's as the rest of the budget holds — from
     LOD2 on, blades a few pixels long are drawn as triangle cards, one triangle each
     instead of a card's two, so twice as many stay (`TRIANGLE_CARD_PX`), but never more
     than the LOD before kept — (nested: a leaf a LOD keeps, the LODs before it keep too;
     each moves to the middle of LOD0's
     leaves it stands for, lod_leaves.gather_leaves, so it sits a little elsewhere in each
     LOD), their blades scaled so the LOD covers on screen,
     at its switch distance, what LOD0 covers (`cover_factors`, lod_factors.py): each region of a
     few pixels keeps LOD0's area (dropped twigs' bark and leaves included) within REGION_CLIP
     of the crown's growth, one factor then matches the whole. A leafless tree thickens its
     kept branches instead.

    plan = plan_lod(tree, bark0, leaf0, budget=0.15 * (bark0 + leaf0), mesh=mesh_k, px=0.03)
    # Result: plan.tree (pruned, thinned), plan.bark_estimate + plan.leaf_triangles <= budget
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .limits import bark_triangles
from .leafshapes import triangle_share
from .lod_factors import cover_factors, thicken
from .lod_nodes import coarsen_nodes, point_tips, stub_stems, twig_keys
from .lod_leaves import (
    LENGTH_SHARE,
    fit_blades,
    grow_leaves,
    prune_stems,
    stem_closure,
    thin_leaves,
)
from .mesh import MeshOptions, girth, stem_sides
from .mesh.options import FULL_CARD_CELL
from .tree import Tree, tree_box


GAP_PX = 6.0  # a dropped stem whose leaves start this many pixels out is kept as a cone
STUB_TOL_PX = 4.0  # ... within this many pixels of the stem it stands for
STUB_SHARE = 0.5  # ... while the cones take at most this share of the triangles the kept bark
# leaves for leaves
NODE_TOL_PX = 1.0  # a branch node within this many pixels of its neighbours' chord is dropped
THIN_TRUNK_PX = 1.0  # a trunk narrower than this at its base is coarsened as a branch is
MAX_TRUNK_TOL_PX = 4.0  # trunks alone over the bark's share: their nodes dropped within up to
# this many pixels of the chord (doubling from NODE_TOL_PX), one ring a segment
TRUNK_PASSES = 8  # ... in up to this many halving passes (lod_nodes.PASSES: 3)
STEM_WORTH = 1.0  # a leafy tree keeps stems showing at least this × a leaf's area per triangle
FILL_PASSES = 3  # keep_stems: passes filling what forks cut with their parent left free
MIN_RADIUS_PX = 0.5  # stems thinner than this many pixels are kept only if worth_keeping;
# a lobed trunk whose lobes are shallower than this is drawn round
RIBBON_PX = 2.0  # a branch of a few sides under this many pixels wide at the switch is drawn
# as two crossed ribbons (MeshOptions.ribbon_radius: 4 triangles a segment where a 3-sided
# tube takes 6, so more twigs and leaves fit; every branch of 4 sides or fewer, whatever its
# width, and the fan palm's far cover fell 6 %)
TRIANGLE_CARD_PX = 3.0  # a LOD from TRIANGLE_CARDS_FROM on whose switch shows LOD0's median
# blade at most this many pixels long draws its leaf cards as triangle cards
# (leafshapes.TRIANGLE_CARD, one triangle a leaf): the outline is not legible, the cover is,
# and twice the leaves fit the budget. Only over the generated atlas, whose alpha is the
# LeafShape outline triangle_share measures (not an artist's image, nor untextured cards)
MAX_BLADE_SHARE = 0.7  # a kept blade grows to at most this share of the crown's extent in
# length or width (the bundled species' far LODs reach 0.67: the fan palm's 1.5 m fronds)
TRIANGLE_CARDS_FROM = 2  # LOD index: LOD1 keeps cards, so leaves thin about evenly LOD by LOD
# (LOD1 in triangle cards held every leaf, and all the thinning fell on the next switch)


@dataclass(frozen=True, eq=False)
class LodPlan:
    tree: Tree
    bark_estimate: int  # upper bound on the bark triangles the mesh will have
    leaf_triangles: int
    area_factor: float  # kept leaves' blade area × this, on average
    mesh: MeshOptions | None = None  # the mesh options to draw it with


def capped_sides(table: tuple[int, ...], cap: tuple[int, ...]) -> tuple[int, ...]:
    """Per level the smaller of two side tables (each one's last entry repeats)."""
    n = max(len(table), len(cap))
    return tuple(min(table[min(i, len(table) - 1)], cap[min(i, len(cap) - 1)]) for i in range(n))


def keep_stems(
    tree: Tree, per_stem: np.ndarray, budget: float, allowed: np.ndarray | None = None
) -> np.ndarray:
    """Stems kept (trunks always) among the `allowed` ones (S,) while their triangles fit
    `budget`; closed under ancestors, and the budget a fork frees when its parent is cut
    goes to the next stems whose parent is kept. A leafy tree keeps its thickest stems first
    (the kept leaves make up for dropped twigs); a leafless one keeps its branches level by
    level, spread over heights and sides within a level (lod_nodes.twig_keys), so every whorl
    and limb keeps a share of its branches rather than the thick lower ones keeping all."""
    trunk = (tree.stem_level != 0).astype(np.int8)
    if tree.n_leaves:
        order = np.lexsort((np.arange(tree.n_stems), -tree.stem_radius, trunk))
    else:
        key = twig_keys(tree)
        order = np.lexsort((np.arange(tree.n_stems), key, tree.stem_level, trunk))
    if allowed is not None:
        order = order[(allowed | (tree.stem_level == 0))[order]]
    total = np.cumsum(per_stem[order])
    keep = np.zeros(tree.n_stems, dtype=bool)
    keep[order[total <= budget]] = True
    keep = stem_closure(tree, keep)
    parent = tree.stem_parent
    for _ in range(FILL_PASSES):  # budget freed by stems whose parent was cut: their siblings
        rest = order[~keep[order] & (parent[order] >= 0) & keep[np.maximum(parent[order], 0)]]
        add = rest[float(per_stem[keep].sum()) + np.cumsum(per_stem[rest]) <= budget]
        if not add.size:
            break
        keep[add] = True
    return keep


def plan_lod(
    tree: Tree,
    bark0: int,
    leaf0: int,
    budget: float,
    mesh: MeshOptions,
    px: float,
    mesh0: MeshOptions | None = None,
    triangle_cards: bool = False,
    max_leaves: int | None = None,
) -> LodPlan:
    """LOD `tree` within `budget` triangles for `mesh` (see the module doc). `bark0`, `leaf0`:
    LOD0's bark and leaf triangles; `px`: metres a pixel spans at the LOD's switch distance;
    `triangle_cards`: blades under TRIANGLE_CARD_PX may be drawn as triangle cards."""
    min_radius = MIN_RADIUS_PX * px
    total0 = bark0 + leaf0
    full, p = tree, tree.params  # LOD0 as drawn (lobes included): the cover to keep
    if (
        p.lobes > 0
        and p.lobe_depth != 0
        and tree.n_stems
        and abs(p.lobe_depth) * float(tree.stem_radius[0]) < min_radius
    ):
        tree = replace(tree, params=replace(p, lobe_depth=0.0))  # lobes under a pixel: round
    per_stem = bark_triangles(tree, mesh)
    if budget >= total0 and per_stem.sum() <= bark0:
        return LodPlan(tree, int(per_stem.sum()), leaf0, 1.0)
    # trunks keep their nodes, but a leafless tree's, one under a pixel wide at its base
    # (barley's 19 stalks, 2 mm: each kept ~99 rings, LOD3 at 78 % of LOD0's triangles), or
    # all of them when they alone exceed the bark's share (barley's stalks at LOD1 and LOD2)
    thin = 2.0 * tree.stem_radius < THIN_TRUNK_PX * px
    share = bark0 / total0 if total0 else 1.0
    trunk = tree.stem_level == 0
    over = bool(per_stem[trunk].sum() > budget * share)
    coarse = coarsen_nodes(tree, NODE_TOL_PX * px, trunks=(not leaf0) | over | thin)

    def still_over() -> bool:
        return bool(bark_triangles(coarse, mesh)[trunk].sum() > budget * share)

    if over and still_over():  # one ring a segment, then the trunks' nodes coarser, until they fit
        mesh = replace(mesh, rings_per_segment=(1,))
        tol = NODE_TOL_PX
        while still_over() and (tol := 2.0 * tol) <= MAX_TRUNK_TOL_PX:
            # from LOD0's nodes each time (a coarsened tree's chords would add up the errors),
            # as many halvings as the tolerance allows (a stalk's 50 nodes kept 7 in PASSES)
            trunks = coarsen_nodes(tree, tol * px, trunks=True, stems=trunk, passes=TRUNK_PASSES)
            coarse = coarsen_nodes(trunks, NODE_TOL_PX * px, trunks=False)
    if not leaf0:  # a leafless crown is its twigs: cones, three for the price of one
        coarse = point_tips(coarse)
    per_stem = bark_triangles(coarse, mesh)
    L = tree.n_leaves
    triangle = (
        triangle_cards
        and bool(L)
        and mesh.leaf_geometry == "card"
        and mesh.leaf_cells != FULL_CARD_CELL  # the generated atlas: its alpha is the outline
        and float(np.median(tree.leaf_size[:, 0])) <= TRIANGLE_CARD_PX * px
    )
    if triangle:
        mesh = replace(mesh, leaf_geometry="triangle")
    per_leaf = (1.0 if triangle else leaf0 / L) if L else 0.0  # triangles a kept leaf costs
    worth = None
    if leaf0:  # stems a pixel wide carry the crown (and its joints); thinner ones must show
        worth = (coarse.stem_radius >= min_radius) | worth_keeping(coarse, per_stem, per_leaf)
    keep = keep_stems(coarse, per_stem, budget * share, worth)
    if leaf0:  # leaves far out on a dropped stem would float: the stem stays, as a cone
        coarse, per_stem, keep = _stubs(coarse, per_stem, keep, mesh, px, budget)
    pruned = prune_stems(coarse, keep)
    room = math.floor((budget - per_stem[keep].sum()) / per_leaf) if L else 0
    if L and room < 1:  # trunks alone over the budget: the leaves keep their share of it (one
        # leaf grown to stand for the crown was a card 883 m wide; none, the crown vanished
        # for a LOD and came back at the impostor: the rush's LOD3 under --profile web)
        room = math.floor((1.0 - share) * budget / per_leaf)
    n_keep = int(min(L, max(0, room), L if max_leaves is None else max_leaves))
    thin = thin_leaves(pruned, n_keep, 1.0)
    if triangle:
        thin = triangle_blades(thin)
    sides = (stem_sides(full, mesh0 or mesh), stem_sides(thin, mesh))
    leaf, radius = cover_factors(full, thin, px, sides, triangle, girth(thin, mesh, sides[1]))
    if thin.n_leaves:
        leaf = capped_growth(thin, leaf, MAX_BLADE_SHARE * float(np.ptp(full.leaf_pos, axis=0).max()))
    mesh_thin = mesh
    if radius != 1.0:  # thicker stems draw the same rings, sides and ribbons
        thin = thicken(thin, radius)
        mesh_thin = replace(
            mesh, thin_radius=mesh.thin_radius * radius, ribbon_radius=mesh.ribbon_radius * radius
        )
    bark = int(bark_triangles(thin, mesh_thin).sum())
    grown = fit_blades(grow_leaves(thin, leaf), *tree_box(full))
    return LodPlan(grown, bark, int(round(n_keep * per_leaf)), float(np.mean(leaf)), mesh_thin)


def _stubs(tree: Tree, per_stem: np.ndarray, keep: np.ndarray, mesh: MeshOptions, px: float, budget: float):
    """(tree, per_stem, keep) with the `floating` stems kept as cones (lod_nodes.stub_stems),
    those carrying the most leaf area first, while they fit STUB_SHARE of what the kept bark
    leaves of the budget (a tight `--lod-triangles` keeps its leaves rather than stubs)."""
    stubs = floating(tree, keep, GAP_PX * px)
    if not stubs.any():
        return tree, per_stem, keep
    stubbed = stub_stems(tree, stubs, STUB_TOL_PX * px)
    cost = bark_triangles(stubbed, mesh)
    carried = np.bincount(tree.leaf_stem, weights=tree.leaf_area, minlength=tree.n_stems)
    order = np.flatnonzero(stubs)
    order = order[np.lexsort((order, -carried[order]))]
    room = STUB_SHARE * max(budget - float(per_stem[keep].sum()), 0.0)
    chosen = order[np.cumsum(cost[order]) <= room]
    if not chosen.size:
        return tree, per_stem, keep
    which = np.zeros(tree.n_stems, dtype=bool)
    which[chosen] = True
    stubbed = stub_stems(tree, which, STUB_TOL_PX * px)
    return stubbed, bark_triangles(stubbed, mesh), keep | which


def floating(tree: Tree, keep: np.ndarray, gap: float) -> np.ndarray:
    """Stems (S,) dropped from `keep` whose parent is kept and whose nearest leaf is `gap`
    metres or more from their base: dropped, their leaves would hang in the air that far from
    any bark (the fan palm's fronds at the end of long petioles), where a dropped twig's
    leaves still sit against its parent."""
    S = tree.n_stems
    if not tree.n_leaves or keep.all():
        return np.zeros(S, dtype=bool)
    base = tree.node_pos[tree.stem_node_start[tree.leaf_stem]]
    reach = np.full(S, np.inf)
    np.minimum.at(reach, tree.leaf_stem, np.linalg.norm(tree.leaf_pos - base, axis=1))
    parent = tree.stem_parent
    return ~keep & (parent >= 0) & keep[np.maximum(parent, 0)] & np.isfinite(reach) & (reach >= gap)


def triangle_blades(tree: Tree) -> Tree:
    """`tree`'s blades sized and placed for triangle cards: grown alike in length and width
    by what the triangle cuts off (leafshapes.triangle_share), and moved so the part drawn
    is centred where the blade was."""
    share, dy = triangle_share(int(tree.params.leaf_shape))
    grown = grow_leaves(tree, 1.0 / share, length_share=0.5)
    pos = grown.leaf_pos - (dy * grown.leaf_size[:, 0])[:, None] * grown.leaf_frame[:, :, 1]
    return replace(grown, leaf_pos=pos)


def capped_growth(tree: Tree, factor, cap: float):
    """`factor` (scalar or (L,)), each blade's area growth, cut where it would draw the blade's
    length or width past `cap` metres (past its own, where that is longer already): a LOD whose
    budget holds a handful of leaves would grow each to stand for a part of the crown.
    `factor` itself where no blade reaches the cap."""
    f = np.broadcast_to(np.asarray(factor, dtype=np.float64), (tree.n_leaves,))
    size = np.maximum(tree.leaf_size, 1e-12)
    most = np.minimum(
        (np.maximum(cap, size[:, 0]) / size[:, 0]) ** (1.0 / LENGTH_SHARE),
        (np.maximum(cap, size[:, 1]) / size[:, 1]) ** (1.0 / (1.0 - LENGTH_SHARE)),
    )
    return factor if np.all(f <= most) else np.minimum(f, most)


def worth_keeping(tree: Tree, per_stem: np.ndarray, per_leaf: float) -> np.ndarray:
    """Stems (S,) that show at least as much area per triangle as the leaves do (seen from
    the side, mean over directions: a stem 2r × length × π/4, a blade its area / 2): twigs
    dropped for leaves would have to be made up by growing the kept leaves further."""
    seg = tree.segments
    length = np.linalg.norm(tree.node_pos[seg + 1] - tree.node_pos[seg], axis=1)
    width = tree.node_radius[seg] + tree.node_radius[seg + 1]
    area = np.bincount(tree.node_stem[seg], weights=width * length, minlength=tree.n_stems) * (np.pi / 4)
    leaf = 0.5 * float(np.mean(tree.leaf_area)) / per_leaf
    return area / np.maximum(per_stem, 1) >= STEM_WORTH * leaf


def _triangles(lod, name: str | None = None) -> int:
    return sum(len(p.indices) // 3 for p in lod.primitives if name is None or p.name == name)


def triangle_fraction(table: tuple[float, ...], k: int) -> float:
    """LOD `k`'s share of LOD0's triangles: `table[k]`, and beyond the table each further LOD
    a step of the table's last ratio down (0.15, 0.05: a third each), never up (the last
    value repeated made a fifth distance's LOD a copy of the fourth's)."""
    if k < len(table):
        return table[k]
    ratio = min(table[-1] / table[-2], 1.0) if len(table) > 1 and table[-2] > 0 else 1.0
    return table[-1] * ratio ** (k - len(table) + 1)


def lod_budget(k: int, lod0, previous, options) -> float:
    """Triangles LOD `k` may have: its fraction of LOD0's, never above the LOD before it."""
    frac = min(triangle_fraction(options.triangles, i) for i in range(k + 1))
    return min(frac * _triangles(lod0), _triangles(previous))


def lod_tree(
    tree: Tree, k: int, lod0, previous, rig_options, mesh_options, options, leaves: int | None = None
):
    """(Tree, RigOptions, MeshOptions) of LOD `k` > 0, cut from LOD0's `tree` within its
    triangle budget (`lod0`, `previous`: the LODs built so far, first and last) and keeping
    at most `leaves`, the LOD before's (Arbaro's wheat, in triangle cards from LOD2 on, kept
    all 1,715 leaves after LOD1's 857: thinned, then back)."""
    table = options.sides[min(k, len(options.sides) - 1)]
    mesh = replace(
        mesh_options, sides=capped_sides(table, mesh_options.sides), match_sides=mesh_options.sides
    )
    frac = options.joint_fraction[min(k, len(options.joint_fraction) - 1)]
    rig = (
        replace(rig_options, max_joints=max(1, int(round(rig_options.max_joints * frac))))
        if frac < 1.0
        else rig_options
    )
    from .lod import pixel_size

    px = pixel_size(options.distances[k], options)
    mesh = replace(mesh, ribbon_radius=0.5 * RIBBON_PX * px)
    plan = plan_lod(
        tree,
        _triangles(lod0, "bark"),
        _triangles(lod0, "leaves"),
        lod_budget(k, lod0, previous, options),
        mesh,
        px,
        mesh_options,
        k >= TRIANGLE_CARDS_FROM,
        leaves,
    )
    return plan.tree, rig, plan.mesh or mesh
