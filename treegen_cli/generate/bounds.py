"""The bounds a tree must stay within, and the options that set them.

Stem and leaf counts are estimated from the parameters alone and refused before anything is
allocated (--max-stems, --max-leaves); the trunk and the grown tree are held to a plausible
size (--max-size). Every refusal is one line naming the key or flag to change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import TreegenError
from ..params import MAX_LEVELS, Params
from ..tree import Tree, tree_box


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
    max_size_flag: str = "--max-size METRES"  # how messages name the bound (a forest's key)


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


def refuse(kind: str, count: float, p: Params, options: GenerateOptions):
    """Refuse a tree whose `kind` (stems or leaves) count is over its limit, naming the key to
    change (see `blame`) and its file line."""
    limit, flag = (
        (options.max_leaves, "--max-leaves") if kind == "leaves" else (options.max_stems, "--max-stems")
    )
    blamed = blame(kind, count, p, options)
    over = f"would grow about {int(count):,} {kind}, over the {flag} limit of {limit:,}"
    if blamed is not None and blamed.key != "Levels":
        value = p.leaves if blamed.key == "Leaves" else p.level[int(blamed.key[0])].branches
        bound = _floor_text(blamed.max_fit)
        allowed = f"at least -{bound}" if value < 0 else f"at most {bound}"
        raise TreegenError(
            f"{blamed.key} = {_num(value)} {over}; {blamed.key} may be {allowed} here (or raise {flag} N)",
            line=p.line_of(blamed.key),
        )
    if blamed is not None:
        raise TreegenError(
            f"Levels = {p.levels} {over}; Levels may be 0..{MAX_LEVELS} and at most "
            f"{int(blamed.max_fit)} fits this species' nBranches (or raise {flag} N)",
            line=p.line_of("Levels"),
        )
    raise TreegenError(
        f"species '{p.name}' {over}; raise it with {flag} N (or lower the species' Branches/Leaves/LeafQuality)"
    )


# A count this many times the median of the file's other counts may be a typo (an extra digit
# is 10x); the bundled species keep theirs within 20x of each other (the willow's 3Branches 300
# against Leaves 15), so this only filters, and "putting it back fits" decides.
OUTLIER = 4.0


@dataclass(frozen=True)
class Blame:
    """The key an oversized count is blamed on, and the largest value of it alone that fits."""

    key: str  # "Leaves", "2Branches", "Levels"
    max_fit: float


def blame(kind: str, count: float, p: Params, options: GenerateOptions) -> Blame | None:
    """The key the user most likely mistyped, for `count` (`kind`: stems or leaves) over its
    limit in `options`; its `max_fit` keeps both the stem and the leaf count within theirs.

    The count is a product of per-parent counts (0Branches, nBranches of the grown levels and,
    for leaves, Leaves), so every factor alone fits when cut by about count / limit: how far a
    value is over its own bound does not single one out (and for stems, a sum over levels, it
    points at the deepest level, whatever was mistyped). A typo does: a count far above the
    file's other counts (OUTLIER times their median or more) that, put back to that median,
    brings the tree within the limits. Of those the count most above the median is blamed
    (0Branches, the number of trunks, against 1). With none, Levels is blamed when fewer levels
    fit and --levels is not given; else None. The estimate of `kind` is scaled to the `count`
    actually reached, so a refusal made while growing blames the same way."""
    levels = options.levels
    n_levels = p.levels if levels is None else max(0, min(levels, p.levels))
    index = 1 if kind == "leaves" else 0
    base = estimate_counts(p, levels=n_levels)[index]
    if not base > 0:
        return None
    scale = [1.0, 1.0]
    scale[index] = count / base

    def fits(q: Params, lv: int = n_levels) -> bool:
        stems, leaves = estimate_counts(q, levels=lv)
        return stems * scale[0] <= options.max_stems and leaves * scale[1] <= options.max_leaves

    counts = {f"{n}Branches": p.level[n].branches for n in range(1, n_levels)}
    counts["0Branches"] = p.level[0].branches
    if kind == "leaves" and n_levels >= 1:
        counts["Leaves"] = abs(p.leaves)
    best: tuple[float, Blame] | None = None
    for key, value in counts.items():
        if value <= 0:
            continue
        others = sorted(v for k, v in counts.items() if k not in (key, "0Branches"))
        # below one per parent is no typical count to put a value back to
        typical = 1.0 if key == "0Branches" else (max(1.0, float(np.median(others))) if others else None)
        if typical is not None and not (value >= OUTLIER * typical and fits(_with(p, key, typical))):
            continue
        max_fit = _max_fit(lambda x, key=key: fits(_with(p, key, x)), value)
        if max_fit is None:
            continue
        score = value / typical if typical is not None else float("inf")
        if best is None or score > best[0]:
            best = (score, Blame(key, max_fit))
    if best is not None:
        return best[1]
    fewer = [n for n in range(n_levels) if fits(p, n)]
    if levels is None and fewer:
        return Blame("Levels", max(fewer))
    return None


def _with(p: Params, key: str, value: float) -> Params:
    """`p` with one count key set (Leaves keeps its sign: negative is a fan)."""
    if key == "Leaves":
        return replace(p, leaves=value if p.leaves >= 0 else -value)
    n = int(key[0])
    lp = replace(p.level[n], branches=value)
    return replace(p, level=p.level[:n] + (lp,) + p.level[n + 1 :])


def _max_fit(fits, value: float) -> float | None:
    """The largest x in [0, value] with fits(x) (the count grows with x), or None."""
    if not fits(0.0):
        return None
    lo, hi = 0.0, value
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def _num(v: float) -> str:
    if not abs(v) < 1e9:  # (a slipped exponent: 1e+300, not 301 digits)
        return f"{v:.6g}"
    return str(int(v)) if float(v).is_integer() else f"{v:.10g}"


def _floor_text(x: float) -> str:
    """`x` rounded down for the message, so the value it names does fit."""
    if not x < 1e9:
        return f"{x:.3g}"
    if x >= 10:
        return f"{math.floor(x):,}"
    return _num(math.floor(x * 100) / 100)


def _value(p: Params, key: str) -> float:
    """A size key's value by its file name ("Ratio", "2LengthV", "0ScaleV")."""
    top = {
        "Scale": p.scale, "ScaleV": p.scale_v, "Ratio": p.ratio, "0Scale": p.scale0,
        "0ScaleV": p.scale0_v, "Flare": p.flare, "LobeDepth": p.lobe_depth,
        "LeafScale": p.leaf_scale, "LeafScaleX": p.leaf_scale_x,
    }  # fmt: skip
    if key in top:
        return top[key]
    level = p.level[int(key[0])]
    return level.length_v if key.endswith("V") else level.length


