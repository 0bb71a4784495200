"""Clip maths: key times, kept keys, what an engine plays, and clip surgery for loops.

Everything that reads or reshapes a baked `Clip` lives here, so wind (which bakes), LOD
(which decimates), the forest (which shifts phases), the preview (which samples files) and
the export preparation (which resamples for USD) share one copy of each rule.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .asset import Clip, Skeleton
from .errors import TreegenError
from .quat import slerp, unit


def loop_times(duration: float, fps: float) -> np.ndarray:
    """Key times of a looping clip: n = max(1, round(duration·fps)) intervals, 0..duration
    inclusive (the closing key repeats the first)."""
    n = max(1, int(round(fps * duration)))
    return np.linspace(0.0, duration, n + 1)


def kept_mask(clip: Clip) -> np.ndarray:
    """Bool (K, J): which keys each joint's track keeps (all when clip.keys is None); the first
    and last keys are always kept, so the clip loops."""
    K, J = np.shape(clip.rotations)[:2]
    if clip.keys is None:
        return np.ones((K, J), dtype=bool)
    kept = np.zeros((K, J), dtype=bool)
    for j, kj in enumerate(clip.keys):  # per joint (hundreds), not per key
        kept[np.asarray(kj, dtype=np.int64), j] = True
    kept[0] = kept[-1] = True
    return kept


def play_keys(
    rotations: np.ndarray, kept: np.ndarray, interpolation: str = "LINEAR", rows: slice = slice(None)
) -> np.ndarray:
    """Local rotations (K, J, 4) an engine plays from the kept keys `kept` (bool (K, J), rows 0
    and K−1 all True): LINEAR slerps between a joint's neighbouring kept keys, STEP holds.
    `rows`: those frames only (the same values as the whole clip's rows)."""
    if interpolation == "LINEAR" and kept.all():  # every key: slerp(q, q, 0) is unit(q), to the bit
        return unit(rotations[rows])
    k = np.arange(rotations.shape[0])[rows, None]
    prev, nxt = (x[rows] for x in _neighbours(kept))
    qa = np.take_along_axis(rotations, prev[..., None], axis=0)
    qb = qa if interpolation == "STEP" else np.take_along_axis(rotations, nxt[..., None], axis=0)
    return _between(qa, qb, k, prev, nxt, interpolation)


def play_at(
    rotations: np.ndarray,
    kept: np.ndarray,
    frames: np.ndarray,
    joints: np.ndarray,
    interpolation: str = "LINEAR",
) -> np.ndarray:
    """play_keys(rotations, kept, interpolation)[frames, joints], (n, 4), slerping only those
    (frame, joint) pairs: the same arithmetic per pair, so the same bits (the LOD check re-plays
    the frames a new key changes, not the whole clip)."""
    if interpolation == "LINEAR" and kept.all():
        return unit(rotations[frames, joints])
    prev, nxt = _neighbours(kept)
    prev, nxt = prev[frames, joints], nxt[frames, joints]
    qa = rotations[prev, joints]
    qb = qa if interpolation == "STEP" else rotations[nxt, joints]
    return _between(qa, qb, frames, prev, nxt, interpolation)


def _neighbours(kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, J) the kept key at or before, and at or after, each frame of each joint."""
    K = kept.shape[0]
    k = np.arange(K)[:, None]
    prev = np.maximum.accumulate(np.where(kept, k, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(kept, k, K)[::-1], axis=0)[::-1]
    return prev, nxt


def _between(qa, qb, k, prev, nxt, interpolation: str) -> np.ndarray:
    """Frame k's rotation between kept keys qa (at prev) and qb (at nxt): held, or slerped."""
    if interpolation == "STEP":
        return qa
    span = nxt - prev
    t = np.where(span > 0, (k - prev) / np.where(span > 0, span, 1), 0.0)
    return slerp(qa, qb, t)


def playback(clip: Clip) -> np.ndarray:
    """(K, J, 4) rotations the clip plays at every one of its times (kept keys interpolated:
    slerp for LINEAR, hold for STEP)."""
    rot = np.asarray(clip.rotations, float)
    if clip.keys is None:
        return rot
    return play_keys(
        rot / np.linalg.norm(rot, axis=-1, keepdims=True), kept_mask(clip), clip.interpolation.upper()
    )


def sample_track(
    times: np.ndarray, values: np.ndarray, t: np.ndarray, interpolation: str = "LINEAR", rotation: bool = True
) -> np.ndarray:
    """Keys (K,), values (K, M, n) → (T, M, n) at times t (T,), held at the ends. LINEAR
    rotations slerp, other paths lerp; STEP holds the previous key (glTF semantics)."""
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    K = len(times)
    t = np.clip(np.asarray(t, dtype=np.float64), times[0], times[-1])
    if K == 1:
        return np.broadcast_to(values[:1], (len(t),) + values.shape[1:]).copy()
    if interpolation == "STEP":
        return values[np.clip(np.searchsorted(times, t, side="right") - 1, 0, K - 1)]
    if interpolation != "LINEAR":
        raise TreegenError(
            f"animation interpolation '{interpolation}' is not supported (LINEAR and STEP are)"
        )
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, K - 2)
    u = (t - times[i]) / np.maximum(times[i + 1] - times[i], 1e-12)
    a, b = values[i], values[i + 1]  # (T, M, n)
    if not rotation:
        return a + (b - a) * u[:, None, None]
    T, M = a.shape[:2]
    return slerp(a.reshape(-1, 4), b.reshape(-1, 4), np.repeat(u, M)).reshape(T, M, 4)


