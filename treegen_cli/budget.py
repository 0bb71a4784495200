"""Triangle budgets: pick the generator's own levers so LOD0 lands on `--triangles N`.

A budget is met before the tree is built for good, with the levers the LOD planner coarsens
trees with (lod.py): LeafQuality (fewer, larger leaves with the same total area, or more,
smaller ones), stem sides and rings per segment, and dropping the finest stem levels (leaves
move to the new finest level, their count kept by keep_leaf_count and their area matched
through LeafScale). The size is known exactly from one generate pass: bark triangles follow
from the stems and the mesh options (limits.estimate_triangles, what mesh.build_mesh emits),
and the leaf count is linear in LeafQuality (the generator error-diffuses count × quality over
the whole level), so each candidate costs a sum over the stems, not a mesh.

    plan = plan_budget(params, seed, MESH_DEFAULTS, BudgetOptions(triangles=20_000))
    # Result (weeping willow, 1.67 M triangles): plan.params has 3 stem levels (its hanging
    # whips kept, CurveRes ×¼) and ×1/118 of LeafQuality; plan.mesh thinner stems;
    # plan.triangles ≈ 20,000 exactly as built.

Choice: among candidates (levels dropped, a scale on every level's sides, rings per segment)
the bark takes about the species' own bark share of the budget (clamped to `bark_share`) and
the leaves the rest, each held to its share both ways (log of the ratio), restructuring
(levels dropped, CurveRes coarsened) counting against a candidate; candidates whose total
cannot land in [(1 − tolerance)·N, N] are skipped, so a budget is never exceeded. A budget
below every candidate is refused naming the smallest one the species reaches; a budget above
the finest candidate builds that one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import TreegenError
from .generate import DEFAULTS as GENERATE_DEFAULTS, GenerateOptions, generate, regrow_leaves
from .limits import estimate_triangles, leaf_outline
from .mesh import MeshOptions
from .params import Params


def keep_leaf_count(params, levels: int, quality: float):
    """`params` with `Leaves` scaled so a tree grown with `levels` stem levels (leaves moved to
    the new finest level) has about as many leaves as the full tree at LeafQuality `quality`,
    by the generator's own count estimate."""
    from .generate import estimate_counts

    _, full = estimate_counts(params, leaf_quality=quality)
    _, fewer = estimate_counts(params, leaf_quality=quality, levels=levels)
    if fewer > 0 and full > 0:
        params = replace(params, leaves=params.leaves * full / fewer)
    return params


@dataclass(frozen=True)
class BudgetOptions:
    """triangles: LOD0 target (None: the species as it is). leaf_quality: bounds on the factor
    applied to the species' LeafQuality (leaf sides scale by 1/√factor: ×16 … ×½). side_scales:
    factors on every level's sides (rounded, at least 3, at most 64), finest first;
    `fixed_sides`: the user gave --sides, keep them. rings: rings per segment per level
    (MeshOptions.rings_per_segment), finest first. min_levels: never fewer stem levels (as the
    LOD planner). bark_share: the species' own bark fraction of its triangles, clamped to this
    range, is the bark's share of the budget. `ceiling`: the budget came from a --profile,
    which only brings a heavier species down to it: one already under it is built as its file
    says (a phone's profile made a 1.2 m grass clump 1.45× and a fan palm 2.3× heavier)."""

    triangles: int | None = None
    ceiling: bool = False
    tolerance: float = 0.10  # LOD0 lands in [(1 − tolerance)·triangles, triangles]
    leaf_quality: tuple[float, float] = (1.0 / 256.0, 4.0)
    side_scales: tuple[float, ...] = (2.0, 1.75, 1.5, 1.25, 1.0, 0.85, 0.7, 0.6, 0.5, 0.4, 0.3, 0.0)
    fixed_sides: bool = False
    rings: tuple[tuple[int, ...], ...] = ((2, 1), (1,))
    min_levels: int = 2
    curve_scales: tuple[float, ...] = (1.0, 0.5, 0.25)
    bark_share: tuple[float, float] = (0.2, 0.8)
    drop_cost: float = 1.0  # a dropped level weighs as much as a share off by ×e
    flag: str = "--triangles"  # what the user set the budget with (a forest: defaults.triangles)
    curve_cost: float = 0.2  # per halving of CurveRes

    def __post_init__(self) -> None:
        if self.triangles is not None and not 1 <= self.triangles <= 100_000_000:
            raise TreegenError(f"--triangles {self.triangles}: allowed range 1..100000000")


