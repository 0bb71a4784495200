"""LOD: leaf update schedules as keyframe decimation per view distance, and geometric LODs.

The paper (Kondo et al.) updates a branch's leaves only when their accumulated on-screen
movement would be visible. Baked into a clip, that schedule is a per-joint set of kept keys:

    clip, report = decimate(skeleton, primitives, dense, distance=130.0)
    # Result: dense (121 keys × J joints) → clip.keys[j] ⊂ 0..120, first and last always kept;
    # played back (LINEAR slerp or STEP hold) it stays within error_px pixels of the dense clip
    # at 130 m (report.max_error_px <= error_px).

Thresholds (metres of movement that make one pixel at distance d, times error_px = i):
  * "exact" (default): one pixel at distance d spans 2·d·tan(fov/2)/width;
  * "paper": the paper's P/d > i·tan(fov_x)/width, i.e. d·tan(fov)/width (×1.5 looser at 60°).

Two steps per distance:
  1. Schedule (the paper's rule): walk the dense clip; per joint accumulate P, the movement its
     own rotation gives the geometry it carries (its leaves and bark and the branches riding on
     it: angular step × the farthest carried point), keep a key when P crosses the threshold,
     reset P. Ancestors' rotations are rigid and preserve lengths, so a child's P does not count
     its parents' motion twice.
  2. Playback check: reconstruct the decimated clip as an engine would (LINEAR: slerp between a
     joint's kept keys; STEP: hold the last kept key), compose the hierarchy (skeleton.pose_world)
     and measure each joint's probes — the corners of a principal-axes box around everything
     it moves, whose error bounds every skinned vertex's (see `probes`) — against the dense
     clip, in pixels at d, on every frame. Where the
     bound is exceeded, the ancestor contributing most to that point's error at that frame gets
     a key there (per joint, the worst frame between two of its kept keys); repeat until the
     bound holds (parents' keys move children). Under LINEAR step 1 runs against
     linear_schedule_scale × the threshold, since slerp errs far less than holding.

Geometric LODs (lod_budget.py): per LOD index a coarser tree cut from LOD0's within
`triangles` × LOD0's triangles — fewer sides, thin stems dropped, a stratified subset of the
leaves scaled to cover what all of them covered (lod_leaves.py) — and a smaller joint budget.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .asset import Clip, Lod, Primitive, Skeleton
from .errors import OptionError, TreegenError
from .clip import kept_mask, play_keys
from .quat import angle as quat_angle, unit as unit_quat
from .skeleton import pose_world


@dataclass(frozen=True)
class LodOptions:
    """View and error model, and the per-LOD coarsening tables (index = LOD; last repeats).

    distances: metres from which each LOD is used, ascending; LOD0 is the first (0 → its clip is
    dense). fov_deg is horizontal, width in pixels; aspect (width/height) only feeds the screen
    coverage hint."""

    distances: tuple[float, ...] = (0.0, 10.0, 30.0, 130.0)
    fov_deg: float = 60.0
    width: int = 1920
    error_px: float = 1.0
    error_form: str = "exact"                  # "exact" 2·d·tan(fov/2)/width, or "paper" d·tan(fov)/width
    interpolation: str = "LINEAR"              # "LINEAR" (slerp) or "STEP" (the paper's hold)
    aspect: float = 16.0 / 9.0
    sides: tuple[tuple[int, ...], ...] = ((16, 8, 6, 4, 3), (8, 6, 4, 3), (6, 4, 3), (4, 3))
    joint_fraction: tuple[float, ...] = (1.0, 0.5, 0.25, 0.125)  # × the joint budget
    triangles: tuple[float, ...] = (1.0, 0.5, 0.15, 0.05)  # × LOD0's triangles (lod_budget.py)
    max_iterations: int = 200                  # playback-check refinement rounds
    linear_schedule_scale: float = 4.0         # LINEAR: the walk's threshold × this (see decimate)

    def __post_init__(self) -> None:
        d = self.distances
        shown = ",".join(f"{x:g}" for x in d) or "(none)"
        if not d or any(not math.isfinite(x) or x < 0 for x in d) or list(d) != sorted(d):
            raise OptionError("distances", shown, "give one or more ascending distances in "
                                                  "metres, each >= 0", "--lod-distances")
        if len(set(d)) != len(d):
            raise OptionError("distances", shown, "distances repeat", "--lod-distances")
        if not 0.0 < self.fov_deg < 180.0:
            raise OptionError("fov_deg", self.fov_deg, "the horizontal field of view must be in "
                                                        "(0, 180) degrees", "--fov")
        if self.error_form == "paper" and self.fov_deg >= 90.0:
            raise OptionError("fov_deg", self.fov_deg, "the paper's tan(fov) form needs fov < 90 "
                                                        "degrees", "--fov")
        if not 1 <= self.width <= 1_000_000:
            raise OptionError("width", self.width, "screen width must be in 1..1000000 pixels",
                              "--width")
        if not (math.isfinite(self.error_px) and 0.0 <= self.error_px <= 1000.0):
            raise OptionError("error_px", self.error_px, "allowed range 0..1000 pixels", "--error-px")
        if self.error_form not in ("exact", "paper"):
            raise OptionError("error_form", self.error_form, "use 'exact' or 'paper'", "--error-form")
        if self.interpolation not in ("LINEAR", "STEP"):
            raise OptionError("interpolation", self.interpolation, "use 'linear' or 'step'",
                              "--interpolation")
        if not (self.aspect > 0 and self.max_iterations >= 1 and self.linear_schedule_scale >= 1):
            raise TreegenError("LOD aspect must be > 0 and max_iterations >= 1")
        if (min(self.joint_fraction) <= 0 or max(self.joint_fraction) > 1
                or min(min(s) for s in self.sides) < 3):
            raise TreegenError("LOD tables: joint_fraction in (0, 1], sides >= 3")
        t = self.triangles
        if not t or any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in t):
            raise TreegenError(f"--lod-triangles {','.join(f'{x:g}' for x in t) or '(none)'}: "
                               "give fractions of LOD0's triangles, each in (0, 1]")


LOD_DEFAULTS = LodOptions()


def _at(table: tuple, index: int):
    return table[min(index, len(table) - 1)]


def pixel_size(distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Metres spanned by one pixel at `distance` (the threshold before error_px)."""
    fov = math.radians(options.fov_deg)
    if options.error_form == "paper":
        return distance * math.tan(fov) / options.width
    return 2.0 * distance * math.tan(0.5 * fov) / options.width


