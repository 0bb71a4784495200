"""Weber–Penn: Params + seed → Tree.

The model is recursive (a stem's children depend on its grown shape), but every stem of one
level shares the same `curve_res`, so a whole level grows at once: the loop runs over levels
and over segment indices, and each step updates all stems of the level as numpy arrays.
Splits ("clones") join the active set of the level when they appear.

Randomness: one `numpy.random.Generator` per (seed, level, purpose), so pruning can regrow a
level with exactly the same random draws and nothing touches the global RNG.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .errors import TreegenError
from .params import MAX_LEVELS, Params
from .shapes import ENVELOPE, flare_factor, shape_ratio, taper_radius
from .tree import Tree

UP = np.array([0.0, 0.0, 1.0])
_GROW, _CHILDREN, _LEAVES, _TREE = 1, 2, 3, 4


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


# ---------------------------------------------------------------------------- rotations


def _rot_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) about unit axes (n, 3) by angles (n,) radians (Rodrigues)."""
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    m = np.empty(axis.shape[:1] + (3, 3))
    m[:, 0, 0] = t * x * x + c
    m[:, 0, 1] = t * x * y - s * z
    m[:, 0, 2] = t * x * z + s * y
    m[:, 1, 0] = t * x * y + s * z
    m[:, 1, 1] = t * y * y + c
    m[:, 1, 2] = t * y * z - s * x
    m[:, 2, 0] = t * x * z - s * y
    m[:, 2, 1] = t * y * z + s * x
    m[:, 2, 2] = t * z * z + c
    return m


def _rot_x(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1], m[..., 1, 2] = c, -s
    m[..., 2, 1], m[..., 2, 2] = s, c
    return m


def _rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    m[..., 0, 0], m[..., 0, 1] = c, -s
    m[..., 1, 0], m[..., 1, 1] = s, c
    m[..., 2, 2] = 1.0
    return m


def _unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    n = np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]
    out = v / np.maximum(n, 1e-12)
    if fallback is not None:
        out = np.where(n > 1e-9, out, fallback)
    return out


def _declination(direction: np.ndarray) -> np.ndarray:
    """Angle (radians) between a direction and world up."""
    return np.arccos(np.clip(direction[..., 2], -1.0, 1.0))


def error_diffuse(values: np.ndarray) -> np.ndarray:
    """Whole counts whose running sum tracks the running sum of fractional `values`.

    Result: (0.4, 0.4, 0.4, 0.4, 0.4) → (0, 1, 0, 1, 0). One accumulator, in array order.
    """
    values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    total = np.floor(np.cumsum(values) + 0.5)
    return np.diff(total, prepend=0.0).astype(np.int64)


def _vary(rng: np.random.Generator, value: float, variation: float, n: int) -> np.ndarray:
    """A size drawn from value ± variation that stays positive: when the variation exceeds the
    value (ScaleV > Scale is legal), draws below a tenth of the value are folded up to it."""
    lo = max(value - abs(variation), 0.1 * value)
    hi = max(value + abs(variation), lo)
    return rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo)


def _spread(rng: np.random.Generator, n, variation) -> np.ndarray:
    """value ± variation: a uniform draw in [−variation, variation] per element."""
    return rng.uniform(-1.0, 1.0, n) * variation


# ---------------------------------------------------------------------------- level batches


@dataclass
class _Level:
    """Stems of one level before they are grown: start pose plus the values growth needs."""

    pos: np.ndarray  # (M, 3)
    frame: np.ndarray  # (M, 3, 3)
    length: np.ndarray  # (M,)
    radius: np.ndarray  # (M,)
    parent: np.ndarray  # (M,) global stem index
    parent_node: np.ndarray  # (M,) global node index
    offset: np.ndarray  # (M,)


@dataclass
class _Grown:
    """A grown level: stems (originals first, then clones in creation order) and their nodes."""

    stem_parent: np.ndarray  # local index of the split origin for clones, -1 otherwise
    stem_origin: np.ndarray  # local index of the original stem a clone belongs to
    stem_first_seg: np.ndarray  # segment index of the stem's first node
    node_stem: np.ndarray  # local stem index per node, grouped by stem, base to tip
    node_seg: np.ndarray  # segment index of the node (z = seg · seg_len)
    node_pos: np.ndarray
    node_frame: np.ndarray


