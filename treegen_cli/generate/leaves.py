"""Leaves on the last stem level: counts, places, and the blade's frame (LeafBend).

Leaves are placed like child stems (error-diffused counts per original stem, shared among
its split members, LeafDistrib along the parent), or in whorls (a negative Rotate) or as a fan
at every stem tip (negative Leaves: palms); each blade then turns its face up and outward
by LeafBend and sits on a petiole of LeafStemLen.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shapes import shape_ratio
from .bounds import GenerateOptions, refuse
from .draws import LEAVES, deviation, error_diffuse
from .frames import unit
from .placement import LevelContext, assign_members, down_angles, placements, rotations


def grow_leaves(
    p: Params, ctx: LevelContext, seed: int, n_levels: int, options: GenerateOptions, scale_tree: float
):
    """Leaves on the last stem level, oriented by the leaf level's angles and LeafBend."""
    lp = p.level[min(n_levels, len(p.level) - 1)]
    rng = np.random.default_rng([seed, n_levels, LEAVES])
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
        refuse("leaves", totals.sum(), p, options)

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
            + deviation(rng, orig.shape[0], lp.rotate_v)
        )
        # a whorl stays on one member: pick per group, then repeat
        first = j % group == 0
        stem = np.repeat(assign_members(ctx, rng, orig[first], z[first]), group)
    else:
        n, orig, j, z = placements(totals, z_lo, L)
        if fan:
            # spread across ±down angle in one plane through the stem
            spread = np.where(n[orig] > 1, j / np.maximum(n[orig] - 1, 1) - 0.5, 0.0)
            rot = np.full(orig.shape[0], 90.0) + deviation(rng, orig.shape[0], lp.rotate_v)
            stem = orig
        else:
            rot = rotations(rng, lp.rotate, lp.rotate_v, orig, j, n)
            stem = assign_members(ctx, rng, orig, z)
    k = stem.shape[0]
    if k > options.max_leaves:
        refuse("leaves", k, p, options)
    pos, pframe, _, pnode = ctx.attach(stem, np.minimum(z, ctx.length[stem] * (1 - 1e-9)))
    if fan:
        down = lp.down_angle * 2.0 * spread + deviation(rng, k, lp.down_angle_v)
        down = np.where(np.abs(down) < 1e-9, 1e-9, down)
    else:
        down = down_angles(rng, lp.down_angle, lp.down_angle_v, z, L[orig], np.zeros(k))
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
    target = unit(unit(outward, np.array([1.0, 0.0, 0.0])) + np.array([0.0, 0.0, 1.0]))
    flip = np.einsum("ni,ni->n", normal, target) < 0
    normal[flip] *= -1.0
    bend = np.clip(p.leaf_bend, 0.0, 1.0)
    normal = unit(normal * (1.0 - bend) + target * bend, normal)
    direction -= normal * np.einsum("ni,ni->n", direction, normal)[:, None]
    fallback = unit(np.cross(normal, np.array([1.0, 0.0, 0.0])), np.array([0.0, 1.0, 0.0]))
    direction = unit(direction, fallback)
    width_axis = np.cross(direction, normal)
    leaf_frame = np.stack([width_axis, direction, normal], axis=2)
    blade_pos = pos + stalk * (p.leaf_stem_len * length)
    size = np.tile([length, width], (k, 1))
    return {"stem": ctx.g0 + stem, "node": pnode, "pos": blade_pos, "frame": leaf_frame, "size": size}


def leaf_fields(leaves: dict | None) -> dict:
    """The Tree's leaf arrays from `grow_leaves`' output (None: a tree without leaves)."""
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
