"""Where stems start: the trunks, and each level's children along their parent stems.

Counts follow the paper's formulas per original stem (nBranches, error-diffused so fractions
add up), offsets spread along the stem (BaseSize, nBranchDist), angles turn about the parent
(nRotate, nDownAngle), lengths follow Shape on the trunk and the parent's length above.
`LevelContext` is a grown level as its children (and leaves.py) see it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..shapes import shape_ratio
from .bounds import GenerateOptions, refuse
from .draws import CHILDREN, deviation, error_diffuse, vary
from .frames import rot_x, rot_z
from .radius import child_radius, trunk_radius
from .stems import Level


def place_trunks(p: Params, rng: np.random.Generator, scale_tree: float) -> Level:
    """The trunks (Arbaro: 0Branches trunks, spread within 0BranchDist·scale around the
    origin), drawn from the tree's own stream right after its scale."""
    lp0 = p.level[0]
    trunks = max(1, int(round(lp0.branches))) if lp0.branches > 0 else 1
    rot = (
        np.arange(trunks) * (lp0.rotate if lp0.rotate != 0 else 360.0 / trunks)
        + deviation(rng, trunks, lp0.rotate_v)
        + rng.uniform(0, 360.0)
    )
    down = lp0.down_angle + deviation(rng, trunks, lp0.down_angle_v) if trunks > 1 else np.zeros(1)
    down = np.broadcast_to(down, (trunks,)).astype(float)
    dist = lp0.branch_dist * scale_tree * np.sqrt(rng.uniform(0, 1, trunks)) if trunks > 1 else np.zeros(1)
    rot_r = np.radians(rot)
    pos0 = np.stack([dist * np.cos(rot_r), dist * np.sin(rot_r), np.zeros(trunks)], axis=1)
    frame0 = rot_z(rot_r) @ rot_x(np.radians(down))
    # a trunk is never shorter than a millimetre per metre of tree (0Length 0 is legal)
    length0 = np.maximum(vary(rng, lp0.length, lp0.length_v, trunks), 1e-3) * scale_tree
    return Level(
        pos=pos0,
        frame=frame0,
        length=length0,
        radius=trunk_radius(p, rng, length0),
        parent=np.full(trunks, -1),
        parent_node=np.full(trunks, -1),
        offset=np.zeros(trunks),
    )


@dataclass
class LevelContext:
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


def placements(totals: np.ndarray, z_lo: np.ndarray, z_hi: np.ndarray):
    """Error-diffused counts per parent stem and evenly spaced offsets in [z_lo, z_hi]."""
    n = error_diffuse(totals)
    stem = np.repeat(np.arange(n.shape[0]), n)
    j = np.arange(stem.shape[0]) - np.repeat(np.cumsum(n) - n, n)
    frac = (j + 0.5) / np.maximum(n[stem], 1)
    z = z_lo[stem] + (z_hi[stem] - z_lo[stem]) * frac
    return n, stem, j, z


def rotations(rng, rotate: float, rotate_v: float, stem: np.ndarray, j: np.ndarray, n: np.ndarray):
    """Angle (degrees) about the parent axis of each child.

    nRotate ≥ 0: each child turns nRotate ± nRotateV further than the previous one (a spiral).
    nRotate < 0: children alternate to either side, ±(180 + nRotate ± nRotateV)."""
    k = stem.shape[0]
    start = rng.uniform(0.0, 360.0, n.shape[0])[stem]
    if rotate >= 0:
        step = rotate + deviation(rng, k, rotate_v)
        csum = np.cumsum(step)
        first = np.repeat(np.cumsum(n) - n, n)
        before = np.where(first > 0, csum[np.maximum(first - 1, 0)], 0.0)
        return start + csum - before - step
    side = np.where(j % 2 == 0, 1.0, -1.0)
    return start + side * (180.0 + rotate + deviation(rng, k, rotate_v))


def down_angles(rng, down: float, down_v: float, z, length, base) -> np.ndarray:
    """nDownAngle ± nDownAngleV; a negative nDownAngleV varies it along the parent instead."""
    if down_v >= 0:
        return down + deviation(rng, z.shape[0], down_v)
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


def assign_members(ctx: LevelContext, rng, origin_of: np.ndarray, z: np.ndarray) -> np.ndarray:
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


def place_children(
    p: Params, ctx: LevelContext, seed: int, scale_tree: float, options: GenerateOptions, stems_so_far: int
) -> Level:
    """Place the next level's stems on this level's stems (counts, offsets, angles, sizes)."""
    child_level = ctx.level + 1
    lp = p.level[child_level]
    rng = np.random.default_rng([seed, child_level, CHILDREN])
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
        refuse("stems", expected, p, options)

    n, orig, j, z = placements(totals, base, L)
    z = _branch_dist(z, ctx.seg_len[orig], base[orig], lp.branch_dist)
    stem = assign_members(ctx, rng, orig, z)
    pos, pframe, prad, pnode = ctx.attach(stem, z)
    rot = rotations(rng, lp.rotate, lp.rotate_v, orig, j, n)
    down = down_angles(rng, lp.down_angle, lp.down_angle_v, z, L[orig], base[orig])
    frame = pframe @ rot_z(np.radians(rot)) @ rot_x(np.radians(down))

    # one draw of nLength ± nLengthV per parent: its children share their maximum length
    length_child_max = (lp.length + deviation(rng, m, lp.length_v))[orig]
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
    radius = child_radius(p, ctx.radius[orig], length, Lp, prad)
    keep = (length > 1e-4) & (radius > 0)
    return Level(
        pos=pos[keep],
        frame=frame[keep],
        length=length[keep],
        radius=radius[keep],
        parent=(ctx.g0 + stem)[keep],
        parent_node=pnode[keep],
        offset=z[keep],
    )
