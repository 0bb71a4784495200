"""Compressed glTF's clips: what to store of LOD0's within 1 mm, of lower LODs' within ¼ px.

Result: with_key_plans(asset, meshopt) → the same asset with every clip's `Clip.plan` set;
the export table runs it for --compress, so the glTF writer only encodes the plan.

A compressed file (--compress quantize|meshopt) keeps every skinned vertex of a dense clip
(LOD0's) within ANIMATION_ERROR (1 mm) of the float file's playback on every frame, measured
on each joint's convex-hull corners (lod.probes(exact=True): the true maximum over its
vertices), composed through the hierarchy. Two things spend that millimetre:

  * 16-bit keys. A key rounded to c/32767 turns its joint by up to ~6e-5 rad, which moves a
    vertex 23 m away by 1.4 mm. Rounded on its own, each key's error is passed down the
    chain (the CA black oak's crown: 2.7 mm). So keys are `aimed`: parents first, a child's
    key is its dense world rotation seen through its parent's rotation *as played* (stored,
    kept and slerped), and the child takes out its parent's rounding instead of adding to it
    (the oak: 0.9 mm). Joints whose lever still needs it get float32 keys, longest reach
    first, until the rounding alone stays within a share of the bound (QUANT_SHARES), and
    quantize then puts back to int16 every float32 joint the finished plan can spare
    (`_trim`). meshopt's QUATERNION filter rounds twice (its bits, then the decoder's int16
    output), so there a joint starts at 12 bits and is raised one bit at a time, largest
    step × reach first, to 16 bits, then to float32 keys under the EXPONENTIAL filter (18,
    then asset.EXP_BITS of mantissa): short twigs stay cheap, long levers exact enough.
  * Keys (quantize only). The rest of the bound goes to lod.keys_within: slerp between kept
    keys instead of every frame, so a slow track keeps a fraction of its keys and a nearly
    still one only its end keys (which the writer stores as one key: the track is constant).
    meshopt keeps every key: its codec packs a dense, smooth 16-bit track into ~1.2 bytes a
    key, less than fewer keys with their own key times cost; its rounding gets the bound.

The plan is checked as a client plays it (stored keys as the client decodes them, meshopt's
filters to the bit: key_codec; slerp, normalised) against the dense
float clip on box corners (never below the hull's error), and the key bound shrinks until the
check passes; `error` measures a plan on the hull corners (tests, bench). meshoptimizer has
two QUATERNION decoders (SIMD, and the scalar one of clients without WebAssembly SIMD) that
round ~1 key in 600 one int16 step apart: a meshopt plan is checked against the worse of the
two (`worst`), so the millimetre holds in either client.

A lower LOD's clip keeps the keys lod_decimate scheduled, but `still` leaves out the tracks
that schedule holds constant where the joint's rest rotation keeps every vertex within
STILL_PIXELS (¼) of a pixel at the LOD's distance: each is ~180 bytes of JSON for one key.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cached_property

import numpy as np

from .asset import EXP_BITS, Asset, Clip, KeyPlan, Lod
from .clip import kept_mask, play_keys
from .key_codec import decodes, stored
from .lod import pixel_size
from .lod_decimate import keys_within
from .lod_playback import PlaybackModel, ancestors
from .lod_probes import probe_world, probes
from .quat import angle, mul, unit
from .skeleton import depth_levels, pose_world

ANIMATION_ERROR = 1e-3  # metres, LOD0's bound for compressed files (geometry has its own)
# metres of it the 16-bit rounding may take (quantize tries each, largest first); the rest
# goes to dropping keys
QUANT_SHARES = (0.9e-3, 0.6e-3, 0.3e-3, 0.15e-3)
MARGIN = 0.05e-3  # metres kept back from the key bound (box probes vs hull corners)
INPUT_JSON = 95  # bytes of JSON a key-time accessor takes
# meshopt: a joint's filter bits, raised step by step: QUATERNION up to 16, then EXPONENTIAL
# (float32 keys, `wide`) with that many bits of mantissa
MESHOPT_LEVELS = (12, 13, 14, 15, 16, 18, EXP_BITS)
# a lower LOD's compressed clip: how far (pixels at the LOD's distance) its vertices may stray
# from the float file's playback, 16-bit rounding and left-out still tracks together
STILL_PIXELS = 0.25
LOWER_BITS = 16  # meshopt: the QUATERNION filter's bits on lower LODs' keys (the default)


class _Check:
    """The dense float clip's probes on every frame, to measure a plan against: box corners
    (`exact=False`, 8 per joint, never below the hull's error: for the search) or hull
    corners (the true maximum: for the result)."""

    def __init__(self, lod: Lod, rotations: np.ndarray, exact: bool):
        self.skeleton = lod.skeleton
        self.probes = probes(lod.skeleton, lod.primitives, exact=exact)
        self.world = pose_world(lod.skeleton, rotations)
        self.dense = probe_world(self.world, self.probes)
        self.parent = np.asarray(lod.skeleton.parent, dtype=np.int64)
        self.levels = depth_levels(self.parent)
        self.turn = _world_turns(self.parent, self.levels, rotations)

    @cached_property
    def model(self) -> PlaybackModel:
        """The box-corner playback model keys_within searches with (built once per clip)."""
        return PlaybackModel.of(self.skeleton, self.probes)

    def errors(self, values: np.ndarray, kept: np.ndarray) -> np.ndarray:
        """Per joint (J,), the farthest any of its hull corners strays from the dense pose
        over the clip when `values` (K, J, 4) are played from the `kept` keys (K, J)."""
        x = probe_world(pose_world(self.skeleton, play_keys(values, kept, "LINEAR")), self.probes)
        d = x - self.dense
        err = np.sqrt(np.add.reduce(d * d, axis=2).max(axis=0))  # = norm(d, axis=2).max(axis=0)
        out = np.zeros(len(self.skeleton.names))
        np.maximum.at(out, self.probes.joint, err)
        return out


_CONJ = np.array([-1.0, -1.0, -1.0, 1.0])


def _world_turns(parent: np.ndarray, levels: list[np.ndarray], local: np.ndarray) -> np.ndarray:
    """World rotations (K, J, 4) of local ones (K, J, 4), parents before children."""
    world = np.empty_like(local)
    for idx in levels:  # depth levels (tens), not joints
        kids = parent[idx] >= 0
        world[:, idx] = local[:, idx]
        world[:, idx[kids]] = mul(world[:, parent[idx[kids]]], local[:, idx[kids]])
    return world


def aimed(
    check: _Check, rot: np.ndarray, kept: np.ndarray, wide: np.ndarray, bits: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(targets, values), each (K, J, 4): the keys to write and what a client reads back
    (`stored`). Parents first, each child's key aims at its dense *world* rotation through its
    parent's world rotation as played from the parent's stored keys (kept and slerped), so
    a parent's rounding (and, at the child's keys, its dropped keys) is taken out by its
    children instead of adding up along the chain: with every key at 16 bits the CA black
    oak's crown strays 2.7 mm from the float file the naive way and 0.9 mm aimed."""
    parent, every = check.parent, bool(kept.all())
    targets, values, played = rot.copy(), np.empty_like(rot), np.empty_like(rot)
    for idx in check.levels:  # depth levels (tens), not joints
        kids = idx[parent[idx] >= 0]
        targets[:, kids] = unit(mul(played[:, parent[kids]] * _CONJ, check.turn[:, kids]))
        values[:, idx] = stored(targets[:, idx], wide[idx], None if bits is None else bits[idx])
        local = unit(values[:, idx]) if every else play_keys(values[:, idx], kept[:, idx], "LINEAR")
        played[:, idx] = local
        kid = parent[idx] >= 0
        played[:, idx[kid]] = mul(played[:, parent[idx[kid]]], local[:, kid])
    return targets, values


def worst(
    check: _Check,
    targets: np.ndarray,
    values: np.ndarray,
    kept: np.ndarray,
    wide: np.ndarray,
    bits: np.ndarray | None = None,
) -> np.ndarray:
    """Per joint (J,), `check.errors` of keys `targets` played from `kept` under the worse of
    the decoders (`decodes`): `values` are the SIMD decode (aimed's), the scalar one is
    decoded again."""
    err = check.errors(values, kept)
    for simd in decodes(bits)[1:]:
        err = np.maximum(err, check.errors(stored(targets, wide, bits, simd), kept))
    return err


def _widen(
    check: _Check,
    rot: np.ndarray,
    wide: np.ndarray,
    share: float,
    bits: np.ndarray | None = None,
    last: tuple[bytes, np.ndarray] | None = None,
) -> tuple[float, tuple[bytes, np.ndarray]]:
    """Raise joints' precision (in place) until the rounding alone keeps every vertex within
    `share` metres: rounds, each raising, per joint too far off, its longest-reach ancestor
    not yet wide by one step (meshopt: `bits` through MESHOPT_LEVELS; quantize:
    int16, then wide). Returns the rounding's error (metres) and `last`: the final precision
    (bytes) with its per-joint errors, which quantize's next share starts from (the only
    measurement a later call can reuse: within a call each round's precision is new)."""
    K, J = rot.shape[:2]
    every = np.ones((K, J), dtype=bool)
    anc = ancestors(np.asarray(check.skeleton.parent, dtype=np.int64))
    while True:
        key = wide.tobytes() + (b"" if bits is None else bits.tobytes())
        if last is None or last[0] != key:
            last = (key, worst(check, *aimed(check, rot, every, wide, bits), every, wide, bits))
        err = last[1]
        bad = np.flatnonzero(err > share)
        chains = anc[bad]
        done = wide[chains] if bits is None else bits[chains] >= MESHOPT_LEVELS[-1]
        lever = check.probes.reach[chains] * (1.0 if bits is None else 2.0 ** -bits[chains])
        lever = np.where(done, -1.0, lever)
        pick = np.unique(chains[np.arange(len(bad)), lever.argmax(axis=1)][lever.max(axis=1) >= 0])
        if not pick.size:
            return float(err.max()), last
        if bits is None:
            wide[pick] = True
            continue
        pick = pick[bits[pick] < MESHOPT_LEVELS[-1]]
        if not pick.size:
            return float(err.max()), last
        bits[pick] = [MESHOPT_LEVELS[MESHOPT_LEVELS.index(b) + 1] for b in bits[pick]]
        wide[pick] = bits[pick] > 16


def _trim(check: _Check, rot: np.ndarray, kept: np.ndarray, wide: np.ndarray, within: bool) -> None:
    """quantize: float32 joints back to int16 (in place) wherever the plan (its `kept` keys)
    stays within ANIMATION_ERROR: `_widen` widens whole chains, longest lever first, before
    any key is dropped, and aimed children let many of them round again. Each round rounds
    every wide joint not yet tried and puts back, per joint that then strays too far, its
    rounded ancestor with the longest reach, until a round stands; a joint put back stays
    wide. (meshopt's `_widen` already stops each joint at the fewest bits its own error
    needs: stepping any back down breaks the bound.) `within`: the plan is known to keep
    ANIMATION_ERROR (else its own error is the limit)."""
    anc = ancestors(check.parent)
    limit = ANIMATION_ERROR
    if not within:
        limit = max(limit, float(check.errors(aimed(check, rot, kept, wide)[1], kept).max()))
    cand = wide.copy()
    while cand.any():  # a few rounds
        err = check.errors(aimed(check, rot, kept, wide & ~cand)[1], kept)
        chains = anc[err > limit]
        if not chains.size:
            wide &= ~cand
            return
        lever = np.where(cand[chains], check.probes.reach[chains], -1.0)
        cand[chains[np.arange(len(chains)), lever.argmax(axis=1)][lever.max(axis=1) >= 0]] = False


def _decimated(check: _Check, rot: np.ndarray, wide: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    """Kept keys (K, J) whose playback of the stored keys stays within ANIMATION_ERROR: keys found
    within `limit` metres of the dense clip, the limit shrunk if slerp of rounded keys strays
    further (met at once, as a rule); every key when no limit is left. And whether the keys
    were checked within the bound (not so for the every-key fallback)."""
    for _ in range(4):
        if limit <= MARGIN:
            break
        kept = keys_within(check.model, rot, check.world, limit)
        error = float(check.errors(aimed(check, rot, kept, wide)[1], kept).max())
        if error <= ANIMATION_ERROR:
            return _cheaper(kept, wide, rot, check), True
        limit -= error - ANIMATION_ERROR + MARGIN
    return np.ones(rot.shape[:2], dtype=bool), False


def _bytes(kept: np.ndarray, wide: np.ndarray) -> int:
    """What a plan costs in a quantize file: 8 bytes a 16-bit key, 16 a float32 one, and per
    distinct key set but the full one its times (4 bytes a key) and accessor."""
    n = kept.sum(axis=0)
    sets = {kept[:, j].tobytes(): int(n[j]) for j in range(kept.shape[1]) if n[j] < kept.shape[0]}
    return int((n * np.where(wide, 16, 8)).sum()) + sum(4 * c + INPUT_JSON for c in sets.values())


def plan(lod: Lod, clip: Clip, meshopt: bool = False) -> KeyPlan:
    """The float32 joints and kept keys of dense `clip` (of `lod`) within ANIMATION_ERROR
    (see the module doc: quantize drops keys, meshopt keeps them). quantize tries each of
    QUANT_SHARES for the rounding (the wide set only grows as the share shrinks) and keeps
    the plan that costs the fewest bytes: a calm tree gains by dropping keys, a restless one
    by rounding fewer joints wide."""
    rot = unit(np.asarray(clip.rotations, dtype=np.float64))
    K, J = rot.shape[:2]
    check = _Check(lod, rot, exact=False)
    wide = np.zeros(J, dtype=bool)
    if meshopt:
        bits = np.full(J, MESHOPT_LEVELS[0])
        every = np.ones((K, J), dtype=bool)
        _widen(check, rot, wide, ANIMATION_ERROR - MARGIN, bits)
        targets = aimed(check, rot, every, wide, bits)[0]
        return KeyPlan(replace(clip, rotations=targets, keys=[np.arange(K)] * J), wide, bits)
    best: tuple[int, np.ndarray, np.ndarray] | None = None
    last = None
    for share in QUANT_SHARES:
        quant, last = _widen(check, rot, wide, share, last=last)
        kept, within = _decimated(check, rot, wide, ANIMATION_ERROR - quant - MARGIN)
        narrow = wide.copy()
        _trim(check, rot, kept, narrow, within)
        cost = _bytes(kept, narrow)
        if best is None or cost < best[0]:
            best = (cost, kept, narrow)
    assert best is not None
    _, kept, wide = best
    targets = aimed(check, rot, kept, wide)[0]
    keys = [np.flatnonzero(kept[:, j]) for j in range(J)]
    return KeyPlan(replace(clip, rotations=targets, keys=keys), wide)


def _cheaper(kept: np.ndarray, wide: np.ndarray, rot: np.ndarray, check: _Check) -> np.ndarray:
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
    return trial if check.errors(aimed(check, rot, trial, wide)[1], trial).max() <= ANIMATION_ERROR else kept


def error(lod: Lod, dense: Clip, kp: KeyPlan, simd: bool | None = None) -> float:
    """Metres: the farthest any skinned vertex of `lod` strays from the dense float clip's
    pose on any frame when played from plan `kp`'s keys (hull corners: the true maximum),
    decoded by meshopt's SIMD or scalar decoder (`simd`), by default the worse of them."""
    rot = unit(np.asarray(dense.rotations, dtype=np.float64))
    kept = np.zeros(rot.shape[:2], dtype=bool)
    for j, k in enumerate(kp.clip.keys):  # per joint (hundreds)
        kept[k, j] = True
    targets = unit(np.asarray(kp.clip.rotations, dtype=np.float64))
    check = _Check(lod, rot, exact=True)
    ways = decodes(kp.bits) if simd is None else (simd,)
    return max(float(check.errors(stored(targets, kp.wide, kp.bits, s), kept).max()) for s in ways)


def still(lod: Lod, clip: Clip, meshopt: bool = False) -> KeyPlan:
    """A lower LOD's clip (its keys already scheduled by lod_decimate) in a compressed file:
    the keys as they are, but tracks the schedule holds constant left out, the joint resting
    at its node's rotation instead, as long as every vertex (hull corners, through the
    hierarchy, 16-bit rounding included) stays within STILL_PIXELS of a pixel at the LOD's
    distance of the float file's playback. A constant track is one key of data but ~180
    bytes of JSON (sampler, channel, accessor); the tracks nearest their rest go first. One
    track is always kept, so the clip keeps its animation."""
    rot = unit(np.asarray(clip.rotations, dtype=np.float64))
    K, J = rot.shape[:2]
    kept = kept_mask(clip)
    check = _Check(lod, play_keys(rot, kept, "LINEAR"), exact=True)
    bits = np.full(J, LOWER_BITS) if meshopt else None
    ways = [stored(rot, np.zeros(J, dtype=bool), bits, simd) for simd in decodes(bits)]
    first = np.argmax(kept, axis=0)
    constant = np.array([not any(np.any(v[kept[:, j], j] != v[first[j], j]) for v in ways) for j in range(J)])
    animated = np.asarray(clip.animated, dtype=bool)
    candidates = np.flatnonzero(animated & constant)
    rest = unit(np.asarray(lod.skeleton.rest_rotation, dtype=np.float32).astype(np.float64))
    shift = angle(rot[first[candidates], candidates], rest[candidates]) * check.probes.reach[candidates]
    order = candidates[np.argsort(shift, kind="stable")][: max(0, min(len(candidates), animated.sum() - 1))]
    bound = STILL_PIXELS * pixel_size(lod.distance)

    def fits(n: int) -> bool:
        every = kept.copy()
        every[:, order[:n]] = True
        for values in ways:  # every decoder's
            trial = values.copy()
            trial[:, order[:n]] = rest[order[:n]]
            if check.errors(trial, every).max() > bound:
                return False
        return True

    lo, hi = 0, len(order)  # the longest prefix of `order` that fits (fits(0): rounding only)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid - 1)
    animated = animated.copy()
    animated[order[:lo]] = False
    return KeyPlan(replace(clip, animated=animated), np.zeros(J, dtype=bool), bits)


def with_key_plans(asset: Asset, meshopt: bool) -> Asset:
    """Every clip planned for a compressed file: dense ones (every key kept: LOD0's) by `plan`,
    lower LODs' scheduled LINEAR ones by `still`."""
    lods = []
    for lod in asset.lods:  # a handful of LODs and clips
        clips = []
        for c in lod.clips:
            if c.keys is None and len(c.times) > 2:
                c = replace(c, plan=plan(lod, c, meshopt))
            elif (
                c.keys is not None
                and c.animated is not None
                and c.interpolation == "LINEAR"
                and lod.distance > 0
            ):
                c = replace(c, plan=still(lod, c, meshopt))
            clips.append(c)
        lods.append(replace(lod, clips=clips))
    return replace(asset, lods=lods)