def _slipped(p: Params, typical: dict[str, float]) -> str:
    """The key farthest past its typical largest value (`typical`: key → value): the one a
    slip most likely hit."""

    def past(key: str) -> float:
        v = _value(p, key)
        return v / typical[key] if v > 0 else 0.0

    return max(typical, key=past)


def _refuse_size(p: Params, key: str, what: str, options: GenerateOptions) -> TreegenError:
    return TreegenError(
        f"{key} = {_num(_value(p, key))} {what}, over the plausibility bound of {options.max_size:g} m; "
        f"lower {key}, or raise the bound with {options.max_size_flag}",
        line=p.line_of(key),
    )


def check_trunk(p: Params, options: GenerateOptions = DEFAULTS) -> None:
    """Before growing, from the parameters alone: the trunk, each branch level's longest stem,
    the trunk's base (flare and lobes included) and a leaf all within --max-size. Each refusal
    names the key a slip most likely hit, with its line; astronomically large values never
    reach the geometry (they overflowed the wind's matrices)."""
    lp0 = p.level[0]
    longest = trunk = (p.scale + p.scale_v) * (lp0.length + lp0.length_v)
    if not trunk <= options.max_size:
        key = _slipped(p, {"Scale": 30.0, "ScaleV": 10.0, "0Length": 1.0, "0LengthV": 0.5})
        raise _refuse_size(p, key, f"makes a trunk up to {_floor_text(trunk)} m long", options)
    for lev in range(1, min(max(p.levels, 1), len(p.level))):
        lp = p.level[lev]
        longest *= max(lp.length + lp.length_v, 0.0)
        if not longest <= options.max_size:
            key = _slipped(p, {f"{lev}Length": 1.0, f"{lev}LengthV": 0.5})
            raise _refuse_size(
                p, key, f"makes level-{lev} branches up to {_floor_text(longest)} m long", options
            )
    base = 2.0 * trunk * p.ratio * (p.scale0 + p.scale0_v) * (1.0 + max(p.flare, 0.0)) * (1.0 + p.lobe_depth)
    if not base <= options.max_size:
        typical = {"Ratio": 0.05, "0Scale": 2.0, "0ScaleV": 1.0, "Flare": 1.5, "LobeDepth": 0.5}
        what = f"makes a trunk {_floor_text(base)} m across at its base"
        raise _refuse_size(p, _slipped(p, typical), what, options)
    if p.leaves != 0 and p.levels >= 1:  # the file's leaf (LeafQuality's trade of count for
        # size is the budget's lever: its candidates at ×1/256 grow leaves 16× longer)
        biggest = max(p.leaf_scale, p.leaf_scale * p.leaf_scale_x)
        if not biggest <= options.max_size:
            key = "LeafScale" if not p.leaf_scale <= options.max_size else "LeafScaleX"
            raise _refuse_size(p, key, f"makes leaves {_floor_text(biggest)} m long or wide", options)