def _grow_level(p: Params, level: int, batch: _Level, length: np.ndarray, seed: int) -> _Grown:
    """Grow every stem of one level segment by segment (curve, curve back, helix, splits,
    split correction, attraction up). Deterministic in (seed, level) whatever `length` is."""
    lp = p.level[level]
    res = max(1, int(lp.curve_res))
    rng = np.random.default_rng([seed, level, _GROW])
    m = batch.pos.shape[0]
    seg_len = length / res

    # active set (originals first; clones appended as they appear)
    act = np.arange(m)
    pos = batch.pos.copy()
    frame = batch.frame.copy()
    correction = np.zeros(m)  # per-segment rotation undoing a split's tilt
    stems = {"parent": np.full(m, -1), "origin": np.arange(m), "first": np.zeros(m, dtype=np.int64)}
    n_stems = m
    rec_stem, rec_seg, rec_pos, rec_frame = [], [], [], []

    helix = lp.curve_v < 0
    if helix:
        # a helix: from segment 1 on the direction leans |nCurveV| off the stem's initial axis
        # and circles it once per stem; splits turn a member's axis with its frame
        helix_axis = frame[:, :, 2].copy()
        tilt = np.radians(-lp.curve_v)

    split_carry = 0.0
    for seg in range(res):
        a = act.shape[0]
        if seg > 0:
            if helix:
                if seg == 1:
                    frame = frame @ _rot_x(np.full(a, tilt))
                frame = _rot_axis(helix_axis[act], np.full(a, 2.0 * np.pi / res)) @ frame
            else:
                if lp.curve_back == 0:
                    bend = np.full(a, lp.curve / res)
                elif seg < (res + 1) // 2:
                    bend = np.full(a, 2.0 * lp.curve / res)
                else:
                    bend = np.full(a, 2.0 * lp.curve_back / res)
                bend = bend + _spread(rng, a, lp.curve_v / res)
                frame = frame @ _rot_x(np.radians(bend) + correction[act])
            if level >= 2 and p.attraction_up != 0.0:
                d = frame[:, :, 2]
                decl = _declination(d)
                ang = p.attraction_up * decl / res
                ang = np.where(ang > 0, np.minimum(ang, decl), np.maximum(ang, -(np.pi - decl)))
                axis = np.cross(d, UP)
                ok = np.linalg.norm(axis, axis=1) > 1e-9
                if ok.any():
                    frame[ok] = _rot_axis(_unit(axis[ok]), ang[ok]) @ frame[ok]

        # splits at this node (never at the base node or on the tip)
        if seg > 0 and seg < res:
            if level == 0 and seg == 1 and p.base_splits > 0:
                counts = np.where(stems["first"][act] == 0, int(p.base_splits), 0)
            elif lp.seg_splits > 0:
                vals = np.full(a, lp.seg_splits)
                total = np.floor(split_carry + np.cumsum(vals) + 0.5)
                counts = np.diff(total, prepend=np.floor(split_carry + 0.5)).astype(np.int64)
                split_carry += vals.sum()
            else:
                counts = np.zeros(a, dtype=np.int64)
            counts = np.minimum(counts, 8)
            if counts.any():
                before, act_before = frame, act
                frame, act, correction, n_new = _split(
                    rng, p, level, seg, res, counts, act, frame, correction, n_stems, stems
                )
                pos = np.concatenate([pos, np.repeat(pos[counts > 0], counts[counts > 0], axis=0)])
                n_stems += n_new
                if helix:
                    src = np.concatenate([np.arange(a), np.repeat(np.arange(a), counts)])
                    turn = np.einsum("nij,nkj->nik", frame, before[src])  # new · oldᵀ
                    axis = np.einsum("nij,nj->ni", turn, helix_axis[act_before[src]])
                    helix_axis = np.concatenate([helix_axis, np.zeros((n_new, 3))])
                    helix_axis[act] = axis
        rec_stem.append(act.copy())
        rec_seg.append(np.full(act.shape[0], seg))
        rec_pos.append(pos.copy())
        rec_frame.append(frame.copy())
        pos = pos + frame[:, :, 2] * seg_len[stems["origin"][act]][:, None]

    rec_stem.append(act.copy())
    rec_seg.append(np.full(act.shape[0], res))
    rec_pos.append(pos.copy())
    rec_frame.append(frame.copy())

    node_stem = np.concatenate(rec_stem)
    node_seg = np.concatenate(rec_seg)
    order = np.lexsort((node_seg, node_stem))
    return _Grown(
        stem_parent=stems["parent"],
        stem_origin=stems["origin"],
        stem_first_seg=stems["first"],
        node_stem=node_stem[order],
        node_seg=node_seg[order],
        node_pos=np.concatenate(rec_pos)[order],
        node_frame=np.concatenate(rec_frame)[order],
    )