DEFAULTS = BudgetOptions()
LEAF_ROOM = 0.75  # share of the triangles between the bark and the budget the leaves may take


@dataclass(frozen=True)
class Plan:
    """What plan_budget chose: the species and mesh options to build LOD0 with, and its exact
    triangle counts (bark + leaves) as mesh.build_mesh will emit them."""

    params: Params
    mesh: MeshOptions
    triangles: int
    bark: int
    leaves: int
    levels: int
    leaf_factor: float  # × the species' LeafQuality
    curve_scale: float  # × every branch level's CurveRes
    minimum: int  # fewest triangles any candidate reaches
    maximum: int  # most triangles among the candidates searched
    under: int | None = None  # a profile's ceiling the species was already under (as it is)

    def describe(self) -> str:
        if self.under is not None:
            return (
                f"{self.triangles:,} triangles ({self.bark:,} bark, {self.leaves:,} leaves): the "
                "species as it is (a profile's budget only brings a heavier species down)"
            )
        sides = ",".join(str(s) for s in self.mesh.sides)
        return (
            f"{self.triangles:,} triangles ({self.bark:,} bark, {self.leaves:,} leaves): "
            f"{self.levels} stem levels, CurveRes ×{self.curve_scale:g}, sides {sides}, "
            f"LeafQuality ×{self.leaf_factor:.3g}"
        )


@dataclass(frozen=True)
class _Candidate:
    tree: int  # index into candidates()
    cost: float  # restructuring: levels dropped, CurveRes coarsened
    mesh: MeshOptions
    bark: int
    factor: float
    leaves: int  # leaf count
    total: int


def _scaled_sides(sides: tuple[int, ...], k: float) -> tuple[int, ...]:
    return tuple(int(min(64, max(3, round(s * k)))) for s in sides)


def _mesh_ladder(mesh: MeshOptions, options: BudgetOptions, coarsen: bool) -> list[MeshOptions]:
    """Mesh options to try: sides scaled down (coarsen) or up, fewer rings only to coarsen."""
    scales = (
        (1.0,)
        if options.fixed_sides
        else tuple(k for k in options.side_scales if (k <= 1.0 if coarsen else k >= 1.0))
    )
    rings_options = options.rings if coarsen else options.rings[:1]
    out: list[MeshOptions] = []
    for k in scales:
        for rings in rings_options:
            m = replace(mesh, sides=_scaled_sides(mesh.sides, k), rings_per_segment=rings)
            if m not in out:
                out.append(m)
    return out


def _leaf_count(per_unit: float, factor: float) -> int:
    return int(math.floor(per_unit * factor + 0.5))


def _leaves_per_unit(small, params: Params, fmin: float, generate_options: GenerateOptions) -> float:
    """Leaves per unit of LeafQuality factor, counted on `small` (grown at factor `fmin`). A
    species whose leaves all round away at `fmin` (a few dozen leaves in all) is counted again
    at factor 1: taken for leafless, its budget plan left them out and the build, which grows
    them, went over the budget (1,506 triangles for --triangles 1500)."""
    if small.n_leaves or not params.leaves:
        return small.n_leaves / fmin
    return float(regrow_leaves(small, params, generate_options).n_leaves)


def _fewer_levels(params: Params, levels: int) -> Params:
    return replace(keep_leaf_count(params, levels, params.leaf_quality), levels=levels)