def moving_joints(clip: Clip, skeleton: Skeleton) -> np.ndarray:
    """Joints that get a track: Clip.animated, else those whose rotation ever leaves rest."""
    if clip.animated is not None:
        return np.flatnonzero(np.asarray(clip.animated, dtype=bool))
    rest = unit(np.asarray(skeleton.rest_rotation, dtype=np.float64))
    rot = unit(np.asarray(clip.rotations, dtype=np.float64))
    dot = np.abs(np.einsum("kji,ji->kj", rot, rest))
    return np.flatnonzero((dot < 1.0 - 1e-12).any(axis=0))


def tracked(moving: np.ndarray) -> np.ndarray:
    """The joints whose tracks a writer stores, of the `moving` ones: all of them, or the root
    alone in a still clip (wind speed 0), written as a still loop so that engines playing
    `wind_loop` by name find it (prepare marks them in Clip.animated, which the writers key;
    the key counts use it too)."""
    return moving if moving.size else np.zeros(1, np.int64)


def tracked_keys(clip: Clip, skeleton: Skeleton) -> int:
    """Keys in the tracks a writer stores (tracked): counted as scheduled, a compressed glTF
    may store a constant track as one key."""
    joints = tracked(moving_joints(clip, skeleton))
    if clip.keys is None:
        return len(clip.times) * int(joints.size)
    return int(sum(len(clip.keys[j]) for j in joints))


def union_timeline(clip: Clip, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frames (U,), rotations (U, len(joints), 4)) for formats that key every joint at the same
    times (USD): the union of the kept keys of `joints` (every key when clip.keys is None; for
    STEP also the frame before each kept key, so a linear player holds until the change), and
    each joint's own playback value at those frames.

    Result: keys {0, 4} and {0, 2, 4} of a 5-key clip → frames (0, 2, 4)."""
    rot = np.asarray(clip.rotations, np.float64)
    K = len(clip.times)
    if clip.keys is None:
        return np.arange(K), rot[:, joints]
    kept = kept_mask(clip)
    ends = np.zeros(K, dtype=bool)
    ends[[0, -1]] = True
    frames = np.flatnonzero(kept[:, joints].any(axis=1) | ends)
    step = clip.interpolation.upper() == "STEP"
    if step:
        frames = np.unique(np.r_[frames, np.maximum(frames - 1, 0)])
    return frames, play_keys(rot, kept, "STEP" if step else "LINEAR")[frames][:, joints]


def phase_rotate(clip: Clip, shift: int) -> Clip:
    """The looping clip started `shift` frames later: key arrays rotated, the kept keys moved
    along, and the wrap frame keyed with the value the clip plays there, so the rotated clip
    plays exactly the original one shifted (slerp split at a point on its own arc is exact).

    Result (K=5, shift 1): rotations (a,b,c,d,a) → (b,c,d,a,b)."""
    K = len(clip.times)
    n = K - 1
    shift = shift % n if n > 0 else 0
    if shift == 0:
        return clip
    played = playback(clip)
    body = np.roll(played[:n], -shift, axis=0)
    rot = np.concatenate([body, body[:1]])
    keys = None
    if clip.keys is not None:
        keys = [
            np.unique(np.r_[(np.asarray(k, int)[np.asarray(k, int) < n] - shift) % n, 0, n])
            for k in clip.keys
        ]
    return replace(clip, rotations=rot, keys=keys)


def repeat_clip(clip: Clip, times: int = 2) -> Clip:
    """The looping clip played `times` periods in a row (USD: room for per-instance offsets).

    Result (K=3, times 2): times (0, 1, 2) → (0, 1, 2, 3, 4)."""
    K = len(clip.times)
    n = K - 1
    if n <= 0 or times <= 1:
        return clip
    period = float(clip.times[-1] - clip.times[0])
    t = np.concatenate(
        [clip.times[:n] + r * period for r in range(times)] + [clip.times[-1:] + (times - 1) * period]
    )
    rot = np.concatenate([clip.rotations[:n]] * times + [clip.rotations[-1:]])
    keys = None
    if clip.keys is not None:
        keys = [
            np.unique(
                np.concatenate(
                    [np.asarray(k, int)[np.asarray(k, int) < n] + r * n for r in range(times)]
                    + [[0, times * n]]
                )
            )
            for k in clip.keys
        ]
    return replace(clip, times=t, rotations=rot, keys=keys)