def _split(rng, p, level, seg, res, counts, act, frame, correction, n_stems, stems):
    """Split the active stems with counts[i] > 0 into counts[i] + 1 members.

    Each member tilts by max(0, nSplitAngle ± nSplitAngleV − declination) and fans out about
    world up; the remaining segments turn back by the tilt spread over them (the paper's
    declination correction), so split limbs diverge without falling over.
    """
    lp = p.level[level]
    splitting = np.nonzero(counts)[0]
    k = counts[splitting]
    n_new = int(k.sum())
    new_local = np.arange(n_stems, n_stems + n_new)
    src = np.repeat(splitting, k)  # index into active set of each clone's origin
    stems["parent"] = np.concatenate([stems["parent"], act[src]])
    stems["origin"] = np.concatenate([stems["origin"], stems["origin"][act[src]]])
    stems["first"] = np.concatenate([stems["first"], np.full(n_new, seg)])

    # members: the original (member 0) and its clones (members 1..k)
    member_idx = np.concatenate(
        [np.zeros(splitting.shape[0], dtype=np.int64), np.arange(n_new) - np.repeat(np.cumsum(k) - k, k) + 1]
    )
    group_k = np.concatenate([k, np.repeat(k, k)])
    f = np.concatenate([frame[splitting], frame[src]])
    d = f[:, :, 2]
    decl = np.degrees(_declination(d))
    nm = f.shape[0]
    angle = np.maximum(0.0, lp.split_angle + _spread(rng, nm, lp.split_angle_v) - decl)
    if level == 0 and seg == 1 and p.base_splits > 0:
        # evenly around, one random turn per group, so no two leaders crowd each other
        turn = rng.uniform(0, 360.0 / (k + 1))
        fan = member_idx * 360.0 / (group_k + 1) + np.concatenate([turn, np.repeat(turn, k)])
    else:
        fan_width = 20.0 + 0.75 * (30.0 + np.abs(decl - 90.0)) * rng.uniform(0, 1, nm) ** 2
        fan = (member_idx / np.maximum(group_k, 1) - 0.5) * 2.0 * fan_width
    ang_r = np.radians(angle)
    f = f @ _rot_x(ang_r)
    f = _rot_axis(np.tile(UP, (nm, 1)), np.radians(fan)) @ f
    remaining = max(res - seg - 1, 1)
    corr = -ang_r / remaining

    frame = frame.copy()
    frame[splitting] = f[: splitting.shape[0]]
    frame = np.concatenate([frame, f[splitting.shape[0] :]])
    # corrections add up over successive splits; a clone carries its origin's so far
    correction = np.concatenate([correction, correction[act[src]]])
    correction[act[splitting]] += corr[: splitting.shape[0]]
    correction[new_local] += corr[splitting.shape[0] :]
    act = np.concatenate([act, new_local])
    return frame, act, correction, n_new


def _inside_envelope(p: Params, scale_tree: float, pts: np.ndarray) -> np.ndarray:
    """True where points (n, 3) lie inside the pruning envelope (tree coordinates)."""
    r = np.hypot(pts[:, 0], pts[:, 1]) / scale_tree
    rel = (scale_tree - pts[:, 2]) / (scale_tree * max(1.0 - p.base_size, 1e-6))
    env = p.prune_width * shape_ratio(
        ENVELOPE, rel, p.prune_width_peak, p.prune_power_low, p.prune_power_high
    )
    return (r <= env) & (rel >= 0.0) & (rel <= 1.0)


