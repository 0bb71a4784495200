"""The bounds a tree must stay within, and the options that set them.

Stem and leaf counts are estimated from the parameters alone and refused before anything is
allocated (--max-stems, --max-leaves); the trunk and the grown tree are held to a plausible
size (--max-size). Every refusal is one line naming the key or flag to change.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import TreegenError
from ..params import MAX_LEVELS, Params
from ..tree import Tree


@dataclass(frozen=True)
class GenerateOptions:
    """Limits and overrides. `leaf_quality` and `levels` override the species (geometric LODs)."""

    max_stems: int = 200_000
    max_leaves: int = 2_000_000
    leaf_quality: float | None = None
    levels: int | None = None
    prune_steps: int = 7  # bisection steps when fitting a stem into the envelope
    max_size: float = 150.0  # metres of height or crown width (plausibility bound: the
    # tallest living tree is ~116 m, the widest crowns ~80 m)


DEFAULTS = GenerateOptions()


def estimate_counts(p: Params, leaf_quality: float | None = None, levels: int | None = None):
    """Expected (stems, leaves) from the parameters alone, before anything is allocated.

    Children and leaves follow the count formulas per original stem (mean factor 0.6 for the
    level-2 length term, 0.75 for 1 − 0.5·offset/L); splits add members, about
    (1 + nSegSplits)^(curve_res − 1) per original, which share the original's children."""
    n_levels = p.levels if levels is None else min(levels, p.levels)
    quality = p.leaf_quality if leaf_quality is None else leaf_quality

    def members(level: int, originals: float) -> float:
        lp = p.level[level]
        grow = (1.0 + lp.seg_splits) ** max(int(lp.curve_res) - 1, 0)
        if level == 0:
            grow *= 1 + min(p.base_splits, 8)  # the generator splits at most 8 ways
        return originals * min(grow, 1e6)

    originals = [max(1, int(round(p.level[0].branches))) if p.level[0].branches > 0 else 1]
    for lev in range(1, max(n_levels, 1)):
        factor = 1.0 if lev == 1 else (0.6 if lev == 2 else 0.75)
        originals.append(originals[-1] * max(p.level[lev].branches, 0.0) * factor)
    stems = sum(members(lev, n) for lev, n in enumerate(originals))
    leaves = 0.0
    if n_levels >= 1 and p.leaves != 0:
        last = len(originals) - 1
        if p.leaves < 0:
            leaves = members(last, originals[last]) * abs(p.leaves) * quality
        else:
            leaves = originals[last] * abs(p.leaves) * quality * (1.0 if last == 0 else 0.75)
    return int(round(stems)), int(round(leaves))


def refuse(kind: str, count: float, limit: int, flag: str, p: Params, levels: int | None):
    """Refuse an oversized tree, naming the key to lower: Levels when fewer levels would fit
    (each level multiplies the count by its nBranches), else the count keys."""
    fits = [n for n in range(p.levels) if estimate_counts(p, levels=n)[kind == "leaves"] <= limit]
    if levels is None and fits and max(fits) < p.levels:
        raise TreegenError(
            f"Levels = {p.levels} would grow about {int(count):,} {kind}, over the {flag} limit "
            f"of {limit:,}; Levels may be 0..{MAX_LEVELS} and at most {max(fits)} fits this "
            f"species' nBranches (or raise {flag} N)"
        )
    raise TreegenError(
        f"species '{p.name}' would grow about {int(count):,} {kind}, over the limit of {limit:,}; "
        f"raise it with {flag} N (or lower the species' Branches/Leaves/LeafQuality)"
    )


def check_trunk(p: Params, options: GenerateOptions = DEFAULTS) -> None:
    """Before growing: a trunk longer than the size bound makes an implausible tree (and
    astronomically large Scale values would overflow the geometry)."""
    lp0 = p.level[0]
    trunk = (p.scale + p.scale_v) * (lp0.length + lp0.length_v)
    if not trunk <= options.max_size:
        raise TreegenError(
            f"Scale = {p.scale:g} (ScaleV {p.scale_v:g}, 0Length {lp0.length:g}) makes a trunk up "
            f"to {trunk:,.0f} m long, over the plausibility bound of {options.max_size:g} m; "
            f"lower Scale, or raise the bound with --max-size METRES"
        )


def check_size(tree: Tree, max_size: float) -> None:
    """After growing: the tree's height and crown width within `max_size` metres, else a
    one-line refusal naming the keys that scale them (every length is ∝ Scale)."""
    p = tree.params
    pts = np.concatenate([tree.node_pos, tree.leaf_pos]) if tree.n_leaves else tree.node_pos
    if not len(pts):
        return
    height = float(pts[:, 2].max())
    width = float(np.max(np.ptp(pts[:, :2], axis=0)))
    fix = "; lower {}, or raise the bound with --max-size METRES"
    if not height <= max_size:
        raise TreegenError(
            f"Scale = {p.scale:g} grows a tree {height:,.1f} m tall (seed {tree.seed}), over the "
            f"plausibility bound of {max_size:g} m" + fix.format("Scale or 0Length")
        )
    if not width <= max_size:
        raise TreegenError(
            f"Scale = {p.scale:g} with 1Length = {p.level[1].length:g} grows a crown {width:,.1f} m "
            f"wide (seed {tree.seed}), over the plausibility bound of {max_size:g} m"
            + fix.format("Scale or 1Length")
        )


def apply_options(p: Params, options: GenerateOptions) -> tuple[Params, int]:
    """Apply the overrides and refuse oversized trees before anything is allocated."""
    if options.leaf_quality is not None:
        p = replace(p, leaf_quality=options.leaf_quality)
    n_levels = p.levels if options.levels is None else max(0, min(options.levels, p.levels))
    est_stems, est_leaves = estimate_counts(p, levels=n_levels)
    if est_stems > options.max_stems:
        refuse("stems", est_stems, options.max_stems, "--max-stems", p, options.levels)
    if est_leaves > options.max_leaves:
        refuse("leaves", est_leaves, options.max_leaves, "--max-leaves", p, options.levels)
    check_trunk(p, options)
    return p, n_levels