def _coarser_curves(params: Params, scale: float) -> Params:
    """`params` with every branch level's CurveRes (segments per stem) × scale, at least 1;
    the trunk keeps its own."""
    level = tuple(
        lp if n == 0 else replace(lp, curve_res=max(1, int(round(lp.curve_res * scale))))
        for n, lp in enumerate(params.level)
    )
    return replace(params, level=level)


def candidates(
    params: Params,
    seed: int,
    options: BudgetOptions,
    coarsen: bool,
    generate_options: GenerateOptions = GENERATE_DEFAULTS,
    first=None,
):
    """The trees every candidate's size is counted on: per (CurveRes scale, levels dropped),
    the species so changed (`Leaves` keeping the count, keep_leaf_count) grown once with
    the fewest leaves (LeafQuality × the lower bound: stems cost the same, leaves next to
    nothing), and its leaves per unit of LeafQuality factor."""
    fmin = options.leaf_quality[0]
    out = []
    seen = []
    for c in options.curve_scales if coarsen else (1.0,):
        pc = _coarser_curves(params, c)
        if pc in seen:
            continue
        seen.append(pc)
        base = first if c == 1.0 else None
        drops = range(0, max(params.levels - options.min_levels, 0) + 1) if coarsen else (0,)
        for drop in drops:
            p = _fewer_levels(pc, params.levels - drop) if drop else pc
            small = replace(p, leaf_quality=p.leaf_quality * fmin)
            t = (
                generate(small, seed, generate_options)
                if base is None
                else base
                if drop == 0
                else regrow_leaves(base, small, generate_options)
            )
            base = t if base is None else base
            out.append((c, drop, p, t, _leaves_per_unit(t, p, fmin, generate_options)))
    return out


def leaf_room(bark: int, T: int, options: BudgetOptions) -> float:
    """Leaf triangles a candidate with `bark` aims for: up to the window's middle, and once
    the bark nears it, LEAF_ROOM of what is left below T (continuous, growing with T; the
    rest is rounding's margin): aiming at the middle alone left nothing past it, so Arbaro's
    wheat at 20,000 kept 7 grains grown 16× (green discs), and a budget 10 triangles larger
    could keep fewer leaves."""
    aim = T * (1.0 - 0.5 * options.tolerance)
    return max(aim - bark, LEAF_ROOM * (T - bark))