def _grow_pruned(
    p: Params, level: int, batch: _Level, scale_tree: float, seed: int, steps: int
) -> tuple[_Level, _Grown, np.ndarray]:
    """Grow a level; with PruneRatio > 0 shorten stems that leave the envelope (bisection on
    each stem's length with the same random draws), final L0 − (L0 − L_fit)·PruneRatio.
    Stems pruned away entirely (no length fits) are removed, as in the paper."""
    length = batch.length.copy()
    grown = _grow_level(p, level, batch, length, seed)
    if p.prune_ratio <= 0.0 or level == 0:
        return batch, grown, length

    def outside_by_stem(g: _Grown) -> np.ndarray:
        bad = ~_inside_envelope(p, scale_tree, g.node_pos)
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
        g = _grow_level(p, level, batch, batch.length * mid, seed)
        bad = outside_by_stem(g)
        hi = np.where(out & bad, mid, hi)
        lo = np.where(out & ~bad, mid, lo)
    fit = batch.length * lo
    final = batch.length - (batch.length - fit) * p.prune_ratio
    final = np.maximum(final, 1e-3 * batch.length)
    grown = _grow_level(p, level, batch, final, seed)
    keep = (lo > 0.0) | (p.prune_ratio < 1.0)
    if keep.all() or not keep.any():
        return batch, grown, final
    return _keep_originals(batch, grown, final, keep)


def _keep_originals(batch: _Level, grown: _Grown, length: np.ndarray, keep: np.ndarray):
    """The level without the original stems `~keep` and their split members."""
    new_origin = np.cumsum(keep) - 1
    stem_keep = keep[grown.stem_origin]
    local = np.full(stem_keep.shape[0], -1)
    local[stem_keep] = np.arange(int(stem_keep.sum()))
    node_keep = stem_keep[grown.node_stem]
    parent = grown.stem_parent[stem_keep]
    kept = _Grown(
        stem_parent=np.where(parent >= 0, local[np.maximum(parent, 0)], -1),
        stem_origin=new_origin[grown.stem_origin[stem_keep]],
        stem_first_seg=grown.stem_first_seg[stem_keep],
        node_stem=local[grown.node_stem[node_keep]],
        node_seg=grown.node_seg[node_keep],
        node_pos=grown.node_pos[node_keep],
        node_frame=grown.node_frame[node_keep],
    )
    trimmed = _Level(
        **{
            f: getattr(batch, f)[keep]
            for f in ("pos", "frame", "length", "radius", "parent", "parent_node", "offset")
        }
    )
    return trimmed, kept, length[keep]


# ---------------------------------------------------------------------------- the generator


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


def _refuse(kind: str, count: float, limit: int, flag: str, p: Params, levels: int | None):
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


def _prepare(p: Params, options: GenerateOptions) -> tuple[Params, int]:
    """Apply the overrides and refuse oversized trees before anything is allocated."""
    if options.leaf_quality is not None:
        p = replace(p, leaf_quality=options.leaf_quality)
    n_levels = p.levels if options.levels is None else max(0, min(options.levels, p.levels))
    est_stems, est_leaves = estimate_counts(p, levels=n_levels)
    if est_stems > options.max_stems:
        _refuse("stems", est_stems, options.max_stems, "--max-stems", p, options.levels)
    if est_leaves > options.max_leaves:
        _refuse("leaves", est_leaves, options.max_leaves, "--max-leaves", p, options.levels)
    check_trunk(p, options)
    return p, n_levels


