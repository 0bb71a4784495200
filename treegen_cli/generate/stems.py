"""One level's stems grown segment by segment: the paper's curvature and vertical attraction.

Every stem of one level shares the same `curve_res`, so the whole level grows at once: the loop
runs over segment indices and each step updates all stems of the level as numpy arrays
(nCurve, nCurveBack, nCurveV or a helix, AttractionUp). Splits ("clones", splits.py) join the
active set when they appear. `Level` is what a level starts from, `Grown` what it becomes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from .draws import GROW, deviation
from .frames import UP, declination, rot_axis, rot_x, unit
from .splits import split_stems


@dataclass
class Level:
    """Stems of one level before they are grown: start pose plus the values growth needs."""

    pos: np.ndarray  # (M, 3)
    frame: np.ndarray  # (M, 3, 3)
    length: np.ndarray  # (M,)
    radius: np.ndarray  # (M,)
    parent: np.ndarray  # (M,) global stem index
    parent_node: np.ndarray  # (M,) global node index
    offset: np.ndarray  # (M,)


@dataclass
class Grown:
    """A grown level: stems (originals first, then clones in creation order) and their nodes."""

    stem_parent: np.ndarray  # local index of the split origin for clones, -1 otherwise
    stem_origin: np.ndarray  # local index of the original stem a clone belongs to
    stem_first_seg: np.ndarray  # segment index of the stem's first node
    node_stem: np.ndarray  # local stem index per node, grouped by stem, base to tip
    node_seg: np.ndarray  # segment index of the node (z = seg · seg_len)
    node_pos: np.ndarray
    node_frame: np.ndarray


def grow_level(p: Params, level: int, batch: Level, length: np.ndarray, seed: int) -> Grown:
    """Grow every stem of one level segment by segment (curve, curve back, helix, splits,
    split correction, attraction up). Deterministic in (seed, level) whatever `length` is."""
    lp = p.level[level]
    res = max(1, int(lp.curve_res))
    rng = np.random.default_rng([seed, level, GROW])
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
                    frame = frame @ rot_x(np.full(a, tilt))
                frame = rot_axis(helix_axis[act], np.full(a, 2.0 * np.pi / res)) @ frame
            else:
                if lp.curve_back == 0:
                    bend = np.full(a, lp.curve / res)
                elif seg < (res + 1) // 2:
                    bend = np.full(a, 2.0 * lp.curve / res)
                else:
                    bend = np.full(a, 2.0 * lp.curve_back / res)
                bend = bend + deviation(rng, a, lp.curve_v / res)
                frame = frame @ rot_x(np.radians(bend) + correction[act])
            if level >= 2 and p.attraction_up != 0.0:
                d = frame[:, :, 2]
                decl = declination(d)
                ang = p.attraction_up * decl / res
                ang = np.where(ang > 0, np.minimum(ang, decl), np.maximum(ang, -(np.pi - decl)))
                axis = np.cross(d, UP)
                ok = np.linalg.norm(axis, axis=1) > 1e-9
                if ok.any():
                    frame[ok] = rot_axis(unit(axis[ok]), ang[ok]) @ frame[ok]

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
                frame, act, correction, n_new = split_stems(
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
    return Grown(
        stem_parent=stems["parent"],
        stem_origin=stems["origin"],
        stem_first_seg=stems["first"],
        node_stem=node_stem[order],
        node_seg=node_seg[order],
        node_pos=np.concatenate(rec_pos)[order],
        node_frame=np.concatenate(rec_frame)[order],
    )