def plan_budget(
    params: Params,
    seed: int,
    mesh: MeshOptions,
    options: BudgetOptions = DEFAULTS,
    generate_options: GenerateOptions = GENERATE_DEFAULTS,
) -> Plan:
    """Choose CurveRes, levels, sides, rings and LeafQuality for LOD0 to land in
    [(1 − tolerance)·triangles, triangles] (see the module doc)."""
    T = options.triangles
    if T is None:
        raise ValueError("plan_budget needs options.triangles")
    if options.ceiling:
        bark, leaves = estimate_triangles(generate(params, seed, generate_options), mesh)
        if bark + leaves <= T:
            n = bark + leaves
            return Plan(params, mesh, n, bark, leaves, params.levels, 1.0, 1.0, n, n, under=T)
    fmin, fmax = options.leaf_quality
    # The candidates are probes, never written: LeafQuality × 1/256 grows leaves 16× longer, over
    # a tight --max-size where the tree the plan picks is not; that tree is grown (and held to
    # the bound) by the caller.
    generate_options = replace(generate_options, max_size=math.inf)
    first = generate(replace(params, leaf_quality=params.leaf_quality * fmin), seed, generate_options)
    tri_per_leaf = len(leaf_outline(first, mesh).triangles) if mesh.leaves else 0
    bark0 = estimate_triangles(first, mesh)[0]
    leaves0 = tri_per_leaf * _leaf_count(_leaves_per_unit(first, params, fmin, generate_options), 1.0)
    lo, hi = options.bark_share
    share = min(max(bark0 / max(bark0 + leaves0, 1), lo), hi)
    coarsen = T < bark0 + leaves0  # over budget: coarsen; under it: refine
    trees = candidates(params, seed, options, coarsen, generate_options, first)
    aim = T * (1.0 - 0.5 * options.tolerance)  # the middle of [(1 − tolerance)·T, T]

    found: list[_Candidate] = []
    minimum, maximum = bark0 + leaves0, bark0 + leaves0
    for i, (c, drop, _p, t, per_unit) in enumerate(trees):
        per_unit = per_unit if tri_per_leaf else 0.0
        for m in _mesh_ladder(mesh, options, coarsen):
            bark = estimate_triangles(t, m)[0]
            minimum = min(minimum, bark + tri_per_leaf * _leaf_count(per_unit, fmin))
            maximum = max(maximum, bark + tri_per_leaf * _leaf_count(per_unit, fmax))
            factor = 1.0
            if per_unit:
                factor = min(max(leaf_room(bark, T, options) / (tri_per_leaf * per_unit), fmin), fmax)
            n = _leaf_count(per_unit, factor)
            cost = drop * options.drop_cost + math.log2(1.0 / c) * options.curve_cost
            found.append(_Candidate(i, cost, m, bark, factor, n, bark + tri_per_leaf * n))

    if T < minimum:
        raise TreegenError(
            f"species '{params.name}' cannot come down to {options.flag} {T:,}: the fewest "
            f"triangles it reaches at LOD0 is {minimum:,} (fewest levels, segments, sides and "
            f"leaves); use {options.flag} {minimum} or more"
        )
    fits = [c for c in found if (1.0 - options.tolerance) * T <= c.total <= T]
    if fits:  # the bark's share and the leaves' (both ways off), least restructuring
        target_bark = aim if leaves0 == 0 else share * aim
        target_leaf = max((1.0 - share) * aim, 1.0) if leaves0 else None

        def off(c: _Candidate) -> float:
            leaf = c.total - c.bark
            bark_off = abs(math.log(max(c.bark, 1) / target_bark))
            return bark_off + (abs(math.log(max(leaf, 1) / target_leaf)) if target_leaf else 0.0)

        best = min(fits, key=lambda c: (off(c) + c.cost, abs(c.total - aim)))
    else:  # the nearest below T (the largest when T is above all)
        best = min(found, key=lambda c: (c.total > T, abs(c.total - aim), c.cost))
    return _realise(params, trees, best, tri_per_leaf, generate_options, minimum, maximum, options, T)


def _realise(
    params,
    trees,
    best: _Candidate,
    tri_per_leaf: int,
    generate_options,
    minimum: int,
    maximum: int,
    options: BudgetOptions,
    T: int,
) -> Plan:
    """The chosen candidate as species parameters, its leaves regrown to count them exactly
    (corrected once or twice for rounding), leaf area matched to the species' own tree."""
    c, drop, p, t, per_unit = trees[best.tree]
    factor, grown = best.factor, t
    fmin, fmax = options.leaf_quality
    if tri_per_leaf and per_unit:
        for _ in range(3):
            grown = regrow_leaves(t, replace(p, leaf_quality=params.leaf_quality * factor), generate_options)
            want = leaf_room(best.bark, T, options) / tri_per_leaf
            total = best.bark + tri_per_leaf * grown.n_leaves
            if grown.n_leaves == 0 or (1.0 - options.tolerance) * T <= total <= T or not fmin < factor < fmax:
                break
            factor = min(max(factor * want / grown.n_leaves, fmin), fmax)
        p = replace(p, leaf_quality=params.leaf_quality * factor)
        if drop or c != 1.0:  # same total leaf area as the species' own tree
            area, full = float(np.sum(grown.leaf_area)), float(np.sum(trees[0][3].leaf_area))
            if area > 0 and full > 0:
                p = replace(p, leaf_scale=p.leaf_scale * math.sqrt(full / area))
    leaves = tri_per_leaf * grown.n_leaves if tri_per_leaf else 0
    return Plan(
        params=p,
        mesh=best.mesh,
        triangles=best.bark + leaves,
        bark=best.bark,
        leaves=leaves,
        levels=p.levels,
        leaf_factor=factor if leaves else 1.0,
        curve_scale=c,
        minimum=minimum,
        maximum=maximum,
    )