def generate(p: Params, seed: int = 0, options: GenerateOptions = DEFAULTS) -> Tree:
    """Grow the whole Weber–Penn tree for `p` and `seed` as a struct of arrays."""
    p, n_levels = _prepare(p, options)

    rng = np.random.default_rng([seed, 0, _TREE])
    scale_tree = float(_vary(rng, p.scale, p.scale_v, 1)[0])
    lp0 = p.level[0]

    # trunks (Arbaro: 0Branches trunks, spread within 0BranchDist·scale around the origin)
    trunks = max(1, int(round(lp0.branches))) if lp0.branches > 0 else 1
    rot = (
        np.arange(trunks) * (lp0.rotate if lp0.rotate != 0 else 360.0 / trunks)
        + _spread(rng, trunks, lp0.rotate_v)
        + rng.uniform(0, 360.0)
    )
    down = lp0.down_angle + _spread(rng, trunks, lp0.down_angle_v) if trunks > 1 else np.zeros(1)
    down = np.broadcast_to(down, (trunks,)).astype(float)
    dist = lp0.branch_dist * scale_tree * np.sqrt(rng.uniform(0, 1, trunks)) if trunks > 1 else np.zeros(1)
    rot_r = np.radians(rot)
    pos0 = np.stack([dist * np.cos(rot_r), dist * np.sin(rot_r), np.zeros(trunks)], axis=1)
    frame0 = _rot_z(rot_r) @ _rot_x(np.radians(down))
    # a trunk is never shorter than a millimetre per metre of tree (0Length 0 is legal)
    length0 = np.maximum(_vary(rng, lp0.length, lp0.length_v, trunks), 1e-3) * scale_tree
    radius0 = length0 * p.ratio * _vary(rng, p.scale0, p.scale0_v, trunks)
    batch = _Level(
        pos=pos0,
        frame=frame0,
        length=length0,
        radius=radius0,
        parent=np.full(trunks, -1),
        parent_node=np.full(trunks, -1),
        offset=np.zeros(trunks),
    )

    out = _Builder()
    leaves = None
    total_stems = 0
    for level in range(max(n_levels, 1)):
        lp = p.level[level]
        batch, grown, length = _grow_pruned(p, level, batch, scale_tree, seed, options.prune_steps)
        origin = grown.stem_origin
        res = max(1, int(lp.curve_res))
        n_local = origin.shape[0]
        total_stems += n_local
        if total_stems > options.max_stems:
            _refuse("stems", total_stems, options.max_stems, "--max-stems", p, options.levels)

        # global indices
        g0, n0 = out.n_stems, out.n_nodes
        counts = np.bincount(grown.node_stem, minlength=n_local)
        node_start = n0 + np.concatenate([[0], np.cumsum(counts)[:-1]])
        seg_len = (length / res)[origin]
        node_z = grown.node_seg * seg_len[grown.node_stem]
        s_len = length[origin]
        s_rad = batch.radius[origin]
        node_radius = taper_radius(s_rad[grown.node_stem], s_len[grown.node_stem], lp.taper, node_z)
        if level == 0:
            node_radius = node_radius * flare_factor(
                p.flare, node_z / np.maximum(s_len[grown.node_stem], 1e-12)
            )
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
            node_radius=node_radius,
            node_z=node_z,
        )
        out.n_stems += n_local
        out.n_nodes += grown.node_pos.shape[0]

        ctx = _LevelContext(
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
            node_radius=node_radius,
            node_z=node_z,
            n_originals=batch.pos.shape[0],
        )
        last = level == max(n_levels, 1) - 1
        if not last:
            batch = _children(p, ctx, seed, scale_tree, options, total_stems)
            if batch.pos.shape[0] == 0:
                last = True
        if last:
            if n_levels >= 1:
                leaves = _leaves(p, ctx, seed, n_levels, options, scale_tree)
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
        **_leaf_fields(leaves),
    )
    check_size(tree, options.max_size)
    return tree


def _leaf_fields(leaves: dict | None) -> dict:
    """The Tree's leaf arrays from `_leaves`' output (None: a tree without leaves)."""
    if leaves is None:
        leaves = {
            k: np.zeros((0,) + t)
            for k, t in (("stem", ()), ("node", ()), ("pos", (3,)), ("frame", (3, 3)), ("size", (2,)))
        }
    return dict(
        leaf_stem=leaves["stem"].astype(np.int32),
        leaf_node=leaves["node"].astype(np.int32),
        leaf_pos=leaves["pos"].astype(np.float64),
        leaf_frame=leaves["frame"].astype(np.float64),
        leaf_size=leaves["size"].astype(np.float64),
    )


def _parent_length(out: _Builder, parent: np.ndarray) -> np.ndarray:
    lengths = out.cat("stem_length", np.float64)
    return np.where(parent >= 0, lengths[np.maximum(parent, 0)] if lengths.size else 1.0, 1.0)


@dataclass
class _LevelContext:
    """A grown level as its children see it (local stem indices, global offsets)."""

    level: int
    g0: int
    node_start: np.ndarray
    counts: np.ndarray
    first_seg: np.ndarray
    origin: np.ndarray
    length: np.ndarray
    seg_len: np.ndarray
    radius: np.ndarray
    offset_on_parent: np.ndarray
    parent_length: np.ndarray
    node_pos: np.ndarray
    node_frame: np.ndarray
    node_radius: np.ndarray
    node_z: np.ndarray
    n_originals: int

    def attach(self, stem: np.ndarray, z: np.ndarray):
        """Point, frame, radius and global node index at distance z along local stems."""
        seg = np.floor(z / np.maximum(self.seg_len[stem], 1e-12)).astype(np.int64)
        seg = np.clip(seg, self.first_seg[stem], self.first_seg[stem] + self.counts[stem] - 2)
        local = self.node_start[stem] - self.node_start[0] + seg - self.first_seg[stem]
        t = np.clip((z - self.node_z[local]) / np.maximum(self.seg_len[stem], 1e-12), 0.0, 1.0)
        pos = self.node_pos[local] + (self.node_pos[local + 1] - self.node_pos[local]) * t[:, None]
        rad = self.node_radius[local] + (self.node_radius[local + 1] - self.node_radius[local]) * t
        return pos, self.node_frame[local], rad, self.node_start[0] + local