def screen_coverage(height: float, distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Screen height a tree of `height` metres fills at `distance`, as a fraction of the view
    (above 1 when it overflows the screen; not clamped, so glTF's MSFT_screencoverage switches
    LODs at the same distances as USD's distance heuristic)."""
    if distance <= 0:
        return 1.0
    view_height = 2.0 * distance * math.tan(0.5 * math.radians(options.fov_deg)) / options.aspect
    return float(height / view_height)


# ---------------------------------------------------------------------------- geometry probes

@dataclass(frozen=True, eq=False)
class Probes:
    """Representative points: `local` (P, 3) in the bind frame of joint `joint` (P,); `rest`
    (P, 3) their rest positions; `reach` (J,) the farthest probe each joint's rotation moves."""

    joint: np.ndarray
    local: np.ndarray
    rest: np.ndarray
    reach: np.ndarray


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Indices of the convex hull's corners of `points` (n, 3); all points when they are too
    few or too flat for a 3-D hull."""
    from scipy.spatial import ConvexHull, QhullError

    n = points.shape[0]
    if n <= 8:
        return np.arange(n)
    try:
        return ConvexHull(points).vertices
    except (QhullError, ValueError):
        if n <= 4096:
            return np.arange(n)
        return ConvexHull(points, qhull_options="QJ").vertices     # flat: joggled corners


def _box_corners(x: np.ndarray, owner: np.ndarray, J: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the 8 corners of a box around its points, aligned with their principal axes
    (a tight box for a branch's elongated cloud). Returns (joint (P,), corner positions (P, 3))."""
    order = np.argsort(owner.astype(np.uint16), kind="stable")   # radix sort: joints < 65536
    bounds = np.searchsorted(owner[order], np.arange(J + 1))
    xs = x[order]
    signs = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
    joints, corners = [], []
    for j in range(J):                             # a few hundred joints, numpy within each
        pts = xs[bounds[j]:bounds[j + 1]].astype(np.float64)
        if not len(pts):
            continue
        mean = pts.mean(axis=0)
        d = pts - mean
        _, axes = np.linalg.eigh(d.T @ d + np.eye(3) * 1e-12)   # columns: principal axes
        u = d @ axes
        ext = np.where(signs, u.max(axis=0), u.min(axis=0))      # (8, 3)
        joints.append(np.full(8, j))
        corners.append(mean + ext @ axes.T)
    return np.concatenate(joints), np.concatenate(corners)


def probes(skeleton: Skeleton, primitives: list[Primitive], exact: bool = False) -> Probes:
    """Points whose pose error bounds the error of every vertex a joint moves.

    Why a few points suffice: a joint's pose error is a rigid-motion difference, affine in the
    vertex's position, so its size is a convex function of the position and peaks at a corner
    of any convex set holding the joint's vertices. A vertex blended between joints moves by
    the weighted mean of its joints' errors, never more than the largest of them, and it counts
    for each joint that moves it. `exact=False` (decimation): the 8 corners of a box around each
    joint's vertices — a guaranteed, slightly pessimistic bound that is cheap to evaluate on
    every frame. `exact=True` (measuring): the corners of each joint's convex hull, the true
    maximum over all vertices. Every joint also probes its own pivot and its children's, so a
    joint with no skinned vertex has a reach."""
    bind = np.asarray(skeleton.bind_world, dtype=np.float64)
    parent = np.asarray(skeleton.parent, dtype=np.int64)
    J = bind.shape[0]
    pivot = bind[:, :3, 3]
    pts, own = [pivot.astype(np.float32), pivot[parent >= 0].astype(np.float32)], \
        [np.arange(J), parent[parent >= 0]]
    for prim in primitives:
        w = np.asarray(prim.weights)
        jn = np.asarray(prim.joints)
        for s in range(jn.shape[1]):               # ≤ 4 influence slots
            use = w[:, s] > 0
            if use.all():
                pts.append(np.asarray(prim.positions, dtype=np.float32))
                own.append(jn[:, s])
            elif use.any():
                pts.append(np.asarray(prim.positions, dtype=np.float32)[use])
                own.append(jn[use, s])
    x = np.concatenate(pts)
    owner = np.concatenate(own).astype(np.intp)
    if exact:
        order = np.argsort(owner, kind="stable")
        bounds = np.searchsorted(owner[order], np.arange(J + 1))
        picks = []
        for j in range(J):                        # one qhull call per joint (≤ a few hundred)
            rows = order[bounds[j]:bounds[j + 1]]
            if rows.size:
                picks.append(rows[_hull_vertices(x[rows].astype(np.float64))])
        pick = np.concatenate(picks)
    else:
        joint_of, corners = _box_corners(x, owner, J)
        x = np.concatenate([x, corners.astype(np.float32)])
        owner = np.concatenate([owner, joint_of])
        pick = np.concatenate([np.arange(J + int(np.count_nonzero(parent >= 0))),
                               x.shape[0] - corners.shape[0] + np.arange(corners.shape[0])])
    joint, rest = owner[pick], x[pick].astype(np.float64)
    inv = skeleton.inverse_bind()[joint]
    local = np.einsum("pij,pj->pi", inv[:, :3, :3], rest) + inv[:, :3, 3]

    # reach: farthest probe (own or descendant's) from each joint, walking probes up the chain
    reach = np.zeros(J)
    cur, at = joint.copy(), rest
    while cur.size:
        np.maximum.at(reach, cur, np.linalg.norm(at - pivot[cur], axis=1))
        up = parent[cur] >= 0
        cur, at = parent[cur[up]], at[up]
    return Probes(joint=joint, local=local, rest=rest, reach=reach)


def probe_world(world: np.ndarray, pr: Probes) -> np.ndarray:
    """World positions (K, P, 3) of the probes under joint world matrices (K, J, 4, 4)."""
    W = world[:, pr.joint]
    return np.einsum("kpij,pj->kpi", W[..., :3, :3], pr.local) + W[..., :3, 3]


# ---------------------------------------------------------------------------- decimation

@dataclass(frozen=True)
class DecimationReport:
    distance: float
    threshold_m: float           # movement that counts as error_px pixels at this distance
    keys_dense: int              # K × J
    keys_kept: int               # Σ_j |keys[j]|
    max_error_px: float          # bound on composed poses (box-corner probes) vs the dense clip
    iterations: int              # playback-check rounds that added keys
    seconds: float

    @property
    def kept_fraction(self) -> float:
        return self.keys_kept / max(self.keys_dense, 1)


def _schedule(rotations: np.ndarray, reach: np.ndarray, threshold: float) -> np.ndarray:
    """The paper's walk: bool (K, J) kept keys. Loops over frames, vectorised over joints."""
    K, J = rotations.shape[:2]
    step = quat_angle(rotations[1:], rotations[:-1]) * reach[None]    # (K−1, J) metres
    kept = np.zeros((K, J), dtype=bool)
    kept[0] = kept[-1] = True
    P = np.zeros(J)
    for k in range(1, K - 1):
        P += step[k - 1]
        hit = P > threshold
        kept[k] = hit
        P[hit] = 0.0
    return kept


def _errors(skeleton, pr, rotations, kept, interpolation, dense_x):
    rec = play_keys(rotations, kept, interpolation)
    x = probe_world(pose_world(skeleton, rec), pr)
    return rec, np.linalg.norm(x - dense_x, axis=2)                    # (K, P) metres


def decimate(skeleton: Skeleton, primitives: list[Primitive], dense: Clip, distance: float,
             options: LodOptions = LOD_DEFAULTS, name: str | None = None,
             pr: Probes | None = None) -> tuple[Clip, DecimationReport]:
    """The dense clip with a per-joint key schedule for `distance` whose playback stays within
    options.error_px pixels (see the module doc). distance 0 or error_px 0 keep every key."""
    t0 = time.perf_counter()
    rot = unit_quat(np.asarray(dense.rotations, dtype=np.float64))
    K, J = rot.shape[:2]
    px = pixel_size(distance, options)
    threshold = options.error_px * px
    name = dense.name if name is None else name
    if threshold <= 0.0 or K <= 2:
        clip = replace(dense, name=name, interpolation=options.interpolation, keys=None)
        return clip, DecimationReport(distance, threshold, K * J, K * J, 0.0, 0,
                                      time.perf_counter() - t0)
    pr = probes(skeleton, primitives) if pr is None else pr
    dense_x = probe_world(pose_world(skeleton, rot), pr)
    # The paper's rule bounds the hold (STEP) error. Slerp's chord error over the same key
    # spacing is far smaller, so under LINEAR the walk runs against a looser threshold and the
    # playback check below adds the keys the bound still needs (fewer keys in total).
    scale = options.linear_schedule_scale if options.interpolation == "LINEAR" else 1.0
    kept = _schedule(rot, pr.reach, threshold * scale)

    parent = np.asarray(skeleton.parent, dtype=np.int64)
    pivot = np.asarray(skeleton.bind_world)[:, :3, 3]
    limit = threshold * (1.0 - 1e-9)
    iterations = 0
    rec, err = _errors(skeleton, pr, rot, kept, options.interpolation, dense_x)
    while (err > limit).any():
        if iterations >= options.max_iterations:   # give up gracefully: key the frames fully
            bad_k = np.flatnonzero((err > limit).any(axis=1))
            kept[bad_k] = True
        else:
            kk, pp = np.nonzero(err > limit)
            ang = quat_angle(rec, rot)                                  # (K, J) local error
            cur = pr.joint[pp].copy()
            best, best_c = cur.copy(), np.full(cur.shape, -1.0)
            alive = np.ones(cur.shape, dtype=bool)
            while alive.any():                                          # one pass per depth
                c = ang[kk, cur] * np.linalg.norm(pr.rest[pp] - pivot[cur], axis=1)
                better = alive & (c > best_c)
                best[better], best_c[better] = cur[better], c[better]
                alive &= parent[cur] >= 0
                cur = np.where(alive, parent[cur], cur)
            # Douglas–Peucker style: per joint, only the worst frame between two of its kept
            # keys gets a key this round (one key fixes its neighbours too under LINEAR).
            seg = np.cumsum(kept, axis=0)[kk, best]
            group = best.astype(np.int64) * (K + 1) + seg
            order = np.lexsort((-best_c, group))
            first = order[np.r_[True, group[order][1:] != group[order][:-1]]]
            kept[kk[first], best[first]] = True
        iterations += 1
        rec, err = _errors(skeleton, pr, rot, kept, options.interpolation, dense_x)

    keys = [np.flatnonzero(kept[:, j]) for j in range(J)]
    clip = replace(dense, name=name, interpolation=options.interpolation, keys=keys)
    report = DecimationReport(distance, threshold, K * J, int(kept.sum()),
                              float(err.max() / px) if px > 0 else 0.0, iterations,
                              time.perf_counter() - t0)
    return clip, report


def measure_error_px(skeleton: Skeleton, primitives: list[Primitive], dense: Clip, clip: Clip,
                     distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Max on-screen error (pixels at `distance`) of `clip`'s playback against `dense`, measured
    on the probes of composed poses — an independent check of a decimated clip."""
    rot = unit_quat(np.asarray(dense.rotations, dtype=np.float64))
    if clip.keys is None:
        return 0.0
    kept = kept_mask(clip)
    pr = probes(skeleton, primitives, exact=True)
    dense_x = probe_world(pose_world(skeleton, rot), pr)
    _, err = _errors(skeleton, pr, rot, kept, clip.interpolation, dense_x)
    px = pixel_size(distance, options)
    return float(err.max() / px) if px > 0 else 0.0


# ---------------------------------------------------------------------------- geometric LODs

# Geometric LODs are cut from LOD0's tree within triangle budgets: lod_budget.py, lod_leaves.py.


# ---------------------------------------------------------------------------- the paper's table

def leaf_vertex_joints(lod: Lod) -> np.ndarray:
    """Leaf vertices carried per joint (J,), from the "leaves" primitive's first influence."""
    J = len(lod.skeleton.names)
    counts = np.zeros(J, dtype=np.int64)
    for p in lod.primitives:
        if p.name == "leaves" and len(p.joints):
            counts += np.bincount(np.asarray(p.joints[:, 0], dtype=np.int64), minlength=J)
    return counts


def _keys_per_joint(clip: Clip | None, n_joints: int) -> np.ndarray:
    """Keys each joint's track keeps (J,); zeros without a clip."""
    if clip is None:
        return np.zeros(n_joints, dtype=np.int64)
    K = len(clip.times)
    return np.full(n_joints, K) if clip.keys is None else np.array([len(k) for k in clip.keys])


def leaf_updates(lod: Lod) -> tuple[int, float]:
    """(leaf vertices, leaf-vertex updates per frame on average) of one LOD: the CPU method's
    cost, Σ_j kept keys_j × leaf vertices on joint j / keys; without a clip nothing moves."""
    per_joint = leaf_vertex_joints(lod)
    clip = lod.clips[0] if lod.clips else None
    K = len(clip.times) if clip is not None else 0
    if K == 0:
        return int(per_joint.sum()), 0.0
    kept = _keys_per_joint(clip, len(per_joint))
    return int(per_joint.sum()), float(np.sum(kept * per_joint) / K)


def lod_table_row(lod: Lod, options: LodOptions = LOD_DEFAULTS) -> dict:
    """One row of the Table-3 analogue: keys kept, max error (measured here, on the LOD's own
    clip against its dense rotations), the CPU method's leaf-vertex updates per frame
    (Σ_j kept keys_j × leaf vertices_j / frames) next to all leaf vertices (the all-GPU
    method's cost per frame), joints, triangles."""
    clip = lod.clips[0] if lod.clips else None
    J = len(lod.skeleton.names)
    K = len(clip.times) if clip is not None else 0
    kept = _keys_per_joint(clip, J)
    leaf_vertices, updates = leaf_updates(lod)
    error = 0.0
    if clip is not None and clip.keys is not None:
        dense = replace(clip, keys=None)
        error = measure_error_px(lod.skeleton, lod.primitives, dense, clip, lod.distance, options)
    row = {
        "distance_m": lod.distance,
        "clip": clip.name if clip else None,
        "keys_kept": int(kept.sum()),
        "keys_dense": int(K * J),
        "keys_kept_pct": round(float(100.0 * kept.sum() / max(K * J, 1)), 2),
        "max_error_px": round(error, 4),
        "leaf_vertex_updates_per_frame": round(updates, 1),
        "leaf_vertices": leaf_vertices,
        "joints": J,
        "triangles": int(sum(len(p.indices) // 3 for p in lod.primitives)),
        "screen_coverage": round(float(lod.screen_coverage), 4),
    }
    return row
