"""Compressed glTF's dense clips (LOD0's): what to store within the 1 mm bound.

A compressed file (--compress quantize|meshopt) keeps every skinned vertex of a dense clip
within ANIMATION_ERROR (1 mm) of the float file's playback on every frame, measured on each
joint's convex-hull corners (lod.probes(exact=True): the true maximum over its vertices),
composed through the hierarchy. Two things spend that millimetre:

  * 16-bit keys. A key rounded to c/32767 turns its joint by up to ~6e-5 rad, which moves a
    vertex 23 m away by 1.4 mm, and the joints of a chain add up: with every key at 16 bits
    the CA black oak's crown moves by 3.5 mm. Joints get float32 keys, longest reach first,
    until the 16-bit rounding alone stays within QUANT_SHARE of the bound.
    meshopt stores them with its EXPONENTIAL filter (compress.EXP_BITS of mantissa) instead.
  * Keys (quantize only). The rest of the bound goes to lod.keys_within: slerp between kept
    keys instead of every frame, so a slow track keeps a fraction of its keys and a nearly
    still one only its end keys (which the writer stores as one key: the track is constant).
    meshopt keeps every key: its codec packs a dense, smooth 16-bit track into ~1.2 bytes a
    key, less than fewer keys with their own key times cost; its rounding gets the bound.

The plan is checked as a client plays it (stored keys, slerp, normalised) against the dense
float clip on box corners (never below the hull's error), and the key bound shrinks until the
check passes; `error` measures a plan on the hull corners (tests, bench).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..asset import Clip, Lod
from ..clip import play_keys
from ..lod import keys_within, probe_world, probes
from ..quat import unit
from ..skeleton import pose_world
from .compress import EXP_BITS

ANIMATION_ERROR = 1e-3  # metres, LOD0's bound for compressed files (geometry has its own)
QUANT_SHARE = 0.3e-3  # metres of it the 16-bit rounding may take; the rest goes to keys
MARGIN = 0.05e-3  # metres kept back from the key bound (box probes vs hull corners)
INPUT_JSON = 95  # bytes of JSON a key-time accessor takes


@dataclass(frozen=True)
class KeyPlan:
    """A dense clip as a compressed file stores it: `clip` with per-joint kept keys, `wide`
    (J,) joints whose keys stay float32."""

    clip: Clip
    wide: np.ndarray
    meshopt: bool


def stored(rotations: np.ndarray, wide: np.ndarray, meshopt: bool = False) -> np.ndarray:
    """Rotations (K, J, 4) as a client reads them back: normalized int16 (c / 32767, as
    compress.snorm16 writes them) except the `wide` joints' float32, which meshopt's
    EXPONENTIAL filter rounds to steps of 2^(2 − EXP_BITS) at most (a unit quaternion's
    shared exponent is ≤ 1)."""
    out = np.rint(np.clip(rotations, -1.0, 1.0) * 32767.0) / 32767.0
    wide_values = rotations[:, wide].astype(np.float32).astype(np.float64)
    if meshopt:
        step = 2.0 ** (2 - EXP_BITS)
        wide_values = np.rint(wide_values / step) * step
    out[:, wide] = wide_values
    return out


def _ancestors(parent: np.ndarray) -> np.ndarray:
    """(J, D): each joint, its parent, grandparent, … (the root repeats once reached)."""
    chain = [np.arange(len(parent))]
    while True:
        up = np.where(parent[chain[-1]] >= 0, parent[chain[-1]], chain[-1])
        if np.array_equal(up, chain[-1]):
            return np.stack(chain, axis=1)
        chain.append(up)


class _Check:
    """The dense float clip's probes on every frame, to measure a plan against: box corners
    (`exact=False`, 8 per joint, never below the hull's error: for the search) or hull
    corners (the true maximum: for the result)."""

    def __init__(self, lod: Lod, rotations: np.ndarray, exact: bool):
        self.skeleton = lod.skeleton
        self.probes = probes(lod.skeleton, lod.primitives, exact=exact)
        self.dense = probe_world(pose_world(lod.skeleton, rotations), self.probes)

    def errors(self, values: np.ndarray, kept: np.ndarray) -> np.ndarray:
        """Per joint (J,), the farthest any of its hull corners strays from the dense pose
        over the clip when `values` (K, J, 4) are played from the `kept` keys (K, J)."""
        x = probe_world(pose_world(self.skeleton, play_keys(values, kept, "LINEAR")), self.probes)
        err = np.linalg.norm(x - self.dense, axis=2).max(axis=0)
        out = np.zeros(len(self.skeleton.names))
        np.maximum.at(out, self.probes.joint, err)
        return out


def plan(lod: Lod, clip: Clip, meshopt: bool = False) -> KeyPlan:
    """The float32 joints and kept keys of dense `clip` (of `lod`) within ANIMATION_ERROR
    (see the module doc: quantize drops keys, meshopt keeps them)."""
    rot = unit(np.asarray(clip.rotations, dtype=np.float64))
    K, J = rot.shape[:2]
    check = _Check(lod, rot, exact=False)
    every = np.ones((K, J), dtype=bool)
    wide = np.zeros(J, dtype=bool)
    anc = _ancestors(np.asarray(lod.skeleton.parent, dtype=np.int64))
    reach = check.probes.reach
    share = ANIMATION_ERROR - MARGIN if meshopt else QUANT_SHARE
    while True:  # a few rounds: each widens, per joint too far off, its longest-reach ancestor
        err = check.errors(stored(rot, wide, meshopt), every)
        bad = np.flatnonzero(err > share)
        chains = anc[bad]
        lever = np.where(wide[chains], -1.0, reach[chains])
        pick = chains[np.arange(len(bad)), lever.argmax(axis=1)][lever.max(axis=1) >= 0]
        if not pick.size:
            break
        wide[pick] = True
    values = stored(rot, wide, meshopt)
    limit = ANIMATION_ERROR - float(err.max()) - MARGIN
    kept = every
    for _ in range(0 if meshopt else 4):  # met at once unless slerp of rounded keys strays
        if limit <= 0:
            break
        trial = keys_within(lod.skeleton, lod.primitives, rot, limit)
        trial_error = float(check.errors(values, trial).max())
        if trial_error <= ANIMATION_ERROR:
            kept = trial
            break
        limit -= trial_error - ANIMATION_ERROR + MARGIN
    kept = _cheaper(kept, wide, check, values)
    keys = [np.flatnonzero(kept[:, j]) for j in range(J)]
    return KeyPlan(replace(clip, keys=keys), wide, meshopt)


def _cheaper(kept: np.ndarray, wide: np.ndarray, check: _Check, values: np.ndarray) -> np.ndarray:
    """`kept` with every key back on the tracks where dropping keys costs more than it saves:
    a decimated track needs its own key times (4 bytes a key and ~INPUT_JSON bytes of
    accessor) while full tracks share one; kept as is if that strays past the bound."""
    K = kept.shape[0]
    n = kept.sum(axis=0)
    per_key = np.where(wide, 16, 8)
    full = (n * (per_key + 4) + INPUT_JSON >= K * per_key) & (n > 1)
    if not full.any():
        return kept
    trial = kept.copy()
    trial[:, full] = True
    return trial if check.errors(values, trial).max() <= ANIMATION_ERROR else kept


def error(lod: Lod, dense: Clip, kp: KeyPlan) -> float:
    """Metres: the farthest any skinned vertex of `lod` strays from the dense float clip's
    pose on any frame when played from plan `kp` (hull corners: the true maximum)."""
    rot = unit(np.asarray(dense.rotations, dtype=np.float64))
    kept = np.zeros(rot.shape[:2], dtype=bool)
    for j, k in enumerate(kp.clip.keys):  # per joint (hundreds)
        kept[k, j] = True
    return float(_Check(lod, rot, exact=True).errors(stored(rot, kp.wide, kp.meshopt), kept).max())