def _placements(totals: np.ndarray, z_lo: np.ndarray, z_hi: np.ndarray):
    """Error-diffused counts per parent stem and evenly spaced offsets in [z_lo, z_hi]."""
    n = error_diffuse(totals)
    stem = np.repeat(np.arange(n.shape[0]), n)
    j = np.arange(stem.shape[0]) - np.repeat(np.cumsum(n) - n, n)
    frac = (j + 0.5) / np.maximum(n[stem], 1)
    z = z_lo[stem] + (z_hi[stem] - z_lo[stem]) * frac
    return n, stem, j, z


def _rotations(rng, rotate: float, rotate_v: float, stem: np.ndarray, j: np.ndarray, n: np.ndarray):
    """Angle (degrees) about the parent axis of each child.

    nRotate ≥ 0: each child turns nRotate ± nRotateV further than the previous one (a spiral).
    nRotate < 0: children alternate to either side, ±(180 + nRotate ± nRotateV)."""
    k = stem.shape[0]
    start = rng.uniform(0.0, 360.0, n.shape[0])[stem]
    if rotate >= 0:
        step = rotate + _spread(rng, k, rotate_v)
        csum = np.cumsum(step)
        first = np.repeat(np.cumsum(n) - n, n)
        before = np.where(first > 0, csum[np.maximum(first - 1, 0)], 0.0)
        return start + csum - before - step
    side = np.where(j % 2 == 0, 1.0, -1.0)
    return start + side * (180.0 + rotate + _spread(rng, k, rotate_v))


def _down_angles(rng, down: float, down_v: float, z, length, base) -> np.ndarray:
    """nDownAngle ± nDownAngleV; a negative nDownAngleV varies it along the parent instead."""
    if down_v >= 0:
        return down + _spread(rng, z.shape[0], down_v)
    rel = (length - z) / np.maximum(length - base, 1e-12)
    return down + down_v * (1.0 - 2.0 * shape_ratio(0, np.clip(rel, 0.0, 1.0)))


def _branch_dist(z: np.ndarray, seg_len: np.ndarray, z_lo: np.ndarray, branch_dist: float):
    """Arbaro's nBranchDist: 1 spreads children evenly along each parent segment (the paper);
    0 gathers a segment's children at its base, as whorls (conifers); between, in between."""
    if branch_dist >= 1.0 or z.shape[0] == 0:
        return z
    seg = np.floor(z / np.maximum(seg_len, 1e-12))
    start = seg * seg_len
    return np.maximum(start + (z - start) * max(branch_dist, 0.0), z_lo)


