"""The last stage before export: fill in what writers need, so writers only encode.

Result: prepare(asset) → the same asset with every clip's moving joints (`Clip.animated`) and
shared timeline (`Clip.timeline`) set; with_bounds(asset) adds every LOD's animated bounds
(`Lod.bounds`), which only formats that store extents need (the export table's USD entry);
prepare_forest(forest) does both and fills the phase variants and repeated clips of the prototypes.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .asset import Asset, Clip, Forest, Lod, Skeleton, lod_bounds
from .clip import moving_joints, phase_rotate, repeat_clip, tracked, union_timeline
from .skeleton import pose_world

BOUNDS_MARGIN = 0.02  # of the box size: slerp between keys can bulge slightly past the keys


def prepare_clip(clip: Clip, skeleton: Skeleton) -> Clip:
    """`animated` (bool (J,): the joints the writers key; an explicit one is kept) and their
    timeline: the moving joints, or the root alone in a still clip (clip.tracked), so a
    still clip is written as a still loop by every writer without a rule of its own."""
    joints = tracked(moving_joints(clip, skeleton))
    animated = np.zeros(len(skeleton.names), dtype=bool)
    animated[joints] = True
    return replace(clip, animated=animated, timeline=union_timeline(clip, joints))


def animated_bounds(lod: Lod) -> tuple[np.ndarray, np.ndarray]:
    """A box holding the skinned geometry at rest and at every key of every clip.

    Cheap (joints × keys, not vertices × keys): each joint's vertices, in its bind frame, fill
    a local box that the joint carries rigidly; a linear blend of such points lies in the
    union of the joints' posed boxes.
    """
    lo, hi = lod_bounds(lod)
    skel = lod.skeleton
    J = len(skel.names)
    clips = [c for c in lod.clips if len(c.times)]
    if not clips or J == 0:
        return lo, hi
    bind = np.asarray(skel.bind_world, np.float64)
    box_lo, box_hi = np.full((J, 3), np.inf), np.full((J, 3), -np.inf)
    for prim in lod.primitives:  # per-joint local boxes: one pass per influence slot
        pos = np.asarray(prim.positions, np.float64)
        joints = np.asarray(prim.joints, np.int64)
        weights = np.asarray(prim.weights)
        for k in range(joints.shape[1] if joints.ndim == 2 else 0):
            used = weights[:, k] > 0
            if not used.any():
                continue
            jv = joints[used, k]
            order = np.argsort(jv, kind="stable")
            jv = jv[order]
            local = np.einsum("nji,nj->ni", bind[jv, :3, :3], pos[used][order] - bind[jv, :3, 3])
            starts = np.flatnonzero(np.r_[True, jv[1:] != jv[:-1]])  # Rᵀ(p − t) per joint run
            js = jv[starts]
            box_lo[js] = np.minimum(box_lo[js], np.minimum.reduceat(local, starts, axis=0))
            box_hi[js] = np.maximum(box_hi[js], np.maximum.reduceat(local, starts, axis=0))
    has = np.isfinite(box_lo[:, 0])
    if not has.any():
        return lo, hi
    corner_sel = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], bool)
    corners = np.where(corner_sel[None], box_hi[has, None, :], box_lo[has, None, :])  # (Jh, 8, 3)
    rest_q = np.asarray(skel.rest_rotation, np.float64)
    for clip in clips:
        K = len(clip.times)
        q = np.broadcast_to(rest_q, (K, J, 4)).copy()
        moving = tracked(moving_joints(clip, skel))
        q[:, moving] = np.asarray(clip.rotations, np.float64)[:, moving]
        world = pose_world(skel, q)
        w_rot, w_pos = world[..., :3, :3], world[..., :3, 3]
        posed = np.einsum("kjab,jcb->kjca", w_rot[:, has], corners) + w_pos[:, has, None, :]
        lo = np.minimum(lo, posed.min(axis=(0, 1, 2)))
        hi = np.maximum(hi, posed.max(axis=(0, 1, 2)))
    margin = BOUNDS_MARGIN * (hi - lo).max()
    return lo - margin, hi + margin


def prepare_lod(lod: Lod, bounds: bool = False) -> Lod:
    lod = replace(lod, clips=[prepare_clip(c, lod.skeleton) for c in lod.clips])
    return replace(lod, bounds=animated_bounds(lod)) if bounds else lod


def prepare(asset: Asset, bounds: bool = False) -> Asset:
    """Every LOD prepared (idempotent); `bounds` also fills `Lod.bounds` (with_bounds)."""
    return replace(asset, lods=[prepare_lod(lod, bounds) for lod in asset.lods])


def with_bounds(asset: Asset) -> Asset:
    """Every LOD's animated bounds filled (kept where already set): forward kinematics over
    every key, so it runs only for formats that store extents (USD: exchange's table)."""
    return replace(
        asset,
        lods=[
            lod if lod.bounds is not None else replace(lod, bounds=animated_bounds(lod)) for lod in asset.lods
        ],
    )


def prepare_forest(forest: Forest) -> Forest:
    """Prototypes prepared; for each (prototype, LOD) an instance uses, its first clip at every
    phase variant (moving joints as the base clip's); and every prototype's clips repeated over two periods."""
    protos = [prepare(a, bounds=True) for a in forest.prototypes]
    used = sorted(
        {
            (i.prototype, k)
            for i in forest.instances
            for k in (range(len(protos[i.prototype].lods)) if forest.all_lods else [i.lod])
        }
    )
    V = max(1, forest.phase_variants)
    variants: dict[tuple[int, int], list[Clip]] = {}
    for p, k in used:  # a few (prototype, LOD) pairs
        lod = protos[p].lods[k]
        if lod.clips and len(lod.clips[0].times) > 1:
            base = lod.clips[0]
            n = len(base.times) - 1
            variants[(p, k)] = [phase_rotate(base, round(v * n / V)) for v in range(V)]
    looped = []
    if forest.loop > 0:
        for a in protos:
            looped.append(
                prepare(
                    replace(
                        a, lods=[replace(lod, clips=[repeat_clip(c, 2) for c in lod.clips]) for lod in a.lods]
                    ),
                    bounds=True,
                )
            )
    return replace(forest, prototypes=protos, variants=variants, looped=looped)


def split_lods(asset: Asset) -> list[Asset]:
    """One complete asset per LOD (its own skeleton, mesh and clip, named as a single-LOD file's:
    "wind_loop"), for engines that take per-LOD files (Unity LODGroup `_LOD0…`, Unreal, Godot
    with visibility ranges). `extras` record the LOD's index, count, distance and coverage.

    Each part keeps only the materials its LOD draws (LOD0 carried the impostor's atlas, the
    impostor the bark and leaf textures).

    Result: a 4-LOD asset → 4 assets of one LOD each, extras lod_index 0..3."""
    out = []
    for k, lod in enumerate(asset.lods):
        clips = [replace(c, name="wind_loop") for c in lod.clips[:1]] + list(lod.clips[1:])
        used = {p.material for p in lod.primitives}
        out.append(
            replace(
                asset,
                materials=[m for m in asset.materials if m.name in used],
                lods=[replace(lod, clips=clips)],
                extras=asset.extras
                | {
                    "lod_index": k,
                    "lod_count": len(asset.lods),
                    "lod_distance_m": float(lod.distance),
                    "lod_screen_coverage": float(lod.screen_coverage),
                },
            )
        )
    return out
