"""Stem splitting (the paper's "clones"): nSegSplits / 0BaseSplits members at a node.

A split stem turns into counts + 1 members that tilt apart and then bend back, so the limbs
diverge without falling over; the clones join the level's active set and grow on from there.
"""

from __future__ import annotations

import numpy as np

from .draws import deviation
from .frames import UP, declination, rot_axis, rot_x


def split_stems(rng, p, level, seg, res, counts, act, frame, correction, n_stems, stems):
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
    decl = np.degrees(declination(d))
    nm = f.shape[0]
    angle = np.maximum(0.0, lp.split_angle + deviation(rng, nm, lp.split_angle_v) - decl)
    if level == 0 and seg == 1 and p.base_splits > 0:
        # evenly around, one random turn per group, so no two leaders crowd each other
        turn = rng.uniform(0, 360.0 / (k + 1))
        fan = member_idx * 360.0 / (group_k + 1) + np.concatenate([turn, np.repeat(turn, k)])
    else:
        fan_width = 20.0 + 0.75 * (30.0 + np.abs(decl - 90.0)) * rng.uniform(0, 1, nm) ** 2
        fan = (member_idx / np.maximum(group_k, 1) - 0.5) * 2.0 * fan_width
    ang_r = np.radians(angle)
    f = f @ rot_x(ang_r)
    f = rot_axis(np.tile(UP, (nm, 1)), np.radians(fan)) @ f
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