def check_size(tree: Tree, max_size: float, flag: str = DEFAULTS.max_size_flag) -> None:
    """After growing: the tree's height and crown width (stems with their radii, leaves with
    their blades) within `max_size` metres, else a one-line refusal naming, of the keys that
    scale what reaches farthest (Scale, the trunk's and each branch level's nLength up to the
    farthest stem's, LeafScale when a blade reaches farthest), the one farthest past its
    typical value (every length is ∝ Scale: a big tree blames Scale, a slipped 1Length 1Length)."""
    if not tree.n_nodes:
        return
    lo, hi = tree_box(tree)
    height, width = float(hi[2]), float(np.max(hi[:2] - lo[:2]))
    if height <= max_size and width <= max_size:
        return
    p, axis = tree.params, 2 if not height <= max_size else int(np.argmax(hi[:2] - lo[:2]))
    reach = np.abs(tree.node_pos[:, axis]) + tree.node_radius  # (the trunk's base: the origin)
    level = int(tree.stem_level[tree.node_stem[int(np.argmax(reach))]])
    typical = {"Scale": 30.0, "ScaleV": 10.0}
    for lev in range(level + 1):
        typical |= {f"{lev}Length": 1.0, f"{lev}LengthV": 0.5}
    if tree.n_leaves and float(np.abs(tree.leaf_pos[:, axis]).max() + tree.leaf_size.max()) > float(
        reach.max()
    ):
        typical["LeafScale"] = 0.5
    key = _slipped(p, typical)
    what = f"a tree {height:,.1f} m tall" if not height <= max_size else f"a crown {width:,.1f} m wide"
    raise TreegenError(
        f"{key} = {_num(_value(p, key))} grows {what} (seed {tree.seed}), over the plausibility "
        f"bound of {max_size:g} m; lower {key}, or raise the bound with {flag}",
        line=p.line_of(key),
    )


def apply_options(p: Params, options: GenerateOptions) -> tuple[Params, int]:
    """Apply the overrides and refuse oversized trees before anything is allocated."""
    if options.leaf_quality is not None:
        p = replace(p, leaf_quality=options.leaf_quality)
    n_levels = p.levels if options.levels is None else max(0, min(options.levels, p.levels))
    check_trunk(p, options)  # first: a size slip is named as such, not as a count
    est_stems, est_leaves = estimate_counts(p, levels=n_levels)
    if est_stems > options.max_stems:
        refuse("stems", est_stems, p, options)
    if est_leaves > options.max_leaves:
        refuse("leaves", est_leaves, p, options)
    return p, n_levels
