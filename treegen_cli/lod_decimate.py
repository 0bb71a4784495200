"""Keyframe decimation: the paper's leaf update schedule baked into a clip.

The paper (Kondo et al.) updates a branch's leaves only when their accumulated on-screen
movement would be visible. Baked into a clip, a schedule is a per-joint set of kept keys (first
and last always kept, so the clip loops):

  * "bounded" (default): slerp (LINEAR) between kept keys, with a perspective-true bound.
    Every skinned vertex, played back and composed through the hierarchy, stays within
    error_px pixels of the dense clip on every frame, seen by a pinhole camera (fov, width)
    anywhere at the LOD's switch distance d from the centre of the tree's bounds, looking at
    that centre, in any direction (`lod.near_pixel_size`). Keys are found Douglas–Peucker
    style on the composed hierarchy (`decimate`, checked by `lod_playback.py` on
    `lod_probes.py`'s points); the camera inside that sphere (d ≤ R) keeps every key.
  * "bounded-step": the same bound with keys held (STEP), as the paper's engine plays them,
    against the dense clip played the same way (every frame held until the next).
  * "paper": the paper's rule as written, unchecked: per joint accumulate P, the movement its
    own rotation gives the geometry it carries; keep a key when P/d > i·tan(fov_x)/width
    (i = error_px), reset P; STEP. Its measured error is reported, not bounded.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .asset import Clip, Primitive, Skeleton
from .clip import kept_mask, play_keys
from .lod import LOD_DEFAULTS, LodOptions, near_pixel_size, paper_pixel_size, pixel_size
from .lod_playback import Playback, PlaybackModel
from .lod_probes import Probes, probe_world, probes
from .quat import angle as quat_angle, unit as unit_quat
from .skeleton import pose_world


@dataclass(frozen=True)
class DecimationReport:
    distance: float
    threshold_m: float  # movement allowed per point (error_px on the nearest screen)
    keys_dense: int  # K × J
    keys_kept: int  # Σ_j |keys[j]|
    max_error_px: float  # perspective-true, on box corners bounding every vertex
    iterations: int  # playback-check rounds that added keys (all levels)
    seconds: float
    radius_m: float = 0.0  # farthest any vertex gets from the centre over the clip
    schedule: str = "bounded"
    work: int = 0  # joint-frames posed and checked, all rounds and levels

    @property
    def kept_fraction(self) -> float:
        return self.keys_kept / max(self.keys_dense, 1)


def _chain(nxt: np.ndarray) -> np.ndarray:
    """Bool (K, J): frame 0 and its successors under the per-joint map nxt (K, J) (nxt > row,
    nxt[K−1] = K−1), found by pointer doubling: log2 K gathers, no loop over keys."""
    K, J = nxt.shape
    pos = np.zeros((K, J), dtype=np.int64)  # pos[t]: the t-th kept key
    t, cols = np.arange(K), np.arange(J)[None, :]
    table, bit = nxt, 0
    while (1 << bit) < K:  # nxt^t(0) = Π nxt^(2^bit)
        rows = ((t >> bit) & 1).astype(bool)
        pos[rows] = table[pos[rows], cols]
        table = table[table, cols]
        bit += 1
    kept = np.zeros((K, J), dtype=bool)
    np.put_along_axis(kept, pos, True, axis=0)
    kept[0] = kept[-1] = True
    return kept


def _walk(step: np.ndarray, threshold: float) -> np.ndarray:
    """The paper's accumulate-and-reset walk as bool (K, J) kept keys, without a loop over keys.

    step (K−1, J): each joint's movement between consecutive frames. From a kept key a the
    movement accumulates as S[m] − S[a] (S = cumulative sum); the next kept key is the first
    m with S[m] − S[a] > threshold (one searchsorted over all joints' S laid side by side),
    and the kept keys are frame 0 and its successors (`_chain`)."""
    K, J = step.shape[0] + 1, step.shape[1]
    S = np.zeros((K, J))
    np.cumsum(step, axis=0, out=S[1:])
    span = float(S[-1].max()) + threshold + 1.0
    off = np.arange(J) * span  # joints side by side, sorted
    nxt = np.searchsorted((S + off).T.ravel(), (S + threshold + off).T.ravel(), side="right").reshape(J, K).T
    return _chain(np.minimum(nxt - np.arange(J) * K, K - 1))  # no later key: the last frame


def _schedule(rotations: np.ndarray, reach: np.ndarray, threshold: float) -> np.ndarray:
    """The paper's rule: per joint accumulate P, the movement its own rotation gives the
    geometry it carries (angular step × reach), keep a key when P > threshold, reset P."""
    step = quat_angle(rotations[1:], rotations[:-1]) * reach[None]  # (K−1, J) metres
    return _walk(step, threshold)


def _refine(
    m: PlaybackModel,
    rot: np.ndarray,
    dense_world: np.ndarray,
    kept: np.ndarray,
    limit: float,
    interpolation: str,
    max_iterations: int,
    half: Playback | None = None,
) -> tuple[np.ndarray, int, int, Playback]:
    """Add keys to `kept` (bool (K, J), modified) until every corner on every frame is within
    `limit` metres of the dense pose: each round, every failing frame blames the ancestor whose
    own rotation error moves the failing joint's corners most, and per blamed joint only the
    worst frame between two of its kept keys gets a key (Douglas–Peucker; under LINEAR one key
    fixes its neighbours too). Returns (squared errors (K, J), rounds, joint-frames checked,
    the final playback); `half`: the playback of every other frame, if known (Playback)."""
    K, J = kept.shape
    limit2 = (limit * (1.0 - 1e-9)) ** 2
    play = Playback(m, rot, kept, interpolation, dense_world, half=half)
    rounds = 0
    while (play.err2 > limit2).any():
        if rounds >= max_iterations:  # give up gracefully: key the frames fully
            kept[np.flatnonzero((play.err2 > limit2).any(axis=1))] = True
            play = Playback(m, rot, kept, interpolation, dense_world, play.work)
        else:
            kk, jj = np.nonzero(play.err2 > limit2)
            a = m.anc[jj]  # (n, D)
            blame = quat_angle(play.rec[kk[:, None], a], rot[kk[:, None], a]) * m.lever[jj]
            pick = blame.argmax(axis=1)
            rows = np.arange(len(jj))
            best, best_c = a[rows, pick], blame[rows, pick]
            cols, col = np.unique(best, return_inverse=True)  # only the blamed joints
            sub = kept[:, cols]
            seg = np.cumsum(sub, axis=0)[kk, col]
            group = col.astype(np.int64) * (K + 1) + seg
            order = np.lexsort((-best_c, group))
            first = order[np.r_[True, group[order][1:] != group[order][:-1]]]
            nk, nj, nc = kk[first], best[first], col[first]
            if kept[nk, nj].all():  # nothing left to blame (rounding): key frames
                kept[np.unique(kk)] = True
                play = Playback(m, rot, kept, interpolation, dense_world, play.work)
                rounds += 1
                continue
            k = np.arange(K)[:, None]  # the new keys' neighbouring kept keys
            prev = np.maximum.accumulate(np.where(sub, k, 0), axis=0)[nk, nc]
            nxt = np.minimum.accumulate(np.where(sub, k, K - 1)[::-1], axis=0)[::-1][nk, nc]
            kept[nk, nj] = True
            play.update(nk, nj, prev, nxt)
        rounds += 1
    return play.err2, rounds, play.work, play


def _bounded(
    m: PlaybackModel,
    rot: np.ndarray,
    dense_world: np.ndarray,
    limit: float,
    interpolation: str,
    max_iterations: int,
) -> tuple[np.ndarray, np.ndarray, int, int, Playback]:
    """Kept keys (K, J) whose playback keeps every corner within `limit` metres, coarse to fine:
    the keys found on every other frame seed the check on all frames, recursively, so each
    level needs a few rounds and the total cost is about twice one pass over the clip — linear
    in its length (starting from the end keys alone needs log2 K rounds over all frames)."""
    K, J = rot.shape[:2]
    kept = np.zeros((K, J), dtype=bool)
    kept[0] = kept[-1] = True
    rounds = work = 0
    half = None
    if K > 33:
        sub = np.unique(np.r_[np.arange(0, K, 2), K - 1])
        sub_kept, _, rounds, work, sub_play = _bounded(
            m, rot[sub], dense_world[sub], limit, interpolation, max_iterations
        )
        kept[sub] = sub_kept
        half = sub_play if K % 2 else None  # odd K: the sub-clip is exactly every other frame
    err2, r, w, play = _refine(m, rot, dense_world, kept, limit, interpolation, max_iterations, half)
    return kept, err2, rounds + r, work + w, play


def _view_radius(primitives: list[Primitive], world: np.ndarray, hom: np.ndarray) -> float:
    """Farthest distance (m) from the centre of the rest bounds of `primitives` to any box
    corner posed by joint world matrices `world` (K, J, 4, 4): it bounds every skinned vertex
    (a linear blend of points inside the joints' boxes), over the whole clip."""
    pts = [np.asarray(p.positions, np.float64) for p in primitives if len(p.positions)]
    if not pts:
        return 0.0
    allp = np.concatenate(pts)
    centre = 0.5 * (allp.min(0) + allp.max(0))
    x = np.matmul(world[..., :3, :], hom) - centre[:, None]  # (K, J, 3, 8)
    return float(np.sqrt(np.einsum("kjac,kjac->kjc", x, x).max()))


def decimate(
    skeleton: Skeleton,
    primitives: list[Primitive],
    dense: Clip,
    distance: float,
    options: LodOptions = LOD_DEFAULTS,
    name: str | None = None,
    pr: Probes | None = None,
) -> tuple[Clip, DecimationReport]:
    """The dense clip with a per-joint key schedule for a LOD used from `distance` (see the
    module doc for the schedules). "bounded*": the playback stays within options.error_px
    pixels on every vertex and frame, perspective-true; distance 0, error_px 0 or a camera
    that can be inside the tree keep every key. "paper": the paper's walk, unchecked.

    Cost: each playback-check round is a few numpy passes over (K, J) arrays (pose, one 3×4 @
    4×8 product per joint and frame), run coarse to fine (`_bounded`): linear in clip length."""
    t0 = time.perf_counter()
    rot = unit_quat(np.asarray(dense.rotations, dtype=np.float64))
    K, J = rot.shape[:2]
    name = dense.name if name is None else name
    interp = options.interpolation

    def dense_clip(radius: float = 0.0, threshold: float = 0.0):
        clip = replace(dense, name=name, interpolation=interp, keys=None)
        return clip, DecimationReport(
            distance, threshold, K * J, K * J, 0.0, 0, time.perf_counter() - t0, radius, options.schedule
        )

    if distance <= 0.0 or options.error_px <= 0.0 or K <= 2:
        return dense_clip()
    pr = probes(skeleton, primitives) if pr is None else pr
    m = PlaybackModel.of(skeleton, pr)
    dense_world = pose_world(skeleton, rot)
    # the decimated pose strays by at most the centre-pixel threshold (≥ the near one)
    radius = _view_radius(primitives, dense_world, m.hom) + options.error_px * pixel_size(distance, options)
    near = near_pixel_size(distance, radius, options)
    if options.schedule == "paper":
        threshold = options.error_px * paper_pixel_size(distance, options)
        kept = _schedule(rot, pr.reach, threshold)
        err2 = Playback(m, rot, kept, interp, dense_world).err2
        rounds, work = 0, err2.size
    else:
        threshold = options.error_px * near
        if threshold <= 0.0:
            return dense_clip(radius)
        kept, err2, rounds, work, _ = _bounded(m, rot, dense_world, threshold, interp, options.max_iterations)
    keys = [np.flatnonzero(kept[:, j]) for j in range(J)]
    error = float(np.sqrt(err2.max()) / near) if near > 0 else math.inf
    clip = replace(dense, name=name, interpolation=interp, keys=keys, error_px=error)
    return clip, DecimationReport(
        distance,
        threshold,
        K * J,
        int(kept.sum()),
        error,
        rounds,
        time.perf_counter() - t0,
        radius,
        options.schedule,
        work,
    )


def measure_error_px(
    skeleton: Skeleton,
    primitives: list[Primitive],
    dense: Clip,
    clip: Clip,
    distance: float,
    options: LodOptions = LOD_DEFAULTS,
) -> float:
    """Max on-screen error (pixels, perspective-true as in the module doc: any camera at
    `distance` from the centre of the rest bounds) of `clip`'s playback against `dense`, on the
    corners of each joint's convex hull (the exact maximum of the world error) — an
    independent check of a decimated clip. inf when the camera can be inside the tree."""
    if clip.keys is None:
        return 0.0
    rot = unit_quat(np.asarray(dense.rotations, dtype=np.float64))
    pr = probes(skeleton, primitives, exact=True)
    dense_x = probe_world(pose_world(skeleton, rot), pr)
    x = probe_world(pose_world(skeleton, play_keys(rot, kept_mask(clip), clip.interpolation)), pr)
    pts = np.concatenate([np.asarray(p.positions, np.float64) for p in primitives])
    centre = 0.5 * (pts.min(0) + pts.max(0))
    radius = float(
        max(np.linalg.norm(dense_x - centre, axis=2).max(), np.linalg.norm(x - centre, axis=2).max())
    )
    near = near_pixel_size(distance, radius, options)
    err = float(np.linalg.norm(x - dense_x, axis=2).max())
    return err / near if near > 0 else math.inf


def keys_within(
    model: PlaybackModel, rotations: np.ndarray, dense_world: np.ndarray, limit: float
) -> np.ndarray:
    """Kept keys (K, J) of the dense `rotations` (K, J, 4, unit), posed as `dense_world`,
    whose slerp playback keeps every skinned vertex within `limit` metres of the dense pose on
    every frame (`model`'s box-corner probes, composed through the hierarchy): the "bounded"
    schedule with a bound in metres rather than pixels (compressed files' LOD0, key_plan.py,
    which calls it several times on one clip and so builds the model and pose once)."""
    kept, _, _, _, _ = _bounded(model, rotations, dense_world, limit, "LINEAR", LOD_DEFAULTS.max_iterations)
    return kept
