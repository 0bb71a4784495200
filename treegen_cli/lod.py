"""LOD: when each LOD takes over, its leaf update schedule as keyframe decimation, and the
geometric LODs.

**Switches.** By default a tree's LODs switch on its height on screen, as engines' LOD groups
do: LOD k+1 takes over when the tree's height falls below `screen[k]` of the screen height
(0.5 / 0.25 / 0.1), i.e. from distance height / (screen[k] · 2·tan(fov_y/2)) of the centre of
its bounds (`switch_distances`); `distances` forces metres instead.

**Schedules.** The paper (Kondo et al.) updates a branch's leaves only when their accumulated
on-screen movement would be visible. Baked into a clip, a schedule is a per-joint set of kept
keys (first and last always kept, so the clip loops):

  * "bounded" (default): slerp (LINEAR) between kept keys, with a perspective-true bound.
    Every skinned vertex, played back and composed through the hierarchy, stays within
    error_px pixels of the dense clip on every frame, seen by a pinhole camera (fov, width)
    anywhere at the LOD's switch distance d from the centre of the tree's bounds, looking at
    that centre, in any direction. With R the farthest any vertex gets from that centre over
    the clip, a point is at depth ≥ d − R and at most atan(R/√(d² − R²)) off axis, so a
    movement δ shows as at most f·δ·d / ((d − R)·√(d² − R²)) pixels, f = width/2 / tan(fov/2)
    (`near_pixel_size`). Keys are found Douglas–Peucker style on the composed hierarchy
    (`decimate`); the camera inside that sphere (d ≤ R) keeps every key.
  * "bounded-step": the same bound with keys held (STEP), as the paper's engine plays them,
    against the dense clip played the same way (every frame held until the next).
  * "paper": the paper's rule as written, unchecked: per joint accumulate P, the movement its
    own rotation gives the geometry it carries; keep a key when P/d > i·tan(fov_x)/width
    (i = error_px), reset P; STEP. Its measured error is reported, not bounded.

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
from .skeleton import depth_levels, pose_world, trs

SCHEDULES = ("bounded", "bounded-step", "paper")


@dataclass(frozen=True)
class LodOptions:
    """View and error model, and the per-LOD coarsening tables (index = LOD; last repeats).

    screen: tree height / screen height below which LOD1, LOD2, … take over (descending);
    distances: metres from the centre of the tree's bounds from which each LOD is used,
    ascending, LOD0 first (0 → its clip is dense); when given it replaces `screen`. fov_deg is
    horizontal, width in pixels, aspect = width/height (the vertical fov for `screen`)."""

    distances: tuple[float, ...] | None = None
    screen: tuple[float, ...] = (0.5, 0.25, 0.1)
    fov_deg: float = 60.0
    width: int = 1920
    error_px: float = 1.0
    schedule: str = "bounded"  # see the module doc
    aspect: float = 16.0 / 9.0
    sides: tuple[tuple[int, ...], ...] = ((16, 8, 6, 4, 3), (8, 6, 4, 3), (6, 4, 3), (4, 3))
    joint_fraction: tuple[float, ...] = (1.0, 0.5, 0.25, 0.125)  # × the joint budget
    triangles: tuple[float, ...] = (1.0, 0.5, 0.15, 0.05)  # × LOD0's triangles (lod_budget.py)
    max_iterations: int = 200  # playback-check refinement rounds per level

    def __post_init__(self) -> None:
        d = self.distances
        if d is not None:
            shown = ",".join(f"{x:g}" for x in d) or "(none)"
            if not d or any(not math.isfinite(x) or x < 0 for x in d) or list(d) != sorted(d):
                raise OptionError(
                    "distances",
                    shown,
                    "give one or more ascending distances in metres, each >= 0",
                    "--lod-distances",
                )
            if len(set(d)) != len(d):
                raise OptionError("distances", shown, "distances repeat", "--lod-distances")
        s = self.screen
        if (
            (d is None and not s)
            or any(not (math.isfinite(x) and 0.0 < x <= 100.0) for x in s)
            or list(s) != sorted(s, reverse=True)
            or len(set(s)) != len(s)
        ):
            raise OptionError(
                "screen",
                ",".join(f"{x:g}" for x in s) or "(none)",
                "give descending fractions of the screen height, each in (0, 100], e.g. 0.5,0.25,0.1",
                "--lod-screen",
            )
        if not 0.0 < self.fov_deg < 180.0:
            raise OptionError(
                "fov_deg", self.fov_deg, "the horizontal field of view must be in (0, 180) degrees", "--fov"
            )
        if self.schedule == "paper" and self.fov_deg >= 90.0:
            raise OptionError(
                "fov_deg", self.fov_deg, "the paper's tan(fov) form needs fov < 90 degrees", "--fov"
            )
        if not 1 <= self.width <= 1_000_000:
            raise OptionError("width", self.width, "screen width must be in 1..1000000 pixels", "--width")
        if not (math.isfinite(self.error_px) and 0.0 <= self.error_px <= 1000.0):
            raise OptionError("error_px", self.error_px, "allowed range 0..1000 pixels", "--error-px")
        if self.schedule not in SCHEDULES:
            raise OptionError("schedule", self.schedule, f"use one of {', '.join(SCHEDULES)}", "--schedule")
        if not (self.aspect > 0 and self.max_iterations >= 1):
            raise TreegenError("LOD aspect must be > 0 and max_iterations >= 1")
        if (
            min(self.joint_fraction) <= 0
            or max(self.joint_fraction) > 1
            or min(min(s) for s in self.sides) < 3
        ):
            raise TreegenError("LOD tables: joint_fraction in (0, 1], sides >= 3")
        t = self.triangles
        if not t or any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in t):
            raise TreegenError(
                f"--lod-triangles {','.join(f'{x:g}' for x in t) or '(none)'}: "
                "give fractions of LOD0's triangles, each in (0, 1]"
            )

    @property
    def interpolation(self) -> str:
        """How the kept keys are played: slerp for "bounded", held for the others."""
        return "LINEAR" if self.schedule == "bounded" else "STEP"

    @property
    def count(self) -> int:
        """Number of LODs."""
        return len(self.distances) if self.distances is not None else len(self.screen) + 1


LOD_DEFAULTS = LodOptions()


def _at(table: tuple, index: int):
    return table[min(index, len(table) - 1)]


def _tan_half_fov_y(options: LodOptions) -> float:
    return math.tan(0.5 * math.radians(options.fov_deg)) / options.aspect


def switch_distances(height: float, options: LodOptions = LOD_DEFAULTS) -> tuple[float, ...]:
    """Metres from which each LOD is used for a tree `height` metres tall: `distances` as
    given, else 0 and, per screen fraction s, the distance at which the tree's height fills s
    of the screen height: height / (s · 2·tan(fov_y/2)).

    Result (height 13 m, fov 60°, 16:9, screen 0.5/0.25/0.1): (0, 40.0, 80.1, 200.1) m."""
    if options.distances is not None:
        return tuple(float(x) for x in options.distances)
    return (0.0,) + tuple(screen_distance(height, s, options) for s in options.screen)


def screen_distance(
    height: float, share: float, options: LodOptions = LOD_DEFAULTS, of: float = 1.0
) -> float:
    """Metres from which a tree `height` metres tall fills `share` of `of` of the screen
    height: a fraction (of = 1, `--lod-screen`) or pixels (of = width / aspect, the
    impostor's switch_px). height · of / (share · 2·tan(fov_y/2))."""
    return float(height * of / (share * (2.0 * _tan_half_fov_y(options))))


def pixel_size(distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Metres spanned by one pixel at the centre of the screen at `distance`: 2·d·tan(fov/2)/width."""
    return 2.0 * distance * math.tan(0.5 * math.radians(options.fov_deg)) / options.width


def paper_pixel_size(distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """The paper's threshold per unit i: P/d > i·tan(fov_x)/width, i.e. d·tan(fov)/width
    (1.5× the exact pixel at 60°)."""
    return distance * math.tan(math.radians(options.fov_deg)) / options.width


def near_pixel_size(distance: float, radius: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Metres of movement that show as at most one pixel for every point within `radius` of a
    centre, seen by a pinhole camera at `distance` from that centre looking at it, from any
    direction (see the module doc): (d − R)·√(d² − R²) / (d·f). 0 when d ≤ R (the camera may be
    inside: no finite bound)."""
    d, r = float(distance), float(radius)
    if d <= r:
        return 0.0
    f = 0.5 * options.width / math.tan(0.5 * math.radians(options.fov_deg))
    return (d - r) * math.sqrt(d * d - r * r) / (d * f)


def screen_coverage(height: float, distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Screen height a tree of `height` metres fills at `distance`, as a fraction of the view
    (above 1 when it overflows the screen; not clamped, so glTF's MSFT_screencoverage switches
    LODs at the same distances as USD's distance heuristic)."""
    if distance <= 0:
        return 1.0
    return float(height / (2.0 * distance * _tan_half_fov_y(options)))


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
        return ConvexHull(points, qhull_options="QJ").vertices  # flat: joggled corners


def _box_corners(x: np.ndarray, owner: np.ndarray, J: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the 8 corners of a box around its points, aligned with their principal axes
    (a tight box for a branch's elongated cloud). Returns (joint (P,), corner positions (P, 3))."""
    order = np.argsort(owner.astype(np.uint16), kind="stable")  # radix sort: joints < 65536
    bounds = np.searchsorted(owner[order], np.arange(J + 1))
    xs = x[order]
    signs = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
    joints, corners = [], []
    for j in range(J):  # a few hundred joints, numpy within each
        pts = xs[bounds[j] : bounds[j + 1]].astype(np.float64)
        if not len(pts):
            continue
        mean = pts.mean(axis=0)
        d = pts - mean
        _, axes = np.linalg.eigh(d.T @ d + np.eye(3) * 1e-12)  # columns: principal axes
        u = d @ axes
        ext = np.where(signs, u.max(axis=0), u.min(axis=0))  # (8, 3)
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
    pts, own = (
        [pivot.astype(np.float32), pivot[parent >= 0].astype(np.float32)],
        [np.arange(J), parent[parent >= 0]],
    )
    for prim in primitives:
        w = np.asarray(prim.weights)
        jn = np.asarray(prim.joints)
        for s in range(jn.shape[1]):  # ≤ 4 influence slots
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
        for j in range(J):  # one qhull call per joint (≤ a few hundred)
            rows = order[bounds[j] : bounds[j + 1]]
            if rows.size:
                picks.append(rows[_hull_vertices(x[rows].astype(np.float64))])
        pick = np.concatenate(picks)
    else:
        joint_of, corners = _box_corners(x, owner, J)
        x = np.concatenate([x, corners.astype(np.float32)])
        owner = np.concatenate([owner, joint_of])
        pick = x.shape[0] - corners.shape[0] + np.arange(corners.shape[0])  # 8 per joint
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


def _corner_errors(world: np.ndarray, dense_world: np.ndarray, hom: np.ndarray) -> np.ndarray:
    """Largest squared distance (K, n) between a joint's 8 box corners posed by joint world
    matrices `world` and by the dense clip's `dense_world` (both (K, n, 4, 4)); hom (n, 4, 8)
    homogeneous corners in the joints' bind frames: one 3×4 @ 4×8 product per joint and frame."""
    diff = np.matmul((world - dense_world)[..., :3, :], hom)
    return np.einsum("kjac,kjac->kjc", diff, diff).max(axis=2)


def _ancestors(parent: np.ndarray) -> np.ndarray:
    """(J, D) table: column 0 the joint itself, then its parent, grandparent, … (the root
    repeats once reached); D = depth of the deepest joint + 1."""
    chain = [np.arange(parent.shape[0])]
    while True:
        up = parent[chain[-1]]
        nxt = np.where(up >= 0, up, chain[-1])
        if np.array_equal(nxt, chain[-1]):
            return np.stack(chain, axis=1)
        chain.append(nxt)


@dataclass(frozen=True, eq=False)
class _Model:
    """What the playback check needs of one LOD: skeleton tables, the probes' corners as
    homogeneous bind-frame points hom (J, 4, 8), ancestors (J, D) and lever[j, a], the
    farthest corner of joint j from the pivot of its a-th ancestor (rest pose)."""

    skeleton: Skeleton
    parent: np.ndarray
    levels: list
    hom: np.ndarray
    anc: np.ndarray
    lever: np.ndarray

    @classmethod
    def of(cls, skeleton: Skeleton, pr: Probes) -> "_Model":
        J = len(skeleton.names)
        parent = np.asarray(skeleton.parent, dtype=np.int64)
        hom = np.concatenate([pr.local.reshape(J, 8, 3).transpose(0, 2, 1), np.ones((J, 1, 8))], axis=1)
        anc = _ancestors(parent)
        pivot = np.asarray(skeleton.bind_world)[:, :3, 3]
        corners = pr.rest.reshape(J, 8, 3)
        lever = np.sqrt(((corners[:, None] - pivot[anc][:, :, None]) ** 2).sum(-1)).max(axis=2)
        return cls(skeleton, parent, depth_levels(parent), hom, anc, lever)


class _Playback:
    """The decimated clip as an engine plays it, kept up to date as keys are added: local
    rotations, composed world matrices and the corner errors (squared, (K, J)). Adding keys to
    some joints re-plays those joints and re-poses only them and their descendants."""

    def __init__(
        self,
        m: _Model,
        rot: np.ndarray,
        kept: np.ndarray,
        interpolation: str,
        dense_world: np.ndarray,
        work: int = 0,
    ):
        self.m, self.rot, self.kept, self.interp, self.dense_world = m, rot, kept, interpolation, dense_world
        self.rec = play_keys(rot, kept, interpolation)
        self.world = pose_world(m.skeleton, self.rec)
        self.err2 = _corner_errors(self.world, dense_world, m.hom)
        self.work = work + self.err2.size

    def update(self, nk: np.ndarray, nj: np.ndarray, prev: np.ndarray, nxt: np.ndarray) -> None:
        """New kept keys at frames nk of joints nj (already set in `kept`), each between kept
        keys prev and nxt: their playback changes only inside (prev, nxt), and so do the poses
        of their descendants there. Re-play those joints, re-pose and re-check only those
        (frame, joint) pairs — work proportional to what changed, not to the clip."""
        m = self.m
        K, J = self.err2.shape
        changed = np.unique(nj)
        self.rec[:, changed] = play_keys(self.rot[:, changed], self.kept[:, changed], self.interp)
        span = np.zeros((K + 1, J), dtype=np.int32)
        np.add.at(span, (prev + 1, nj), 1)
        np.add.at(span, (nxt, nj), -1)
        mask = np.cumsum(span[:K], axis=0) > 0  # (K, J) pairs to redo
        for level in m.levels[1:]:  # children follow parents
            mask[:, level] |= mask[:, m.parent[level]]
        rest_t = np.asarray(m.skeleton.rest_translation)
        for level in m.levels:
            kk, col = np.nonzero(mask[:, level])
            if not kk.size:
                continue
            j = level[col]
            local = trs(rest_t[j], self.rec[kk, j])
            p = m.parent[j]
            root = p < 0
            self.world[kk[root], j[root]] = local[root]
            self.world[kk[~root], j[~root]] = self.world[kk[~root], p[~root]] @ local[~root]
        kk, jj = np.nonzero(mask)
        diff = np.matmul((self.world[kk, jj] - self.dense_world[kk, jj])[:, :3, :], m.hom[jj])
        self.err2[kk, jj] = np.einsum("nac,nac->nc", diff, diff).max(axis=1)
        self.work += len(kk)


def _refine(
    m: _Model,
    rot: np.ndarray,
    dense_world: np.ndarray,
    kept: np.ndarray,
    limit: float,
    interpolation: str,
    max_iterations: int,
) -> tuple[np.ndarray, int, int]:
    """Add keys to `kept` (bool (K, J), modified) until every corner on every frame is within
    `limit` metres of the dense pose: each round, every failing frame blames the ancestor whose
    own rotation error moves the failing joint's corners most, and per blamed joint only the
    worst frame between two of its kept keys gets a key (Douglas–Peucker; under LINEAR one key
    fixes its neighbours too). Returns (squared errors (K, J), rounds, joint-frames checked)."""
    K, J = kept.shape
    limit2 = (limit * (1.0 - 1e-9)) ** 2
    play = _Playback(m, rot, kept, interpolation, dense_world)
    rounds = 0
    while (play.err2 > limit2).any():
        if rounds >= max_iterations:  # give up gracefully: key the frames fully
            kept[np.flatnonzero((play.err2 > limit2).any(axis=1))] = True
            play = _Playback(m, rot, kept, interpolation, dense_world, play.work)
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
                play = _Playback(m, rot, kept, interpolation, dense_world, play.work)
                rounds += 1
                continue
            k = np.arange(K)[:, None]  # the new keys' neighbouring kept keys
            prev = np.maximum.accumulate(np.where(sub, k, 0), axis=0)[nk, nc]
            nxt = np.minimum.accumulate(np.where(sub, k, K - 1)[::-1], axis=0)[::-1][nk, nc]
            kept[nk, nj] = True
            play.update(nk, nj, prev, nxt)
        rounds += 1
    return play.err2, rounds, play.work


def _bounded(
    m: _Model, rot: np.ndarray, dense_world: np.ndarray, limit: float, interpolation: str, max_iterations: int
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Kept keys (K, J) whose playback keeps every corner within `limit` metres, coarse to fine:
    the keys found on every other frame seed the check on all frames, recursively, so each
    level needs a few rounds and the total cost is about twice one pass over the clip — linear
    in its length (starting from the end keys alone needs log2 K rounds over all frames)."""
    K, J = rot.shape[:2]
    kept = np.zeros((K, J), dtype=bool)
    kept[0] = kept[-1] = True
    rounds = work = 0
    if K > 33:
        sub = np.unique(np.r_[np.arange(0, K, 2), K - 1])
        sub_kept, _, rounds, work = _bounded(
            m, rot[sub], dense_world[sub], limit, interpolation, max_iterations
        )
        kept[sub] = sub_kept
    err2, r, w = _refine(m, rot, dense_world, kept, limit, interpolation, max_iterations)
    return kept, err2, rounds + r, work + w


def keys_within(
    skeleton: Skeleton, primitives: list[Primitive], rotations: np.ndarray, limit: float
) -> np.ndarray:
    """Kept keys (K, J) of the dense `rotations` (K, J, 4, unit) whose slerp playback keeps
    every skinned vertex within `limit` metres of the dense pose on every frame (box-corner
    probes, composed through the hierarchy): the "bounded" schedule with a bound in metres
    rather than pixels (compressed files' LOD0, exchange/key_plan.py)."""
    m = _Model.of(skeleton, probes(skeleton, primitives))
    kept, _, _, _ = _bounded(
        m, rotations, pose_world(skeleton, rotations), limit, "LINEAR", LOD_DEFAULTS.max_iterations
    )
    return kept


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
    m = _Model.of(skeleton, pr)
    dense_world = pose_world(skeleton, rot)
    # the decimated pose strays by at most the centre-pixel threshold (≥ the near one)
    radius = _view_radius(primitives, dense_world, m.hom) + options.error_px * pixel_size(distance, options)
    near = near_pixel_size(distance, radius, options)
    if options.schedule == "paper":
        threshold = options.error_px * paper_pixel_size(distance, options)
        kept = _schedule(rot, pr.reach, threshold)
        err2 = _Playback(m, rot, kept, interp, dense_world).err2
        rounds, work = 0, err2.size
    else:
        threshold = options.error_px * near
        if threshold <= 0.0:
            return dense_clip(radius)
        kept, err2, rounds, work = _bounded(m, rot, dense_world, threshold, interp, options.max_iterations)
    keys = [np.flatnonzero(kept[:, j]) for j in range(J)]
    clip = replace(dense, name=name, interpolation=interp, keys=keys)
    error = float(np.sqrt(err2.max()) / near) if near > 0 else math.inf
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


PAPER_DISTANCES = (30.0, 130.0)  # the paper's Table 3


def animation_bytes(clip: Clip | None, n_joints: int) -> int:
    """Bytes the glTF writer stores for the clip's rotation keys: float32 xyzw per kept key
    and joint, plus one float32 time accessor per distinct key set (tracks with the same
    schedule share it); every joint counted as moving."""
    if clip is None:
        return 0
    K = len(clip.times)
    if clip.keys is None:
        return 16 * K * n_joints + 4 * K
    sets = {np.asarray(k, np.int64).tobytes(): len(k) for k in clip.keys}
    return int(16 * sum(len(k) for k in clip.keys) + 4 * sum(sets.values()))


def schedule_rows(lod: Lod, distances=PAPER_DISTANCES, options: LodOptions = LOD_DEFAULTS) -> list[dict]:
    """The paper's Table 3 for one LOD's dense clip: per distance, the bounded schedule and
    the paper's rule side by side — keys kept, animation bytes, measured max error
    (perspective-true, `measure_error_px`) and leaf-vertex updates per frame."""
    dense = replace(lod.clips[0], keys=None)
    pr = probes(lod.skeleton, lod.primitives)
    J = len(lod.skeleton.names)
    rows = []
    for d in distances:
        for schedule in ("bounded", "paper"):
            opts = replace(options, schedule=schedule)
            clip, rep = decimate(lod.skeleton, lod.primitives, dense, d, opts, pr=pr)
            err = measure_error_px(lod.skeleton, lod.primitives, dense, clip, d, opts)
            _, updates = leaf_updates(replace(lod, clips=[clip]))
            rows.append(
                {
                    "distance_m": float(d),
                    "schedule": schedule,
                    "keys_kept": rep.keys_kept,
                    "keys_dense": rep.keys_dense,
                    "keys_kept_pct": round(100.0 * rep.kept_fraction, 2),
                    "animation_bytes": animation_bytes(clip, J),
                    "animation_bytes_dense": animation_bytes(dense, J),
                    "max_error_px": round(err, 4),
                    "leaf_vertex_updates_per_frame": round(updates, 1),
                    "seconds": round(rep.seconds, 4),
                }
            )
    return rows


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
        "animation_bytes": animation_bytes(clip, J),
        "max_error_px": round(error, 4),
        "leaf_vertex_updates_per_frame": round(updates, 1),
        "leaf_vertices": leaf_vertices,
        "joints": J,
        "triangles": int(sum(len(p.indices) // 3 for p in lod.primitives)),
        "screen_coverage": round(float(lod.screen_coverage), 4),
    }
    imp = lod.impostor
    if imp is not None:  # the last LOD: crossed cards cut from a view atlas
        row["impostor"] = {
            "grid": imp.grid,
            "cell_px": imp.cell,
            "atlas_px": imp.grid * imp.cell,
            "card_m": round(2.0 * imp.radius, 3),
            "atlas_bytes": len(imp.albedo.png) + len(imp.normal_depth.png),
        }
    return row