def _assign_members(ctx: _LevelContext, rng, origin_of: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Pick, for each child at distance z on an original stem, one of the split members alive
    there. A split shares its stem's children among the members instead of multiplying them,
    so counts follow the paper's formulas whatever nSegSplits is."""
    if z.shape[0] == 0:
        return origin_of
    start = ctx.first_seg * ctx.seg_len
    order = np.lexsort((start, ctx.origin))
    big = 2.0 * (float(start.max()) + float(z.max()) + 1.0)
    keys = ctx.origin[order] * big + start[order]
    begin = np.searchsorted(ctx.origin[order], origin_of, side="left")
    end = np.searchsorted(keys, origin_of * big + z + 1e-9, side="right")
    alive = np.maximum(end - begin, 1)
    pick = begin + np.minimum((rng.uniform(0.0, 1.0, z.shape[0]) * alive).astype(np.int64), alive - 1)
    return order[pick]


def _children(
    p: Params, ctx: _LevelContext, seed: int, scale_tree: float, options: GenerateOptions, stems_so_far: int
) -> _Level:
    """Place the next level's stems on this level's stems (counts, offsets, angles, sizes)."""
    child_level = ctx.level + 1
    lp = p.level[child_level]
    rng = np.random.default_rng([seed, child_level, _CHILDREN])
    m = ctx.n_originals
    L = ctx.length[:m]
    # the bare base of the trunk is BaseSize of the tree's scale (the paper's base_length)
    base = np.minimum(p.base_size * scale_tree, L) if ctx.level == 0 else np.zeros_like(L)
    if ctx.level == 0:
        totals = np.full(m, lp.branches)
    elif ctx.level == 1:
        lcm_parent = max(p.level[1].length, 1e-12)
        totals = lp.branches * (0.2 + 0.8 * (L / ctx.parent_length[:m]) / lcm_parent)
    else:
        totals = lp.branches * (1.0 - 0.5 * ctx.offset_on_parent[:m] / ctx.parent_length[:m])
    totals = np.maximum(totals, 0.0)
    expected = stems_so_far + totals.sum()
    if expected > options.max_stems:
        _refuse("stems", expected, options.max_stems, "--max-stems", p, options.levels)

    n, orig, j, z = _placements(totals, base, L)
    z = _branch_dist(z, ctx.seg_len[orig], base[orig], lp.branch_dist)
    stem = _assign_members(ctx, rng, orig, z)
    pos, pframe, prad, pnode = ctx.attach(stem, z)
    rot = _rotations(rng, lp.rotate, lp.rotate_v, orig, j, n)
    down = _down_angles(rng, lp.down_angle, lp.down_angle_v, z, L[orig], base[orig])
    frame = pframe @ _rot_z(np.radians(rot)) @ _rot_x(np.radians(down))

    # one draw of nLength ± nLengthV per parent: its children share their maximum length
    length_child_max = (lp.length + _spread(rng, m, lp.length_v))[orig]
    Lp = L[orig]
    if ctx.level == 0:
        rel = (Lp - z) / np.maximum(Lp - base[orig], 1e-12)
        ratio = shape_ratio(
            p.shape, np.clip(rel, 0.0, 1.0), p.prune_width_peak, p.prune_power_low, p.prune_power_high
        )
        length = Lp * length_child_max * ratio
    else:
        length = length_child_max * (Lp - 0.6 * z)
    length = np.maximum(length, 0.0)
    radius = ctx.radius[orig] * (length / np.maximum(Lp, 1e-12)) ** p.ratio_power
    radius = np.minimum(radius, prad)
    keep = (length > 1e-4) & (radius > 0)
    return _Level(
        pos=pos[keep],
        frame=frame[keep],
        length=length[keep],
        radius=radius[keep],
        parent=(ctx.g0 + stem)[keep],
        parent_node=pnode[keep],
        offset=z[keep],
    )


def _leaves(
    p: Params, ctx: _LevelContext, seed: int, n_levels: int, options: GenerateOptions, scale_tree: float
):
    """Leaves on the last stem level, oriented by the leaf level's angles and LeafBend."""
    lp = p.level[min(n_levels, len(p.level) - 1)]
    rng = np.random.default_rng([seed, n_levels, _LEAVES])
    quality = p.leaf_quality
    fan = p.leaves < 0
    if fan:
        # a fan at every stem tip (palms), split members included: |Leaves| each
        L = ctx.length
        totals = np.full(L.shape, abs(p.leaves) * quality)
        z_lo = L.copy()
    else:
        # per original stem, shared among its split members like child stems
        m = ctx.n_originals
        L = ctx.length[:m]
        rel = np.where(ctx.parent_length[:m] > 0, ctx.offset_on_parent[:m] / ctx.parent_length[:m], 1.0)
        if ctx.level == 0:
            rel = np.ones_like(L)
        distrib = int(p.leaf_distrib) if 0 <= int(p.leaf_distrib) <= 7 else 4
        totals = abs(p.leaves) * shape_ratio(distrib, np.clip(rel, 0, 1)) * quality
        z_lo = np.minimum(p.base_size * scale_tree, L) if ctx.level == 0 else np.zeros_like(L)
    if totals.sum() > options.max_leaves:
        _refuse("leaves", totals.sum(), options.max_leaves, "--max-leaves", p, options.levels)

    if not fan and lp.rotate < 0:
        # whorls: groups of 360/(−Rotate) leaves share an offset, evenly around the stem
        group = max(1, int(round(360.0 / -lp.rotate)))
        n_groups = error_diffuse(totals / group)
        n = n_groups * group
        orig = np.repeat(np.arange(n.shape[0]), n)
        j = np.arange(orig.shape[0]) - np.repeat(np.cumsum(n) - n, n)
        g = j // group
        frac = (g + 0.5) / np.maximum(n_groups[orig], 1)
        z = z_lo[orig] + (L[orig] - z_lo[orig]) * frac
        twist = np.where(g % 2 == 0, 0.0, 180.0 / group)  # successive whorls interleave
        rot = (
            rng.uniform(0, 360.0, n.shape[0])[orig]
            + (j % group) * (360.0 / group)
            + twist
            + _spread(rng, orig.shape[0], lp.rotate_v)
        )
        # a whorl stays on one member: pick per group, then repeat
        first = j % group == 0
        stem = np.repeat(_assign_members(ctx, rng, orig[first], z[first]), group)
    else:
        n, orig, j, z = _placements(totals, z_lo, L)
        if fan:
            # spread across ±down angle in one plane through the stem
            spread = np.where(n[orig] > 1, j / np.maximum(n[orig] - 1, 1) - 0.5, 0.0)
            rot = np.full(orig.shape[0], 90.0) + _spread(rng, orig.shape[0], lp.rotate_v)
            stem = orig
        else:
            rot = _rotations(rng, lp.rotate, lp.rotate_v, orig, j, n)
            stem = _assign_members(ctx, rng, orig, z)
    k = stem.shape[0]
    if k > options.max_leaves:
        _refuse("leaves", k, options.max_leaves, "--max-leaves", p, options.levels)
    pos, pframe, _, pnode = ctx.attach(stem, np.minimum(z, ctx.length[stem] * (1 - 1e-9)))
    if fan:
        down = lp.down_angle * 2.0 * spread + _spread(rng, k, lp.down_angle_v)
        down = np.where(np.abs(down) < 1e-9, 1e-9, down)
    else:
        down = _down_angles(rng, lp.down_angle, lp.down_angle_v, z, L[orig], np.zeros(k))
    # columns 1 and 2 of pframe·Rz(rot)·Rx(down), without building k 3×3 products
    r, d = np.radians(rot), np.radians(down)
    sr, cr, sd, cd = np.sin(r), np.cos(r), np.sin(d), np.cos(d)
    local_z = np.stack([sd * sr, -sd * cr, cd], axis=1)
    local_y = np.stack([-sr * cd, cr * cd, sd], axis=1)
    direction = np.einsum("nij,nj->ni", pframe, local_z)  # blade length axis
    normal = np.einsum("nij,nj->ni", pframe, local_y)  # blade faces the parent's "up" side
    stalk = direction.copy()

    length = p.leaf_scale / np.sqrt(quality)
    width = p.leaf_scale * p.leaf_scale_x / np.sqrt(quality)
    # LeafBend: turn the blade's face toward up-and-outward (light), by that fraction
    outward = pos.copy()
    outward[:, 2] = 0.0
    target = _unit(_unit(outward, np.array([1.0, 0.0, 0.0])) + np.array([0.0, 0.0, 1.0]))
    flip = np.einsum("ni,ni->n", normal, target) < 0
    normal[flip] *= -1.0
    bend = np.clip(p.leaf_bend, 0.0, 1.0)
    normal = _unit(normal * (1.0 - bend) + target * bend, normal)
    direction -= normal * np.einsum("ni,ni->n", direction, normal)[:, None]
    fallback = _unit(np.cross(normal, np.array([1.0, 0.0, 0.0])), np.array([0.0, 1.0, 0.0]))
    direction = _unit(direction, fallback)
    width_axis = np.cross(direction, normal)
    leaf_frame = np.stack([width_axis, direction, normal], axis=2)
    blade_pos = pos + stalk * (p.leaf_stem_len * length)
    size = np.tile([length, width], (k, 1))
    return {"stem": ctx.g0 + stem, "node": pnode, "pos": blade_pos, "frame": leaf_frame, "size": size}


def regrow_leaves(tree: Tree, p: Params, options: GenerateOptions = DEFAULTS) -> Tree:
    """What `generate(p, tree.seed, options)` grows, for a `p`/`options` that differ from the
    tree's only in its leaves (Leaves, LeafQuality) and a lower or equal Levels — the geometric
    LODs. Stems of the kept levels come from the same random streams, so they are taken from
    `tree` as they are and only the leaves grow again: same arrays, a fraction of the time."""
    p, n_levels = _prepare(p, options)
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
    ctx = _LevelContext(
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
    leaves = _leaves(p, ctx, tree.seed, n_levels, options, tree.scale) if n_levels >= 1 else None
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
        **_leaf_fields(leaves),
    )
